"""Atomic file output: nothing half-written is ever left at the destination.

Every file froude writes (BVH, reports, plots, renders, table caches, batch indexes) goes through
``atomic_write``: the content is written to a temporary file in the destination's folder and moved into
place with ``os.replace`` (atomic on POSIX), and the temporary file is removed on any error or interrupt.
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Callable


def atomic_write(path: str | os.PathLike, write: Callable[[str], None]) -> Path:
    """Call ``write(temp_path)`` and move the result to ``path``; returns the path.

    The temporary file sits beside ``path`` with the same suffix (so writers that choose a format by
    extension work) and gets ordinary permissions (mkstemp's 0600 would make outputs private).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix or ".tmp", dir=str(path.parent))
    os.close(fd)
    try:
        write(tmp)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    return path


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    """Write text (LF line ends) to path atomically."""

    def write(tmp: str) -> None:
        with open(tmp, "w", newline="\n") as f:
            f.write(text)

    return atomic_write(path, write)
