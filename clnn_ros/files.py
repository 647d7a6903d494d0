"""Writing result files so that a full disk or an unwritable file costs one clear line and
never a file already written: each is written to a temporary file beside it, then renamed; and
whether an output directory can be made, asked before anything is written."""

from __future__ import annotations

import errno
import os
from pathlib import Path
from typing import Callable


def write_atomically(path: Path, write: Callable[[Path], None]) -> None:
    """`write(temporary path)`, then rename it to `path`; on an OSError the old `path` (if any)
    is untouched, the temporary file removed and the error raised."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        write(temporary)
        os.replace(temporary, path)
    except OSError as error:
        temporary.unlink(missing_ok=True)
        error.filename = str(path)  # the file meant, not the temporary one
        raise


def write_text_atomically(path: Path, text: str) -> None:
    write_atomically(path, lambda temporary: temporary.write_text(text))


def describe_write_error(error: OSError, path=None) -> str:
    """One line: 'disk full writing PATH' or 'cannot write PATH: <reason>'."""
    where = path if path is not None else (error.filename or "a file")
    if error.errno in (errno.ENOSPC, errno.EDQUOT):
        return f"disk full writing {where}"
    return f"cannot write {where}: {error.strerror or error}"


def cannot_create(directory: Path) -> str | None:
    """Why `directory` can neither be used nor created, or None: it, or else its nearest
    existing ancestor, must be a writable directory."""
    existing = directory.absolute()
    while not existing.exists():
        existing = existing.parent
    if not existing.is_dir():
        return f"{existing} is not a directory"
    if not os.access(existing, os.W_OK | os.X_OK):
        return f"{existing} is not writable"
    return None
