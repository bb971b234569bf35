"""A small tmpfs to fill up: the disk-full tests of the tlog, the parameter file (and the
flight recorder). ``small_tmpfs`` mounts one (needs ``mount``: root or CAP_SYS_ADMIN) or skips
the test with the reason; ``fill`` takes every free byte, ``free_up`` gives them back."""

from __future__ import annotations

import contextlib
import os
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest


@contextlib.contextmanager
def small_tmpfs(path: Path, size_kb: int = 256) -> Iterator[Path]:
    """Mount a ``size_kb`` tmpfs at ``path`` (created) for the block; skip where not allowed."""
    path.mkdir(parents=True, exist_ok=True)
    res = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size_kb}k", "tmpfs", str(path)],
                         capture_output=True, text=True, check=False)
    if res.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here ({res.stderr.strip() or res.returncode}): "
                    "the disk-full test needs root or CAP_SYS_ADMIN")
    try:
        yield path
    finally:
        subprocess.run(["umount", "-l", str(path)], capture_output=True, check=False)


def fill(mount: Path, name: str = "ballast") -> Path:
    """Write zeros into ``mount/name`` until the disk is full (ENOSPC); returns the file."""
    ballast = mount / name
    with open(ballast, "wb", buffering=0) as f:
        chunk = bytes(4096)
        with contextlib.suppress(OSError):
            while True:
                f.write(chunk)
        with contextlib.suppress(OSError):
            while True:
                f.write(b"\0")
    return ballast


def free_up(ballast: Path) -> None:
    os.unlink(ballast)
