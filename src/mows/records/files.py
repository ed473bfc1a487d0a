"""Files a command writes: never over one of its inputs, never over a file that is already
there unless told to (``force``, and then only over a regular file), and never half-written.

:func:`check_output` says before any work starts whether an output path may be written
(so that a long analysis does not end in a refusal); :func:`writing` writes one or several
outputs through temporary files in their directories and renames them into place only once
every writer has finished, so a crash, an error, Ctrl-C or SIGTERM leaves the old files (or
none) and never a torn one, nor one output written and another not: a rename that fails puts
back what the renames before it replaced.

A process killed outright (SIGKILL, a power cut) leaves its temporaries and, mid-commit, a
journal; the next :func:`writing` into that directory puts the old set back from the journal
when every file in it is as that writer left it (:mod:`mows.records.journal`).

A bag folder (a directory holding a rosbag2 ``metadata.yaml`` and its storage files) is never
written in, whether the bag is an input or not: a file dropped there may break the recording,
and a bag named by its ``.mcap`` file protects its whole folder.

A command's inputs are more than its arguments: a scenario pulls in its ``extends:`` base and its
``probe:`` files, a reference its scenario. Within :func:`command_inputs` every file read through
:func:`read_input` (the YAML loader and the table readers call it) is an input too, so ``--force``
never replaces a file the command read, whichever way it came in.
"""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import os
import pathlib
import stat
from collections.abc import Callable, Iterable, Iterator, Sequence

from mows.records.journal import (
    create_beside,
    discard,
    intent_path,
    journal_path,
    put_back,
    recover,
    set_aside,
    write_intent,
    write_journal,
)


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


class InputRefused(ValueError):
    """An input that is no file to read: a FIFO, a device, a socket (reading would block or never end)."""


def read_input(path: str | os.PathLike[str]) -> pathlib.Path:
    """``path``, kept (within :func:`command_inputs`) as a file the command read; a FIFO, a
    device or a socket is refused (:class:`InputRefused`): a command reads files and folders."""
    path = pathlib.Path(path)
    with contextlib.suppress(OSError):
        mode = path.stat().st_mode
        if not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
            raise InputRefused(f"{path} is {_kind(mode)}, not a file: give a file to read")
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
    check_not_input(path, inputs)
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


def bag_folder(path) -> pathlib.Path | None:
    """The bag folder ``path`` is in or is (a directory, or an ancestor, holding a rosbag2
    ``metadata.yaml`` beside its ``.mcap`` or ``.db3`` storage), None if none."""
    resolved = pathlib.Path(path).resolve()
    for directory in [resolved, *resolved.parents]:
        if (directory / "metadata.yaml").is_file() and (any(directory.glob("*.mcap")) or any(directory.glob("*.db3"))):
            return directory
    return None


def check_not_input(path, inputs: Iterable = ()) -> None:
    """:class:`OutputRefused` if ``path`` is an input of the command (of ``inputs``, or read
    within :func:`command_inputs`), inside an input directory, or inside a bag folder."""
    path = pathlib.Path(path)
    resolved = path.resolve()
    for source in [*inputs, *sorted(_read_by_command.get() or ())]:
        source_path = pathlib.Path(source).resolve()
        if _inside(resolved, source_path) or (source_path.is_file() and resolved == source_path):
            raise OutputRefused(f"output {path} is an input of this command ({source}): choose another output path")
    bag = bag_folder(resolved.parent)
    if bag is not None:
        raise OutputRefused(
            f"output {path} is inside the bag {bag}: a bag's folder is never written in; choose a path outside it"
        )


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
    protected = [*inputs, *sorted(_read_by_command.get() or ())]
    for directory in {pathlib.Path(path).resolve().parent for path in paths}:
        if bag_folder(directory) is None:
            recover(directory, protected)
    targets = check_outputs(paths, inputs, force)
    outputs = Outputs(targets, [])
    made: list[pathlib.Path] = []  # every file this writer makes, named before it exists
    try:
        for path in targets:
            try:
                temporary = create_beside(path, f".partial{path.suffix}", made)
            except OSError as error:
                raise _unwritable(path, error) from error
            outputs.temporaries.append(temporary)
            made.append(intent_path(path, temporary))
            write_intent(path, temporary)
        yield outputs
        check_outputs(paths, inputs, force)
        for temporary in outputs.temporaries:
            with open(temporary, "rb+") as handle:  # on disk before the rename makes it the output
                os.fsync(handle.fileno())
            os.chmod(temporary, 0o666 & ~_umask())
        outputs.replaced = [os.path.lexists(path) for path in targets]
        _replace_all(outputs.temporaries, targets)
    finally:
        # a directory that turned read-only keeps its temporary: the error that says so matters more
        _each(discard, made)


def _each(action: Callable[[pathlib.Path], None], paths: Sequence[pathlib.Path]) -> None:
    """``action`` on every path, even when Ctrl-C or SIGTERM comes meanwhile (it is raised once
    all are done): a clean-up cut short would leave files behind, or an old file not put back.
    Each action may be done twice (removing a file that is gone is nothing)."""
    interrupt = None
    for path in paths:
        while True:
            try:
                action(path)
                break
            except KeyboardInterrupt as error:
                interrupt = error
    if interrupt is not None:
        raise interrupt


def _replace_all(temporaries: Sequence[pathlib.Path], targets: Sequence[pathlib.Path]) -> None:
    """Rename each temporary onto its target, all or none. The files they replace are copied
    aside and the journal written first; a rename that fails (or Ctrl-C between two) puts back
    what the earlier ones replaced and removes what they created, and so does
    :func:`mows.records.journal.recover` for a process killed between two renames. Which
    renames were done is read from the disk (a temporary gone is renamed), not counted: an
    interrupt may come between a rename and its count."""
    journal = journal_path(targets)
    copies: list[pathlib.Path] = []  # every copy made, named before it exists
    asides: list[pathlib.Path | None] = []
    done = False
    try:
        try:
            for path in targets:
                asides.append(set_aside(path, copies))
            write_journal(temporaries, targets, asides)
        except OSError as error:
            raise _unwritable(targets[len(asides) if len(asides) < len(targets) else 0], error) from error
        for temporary, path in zip(temporaries, targets):
            try:
                os.replace(temporary, path)
            except OSError as error:
                raise _unwritable(path, error) from error
        done = True
    finally:
        renamed = {path for temporary, path in zip(temporaries, targets) if not os.path.lexists(temporary)}
        if not done:
            _each(lambda path: put_back(path, asides[targets.index(path)]), [p for p in targets if p in renamed])
        # copies of files left as they were, or of a commit done; a copy put back is gone, and
        # one that could not be is kept (its file is not as it was)
        kept = set() if done else {a for p, a in zip(targets, asides) if p in renamed and a is not None}
        _each(discard, [journal, *(copy for copy in copies if copy not in kept)])


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
