"""The core library ``mows`` never imports rclpy: not in its source, not when imported."""
import ast
import json
import subprocess
import sys
from pathlib import Path

import mows

SOURCE = Path(mows.__file__).parent
FORBIDDEN = "rclpy"


def imported_modules(path: Path) -> list[str]:
    """Absolute module names imported anywhere in the Python file at ``path``."""
    names = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0:
            names.append(node.module)
    return names


def mows_modules() -> list[str]:
    """Every module of the package; __main__ is left out, importing it would run it."""
    return sorted(
        ".".join(("mows", *path.relative_to(SOURCE).with_suffix("").parts)).removesuffix(
            ".__init__"
        )
        for path in SOURCE.rglob("*.py")
        if path.stem != "__main__"
    )


def test_the_scan_sees_an_rclpy_import(tmp_path):
    module = tmp_path / "m.py"
    module.write_text("def f():\n    from rclpy.node import Node\n")
    assert imported_modules(module) == ["rclpy.node"]


def test_no_source_file_imports_rclpy():
    offenders = [
        f"{path.relative_to(SOURCE)}: {name}"
        for path in SOURCE.rglob("*.py")
        for name in imported_modules(path)
        if name.split(".")[0] == FORBIDDEN
    ]
    assert offenders == []


def test_importing_every_module_loads_no_rclpy():
    modules = mows_modules()
    assert "mows.device.bags" in modules
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
