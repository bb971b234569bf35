"""The processes a test started and may have left behind, from /proc (Linux)."""

from __future__ import annotations

import os


def descendants(pid: int | None = None) -> set[int]:
    """The living processes below ``pid`` (default: this one), from /proc's parent ids."""
    root = os.getpid() if pid is None else pid
    parent: dict[int, int] = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat", encoding="ascii", errors="replace") as f:
                stat = f.read()
        except OSError:  # gone meanwhile
            continue
        fields = stat[stat.rindex(")") + 2 :].split()
        if fields[0] != "Z":  # a zombie is not a worker left running
            parent[int(entry)] = int(fields[1])
    found: set[int] = set()
    frontier = {root}
    while frontier:
        kids = {p for p, pp in parent.items() if pp in frontier} - found
        found |= kids
        frontier = kids
    return found


def cmdline(pid: int) -> str:
    """A process's command line ('' when it is gone)."""
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            return f.read().replace(b"\0", b" ").decode("utf-8", "replace").strip()
    except OSError:
        return ""


# Run as a child: makes itself the subreaper of what it starts (so that a process the command
# leaves behind is re-parented to it, not to init), runs the command, then waits up to GRACE
# seconds for each process still below it to end (pidfd + select: no polling), prints the
# command's exit status and what was left as JSON, and kills what was left.
_LEFTOVERS = r"""
import ctypes, json, os, select, signal, subprocess, sys, time
from tests.processes import cmdline, descendants
PR_SET_CHILD_SUBREAPER = 36
libc = ctypes.CDLL(None, use_errno=True)
if libc.prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0) != 0:
    sys.exit("prctl(PR_SET_CHILD_SUBREAPER) failed")
grace = float(sys.argv[1])
rc = subprocess.call(sys.argv[2:], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
deadline = time.monotonic() + grace
left = []
for pid in sorted(descendants()):
    try:
        fd = os.pidfd_open(pid)
    except OSError:
        continue
    ready, _, _ = select.select([fd], [], [], max(0.0, deadline - time.monotonic()))
    os.close(fd)
    if not ready:
        left.append(cmdline(pid))
        os.kill(pid, signal.SIGKILL)
print(json.dumps({"rc": rc, "left": left}))
"""


def leftovers(cmd: list[str], root: str, grace_s: float = 20.0) -> tuple[int, list[str]]:
    """``cmd``'s exit status and the command lines of the processes it left running
    ``grace_s`` seconds after it ended (``root``: the project's tree, for this module)."""
    import json
    import subprocess
    import sys

    env = dict(os.environ, PYTHONPATH=os.pathsep.join([root, os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.run([sys.executable, "-c", _LEFTOVERS, str(grace_s), *cmd], env=env,
                          capture_output=True, text=True, check=True, cwd=root)
    doc = json.loads(proc.stdout.strip().splitlines()[-1])
    return int(doc["rc"]), list(doc["left"])
