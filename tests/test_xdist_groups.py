"""The suite's own scheduling: tests marked with one xdist group run on one worker.

The real-time tests share the group "realtime" so that no two of them run side by side
(pyproject.toml). pytest-xdist 3.8.0 tells its scheduler a test's group by appending "@group"
to the test's node id on the worker. From pytest 9.2 on that change no longer takes effect,
and every group is silently spread over the workers
(https://github.com/pytest-dev/pytest-xdist/issues/1386). That is why
pytest is pinned to 9.1.1; this test fails if an upgrade loses the grouping again."""

import re
import subprocess
import sys

GROUPED = """
import pytest

pytestmark = pytest.mark.xdist_group("together")


@pytest.mark.parametrize("i", range(8))
def test_one_of_a_group(i):
    pass
"""


def test_a_group_runs_on_one_worker(tmp_path):
    (tmp_path / "test_grouped.py").write_text(GROUPED)
    (tmp_path / "pytest.ini").write_text("[pytest]\n")
    run = subprocess.run(
        [sys.executable, "-m", "pytest", "-v", "-p", "no:cacheprovider", "-n", "2", "--dist=loadgroup", "."],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert run.returncode == 0, run.stdout + run.stderr
    workers = re.findall(r"^\[(gw\d)\] .*PASSED", run.stdout, re.MULTILINE)
    assert len(workers) == 8 and len(set(workers)) == 1, run.stdout
