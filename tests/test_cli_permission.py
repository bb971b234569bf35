"""A path in a directory this user may not search: a clear message, never "internal error"
(issue C item 9: ``PermissionError`` from the argument checks reached the CLI's last line of
defence, exit 1 with "internal error: PermissionError").

The commands run as a user would run them (a real subprocess). A directory without search
permission for the user running the command: a directory of ``nobody`` with mode 0700. Root
passes every permission check (CAP_DAC_OVERRIDE, CAP_DAC_READ_SEARCH), so as root the command
runs under ``setpriv`` without those two capabilities (everything else as root); the test is
skipped with the reason where neither works.
"""

from __future__ import annotations

import json
import os
import pwd
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
_NO_DAC = ["--inh-caps=-dac_override,-dac_read_search",
           "--bounding-set=-dac_override,-dac_read_search"]


@pytest.fixture(scope="module")
def locked(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[str]]:
    """(a directory the command may not search, the prefix that runs the command)."""
    base = tmp_path_factory.mktemp("perm")
    base.chmod(0o755)
    d = base / "locked"
    d.mkdir(mode=0o700)
    prefix: list[str] = []
    if os.geteuid() == 0:
        setpriv = shutil.which("setpriv")
        if setpriv is None:
            pytest.skip("as root a permission error needs setpriv (util-linux) to drop "
                        "CAP_DAC_OVERRIDE")
        os.chown(d, pwd.getpwnam("nobody").pw_uid, -1)
        prefix = [setpriv, *_NO_DAC]
    probe = subprocess.run([*prefix, sys.executable, "-c",
                            f"import os,sys; sys.exit(os.access({str(d)!r}, os.X_OK))"],
                           capture_output=True, check=False)
    if probe.returncode != 0:
        pytest.skip(f"cannot run without search permission on a directory here: "
                    f"{probe.stderr.decode(errors='replace').strip()}")
    return d, prefix


def _cli(prefix: list[str], cwd: Path, *argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*prefix, sys.executable, "-m", "firmware_host.cli", *argv],
                          cwd=cwd, capture_output=True, text=True, timeout=120,
                          stdin=subprocess.DEVNULL, env=dict(os.environ, PYTHONPATH=str(ROOT)))


@pytest.mark.parametrize("argv", [
    ["replay", "{d}/x.nmea", "--out", "{t}/o"],
    ["record", "loop://", "--out", "{d}/x.cap", "--duration", "1"],
    ["sim", "rover", "--duration", "5", "--out", "{d}/o"],
    ["eval", "{d}/run"],
    ["calibrate", "{d}/x.cap", "--config", "rover", "--out", "{t}/c.toml"],
], ids=["replay-input", "record-out", "sim-out", "eval-input", "calibrate-input"])
def test_unsearchable_path_is_a_usage_error(locked: tuple[Path, list[str]], tmp_path: Path,
                                            argv: list[str]) -> None:
    d, prefix = locked
    args = [a.replace("{d}", str(d)).replace("{t}", str(tmp_path)) for a in argv]
    r = _cli(prefix, tmp_path, *args)
    assert "internal error" not in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert r.returncode == 2, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert f"{d}/" in r.stderr and "Permission denied" in r.stderr, r.stderr
    assert "may not search a directory on the path" in r.stderr


def test_run_out_in_an_unsearchable_directory_runs_on(locked: tuple[Path, list[str]],
                                                      tmp_path: Path) -> None:
    """``run --out`` there is an output the disk refuses: said, and the bridge runs."""
    d, prefix = locked
    r = _cli(prefix, tmp_path, "run", "--config", "rover", "--out", str(d / "out"),
             "--duration", "1", "--json")
    assert "internal error" not in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert r.returncode == 0, r.stderr
    assert f"could not create {d / 'out' / 'epochs.jsonl'}: Permission denied" in r.stderr
    assert json.loads(r.stdout)["epochs_file"]["writing"] is False
