"""The README shows what `make demo` prints today: its demo block has the lines and the format of
a fresh demo's output, not its numbers (they move from run to run).

The demo runs once, as `make demo` runs it (`mows-demo`), with a shorter sweep (6 orientations ×
1 ring-down) that prints the same lines, and with ``--foxglove=0`` (the viz node on any free port;
`make demo DEMO_ARGS=--foxglove`), whose address line it must print once the node serves it
(the ``demo_session`` fixture, whose recording tests/ros/test_recording_conclusions.py reads).

The results table (header, the five components, the χ²/dof line) must match line for line in its
words and in each row's width, so that its columns line up as they do; every other line the
README shows must be a kind of line the demo prints."""

import re
from pathlib import Path

import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.xdist_group("realtime")]

ROOT = Path(__file__).parents[2]
NUMBER = re.compile(r"[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?")
TABLE_HEADER = "first principles"
TABLE_END = "χ²/dof: first principles"


def readme_demo_lines() -> list[str]:
    """The README's fenced block that holds the demo's results table."""
    blocks = re.findall(r"```\n(.*?)```", (ROOT / "README.md").read_text(), flags=re.S)
    return next(block for block in blocks if TABLE_END in block).splitlines()


def table(lines: list[str]) -> list[str]:
    start = next(i for i, line in enumerate(lines) if TABLE_HEADER in line and "published model" in line)
    end = next(i for i, line in enumerate(lines) if TABLE_END in line)
    return lines[start : end + 1]


def words(line: str) -> str:
    """A line with every number replaced by '#' and runs of blanks by one."""
    return " ".join(NUMBER.sub("#", line).split())


def kind(line: str) -> str:
    """What a line is about: its indentation and first word after the ``[graph]`` prefix."""
    match = re.match(r"(\[graph\]\s*)(\S*)", line)
    return match.group(1) + NUMBER.sub("#", match.group(2).split(":")[0]) if match else line


@pytest.fixture
def demo_lines(demo_session):
    return demo_session.lines


def test_the_readme_shows_a_demo_block_with_its_results_table():
    shown = table(readme_demo_lines())
    assert len(shown) == 7  # header, Bx, By, Gxx, Gxy, Gyy, χ²/dof


def without_note(line: str) -> str:
    """The χ²/dof line without the note the demo adds when first principles is far above 1 (a
    6-orientation sweep has few degrees of freedom, so that varies from run to run)."""
    return re.sub(r"\s+\(.*\)$", "", line)


def test_the_readme_results_table_has_the_demo_s_lines_and_format(demo_lines):
    shown, fresh = table(readme_demo_lines()), table(demo_lines)
    assert [words(without_note(line)) for line in shown] == [words(without_note(line)) for line in fresh]
    # The header and the five rows are fixed-width columns: the same width means they line up.
    assert [len(line) for line in shown[:-1]] == [len(line) for line in fresh[:-1]]


def test_every_line_the_readme_shows_is_a_line_the_demo_prints(demo_lines):
    printed = {kind(line) for line in demo_lines}
    assert [line for line in readme_demo_lines() if kind(line) not in printed] == []


def test_the_demo_prints_the_foxglove_address_once_the_viz_node_serves_it(demo_lines):
    addresses = [line for line in demo_lines if re.fullmatch(r"\[graph\] Foxglove: open ws://127\.0\.0\.1:\d+", line)]
    assert len(addresses) == 1, [line for line in demo_lines if "Foxglove" in line]
    port = int(addresses[0].rpartition(":")[2])
    assert port > 0  # the port the server took, not the 0 asked for


def test_the_demo_takes_foxglove_with_or_without_a_port():
    from mows_bringup.demo import parse_arguments
    from mows_bringup.nodes import FOXGLOVE_PORT

    assert parse_arguments([]).foxglove is None
    assert parse_arguments(["--foxglove"]).foxglove == FOXGLOVE_PORT
    assert parse_arguments(["--foxglove=0"]).foxglove == 0
    with pytest.raises(SystemExit):
        parse_arguments(["--foxglove=70000"])
