"""The repository's map and references: docs/architecture.md names every module of `mows`, and
nothing refers to a path outside the repository.

A module ``src/mows/<package>/<sub>/.../<name>.py`` counts as named when docs/architecture.md
holds its dotted path (``mows.package.sub.name``) or its slash path (``package/sub/name.py``,
with or without ``mows/`` or ``src/mows/`` before it), or when the table row of its top-level
package (the row whose first cell is `` `mows.package` ``) names, in backticks, the module and
every sub-package on the way to it. ``__init__.py`` files are not modules of their own here.
"""

import pathlib
import re
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
ARCHITECTURE = ROOT / "docs" / "architecture.md"
OUTSIDE = ".." + "/shared"  # spelt in two parts so that this file does not find itself
LINK = re.compile(r"\]\(([^)\s]+)\)")
TEXT_SUFFIXES = {".py", ".md", ".txt", ".toml", ".yaml", ".yml", ".json", ".cfg", ".xml", ".sh", ".bash", ".msg"}
TEXT_NAMES = {"Makefile", "CMakeLists.txt", "README.md", "constraints.txt", "requirements.txt"}


def modules() -> list[pathlib.Path]:
    package = ROOT / "src" / "mows"
    return sorted(p.relative_to(package) for p in package.rglob("*.py") if p.name != "__init__.py")


def package_rows(text: str) -> dict[str, str]:
    """Each top-level package's table row in docs/architecture.md, by package name."""
    rows: dict[str, str] = {}
    for line in text.splitlines():
        if not line.startswith("|"):
            continue
        first_cell = line.split("|")[1]
        for name in re.findall(r"`mows\.([a-z_]+)`", first_cell):
            rows[name] = rows.get(name, "") + line
    return rows


def is_named(module: pathlib.Path, text: str, rows: dict[str, str]) -> bool:
    parts = module.with_suffix("").parts
    dotted = "mows." + ".".join(parts)
    slash = "/".join(parts) + ".py"
    if re.search(re.escape(dotted) + r"(?![\w])", text) or re.search(r"(?<![\w/])" + re.escape(slash), text):
        return True
    if re.search(r"(?:^|[\s`(])(?:src/)?mows/" + re.escape(slash), text):
        return True
    if len(parts) == 1:
        return False
    row = rows.get(parts[0], "")
    return all(f"`{part}`" in row for part in parts[1:])


def test_architecture_names_every_module():
    text = ARCHITECTURE.read_text(encoding="utf-8")
    rows = package_rows(text)
    missing = [str(m) for m in modules() if not is_named(m, text, rows)]
    assert not missing, f"docs/architecture.md does not name these modules of src/mows/: {missing}"


def test_the_rule_sees_a_module_missing():
    text = "| `mows.physics` | x | `probe`, `field` (`sources`) | records |"
    rows = package_rows(text)
    assert is_named(pathlib.Path("physics/probe.py"), text, rows)
    assert is_named(pathlib.Path("physics/sources.py"), text, rows)
    assert not is_named(pathlib.Path("physics/potential.py"), text, rows)
    assert not is_named(pathlib.Path("sim/probe.py"), text, rows)
    assert not is_named(pathlib.Path("physics/extra/probe.py"), text, rows)
    assert is_named(pathlib.Path("physics/extra/probe.py"), "see `mows.physics.extra.probe`", {})


def tracked_files() -> list[pathlib.Path]:
    try:
        listed = subprocess.run(
            ["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True, text=True
        ).stdout.split("\0")
        files = [ROOT / name for name in listed if name]
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout: the tracked files are unknown")
    return [f for f in files if f.is_file() and (f.suffix in TEXT_SUFFIXES or f.name in TEXT_NAMES)]


def test_nothing_refers_outside_the_repository():
    offenders = []
    for path in tracked_files():
        text = path.read_text(encoding="utf-8", errors="replace")
        if OUTSIDE in text:
            offenders.append(f"{path.relative_to(ROOT)}: {OUTSIDE}")
        if path.suffix != ".md":
            continue
        for target in LINK.findall(text):
            target = target.split("#")[0]
            if not target or re.match(r"[a-z]+:", target):
                continue
            resolved = (path.parent / target).resolve()
            if not resolved.is_relative_to(ROOT):
                offenders.append(f"{path.relative_to(ROOT)}: link to {target}")
    assert not offenders, f"references to paths outside the repository: {offenders}"


def test_the_tests_mirror_the_packages_of_mows():
    """Each package of ``mows`` has its tests in the folder of its name, and every folder of
    tests but the nodes' (``ros``) is one of them: a newcomer finds a module's tests where the
    module is."""
    packages = {p.name for p in (ROOT / "src" / "mows").iterdir() if (p / "__init__.py").is_file()}
    folders = {p.name for p in (ROOT / "tests").iterdir() if p.is_dir() and any(p.glob("test_*.py"))}
    assert folders - {"ros"} == packages
