"""A stale commit journal is acted on only when every file in it is as its dead writer left it.

Requirement: a writer killed between its renames leaves a journal; the next write into that
folder puts the old pair back from it (tests/cli/test_cli_guards.py), but only when the journal
names files of its own folder and its own writer, its process is gone, none of its files is an
input of the command now writing, and each holds the bytes the journal recorded. In every other
case no byte of any file changes, and one warning names the journal.
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

from mows.records.files import writing
from mows.records.journal import JournalLeft

KILLED_BETWEEN_RENAMES = """
import os, signal, sys
import mows.records.files as files
renamed = []
def replace(source, target):
    if os.path.basename(target) in ("a.txt", "b.txt"):
        if renamed:
            os.kill(os.getpid(), signal.SIGKILL)
        renamed.append(target)
    os.rename(source, target)
files.os.replace = replace
folder = sys.argv[1]
with files.writing([folder + "/a.txt", folder + "/b.txt"], force=True) as outputs:
    for temporary in outputs.temporaries:
        temporary.write_text("new " + temporary.name)
"""


def state(*folders: pathlib.Path) -> dict:
    return {p: hashlib.sha256(p.read_bytes()).hexdigest() for f in folders for p in sorted(f.iterdir()) if p.is_file()}


@pytest.fixture
def scene(tmp_path) -> pathlib.Path:
    """A folder whose a.txt and b.txt a writer was replacing when it was killed between the renames."""
    folder = tmp_path / "scene"
    folder.mkdir()
    for name in ("a.txt", "b.txt"):
        (folder / name).write_text(f"old {name}")
    run = subprocess.run([sys.executable, "-c", KILLED_BETWEEN_RENAMES, str(folder)], timeout=120)
    assert run.returncode == -signal.SIGKILL
    assert (folder / "a.txt").read_text().startswith("new") and (folder / "b.txt").read_text() == "old b.txt"
    return folder


def journal_of(folder: pathlib.Path) -> pathlib.Path:
    (journal,) = folder.glob(".*.commit")
    return journal


def write_new(folder: pathlib.Path, inputs=()) -> list:
    """A new output in the folder (as `mows sim --out new.npz`), with the warnings it gave."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with writing([folder / "new.txt"], inputs) as outputs:
            outputs.temporaries[0].write_text("new")
    return [w for w in caught if issubclass(w.category, JournalLeft)]


def test_a_whole_journal_puts_the_old_pair_back(scene):
    assert write_new(scene) == []
    assert sorted(p.name for p in scene.iterdir()) == ["a.txt", "b.txt", "new.txt"]
    assert (scene / "a.txt").read_text() == "old a.txt" and (scene / "b.txt").read_text() == "old b.txt"


def edit_output(scene):
    (scene / "a.txt").write_text("edited by the user after the crash")


def journal_elsewhere(scene):
    """The journal's files named in another folder (absolute paths, as an older journal held)."""
    other = scene.parent / "other"
    other.mkdir()
    (other / "a.txt").write_text("another folder's file")
    journal = journal_of(scene)
    document = json.loads(journal.read_text())
    for entry in document["entries"]:
        entry["directory"] = str(other)
    journal.write_text(json.dumps(document))


def journal_with_absolute_paths(scene):
    journal = journal_of(scene)
    document = json.loads(journal.read_text())
    entries = document["entries"]
    for entry in entries:
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
    (replaced,) = scene.glob(".a.txt.*.replaced")
    replaced.write_text("not the copy the writer made")


STALE = [edit_output, journal_elsewhere, journal_with_absolute_paths, journal_of_an_older_format, copy_changed]


@pytest.mark.parametrize("plant", STALE, ids=lambda f: f.__name__)
def test_a_journal_that_cannot_be_trusted_changes_no_byte(scene, plant):
    plant(scene)
    before = state(scene, scene.parent)
    left = write_new(scene)
    after = state(scene, scene.parent)
    del after[scene / "new.txt"]
    assert after == before
    (journal,) = scene.glob(".*.commit")
    assert len(left) == 1 and str(journal) in str(left[0].message), [str(w.message) for w in left]


def test_a_journal_whose_output_the_command_reads_is_left(scene):
    """The command now writing reads a.txt: undoing the dead commit would delete its input."""
    before = state(scene)
    left = write_new(scene, inputs=[scene / "a.txt"])
    after = state(scene)
    del after[scene / "new.txt"]
    assert after == before and len(left) == 1 and "input" in str(left[0].message)


def test_the_journal_of_a_running_writer_is_left_quietly(scene):
    dead = journal_of(scene).name.split(".")[-2]
    for path in scene.glob(f".*.{dead}.*"):  # as if this (running) process were its writer
        path.rename(scene / path.name.replace(f".{dead}.", f".{os.getpid()}."))
    before = state(scene)
    assert write_new(scene) == []
    after = state(scene)
    del after[scene / "new.txt"]
    assert after == before


def test_a_user_s_files_named_like_a_writer_s_are_never_removed(tmp_path):
    names = [".notes.txt.999999.commit", ".notes.txt.999999.writing", ".new.txt.999999.abcdefgh.partial.txt"]
    for name in names:
        (tmp_path / name).write_text("the user's own notes")
    before = state(tmp_path)
    left = write_new(tmp_path)
    after = state(tmp_path)
    del after[tmp_path / "new.txt"]
    assert after == before
    assert sorted(str(w.message).split()[1] for w in left) == sorted(str(tmp_path / n) for n in names[:2])
