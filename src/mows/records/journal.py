"""The commit journal of :mod:`mows.records.files`, and the recovery from a writer killed
mid-commit.

A process killed outright (SIGKILL, a power cut) runs no clean-up, so what it leaves says whose
it was: every temporary is named ``.NAME.PID.XXXXXXXX.partial.SUFFIX`` after the writing
process (a copy of a file it replaces ``.NAME.PID.XXXXXXXX.replaced``), and before its renames
a commit writes a journal (``.NAME.PID.commit``: each temporary, its output, the copy of the
file it replaces, and the SHA-256 of the bytes of each). The next write into that directory
puts the old set back from the journal, so the outputs are never a mix of two runs and the next
run does the whole job again.

A journal is acted on only when everything in it is as that writer left it: its process is
gone, every path it names is in its own directory and carries its writer's name, none is an
input of the command now running, and each file holds the very bytes the journal recorded (a
file edited since the crash is the user's). Otherwise nothing is touched, not even that
writer's temporaries, and a warning names the journal. Only files a journal (or a temporary's
own name) shows the writer made are ever removed.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import pathlib
import re
import secrets
import shutil
import warnings
from collections.abc import Iterable, Sequence

JOURNAL_FORMAT = 2  # entries carry the SHA-256 of the temporary and of the copy set aside
# What only this module names a file: the writer's prefix, mkstemp's eight characters, the role.
COMMIT = re.compile(r"^\.(?P<name>.+)\.(?P<pid>\d+)\.commit$")
INTENT = re.compile(r"^\.(?P<name>.+)\.(?P<pid>\d+)\.writing$")


class JournalLeft(UserWarning):
    """A stale journal left untouched because acting on it could change a file that is not its writer's."""


def own_prefix(path: pathlib.Path, pid: int | None = None) -> str:
    """The start of the name of every file this process leaves beside ``path`` while it writes."""
    return f".{path.name}.{os.getpid() if pid is None else pid}."


def digest(path: pathlib.Path) -> str:
    """The SHA-256 of the file's bytes."""
    sha = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            sha.update(block)
    return sha.hexdigest()


def journal_path(targets: Sequence[pathlib.Path]) -> pathlib.Path:
    """Where the journal of a commit of ``targets`` is written: beside the first."""
    return targets[0].resolve().parent / f"{own_prefix(targets[0])}commit"


def write_journal(
    temporaries: Sequence[pathlib.Path], targets: Sequence[pathlib.Path], asides: Sequence[pathlib.Path | None]
) -> pathlib.Path:
    """The commit's journal, on disk before the first rename, at :func:`journal_path`."""
    entries = [
        {
            "temporary": t.name,
            "output": o.name,
            "directory": str(o.resolve().parent),
            "written_sha256": digest(t),
            "replaced": None if a is None else a.name,
            "replaced_sha256": None if a is None else digest(a),
        }
        for t, o, a in zip(temporaries, targets, asides)
    ]
    journal = journal_path(targets)
    with open(journal, "w", encoding="utf-8") as handle:
        json.dump({"format": JOURNAL_FORMAT, "entries": entries}, handle)
        handle.flush()
        os.fsync(handle.fileno())
    return journal


def create_beside(path: pathlib.Path, suffix: str, made: list[pathlib.Path]) -> pathlib.Path:
    """A new empty file beside ``path`` named after this process (``.NAME.PID.XXXXXXXX`` and
    ``suffix``). Its name joins ``made`` before the file exists: an interrupt at any moment
    leaves it named there, for the clean-up."""
    while True:
        name = path.resolve().parent / f"{own_prefix(path)}{secrets.token_hex(4)}{suffix}"
        made.append(name)
        try:
            os.close(os.open(name, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
        except FileExistsError:  # another's file (a name drawn twice): not ours to remove
            made.pop()
            continue
        return name


def set_aside(path: pathlib.Path, made: list[pathlib.Path]) -> pathlib.Path | None:
    """A copy of the file at ``path`` beside it (None where there is none yet), named in ``made``
    before it exists. A copy, not a rename, so the output never goes missing; not a hard link,
    which an immutable file refuses. OSError where it cannot be made."""
    if not os.path.lexists(path):
        return None
    copy = create_beside(path, ".replaced", made)
    shutil.copy2(path, copy)
    return copy


def put_back(path: pathlib.Path, aside: pathlib.Path | None) -> None:
    """``path`` as it was before a commit; where that fails, the copy stays beside it (named
    ``.NAME.PID.*.replaced``) rather than be lost."""
    with contextlib.suppress(OSError):
        if aside is None:
            path.unlink(missing_ok=True)
        else:
            os.replace(aside, path)


def discard(aside: pathlib.Path | None) -> None:
    if aside is not None:
        with contextlib.suppress(OSError):
            aside.unlink(missing_ok=True)


def running(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process: running
        return True
    return True


def recover(directory, inputs: Iterable = ()) -> list[pathlib.Path]:
    """Undo what writers killed in ``directory`` left half done (module docstring): each
        trustworthy journal's outputs put back as they were before its commit, its temporaries and
        copies removed, and the temporaries of dead writers that never reached a commit removed
    (those their ``.NAME.PID.writing`` note names, by name and inode).
        Returns the outputs put back. A journal that cannot be trusted is left, with a
        :class:`JournalLeft` warning naming it; leftovers of a running process are not touched."""
    directory = pathlib.Path(directory)
    try:
        names = sorted(os.listdir(directory))
    except OSError:
        return []
    protected = {pathlib.Path(path).resolve() for path in inputs}
    restored: list[pathlib.Path] = []
    left: set[int] = set()  # the writers whose journal stays: every file of theirs stays with it
    for name in names:
        match = COMMIT.match(name)
        if match is None or running(int(match["pid"])):
            continue
        journal = directory / name
        entries, problem = _trusted_entries(journal, int(match["pid"]), protected)
        if problem:
            left.add(int(match["pid"]))
            warnings.warn(f"left {journal} as it is: {problem}", JournalLeft, stacklevel=2)
            continue
        restored += _roll_back(directory, entries)
        for entry in entries:
            discard(directory / entry["temporary"])
            if entry["replaced"] is not None:
                discard(directory / entry["replaced"])
        discard(journal)
    for name in names:
        match = INTENT.match(name)
        if match and int(match["pid"]) not in left and not running(int(match["pid"])):
            _remove_temporary(directory / name, own_prefix(pathlib.Path(match["name"]), int(match["pid"])))
    return restored


def intent_path(output: pathlib.Path, temporary: pathlib.Path) -> pathlib.Path:
    """Where the note that this process made ``temporary`` (for ``output``) is written."""
    return temporary.parent / f"{own_prefix(output)}writing"


def write_intent(output: pathlib.Path, temporary: pathlib.Path) -> pathlib.Path:
    """A note beside ``temporary`` (:func:`intent_path`) that this process made it, by name and
    inode: what lets the next write remove it if this process is killed, and nothing else."""
    info = temporary.stat()
    intent = intent_path(output, temporary)
    document = {"format": JOURNAL_FORMAT, "temporary": temporary.name, "inode": info.st_ino, "device": info.st_dev}
    intent.write_text(json.dumps(document), encoding="utf-8")
    return intent


def _remove_temporary(intent: pathlib.Path, prefix: str) -> None:
    """The temporary a dead writer's intent names, removed if it is still the very file it made
    (its name and inode); then the intent."""
    try:
        document = json.loads(intent.read_text(encoding="utf-8"))
        name, inode, device = document["temporary"], document["inode"], document["device"]
        valid = document["format"] == JOURNAL_FORMAT and os.path.basename(name) == name
    except (OSError, ValueError, TypeError, KeyError):
        valid = False
    if not valid or not name.startswith(prefix):
        warnings.warn(f"left {intent} as it is: it is not a note this version wrote", JournalLeft, stacklevel=3)
        return
    temporary = intent.parent / name
    with contextlib.suppress(OSError):
        info = temporary.lstat()
        if (info.st_ino, info.st_dev) == (inode, device):
            temporary.unlink()
    discard(intent)


def _trusted_entries(journal: pathlib.Path, pid: int, protected: set[pathlib.Path]) -> tuple[list[dict], str]:
    """(entries, "") of a journal that may be acted on, else ([], why not)."""
    try:
        document = json.loads(journal.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return [], "it cannot be read"
    if not isinstance(document, dict) or document.get("format") != JOURNAL_FORMAT:
        return [], "it is not a journal this version wrote (no checksums)"
    entries = document.get("entries")
    if not isinstance(entries, list) or not entries:
        return [], "it lists no files"
    for entry in entries:
        problem = _entry_problem(journal.parent, pid, entry, protected)
        if problem:
            return [], problem
    return entries, ""


def _entry_problem(directory: pathlib.Path, pid: int, entry, protected: set[pathlib.Path]) -> str:
    """Why one entry of a journal must not be acted on ("" if it may)."""
    try:
        output, temporary, replaced = entry["output"], entry["temporary"], entry["replaced"]
        names = [output, temporary] + ([replaced] if replaced is not None else [])
        if entry["directory"] != str(directory.resolve()) or any(os.path.basename(n) != n for n in names):
            return "it names files outside its own directory"
        prefix = own_prefix(pathlib.Path(output), pid)
        if not temporary.startswith(prefix) or (replaced is not None and not replaced.startswith(prefix)):
            return f"it names files that are not its writer's ({output})"
        if (directory / output).resolve() in protected:
            return f"{directory / output} is an input of this command"
        if os.path.lexists(directory / temporary):
            expected = [(temporary, entry["written_sha256"])]
        else:  # renamed onto its output: the output holds what was written, the copy what it replaced
            expected = [(output, entry["written_sha256"])]
        if replaced is not None:
            expected.append((replaced, entry["replaced_sha256"]))
        for name, sha in expected:
            if (
                not os.path.isfile(directory / name)
                or os.path.islink(directory / name)
                or digest(directory / name) != sha
            ):
                return f"{directory / name} is not what its writer left (changed or gone since)"
    except (KeyError, TypeError, AttributeError, OSError):
        return "it cannot be read"
    return ""


def _roll_back(directory: pathlib.Path, entries: list[dict]) -> list[pathlib.Path]:
    """The outputs of an interrupted commit as they were before it."""
    restored = []
    for entry in entries:
        if not os.path.lexists(directory / entry["temporary"]):  # renamed onto its output already
            aside = entry["replaced"]
            output = directory / entry["output"]
            put_back(output, None if aside is None else directory / aside)
            restored.append(output)
    return restored
