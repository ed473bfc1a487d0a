"""The repository's map and references: docs/architecture.md names every module of `mows` and of
the node packages, every module, package and definition it names exists, and nothing refers to
a path outside the repository.

In the map's tables a module is written ``name.py`` and a sub-package ``name/``. A module
``src/mows/<package>/<sub>/.../<name>.py`` counts as named when docs/architecture.md holds its
dotted path (``mows.package.sub.name``) or its slash path (``package/sub/name.py``, with or
without ``mows/`` or ``src/mows/`` before it), or when the table row of its top-level package
(the row whose first cell is `` `mows.package` ``) names, in backticks, the module (``name.py``)
and every sub-package on the way to it (``sub/``). A node package's module
``mows_x/mows_x/name.py`` counts as named by its path ``mows_x/name.py``, its dotted path
``mows_x.name`` or its name ``name.py`` in the layout row whose first cell names `` `mows_x/` ``.
``__init__.py`` files are not modules of their own here.

The other way round, a name is stale (:func:`stale_names`) when a package row names a module or
sub-package its package does not have, a dotted path ``mows.…`` or ``mows_x.…`` leads to no
module or to a name its module does not define, or a slash path ``….py`` is no file.
"""

import ast
import pathlib
import re
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
SRC = ROOT / "src"
ARCHITECTURE = ROOT / "docs" / "architecture.md"
OUTSIDE = ".." + "/shared"  # spelt in two parts so that this file does not find itself
LINK = re.compile(r"\]\(([^)\s]+)\)")
TEXT_SUFFIXES = {".py", ".md", ".txt", ".toml", ".yaml", ".yml", ".json", ".cfg", ".xml", ".sh", ".bash", ".msg"}
TEXT_NAMES = {"Makefile", "CMakeLists.txt", "README.md", "constraints.txt", "requirements.txt"}
# A dotted path into our packages, not part of a file name (config/mows.foxglove.json).
DOTTED = re.compile(r"(?<![\w./-])(mows(?:_[a-z]+)?(?:\.[A-Za-z_]\w*)+)")
SLASHED = re.compile(r"(?<![\w./-])((?:[\w-]+/)+\w+\.py)\b")
ROW_MODULE = re.compile(r"`(\w+)\.py`")
ROW_PACKAGE = re.compile(r"`(\w+)/`")


def modules() -> list[pathlib.Path]:
    package = SRC / "mows"
    return sorted(p.relative_to(package) for p in package.rglob("*.py") if p.name != "__init__.py")


def node_packages() -> list[str]:
    """The ROS packages with Python modules of their own (mows_driver, mows_bringup, ...)."""
    return sorted(
        p.parent.name for p in ROOT.glob("mows_*/mows_*/__init__.py") if p.parent.name == p.parent.parent.name
    )


def node_modules() -> list[pathlib.Path]:
    """Each node package's modules as ``mows_x/name.py``."""
    return sorted(
        pathlib.Path(name, p.name)
        for name in node_packages()
        for p in (ROOT / name / name).glob("*.py")
        if p.name != "__init__.py"
    )


def table_rows(text: str) -> list[tuple[list[str], str]]:
    """The table rows of docs/architecture.md that describe packages, each with the packages its
    first cell names: `` `mows.x` `` as ``x``, the layout's `` `mows_x/` `` as ``mows_x`` (a row
    may describe several)."""
    rows = []
    for line in text.splitlines():
        if not line.startswith("|"):
            continue
        first_cell = line.split("|")[1]
        names = re.findall(r"`mows\.([a-z_]+)`", first_cell) + re.findall(r"`(mows_[a-z]+)/`", first_cell)
        if names:
            rows.append((names, line))
    return rows


def package_rows(text: str) -> dict[str, str]:
    """Each package's table row (its rows joined), by package name (:func:`table_rows`)."""
    rows: dict[str, str] = {}
    for names, line in table_rows(text):
        for name in names:
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
    return f"`{parts[-1]}.py`" in row and all(f"`{part}/`" in row for part in parts[1:-1])


def is_named_node(module: pathlib.Path, text: str, rows: dict[str, str]) -> bool:
    package, name = module.parent.name, module.stem
    if re.search(r"(?<![\w/])" + re.escape(f"{package}/{name}.py"), text):
        return True
    if re.search(re.escape(f"{package}.{name}") + r"(?![\w])", text):
        return True
    return f"`{name}.py`" in rows.get(package, "")


def test_architecture_names_every_module():
    text = ARCHITECTURE.read_text(encoding="utf-8")
    rows = package_rows(text)
    missing = [str(m) for m in modules() if not is_named(m, text, rows)]
    missing += [str(m) for m in node_modules() if not is_named_node(m, text, rows)]
    assert not missing, f"docs/architecture.md does not name these modules: {missing}"


def test_every_name_in_the_architecture_exists():
    stale = stale_names(ARCHITECTURE.read_text(encoding="utf-8"))
    assert not stale, f"docs/architecture.md names what does not exist: {stale}"


def test_the_rule_sees_a_module_missing():
    text = "| `mows.physics` | x | `probe.py`, `field.py` (`sources.py`), `extra/` (`more.py`) | records |"
    rows = package_rows(text)
    assert is_named(pathlib.Path("physics/probe.py"), text, rows)
    assert is_named(pathlib.Path("physics/sources.py"), text, rows)
    assert not is_named(pathlib.Path("physics/potential.py"), text, rows)
    assert not is_named(pathlib.Path("sim/probe.py"), text, rows)
    assert not is_named(pathlib.Path("physics/other/probe.py"), text, rows)
    assert is_named(pathlib.Path("physics/extra/more.py"), text, rows)
    assert is_named(pathlib.Path("physics/extra/probe.py"), "see `mows.physics.extra.probe`", {})
    node_row = "| `mows_driver/`, `mows_mapper/` | the nodes: `node.py` translates |"
    node_rows = package_rows(node_row)
    assert is_named_node(pathlib.Path("mows_mapper/node.py"), node_row, node_rows)
    assert not is_named_node(pathlib.Path("mows_driver/requesters.py"), node_row, node_rows)
    assert is_named_node(pathlib.Path("mows_driver/requesters.py"), "`mows_driver.requesters`", {})


@pytest.mark.parametrize(
    "text, stale",
    [
        # a module or sub-package named in its package's row that the package does not have
        ("| `mows.sim` | x | `simulator.py`, `cycle.py` (one simulated cycle) | physics |", "mows.sim: cycle.py"),
        ("| `mows.device` | x | `stream/` (`session.py`), `loops/` | sim |", "mows.device: loops/"),
        ("| `mows_driver/` | the node: `node.py`, `gone.py` |", "mows_driver: gone.py"),
        # a dotted path to a module or a name that does not exist
        ("the cycle: `mows.sim.simulator.CycleSequencer`", "mows.sim.simulator.CycleSequencer"),
        ("`mows.sim.cycle.simulate_cycle`", "mows.sim.cycle.simulate_cycle"),
        ("`mows_ros.node.NoSuchNode`", "mows_ros.node.NoSuchNode"),
        (
            "the cycle (`mows.device.cycle.sequencer.CycleSequencer.no_such_step`)",
            "mows.device.cycle.sequencer.CycleSequencer.no_such_step",
        ),
        # a slash path that is no file
        ("# sim/cycle.py\nsimulate_cycle(device, ...)", "sim/cycle.py"),
    ],
)
def test_the_rule_sees_a_stale_name(text, stale):
    assert stale in stale_names(text)


def test_the_rule_passes_names_that_exist():
    text = (
        "| `mows.sim` | x | `scenario.py`, `kernel.py` | physics |\n"
        "| `mows.device` | x | `stream/` (`session.py`), `instruments/` (`hardware/`) | sim |\n"
        "`mows.physics.potential.ArcPotential.rest_angle_rad`, `mows.sweep.decompose`, `mows_bringup.lifecycle`, "
        "`mows.estimate.ringdown.fit_ringdowns` (re-exported), `config/mows.foxglove.json`, "
        "`mows/device/__init__.py`, `src/mows/sim/scenario.py`, `physics/probe.py`, "
        "`mows_driver/node.py`, `tests/test_docs_map.py`"
    )
    assert stale_names(text) == []


def stale_names(text: str) -> list[str]:
    """Every name in ``text`` (docs/architecture.md) that does not exist (module docstring)."""
    stale = []
    for packages, row in table_rows(text):
        folders = [folder for package in packages for folder in package_folders(package)]
        label = ", ".join(package_label(package) for package in packages)
        for module in ROW_MODULE.findall(row):
            if not any(any(folder.rglob(f"{module}.py")) for folder in folders):
                stale.append(f"{label}: {module}.py")
        for sub in ROW_PACKAGE.findall(row):
            if sub not in packages and not any(p.is_dir() for folder in folders for p in folder.rglob(sub)):
                stale.append(f"{label}: {sub}/")
    stale += [dotted for dotted in sorted(set(DOTTED.findall(text))) if not dotted_exists(dotted)]
    stale += [path for path in sorted(set(SLASHED.findall(text))) if not path_exists(path)]
    return stale


def package_label(package: str) -> str:
    return package if package.startswith("mows_") else f"mows.{package}"


def package_folders(package: str) -> list[pathlib.Path]:
    """Where a row's package keeps its modules: src/mows/x, or the node package's mows_x/mows_x."""
    if package.startswith("mows_"):
        return [ROOT / package / package]
    return [SRC / "mows" / package]


def dotted_exists(dotted: str) -> bool:
    """Whether ``mows.a.b.Name.member`` leads to a package or module and to names it defines
    (a member checked in a class's own body)."""
    parts = dotted.split(".")
    if parts[0] == "mows_msgs":
        return True  # generated by rosidl: no source here
    path = SRC / "mows" if parts[0] == "mows" else ROOT / parts[0] / parts[0]
    if not (path / "__init__.py").is_file():
        return False
    rest = parts[1:]
    while rest and (path / rest[0] / "__init__.py").is_file():
        path, rest = path / rest[0], rest[1:]
    source = path / "__init__.py"
    if rest and (path / f"{rest[0]}.py").is_file():
        source, rest = path / f"{rest[0]}.py", rest[1:]
    if not rest:
        return True
    body = ast.parse(source.read_text(encoding="utf-8")).body
    if rest[0] not in defined_names(body):
        return False
    if len(rest) == 1:
        return True
    classes = [node for node in body if isinstance(node, ast.ClassDef) and node.name == rest[0]]
    return not classes or rest[1] in defined_names(classes[0].body)


def defined_names(body: list[ast.stmt]) -> set[str]:
    """The names a module's or a class's body defines or imports."""
    names: set[str] = set()
    for node in body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Assign):
            names.update(t.id for t in node.targets if isinstance(t, ast.Name))
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names.update((alias.asname or alias.name).split(".")[0] for alias in node.names)
    return names


def path_exists(path: str) -> bool:
    """Whether a slash path is a file: from the repository, from src/, from src/mows/, or in a
    node package (``mows_driver/node.py``)."""
    first = path.split("/")[0]
    candidates = [ROOT / path, SRC / path, SRC / "mows" / path, ROOT / first / path]
    return any(candidate.is_file() for candidate in candidates)


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
