"""Files written atomically: into a temporary file beside the target, then moved into place.

A reader sees either the old file or the whole new one, never a part; a write that fails (an
exception, a killed process) leaves the old file as it was and no temporary file behind it
(a killed process may leave a hidden `.<name>.<pid>-....tmp` file, never the target
half-written; the next write of the same file on this machine removes it once that process has
ended). A write that fails for want of space raises an OSError that names the target.

Files that grow a line at a time (results CSVs) are appended whole or not at all
(`append_bytes`) and read up to their last newline (`whole_lines`), so that a line cut short
is never taken for a row.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import os
import re
import socket
import tempfile
from collections.abc import Iterator
from pathlib import Path

_UMASK = os.umask(0)
os.umask(_UMASK)
_HOST = hashlib.sha256(socket.gethostname().encode()).hexdigest()[:6]
NO_SPACE = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)
"""What a write that ran out of room raises: no space on the device, over a quota, over the
process's file size limit."""


def cache_dir() -> Path:
    """Where what can be made again is kept between runs (base policies without committed
    weights, drawn top views): $DFA_CACHE, else ~/.cache/dfa."""
    return Path(os.environ.get("DFA_CACHE", Path.home() / ".cache" / "dfa"))


def temp_beside(path: str | Path) -> Path:
    """A new, empty, hidden temporary file in `path`'s folder (created with it if needed).

    Its name keeps `path`'s suffix, so tools that look at the extension still accept it, and
    names this process: the temporary files of `path` that processes on this machine left
    when they were killed are removed first.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    for stale in stale_temps(path):
        discard(stale)
    fd, tmp = tempfile.mkstemp(
        dir=path.parent, prefix=f".{path.stem}.{os.getpid()}-{_HOST}-", suffix=f".tmp{path.suffix}"
    )
    os.close(fd)
    return Path(tmp)


def stale_temps(path: str | Path) -> list[Path]:
    """The temporary files of `path` (temp_beside's) whose process on this machine has ended."""
    path = Path(path)
    name = re.compile(
        rf"\.{re.escape(path.stem)}\.(\d+)-{_HOST}-[a-z0-9_]+\.tmp{re.escape(path.suffix)}"
    )
    try:
        names = os.listdir(path.parent)
    except FileNotFoundError:
        return []
    return [
        path.parent / n
        for n in sorted(names)
        if (m := name.fullmatch(n)) and not _running(int(m.group(1)))
    ]


def _running(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's
        return True
    return True


def commit(tmp: str | Path, path: str | Path) -> Path:
    """Move a finished temporary file into place: fsync it, give it a normal file's mode
    (mkstemp makes 0600), rename it over `path`, fsync the folder."""
    tmp, path = Path(tmp), Path(path)
    with open(tmp, "rb") as f:
        os.fsync(f.fileno())
    os.chmod(tmp, 0o666 & ~_UMASK)
    os.replace(tmp, path)
    fd = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
    return path


def discard(tmp: str | Path) -> None:
    """Remove a temporary file that will not be committed (if it is still there)."""
    with contextlib.suppress(FileNotFoundError):
        os.unlink(tmp)


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path to write `path`'s new content to; committed when the block ends
    without an exception, discarded when it raises."""
    tmp = temp_beside(path)
    try:
        yield tmp
        commit(tmp, path)
    except OSError as e:
        raise naming(e, path, tmp) from e
    finally:
        discard(tmp)


def naming(error: OSError, path: str | Path, tmp: str | Path | None = None) -> OSError:
    """`error`, or where it names no file (a failed write() names none) or the temporary file
    `tmp`, the same error naming `path`, the file the user knows."""
    if error.filename is not None and (tmp is None or Path(error.filename) != Path(tmp)):
        return error
    return OSError(error.errno, error.strerror or str(error), str(path))


def append_bytes(path: str | Path, data: bytes) -> None:
    """Append `data` to the end of `path` and fsync it, all of it or nothing: a write that
    fails (a full disk) cuts the file back to where it was and raises an OSError naming it."""
    fd = os.open(path, os.O_WRONLY | os.O_APPEND)
    try:
        size = os.fstat(fd).st_size
        try:
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view) :]  # a full disk writes part, then raises
            os.fsync(fd)
        except OSError as e:
            with contextlib.suppress(OSError):
                os.ftruncate(fd, size)
                os.fsync(fd)
            raise naming(e, path) from e
    finally:
        os.close(fd)


def whole_lines(path: str | Path) -> str:
    """The UTF-8 text of `path` up to and including its last newline: a last line that a
    killed process or a full disk cut short is left out."""
    text = Path(path).read_text()
    return text[: text.rfind("\n") + 1]


def write_bytes(path: str | Path, data: bytes) -> Path:
    """Write `data` to `path` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_text(path: str | Path, text: str) -> Path:
    """Write UTF-8 `text` to `path` atomically."""
    return write_bytes(path, text.encode())


def safe_name(text: str) -> str:
    """`text` as a file name on any system: every run of characters other than letters, digits,
    '.', '_' and '-' becomes one '_' (a world "minigrid:MiniGrid-DoorKey-5x5-v0:tile=12" gives
    "minigrid_MiniGrid-DoorKey-5x5-v0_tile_12")."""
    return re.sub(r"[^A-Za-z0-9._-]+", "_", text)


def sha256(path: str | Path) -> str:
    """The hex sha256 of a file's bytes, read a megabyte at a time."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(1 << 20):
            digest.update(block)
    return digest.hexdigest()
