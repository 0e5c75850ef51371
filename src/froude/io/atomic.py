"""Atomic file output and the output guard: nothing half-written, nothing overwritten by mistake.

Every file froude writes (BVH, reports, plots, renders, table caches, batch indexes) goes through
``atomic_write``: the content is written to a temporary file ``.NAME.XXXXXXXX.EXT`` in the destination's
folder and moved into place with ``os.replace`` (atomic on POSIX); the temporary file is removed on any
error or interrupt (SIGTERM included: the CLI turns it into an exception).

``atomic_group()`` makes the files of one result all-or-none: inside it, ``atomic_write`` only writes the
temporary files; they are moved into place together when the block ends without an error, and all
removed otherwise. ``check_outputs`` is the guard every command runs before any work: every output is
a writable file path, none is an input (after resolving links) or another output of the same command.
"""
from __future__ import annotations

import contextlib
import contextvars
import os
import tempfile
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

from ..errors import FroudeError

#: Prefix and suffix pattern of the temporaries (``.NAME.`` + 8 random characters + the final suffix);
#: ``is_temporary`` recognises them, so cleaners and clip finders can skip or remove them.
TEMP_PREFIX = "."

_group: contextvars.ContextVar[list | None] = contextvars.ContextVar("froude_atomic_group", default=None)


class OutputError(FroudeError):
    """An output cannot be written, or would overwrite an input or another output."""


def _temp_path(path: Path) -> str:
    fd, tmp = tempfile.mkstemp(prefix=f"{TEMP_PREFIX}{path.stem}.", suffix=path.suffix or ".tmp",
                               dir=str(path.parent))
    os.close(fd)
    return tmp


def is_temporary(path: str | os.PathLike) -> bool:
    """True for a temporary of ``atomic_write`` (``.NAME.XXXXXXXX.EXT``)."""
    name = Path(path).name
    parts = name.split(".")
    return name.startswith(TEMP_PREFIX) and len(parts) >= 4 and len(parts[-2]) == 8


def _unlink_quietly(tmp: str) -> None:
    try:
        os.unlink(tmp)
    except OSError:
        pass


def atomic_write(path: str | os.PathLike, write: Callable[[str], None]) -> Path:
    """Call ``write(temp_path)`` and move the result to ``path``; returns the path.

    The temporary file sits beside ``path`` with the same suffix (so writers that choose a format by
    extension work) and gets ordinary permissions (mkstemp's 0600 would make outputs private). Inside
    ``atomic_group()`` the move waits for the end of the group. The destination's folder
    is created if missing (library callers such as batch rely on it; the CLI's ``check_outputs`` refuses a
    missing folder before any work instead, so a typo in ``-o`` never creates folders).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _temp_path(path)
    try:
        write(tmp)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        group = _group.get()
        if group is not None:
            group.append((tmp, path))
            return path
        os.replace(tmp, path)
    except BaseException:
        _unlink_quietly(tmp)
        raise
    return path


@contextlib.contextmanager
def atomic_group() -> Iterator[list]:
    """All the ``atomic_write`` calls inside the block land together, or none does.

    Yields the list of (temporary, destination) pairs written so far. Nested groups join the outer one.
    """
    outer = _group.get()
    if outer is not None:
        yield outer
        return
    pending: list = []
    token = _group.set(pending)
    try:
        yield pending
    except BaseException:
        _group.reset(token)
        for tmp, _ in pending:
            _unlink_quietly(tmp)
        raise
    _group.reset(token)
    done = []
    try:
        for tmp, path in pending:
            os.replace(tmp, path)
            done.append(path)
    except BaseException:
        # a rename failed after the writability check (a disk pulled out, a race): take back the
        # files this group already moved so no half result stays
        for tmp, _ in pending:
            _unlink_quietly(tmp)
        for path in done:
            _unlink_quietly(str(path))
        raise


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    """Write text (LF line ends) to path atomically."""

    def write(tmp: str) -> None:
        with open(tmp, "w", newline="\n") as f:
            f.write(text)

    return atomic_write(path, write)


# ---- the output guard --------------------------------------------------------------------------------
def _identity(path: Path) -> tuple:
    """What makes two paths the same file: (device, inode) when it exists, else the resolved path."""
    try:
        st = os.stat(path)
        return ("inode", st.st_dev, st.st_ino)
    except OSError:
        return ("path", os.path.normcase(os.path.realpath(path)))


def _same(a: Path, b: Path) -> bool:
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    ia, ib = _identity(a), _identity(b)
    return ia[0] == "inode" and ia == ib


def _check_folder(out: Path, folder: Path, probed: dict) -> None:
    if folder in probed:
        if probed[folder]:
            raise OutputError(f"{out}: {probed[folder]}")
        return
    probed[folder] = ""
    if not folder.exists():
        # a path through a file ("clip.bvh/o.bvh") reads as a missing folder to exists()
        for up in folder.parents:
            if up.exists():
                if not up.is_dir():
                    probed[folder] = f"'{up}' is a file, not a folder"
                break
        probed[folder] = probed[folder] or f"folder '{folder}' does not exist (create it first)"
    elif not folder.is_dir():
        probed[folder] = f"'{folder}' is a file, not a folder"
    else:
        # the only true test of "can I create a file here" (permissions, read-only mounts, /proc, ACLs)
        try:
            fd, probe = tempfile.mkstemp(prefix=".froude-probe.", dir=str(folder))
            os.close(fd)
            os.unlink(probe)
        except OSError as e:
            probed[folder] = f"cannot write in folder '{folder}': {e.strerror or e}"
    if probed[folder]:
        raise OutputError(f"{out}: {probed[folder]}")


def check_outputs(outputs: Iterable, inputs: Iterable = (), *, folders: Iterable = ()) -> list[Path]:
    """The output guard: raise OutputError (one line) unless every output can be written safely.

    outputs: files the command will write (None entries are skipped); inputs: files it reads (None and
    missing ones skipped); folders: output folders the command will fill (an existing folder must accept
    new files; a missing one needs a writable parent). Checks, for each output: not an existing folder or special
    file; its folder
    exists and accepts a new file (probed by creating and removing one); not an input after resolving
    symbolic and hard links; not the same file as another output. Returns the outputs as Paths.
    """
    outs = [Path(o) for o in outputs if o is not None]
    ins = [Path(i) for i in inputs if i is not None and Path(i).exists()]
    probed: dict = {}
    for d in (Path(f) for f in folders if f is not None):
        if d.exists() and not d.is_dir():
            raise OutputError(f"{d}: is a file, not a folder")
        target = d if d.exists() else (d.parent if str(d.parent) else Path("."))
        _check_folder(d, target, probed)
        probed.setdefault(d, "")  # a folder still to be made accepts the files checked against it
    for k, out in enumerate(outs):
        if out.is_dir():
            raise OutputError(f"{out}: is a folder; give a file name")
        if out.exists() and not out.is_file():
            raise OutputError(f"{out}: exists and is not a regular file; refusing to replace it")
        for inp in ins:
            if _same(out, inp):
                raise OutputError(f"{out}: would overwrite the input '{inp}'; choose another output name")
        for other in outs[:k]:
            if _same(out, other):
                raise OutputError(f"{out}: given twice as an output (also as '{other}')")
        folder = out.parent if str(out.parent) else Path(".")
        _check_folder(out, folder, probed)
    return outs


def require_suffix(path, allowed: tuple[str, ...], what: str = "output") -> Path:
    """Raise OutputError unless ``path`` ends with one of ``allowed`` (case-insensitive, with the dot)."""
    p = Path(path)
    if p.suffix.lower() not in allowed:
        got = f"'{p.suffix}'" if p.suffix else "no extension"
        raise OutputError(f"{p}: the {what} must be a {' or '.join(allowed)} file, got {got}")
    return p
