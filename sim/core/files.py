"""Files written atomically: into a temporary file beside the target, then moved into place.

A reader sees either the old file or the whole new one, never a part; a write that fails (an
exception, a killed process) leaves the old file as it was and no temporary file behind it
(a killed process may leave a hidden `.<name>.*.tmp` file, never the target half-written).
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
import tempfile
from collections.abc import Iterator
from pathlib import Path

_UMASK = os.umask(0)
os.umask(_UMASK)


def cache_dir() -> Path:
    """Where what can be made again is kept between runs (base policies without committed
    weights, drawn top views): $DFA_CACHE, else ~/.cache/dfa."""
    return Path(os.environ.get("DFA_CACHE", Path.home() / ".cache" / "dfa"))


def temp_beside(path: str | Path) -> Path:
    """A new, empty, hidden temporary file in `path`'s folder (created with it if needed).

    Its name keeps `path`'s suffix, so tools that look at the extension still accept it.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(
        dir=path.parent, prefix=f".{path.stem}.", suffix=f".tmp{path.suffix}"
    )
    os.close(fd)
    return Path(tmp)


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
    finally:
        discard(tmp)


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
