"""A stale commit journal is acted on only when every file in it is as its dead writer left it.

Requirement: a writer killed between its renames leaves a journal; the next write into that
folder puts the old pair back from it (tests/cli/test_cli_guards.py), but only when the journal
names files of its own folder and its own writer, its process is gone, none of its files is an
input of the command now writing, and each holds the bytes the journal recorded. In every other
case no byte of any file changes (every file under the test's folder hashed before and after,
the journal's and the other folders' too), nothing is removed that the journal's writer did not
make, and one warning names the journal: through the library's writer and through a command
(``mows sim --out new.npz``, as a user next runs one).
"""

import hashlib
import json
import os
import pathlib
import signal
import subprocess
import sys
import warnings

import pytest

from mows.cli.main import main
from mows.records.files import writing
from mows.records.journal import JournalLeft

OLD = "extends: paper_largest_spacing\nname: old {}\n"  # scenarios: the command can read them
KILLED_BETWEEN_RENAMES = """
import os, signal, sys
import mows.records.files as files
renamed = []
def replace(source, target):
    if os.path.basename(target) in ("a.yaml", "b.yaml"):
        if renamed:
            os.kill(os.getpid(), signal.SIGKILL)
        renamed.append(target)
    os.rename(source, target)
files.os.replace = replace
folder = sys.argv[1]
with files.writing([folder + "/a.yaml", folder + "/b.yaml"], force=True) as outputs:
    for temporary in outputs.temporaries:
        temporary.write_text("extends: paper_largest_spacing\\nname: new\\n")
"""


def state(folder: pathlib.Path) -> dict:
    """Every path under ``folder``: a file's SHA-256, a symbolic link's target, a directory's name."""
    snapshot = {}
    for path in sorted(folder.rglob("*")):
        if path.is_symlink():
            snapshot[path] = ("link", os.readlink(path))
        elif path.is_file():
            snapshot[path] = hashlib.sha256(path.read_bytes()).hexdigest()
        else:
            snapshot[path] = "directory"
    return snapshot


@pytest.fixture
def scene(tmp_path) -> pathlib.Path:
    """A folder whose a.yaml and b.yaml a writer was replacing when it was killed between the renames."""
    folder = tmp_path / "scene"
    folder.mkdir()
    for name in ("a", "b"):
        (folder / f"{name}.yaml").write_text(OLD.format(name))
    run = subprocess.run([sys.executable, "-c", KILLED_BETWEEN_RENAMES, str(folder)], timeout=120)
    assert run.returncode == -signal.SIGKILL
    assert "new" in (folder / "a.yaml").read_text() and (folder / "b.yaml").read_text() == OLD.format("b")
    return folder


def journal_of(folder: pathlib.Path) -> pathlib.Path:
    (journal,) = folder.glob(".*.commit")
    return journal


def write_new(folder: pathlib.Path, inputs=()) -> list[str]:
    """A new output in the folder through the library's writer; the warnings it gave."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with writing([folder / "new.txt"], inputs) as outputs:
            outputs.temporaries[0].write_text("new")
    return [str(w.message) for w in caught if issubclass(w.category, JournalLeft)]


def command_new(folder: pathlib.Path, capsys, scenario: str = "paper_largest_spacing") -> list[str]:
    """A new output in the folder from a command, ``mows sim SCENARIO --out new.npz``; its warnings."""
    status = main(["sim", scenario, "--out", str(folder / "new.npz")])
    err = capsys.readouterr().err
    assert status == 0, err
    return [line.removeprefix("mows sim: warning: ") for line in err.splitlines()]


def test_a_whole_journal_puts_the_old_pair_back(scene):
    assert write_new(scene) == []
    assert sorted(p.name for p in scene.iterdir()) == ["a.yaml", "b.yaml", "new.txt"]
    assert (scene / "a.yaml").read_text() == OLD.format("a") and (scene / "b.yaml").read_text() == OLD.format("b")


def edit_output(scene):
    """The output the dead writer renamed into place, edited by the user after the crash."""
    (scene / "a.yaml").write_text("extends: paper_largest_spacing\nname: edited by the user\n")


def journal_elsewhere(scene):
    """The journal's files named in another folder (absolute paths, as an older journal held)."""
    other = scene.parent / "other"
    other.mkdir()
    (other / "a.yaml").write_text("another folder's file")
    journal = journal_of(scene)
    document = json.loads(journal.read_text())
    for entry in document["entries"]:
        entry["directory"] = str(other)
    journal.write_text(json.dumps(document))


def journal_with_absolute_paths(scene):
    journal = journal_of(scene)
    document = json.loads(journal.read_text())
    for entry in document["entries"]:
        entry["output"] = str(scene.parent / "other.txt")
    (scene.parent / "other.txt").write_text("a file outside")
    journal.write_text(json.dumps(document))


def journal_of_an_older_format(scene):
    """The format without checksums: paths only, absolute."""
    journal = journal_of(scene)
    entries = json.loads(journal.read_text())["entries"]
    old = [
        {
            "temporary": str(scene / e["temporary"]),
            "output": str(scene / e["output"]),
            "replaced": e["replaced"] and str(scene / e["replaced"]),
        }
        for e in entries
    ]
    journal.write_text(json.dumps(old))


def copy_changed(scene):
    (replaced,) = scene.glob(".a.yaml.*.replaced")
    replaced.write_text("not the copy the writer made")


def output_now_a_link(scene):
    """The output replaced by a link to a file of the same bytes elsewhere: the file is not the writer's."""
    elsewhere = scene.parent / "elsewhere.yaml"
    elsewhere.write_bytes((scene / "a.yaml").read_bytes())
    (scene / "a.yaml").unlink()
    (scene / "a.yaml").symlink_to(elsewhere)


def journal_names_a_user_s_files(scene):
    """Its copy and its temporary named as files the writer did not make (the user's, with the
    very bytes the journal recorded): removing them would delete the user's."""
    journal = journal_of(scene)
    document = json.loads(journal.read_text())
    for entry in document["entries"]:
        for key, name in (("replaced", "notes.yaml"), ("temporary", "draft.yaml")):
            own = scene / entry[key] if entry[key] else None
            if own is not None and own.exists():
                (scene / name).write_bytes(own.read_bytes())
            entry[key] = name
    journal.write_text(json.dumps(document))


def journal_torn(scene):
    """A journal cut short (a full disk): it cannot say what its writer did."""
    journal = journal_of(scene)
    journal.write_text(journal.read_text()[:40])


STALE = [
    edit_output,
    journal_elsewhere,
    journal_with_absolute_paths,
    journal_of_an_older_format,
    copy_changed,
    output_now_a_link,
    journal_names_a_user_s_files,
    journal_torn,
]


@pytest.mark.parametrize("writer", ["library", "mows sim"])
@pytest.mark.parametrize("plant", STALE, ids=lambda f: f.__name__)
def test_a_journal_that_cannot_be_trusted_changes_no_byte(scene, capsys, plant, writer):
    plant(scene)
    before = state(scene.parent)
    left = write_new(scene) if writer == "library" else command_new(scene, capsys)
    after = state(scene.parent)
    new = scene / ("new.txt" if writer == "library" else "new.npz")
    del after[new]
    assert after == before
    assert len(left) == 1 and str(journal_of(scene)) in left[0], left


@pytest.mark.parametrize("writer", ["library", "mows sim"])
def test_a_journal_whose_output_the_command_reads_is_left(scene, capsys, writer):
    """The command now writing reads a.yaml: undoing the dead commit would delete its input."""
    before = state(scene.parent)
    if writer == "library":
        left = write_new(scene, inputs=[scene / "a.yaml"])
    else:
        left = command_new(scene, capsys, scenario=str(scene / "a.yaml"))
    after = state(scene.parent)
    del after[scene / ("new.txt" if writer == "library" else "new.npz")]
    assert after == before and len(left) == 1 and "input" in left[0], left


def test_the_journal_of_a_running_writer_is_left_quietly(scene):
    dead = journal_of(scene).name.split(".")[-2]
    for path in scene.glob(f".*.{dead}.*"):  # as if this (running) process were its writer
        path.rename(scene / path.name.replace(f".{dead}.", f".{os.getpid()}."))
    before = state(scene.parent)
    assert write_new(scene) == []
    after = state(scene.parent)
    del after[scene / "new.txt"]
    assert after == before


@pytest.mark.parametrize("writer", ["library", "mows sim"])
def test_a_user_s_files_named_like_a_writer_s_are_never_removed(tmp_path, capsys, writer):
    names = [".notes.txt.999999.commit", ".notes.txt.999998.writing", ".new.txt.999999.abcdefgh.partial.txt"]
    for name in names:
        (tmp_path / name).write_text("the user's own notes")
    before = state(tmp_path)
    left = write_new(tmp_path) if writer == "library" else command_new(tmp_path, capsys)
    after = state(tmp_path)
    del after[tmp_path / ("new.txt" if writer == "library" else "new.npz")]
    assert after == before
    assert sorted(line.split()[1] for line in left) == sorted(str(tmp_path / n) for n in names[:2])
