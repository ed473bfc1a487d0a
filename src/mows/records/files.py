"""Files a command writes: never over one of its inputs, never over a file that is already
there unless told to (``force``), and never half-written.

:func:`check_output` says before any work starts whether an output path may be written
(so that a long analysis does not end in a refusal); :func:`replacing` writes through a
temporary file in the same directory and renames it into place only once the writer has
finished, so a crash or an error leaves the old file (or none) and never a torn one.
"""

from __future__ import annotations

import contextlib
import os
import pathlib
import tempfile
from collections.abc import Iterable, Iterator


class OutputRefused(ValueError):
    """An output path a command must not write: an input, inside an input, or existing."""


def _inside(path: pathlib.Path, directory: pathlib.Path) -> bool:
    return directory == path or directory in path.parents


def check_output(path, inputs: Iterable = (), force: bool = False) -> pathlib.Path:
    """``path`` if a command reading ``inputs`` may write it, else :class:`OutputRefused`.

    An input, or any path inside an input directory (a bag's ``metadata.yaml``), is refused
    even with ``force``: the command would destroy what it reads. An existing file is refused
    unless ``force``; a directory always.
    """
    path = pathlib.Path(path)
    resolved = path.resolve()
    for source in inputs:
        source_path = pathlib.Path(source).resolve()
        if _inside(resolved, source_path) or (source_path.is_file() and resolved == source_path):
            raise OutputRefused(f"output {path} is an input of this command ({source}): choose another output path")
    if path.is_dir():
        raise OutputRefused(f"output {path} is a directory: give a file path")
    if (path.exists() or path.is_symlink()) and not force:
        raise OutputRefused(f"output {path} exists: choose another path or pass --force to replace it")
    if not resolved.parent.is_dir():
        raise OutputRefused(f"output {path}: directory {path.parent} does not exist")
    return path


@contextlib.contextmanager
def replacing(path, inputs: Iterable = (), force: bool = False) -> Iterator[pathlib.Path]:
    """A temporary path next to ``path`` to write the output to; renamed onto ``path`` when
    the ``with`` block ends without an error, removed otherwise. ``path`` is checked with
    :func:`check_output` first. The temporary file keeps ``path``'s suffix (numpy, for one,
    appends ``.npz`` to names without it)."""
    path = check_output(path, inputs, force)
    descriptor, name = tempfile.mkstemp(
        prefix=f".{path.name}.", suffix=f".partial{path.suffix}", dir=path.resolve().parent
    )
    os.close(descriptor)
    temporary = pathlib.Path(name)
    try:
        yield temporary
        with open(temporary, "rb+") as handle:  # on disk before the rename makes it the output
            os.fsync(handle.fileno())
        os.chmod(temporary, 0o666 & ~_umask())
        os.replace(temporary, path)
    finally:
        temporary.unlink(missing_ok=True)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
