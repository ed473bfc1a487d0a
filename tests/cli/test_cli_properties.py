"""Property: whatever is wrong with a table, a probe file, a scenario or a plugin's output, the
command exits 2 with one line and no traceback, and its input files are byte-identical
afterwards. Every generated input is broken on purpose, in one way drawn at random."""

import contextlib
import io
import math
import pathlib
import tempfile

import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from mows.cli.main import main

TABLE = (pathlib.Path(__file__).parents[1] / "lab" / "data" / "demo_sweep.csv").read_bytes()
HEADER, *ROWS = TABLE.decode().splitlines()
COLUMNS = HEADER.split(",")
PROBE = {"moment_am2": 0.89e-3, "magnet_mass_kg": 7.2e-6, "spring_nm_per_rad": 1.36e-5, "f00_hz": None}
SETTINGS = settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow])

NOT_A_NUMBER = st.one_of(
    st.text(min_size=1, max_size=8).filter(lambda t: not _is_number(t)),
    st.none(),
    st.booleans(),
    st.lists(st.integers(), max_size=3),
)


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def run(files: dict, arguments) -> tuple[int, str]:
    """Write ``files`` (name → bytes) into a fresh directory, run ``mows`` with ``arguments``
    (names replaced by paths); the exit status and stderr, after checking nothing changed."""
    with tempfile.TemporaryDirectory() as directory:
        paths = {name: pathlib.Path(directory) / name for name in files}
        for name, data in files.items():
            paths[name].write_bytes(data)
        err = io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            status = main([str(paths[a]) if a in paths else a for a in arguments])
        for name, data in files.items():
            assert paths[name].read_bytes() == data, f"{name} changed"
    return status, err.getvalue()


def assert_one_line_refusal(status: int, err: str) -> None:
    assert status == 2, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err


# --- tables ---------------------------------------------------------------------------------
@st.composite
def broken_tables(draw) -> bytes:
    rows = [row.split(",") for row in ROWS]
    how = draw(st.sampled_from(["cell", "column", "short row", "not utf-8", "negative", "empty", "header only"]))
    row, column = draw(st.integers(0, len(rows) - 1)), draw(st.integers(0, 2))  # a required column
    header = list(COLUMNS)
    if how == "cell":
        rows[row][column] = draw(
            st.text(min_size=1, max_size=6).filter(
                lambda t: (
                    not _is_number(t)
                    and "," not in t
                    and "\n" not in t
                    and "\r" not in t
                    and '"' not in t
                    and t.strip()
                )
            )
        )
    elif how == "column":
        del header[column]
        for cells in rows:
            del cells[column]
    elif how == "short row":
        rows[row] = rows[row][: draw(st.integers(1, len(header) - 1))]
    elif how == "negative":
        rows[row][2] = repr(-draw(st.floats(0.0, 1.0)))  # f_std_hz must be > 0
    elif how == "empty":
        return draw(st.sampled_from([b"", b"\n\n", b"\xef\xbb\xbf"]))
    elif how == "header only":
        rows = []
    text = "\n".join([",".join(header)] + [",".join(cells) for cells in rows]).encode()
    if how == "not utf-8":
        at = draw(st.integers(0, len(text)))
        text = text[:at] + draw(st.sampled_from([b"\xff", b"\xe9", b"\xc3\x28"])) + text[at:]
    return draw(st.sampled_from([b"", b"\xef\xbb\xbf"])) + text


@SETTINGS
@given(broken_tables())
def test_a_broken_table_is_refused_in_one_line(table):
    assert_one_line_refusal(*run({"table.csv": table}, ["lab", "compare", "table.csv", "--no-cv"]))


# --- probe files ----------------------------------------------------------------------------
@st.composite
def broken_probes(draw) -> bytes:
    probe = {k: v for k, v in PROBE.items() if v is not None}
    how = draw(st.sampled_from(["not a number", "not finite", "unknown key", "not a mapping", "not YAML"]))
    key = draw(st.sampled_from(sorted(probe) + ["f00_hz", "damping_per_s"]))
    if how == "not a number":
        probe[key] = draw(NOT_A_NUMBER)
    elif how == "not finite":
        probe[key] = draw(st.sampled_from([math.nan, math.inf, -math.inf]))
    elif how == "unknown key":
        probe[
            draw(
                st.text("abcdefghijklmnopqrstuvwxyz_", min_size=1, max_size=12).filter(
                    lambda k: k not in PROBE and k not in ("damping_per_s", "lever_m", "inertia_kgm2")
                )
            )
            + "_x"
        ] = 1.0
    elif how == "not a mapping":
        return yaml.safe_dump(draw(st.lists(st.floats(allow_nan=False), max_size=3))).encode()
    else:
        return b"moment_am2: [1\n" + draw(st.binary(max_size=8)).replace(b"]", b"")
    return yaml.safe_dump(probe).encode()


@SETTINGS
@given(broken_probes())
def test_a_broken_probe_file_is_refused_in_one_line(probe):
    status, err = run(
        {"table.csv": TABLE, "probe.yaml": probe}, ["lab", "compare", "table.csv", "--probe", "probe.yaml", "--no-cv"]
    )
    assert_one_line_refusal(status, err)
    assert "probe.yaml" in err


# --- scenarios ------------------------------------------------------------------------------
SCENARIO_NUMBERS = [
    ("excitation", "amplitude_a"),
    ("excitation", "excite_s"),
    ("pose", "theta0_deg"),
    ("environment", "temperature_k"),
    ("noise", "sensor_white_t_per_rthz"),
    (None, "sample_rate_hz"),
]


@st.composite
def broken_scenarios(draw) -> bytes:
    section, key = draw(st.sampled_from(SCENARIO_NUMBERS))
    how = draw(st.sampled_from(["not a number", "not finite", "unknown key", "over the cap"]))
    value = {"not a number": draw(NOT_A_NUMBER), "not finite": draw(st.sampled_from([math.nan, math.inf]))}.get(how)
    if how == "unknown key":
        key, value = key + "_typo", 1.0
    elif how == "over the cap":
        section, key, value = "excitation", "amplitude_a", draw(st.floats(10.001, 1e6))
    scenario = {"name": "broken"}
    if section is None:
        scenario[key] = value
    else:
        scenario[section] = {key: value}
    return yaml.safe_dump(scenario).encode()


@SETTINGS
@given(broken_scenarios())
def test_a_broken_scenario_is_refused_in_one_line(scenario):
    status, err = run({"scene.yaml": scenario}, ["sim", "scene.yaml"])
    assert_one_line_refusal(status, err)
    assert "scene.yaml" in err


# --- plugin outputs -------------------------------------------------------------------------
PLUGIN_RESULTS = st.one_of(
    st.sampled_from(
        [
            "float('nan')",
            "float('inf')",
            "'fast'",
            "None",
            "[1.0, 2.0]",
            "{'frequency_hz'}",
            "{'frequency_hz': float('nan')}",
            "{'stiffness_nm_per_rad': 'stiff'}",
            "{'frequency_hz': [1.0, 2.0]}",
            "{'speed_hz': 1.0}",
            "1 / 0",
            "rows.no_such_column.sum()",
            "{'frequency_hz': rows.f_hz * float('inf')}",
        ]
    ),
    st.text("abc", min_size=1, max_size=4).map(lambda t: f"{{'frequency_hz': {t!r}}}"),
)


@SETTINGS
@given(PLUGIN_RESULTS)
def test_a_plugin_that_returns_garbage_is_refused_in_one_line(result):
    plugin = (
        "from mows.lab import effect\n\n"
        "@effect(name='garbage', parameters={'k': (0.0, -1.0, 1.0, 'Hz')})\n"
        f"def garbage(rows, k):\n    return {result}\n"
    ).encode()
    status, err = run(
        {"table.csv": TABLE, "plugin.py": plugin},
        ["lab", "add", "table.csv", "garbage", "--plugin", "plugin.py", "--no-cv"],
    )
    assert_one_line_refusal(status, err)
    assert "garbage" in err
