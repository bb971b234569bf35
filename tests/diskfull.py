"""Test helpers for a full or read-only disk: a small tmpfs, filled and freed on demand.

Shared by the recorder's tests and any other writer's (tlog, parameter file)::

    with small_tmpfs(tmp_path / "disk", size_kb=256) as disk:
        filler = fill(disk)       # the file system is now full (ENOSPC on the next write)
        ...
        filler.unlink()           # space is back
        remount(disk, read_only=True)   # or: the disk goes read-only

``small_tmpfs`` skips the test with the reason when mounting is not allowed (not root, no
``mount``, a container without CAP_SYS_ADMIN).
"""

from __future__ import annotations

import errno
import os
import shutil
import subprocess
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest


@contextmanager
def small_tmpfs(path: Path, size_kb: int = 256) -> Iterator[Path]:
    """A tmpfs of ``size_kb`` mounted at ``path`` for the block; skip if mount is refused."""
    path.mkdir(parents=True, exist_ok=True)
    if os.geteuid() != 0 or shutil.which("mount") is None:
        pytest.skip("a small full disk needs `mount -t tmpfs` (run as root to include it)")
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size_kb}k", "fdi-test-tmpfs",
                        str(path)], capture_output=True, text=True, check=False)
    if r.returncode != 0:
        pytest.skip(f"mount -t tmpfs is not allowed here: {r.stderr.strip()}")
    try:
        yield path
    finally:
        subprocess.run(["umount", "-l", str(path)], capture_output=True, check=False)


def fill(directory: Path, name: str = ".filler") -> Path:
    """Fill the file system of ``directory`` to the last byte; return the filler file."""
    filler = directory / name
    fd = os.open(filler, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
    try:
        for size in (65536, 4096, 512, 1):
            while True:
                try:
                    os.write(fd, b"\0" * size)
                except OSError as err:
                    if err.errno != errno.ENOSPC:
                        raise
                    break
    finally:
        os.close(fd)
    return filler


def remount(path: Path, *, read_only: bool) -> None:
    """Make the tmpfs at ``path`` read-only (or writable again)."""
    mode = "ro" if read_only else "rw"
    subprocess.run(["mount", "-o", f"remount,{mode}", str(path)], check=True,
                   capture_output=True)
