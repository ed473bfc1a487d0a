"""The core library ``mows`` never loads rclpy when imported, not even through a dependency.

Its source never imports rclpy either: the import contract "mows is free of ROS"
(pyproject.toml, checked by `make lint`).
"""

import json
import subprocess
import sys
from pathlib import Path

import mows

SOURCE = Path(mows.__file__).parent
FORBIDDEN = "rclpy"


def mows_modules() -> list[str]:
    """Every module of the package; __main__ is left out, importing it would run it."""
    return sorted(
        ".".join(("mows", *path.relative_to(SOURCE).with_suffix("").parts)).removesuffix(".__init__")
        for path in SOURCE.rglob("*.py")
        if path.stem != "__main__"
    )


def test_importing_every_module_loads_no_rclpy():
    modules = mows_modules()
    assert "mows.device.recording.bags" in modules
    code = (
        "import importlib, json, sys\n"
        f"for name in {modules!r}:\n"
        "    importlib.import_module(name)\n"
        "print(json.dumps(sorted(sys.modules)))\n"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    loaded = json.loads(run.stdout.splitlines()[-1])
    assert set(modules) <= set(loaded)
    assert [name for name in loaded if name.split(".")[0] == FORBIDDEN] == []
