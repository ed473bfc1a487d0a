"""Files a command writes: never over one of its inputs, never over a file that is already
there unless told to (``force``, and then only over a regular file), and never half-written.

:func:`check_output` says before any work starts whether an output path may be written
(so that a long analysis does not end in a refusal); :func:`writing` writes one or several
outputs through temporary files in their directories and renames them into place only once
every writer has finished, so a crash, an error, Ctrl-C or SIGTERM leaves the old files (or
none) and never a torn one, nor one output written and another not: a rename that fails puts
back what the renames before it replaced.

A process killed outright (SIGKILL, a power cut) runs no clean-up, so what it leaves says whose
it was: every temporary is named ``.NAME.PID.*`` after the writing process, and before its
renames a commit writes a journal (``.NAME.PID.commit``: each temporary, its output and the copy
of the file it replaces). The next :func:`writing` into that directory finds the leftovers of
writers no longer running and puts the old set back from the journal, so the outputs are never
a mix of two runs and the next run does the whole job again.

A command's inputs are more than its arguments: a scenario pulls in its ``extends:`` base and its
``probe:`` files, a reference its scenario. Within :func:`command_inputs` every file read through
:func:`read_input` (the YAML loader and the table readers call it) is an input too, so ``--force``
never replaces a file the command read, whichever way it came in.
"""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import json
import os
import pathlib
import re
import shutil
import stat
import tempfile
from collections.abc import Iterable, Iterator, Sequence


class OutputRefused(ValueError):
    """An output path a command must not write: an input, inside an input, or existing."""


# The files the running command has read (None: no command runs, reads are not kept).
_read_by_command: contextvars.ContextVar[set[pathlib.Path] | None] = contextvars.ContextVar(
    "read_by_command", default=None
)


@contextlib.contextmanager
def command_inputs() -> Iterator[None]:
    """Within the block, every file read through :func:`read_input` is an input of every check."""
    token = _read_by_command.set(set())
    try:
        yield
    finally:
        _read_by_command.reset(token)


def read_input(path: str | os.PathLike[str]) -> pathlib.Path:
    """``path``, kept (within :func:`command_inputs`) as a file the command read."""
    path = pathlib.Path(path)
    read = _read_by_command.get()
    if read is not None:
        read.add(path.resolve())
    return path


def _inside(path: pathlib.Path, directory: pathlib.Path) -> bool:
    return directory == path or directory in path.parents


def _kind(mode: int) -> str:
    """What a file that is not a regular one is, in words."""
    kinds = [
        (stat.S_ISLNK, "a symbolic link"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISFIFO, "a FIFO"),
        (stat.S_ISSOCK, "a socket"),
        (stat.S_ISDIR, "a directory"),
    ]
    return next((name for test, name in kinds if test(mode)), "not a regular file")


def check_output(path, inputs: Iterable = (), force: bool = False) -> pathlib.Path:
    """``path`` if a command reading ``inputs`` may write it, else :class:`OutputRefused`.

    An input (of ``inputs``, or read within :func:`command_inputs`), or any path inside an input
    directory (a bag's ``metadata.yaml``), is refused even with ``force``: the command would
    destroy what it reads. An existing file is refused
    unless ``force``; anything but a regular file (a directory, a device, a FIFO, a link)
    always: ``force`` replaces files, never what a path stands for.
    """
    path = pathlib.Path(path)
    resolved = path.resolve()
    for source in [*inputs, *sorted(_read_by_command.get() or ())]:
        source_path = pathlib.Path(source).resolve()
        if _inside(resolved, source_path) or (source_path.is_file() and resolved == source_path):
            raise OutputRefused(f"output {path} is an input of this command ({source}): choose another output path")
    if not resolved.parent.is_dir():
        what = "is a file, not a directory" if resolved.parent.exists() else "does not exist"
        raise OutputRefused(f"output {path}: directory {path.parent} {what}")
    try:
        mode = path.lstat().st_mode
    except FileNotFoundError:
        mode = None
    if mode is not None and not stat.S_ISREG(mode):
        raise OutputRefused(f"output {path} is {_kind(mode)}, not a regular file: give a new file path")
    if mode is not None and not force:
        raise OutputRefused(f"output {path} exists: choose another path or pass --force to replace it")
    # access() also sees what the mode bits do not: a read-only mount, an immutable directory
    if not os.access(resolved.parent, os.W_OK):
        raise OutputRefused(f"output {path}: directory {path.parent} is not writable")
    return path


def _unwritable(path: pathlib.Path, error: OSError) -> OutputRefused:
    """The output's directory, not an input, is what failed (checked writable a moment before)."""
    return OutputRefused(f"output {path}: cannot write in directory {path.parent}: {error.strerror or error}")


def check_outputs(paths: Sequence, inputs: Iterable = (), force: bool = False) -> list[pathlib.Path]:
    """:func:`check_output` of each of a command's outputs; two that are one file are refused
    (one would overwrite the other)."""
    checked = [check_output(path, inputs, force) for path in paths]
    resolved = [path.resolve() for path in checked]
    for i, path in enumerate(resolved):
        if path in resolved[:i]:
            raise OutputRefused(
                f"outputs {checked[resolved.index(path)]} and {checked[i]} are one file: give two paths"
            )
    return checked


@dataclasses.dataclass
class Outputs:
    """The outputs of one :func:`writing` block: the temporary path to write each to, and, once
    the block has ended, which of them replaced an existing file."""

    paths: list[pathlib.Path]
    temporaries: list[pathlib.Path]
    replaced: list[bool] = dataclasses.field(default_factory=list)

    def report(self) -> str:
        """ "wrote A" / "replaced A" for each output, one per line."""
        return "\n".join(
            f"{'replaced' if replaced else 'wrote'} {path}" for path, replaced in zip(self.paths, self.replaced)
        )


@contextlib.contextmanager
def writing(paths: Sequence, inputs: Iterable = (), force: bool = False) -> Iterator[Outputs]:
    """Temporary paths next to each of ``paths`` to write the outputs to; all renamed into place
    when the ``with`` block ends without an error (or interrupt), all removed otherwise. The
    paths are checked with :func:`check_outputs` first, and again just before the renames (a file
    may have appeared meanwhile). Each temporary keeps its target's suffix (numpy, for one,
    appends ``.npz`` to names without it)."""
    for directory in {pathlib.Path(path).resolve().parent for path in paths}:
        recover(directory)
    targets = check_outputs(paths, inputs, force)
    outputs = Outputs(targets, [])
    try:
        for path in targets:
            try:
                descriptor, name = tempfile.mkstemp(
                    prefix=_own_prefix(path), suffix=f".partial{path.suffix}", dir=path.resolve().parent
                )
            except OSError as error:
                raise _unwritable(path, error) from error
            os.close(descriptor)
            outputs.temporaries.append(pathlib.Path(name))
        yield outputs
        check_outputs(paths, inputs, force)
        for temporary in outputs.temporaries:
            with open(temporary, "rb+") as handle:  # on disk before the rename makes it the output
                os.fsync(handle.fileno())
            os.chmod(temporary, 0o666 & ~_umask())
        outputs.replaced = [os.path.lexists(path) for path in targets]
        _replace_all(outputs.temporaries, targets)
    finally:
        for temporary in outputs.temporaries:
            # a directory that turned read-only keeps its temporary: the error that says so matters more
            with contextlib.suppress(OSError):
                temporary.unlink(missing_ok=True)


def _replace_all(temporaries: Sequence[pathlib.Path], targets: Sequence[pathlib.Path]) -> None:
    """Rename each temporary onto its target, all or none. The files they replace are copied
    aside and the journal written first; a rename that fails (or Ctrl-C between two) puts back
    what the earlier ones replaced and removes what they created, and so does :func:`recover`
    for a process killed between two renames."""
    asides = [_set_aside(path) for path in targets]
    journal = _write_journal(temporaries, targets, asides)
    placed = 0
    try:
        for temporary, path in zip(temporaries, targets):
            try:
                os.replace(temporary, path)
            except OSError as error:
                raise _unwritable(path, error) from error
            placed += 1
    except BaseException:
        for path, aside in reversed(list(zip(targets[:placed], asides))):
            _put_back(path, aside)
        raise
    finally:
        journal.unlink(missing_ok=True)
        for aside in asides[placed:] if placed < len(targets) else asides:
            _discard(aside)  # copies of files left as they were, or of a commit done


def _own_prefix(path: pathlib.Path, pid: int | None = None) -> str:
    """The start of the name of every file this process leaves beside ``path`` while it writes."""
    return f".{path.name}.{os.getpid() if pid is None else pid}."


def _write_journal(
    temporaries: Sequence[pathlib.Path], targets: Sequence[pathlib.Path], asides: Sequence[pathlib.Path | None]
) -> pathlib.Path:
    """The commit's journal, on disk before the first rename, beside the first output."""
    entries = [
        {"temporary": str(t), "output": str(o), "replaced": None if a is None else str(a)}
        for t, o, a in zip(temporaries, targets, asides)
    ]
    journal = targets[0].resolve().parent / f"{_own_prefix(targets[0])}commit"
    with open(journal, "w", encoding="utf-8") as handle:
        json.dump(entries, handle)
        handle.flush()
        os.fsync(handle.fileno())
    return journal


LEFTOVER = re.compile(r"^\.(?P<name>.+)\.(?P<pid>\d+)\.(?:commit|.*\.partial.*|.*\.replaced)$")


def _running(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process: running
        return True
    return True


def recover(directory) -> list[pathlib.Path]:
    """Undo what writers killed in ``directory`` left half done: each journal's outputs put back
    as they were before its commit, then every temporary and copy of those writers removed.
    Returns the outputs put back. Leftovers of a running process are not touched."""
    directory = pathlib.Path(directory)
    try:
        names = sorted(os.listdir(directory))
    except OSError:
        return []
    dead = [name for name in names if (m := LEFTOVER.match(name)) and not _running(int(m["pid"]))]
    restored = []
    for name in dead:
        if name.endswith(".commit"):
            restored += _roll_back(directory / name)
    for name in dead:
        with contextlib.suppress(OSError):
            (directory / name).unlink(missing_ok=True)
    return restored


def _roll_back(journal: pathlib.Path) -> list[pathlib.Path]:
    """The outputs of an interrupted commit as they were before it (an unreadable journal, torn
    while it was written, means no rename had begun)."""
    try:
        entries = json.loads(journal.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return []
    restored = []
    for entry in entries:
        if not os.path.lexists(entry["temporary"]):  # renamed onto its output already
            aside = entry["replaced"]
            _put_back(pathlib.Path(entry["output"]), None if aside is None else pathlib.Path(aside))
            restored.append(pathlib.Path(entry["output"]))
    return restored


def _set_aside(path: pathlib.Path) -> pathlib.Path | None:
    """A copy of the file at ``path`` beside it (None where there is none yet). A copy, not a
    rename, so the output never goes missing; not a hard link, which an immutable file refuses."""
    if not os.path.lexists(path):
        return None
    try:
        descriptor, name = tempfile.mkstemp(prefix=_own_prefix(path), suffix=".replaced", dir=path.resolve().parent)
        os.close(descriptor)
        shutil.copy2(path, name)
    except OSError as error:
        raise _unwritable(path, error) from error
    return pathlib.Path(name)


def _put_back(path: pathlib.Path, aside: pathlib.Path | None) -> None:
    """``path`` as it was before :func:`_replace_all`; where that fails, the copy stays beside it
    (named ``.NAME.PID.*.replaced``) rather than be lost."""
    with contextlib.suppress(OSError):
        if aside is None:
            path.unlink(missing_ok=True)
        else:
            os.replace(aside, path)


def _discard(aside: pathlib.Path | None) -> None:
    if aside is not None:
        with contextlib.suppress(OSError):
            aside.unlink(missing_ok=True)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
