"""Every command with bad arguments, as a user runs it (a real subprocess, nothing mocked):
exit 2 for a usage or config error, 1 for a runtime failure, one line on stderr naming what
was wrong, and never a Python traceback (issue 17)."""

from __future__ import annotations

import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from firmware_host.devtools.rover_sim import RoverScenario, write_run

ROOT = Path(__file__).resolve().parents[1]

# (id, argv with {t} = a scratch directory, expected exit status, text stderr must contain)
CASES: list[tuple[str, list[str], int, str]] = [
    ("replay-dir-as-capture", ["replay", "{t}", "--out", "{t}/o"], 2, "is a directory"),
    ("replay-missing-capture", ["replay", "{t}/nope.nmea", "--out", "{t}/o"], 2, "no such file"),
    ("replay-out-is-file", ["replay", "{t}/run/rover.nmea", "--out", "{t}/afile"], 2,
     "not a directory"),
    ("replay-out-under-file", ["replay", "{t}/run/rover.nmea", "--out", "{t}/afile/sub"], 2,
     "cannot be created"),
    ("replay-speed-negative", ["replay", "{t}/run/rover.nmea", "--out", "{t}/o", "--speed",
                               "-1"], 2, "--speed"),
    ("replay-speed-nan", ["replay", "{t}/run/rover.nmea", "--out", "{t}/o", "--speed", "nan"],
     2, "finite"),
    ("replay-mavlink-scheme", ["replay", "{t}/run/rover.nmea", "--out", "{t}/o", "--mavlink",
                               "foo://bar"], 2, "unknown URL scheme"),
    ("replay-mavlink-port", ["replay", "{t}/run/rover.nmea", "--out", "{t}/o", "--mavlink",
                             "udpout:127.0.0.1:99999"], 2, "out of range"),
    ("replay-mavlink-no-host", ["replay", "{t}/run/rover.nmea", "--out", "{t}/o", "--mavlink",
                                "udpout:14550"], 2, "HOST:PORT"),
    ("replay-pty-missing-dir", ["replay", "{t}/run/rover.nmea", "--out", "{t}/o", "--nmea-out",
                                "pty:/nonexistent/dir/link"], 2, "does not exist"),
    ("replay-nmea-out-missing-port", ["replay", "{t}/run/rover.nmea", "--out", "{t}/o",
                                      "--nmea-out", "{t}/ttyUSB9"], 1, "cannot open the port"),
    ("replay-empty", ["replay", "{t}/empty.nmea", "--out", "{t}/o-empty"], 1,
     "no NMEA sentences found"),
    ("replay-elf", ["replay", "{t}/elf.bin", "--out", "{t}/o-elf"], 1,
     "no NMEA sentences found"),
    ("replay-bad-config", ["replay", "{t}/run/rover.nmea", "--out", "{t}/o", "--config",
                           "{t}/nope.toml"], 2, "nope"),
    ("record-missing-port", ["record", "{t}/ttyUSB9", "--out", "{t}/x.cap", "--duration", "1"],
     1, "cannot open the port"),
    ("record-missing-parent", ["record", "loop://", "--out", "{t}/nodir/x.cap"], 2,
     "does not exist"),
    ("record-out-is-dir", ["record", "loop://", "--out", "{t}"], 2, "is a directory"),
    ("record-baud-zero", ["record", "loop://", "--out", "{t}/x.cap", "--baud", "0"], 2,
     "--baud"),
    ("record-bad-url", ["record", "bogus://x", "--out", "{t}/x.cap"], 2, "unknown URL scheme"),
    ("record-parity", ["record", "loop://", "--out", "{t}/x.cap", "--parity", "X"], 2,
     "--parity"),
    ("run-duration-negative", ["run", "--config", "rover", "--duration", "-1"], 2,
     "--duration"),
    ("run-mavlink-port-zero", ["run", "--config", "rover", "--mavlink", "udpout:127.0.0.1:0"],
     2, "out of range"),
    ("run-missing-config", ["run", "--config", "{t}/nope.toml"], 2, "nope"),
    ("sim-rover-out-is-file", ["sim", "rover", "--out", "{t}/afile"], 2, "not a directory"),
    ("sim-rover-duration-zero", ["sim", "rover", "--duration", "0", "--out", "{t}/d"], 2,
     "--duration"),
    ("sim-rover-too-short", ["sim", "rover", "--duration", "0.01", "--out", "{t}/d"], 2,
     "one epoch"),
    ("sim-rover-kinds", ["sim", "rover", "--kinds", "jump,bogus", "--out", "{t}/d"], 2,
     "bogus"),
    ("sim-rov-duration-negative", ["sim", "rov", "--duration", "-5", "--out", "{t}/d"], 2,
     "--duration"),
    ("sim-rov-too-short", ["sim", "rov", "--duration", "0.01", "--out", "{t}/d"], 2,
     "control period"),
    ("sim-rov-bad-fault", ["sim", "rov", "--fault", "bogus", "--out", "{t}/d"], 2, "--fault"),
    ("sim-rov-out-is-file", ["sim", "rov", "--out", "{t}/afile"], 2, "not a directory"),
    ("sim-insgnss-out-is-file", ["sim", "insgnss", "--out", "{t}/afile"], 2, "not a directory"),
    ("sim-insgnss-missing-config", ["sim", "insgnss", "--config", "{t}/nope.toml", "--out",
                                    "{t}/d"], 2, "no such file"),
    ("insgnss-report-missing-parent", ["sim", "insgnss-report", "--out", "{t}/nodir/r.md"], 2,
     "does not exist"),
    ("demo-duration-zero", ["demo", "--duration", "0"], 2, "--duration"),
    ("demo-duration-short", ["demo", "--duration", "1"], 2, "at least"),
    ("demo-out-is-file", ["demo", "--out", "{t}/afile"], 2, "not a directory"),
    ("demo-rov-out-is-file", ["demo", "rov", "--out", "{t}/afile"], 2, "not a directory"),
    ("demo-unknown", ["demo", "bogus"], 2, "unknown demo"),
    ("eval-suite-out-is-file", ["eval", "--suite", "--out", "{t}/afile"], 2, "not a directory"),
    ("eval-missing-truth", ["eval", "{t}/run", "--truth", "{t}/nope.jsonl"], 2, "no such file"),
    ("eval-nothing", ["eval"], 2, "--suite"),
    ("eval-dir-without-epochs", ["eval", "{t}/run"], 2, "epochs.jsonl"),
    ("bench-json-missing-parent", ["bench", "--json", "{t}/nodir/b.json"], 2,
     "does not exist"),
    ("bench-duration-zero", ["bench", "--duration", "0"], 2, "--duration"),
    ("fuzz-out-missing-parent", ["fuzz", "--out", "{t}/nodir/f.json"], 2, "does not exist"),
    ("fuzz-seconds-negative", ["fuzz", "--seconds", "-1"], 2, "--seconds"),
    ("soak-minutes-negative", ["soak", "--minutes", "-1"], 2, "--minutes"),
    ("soak-out-missing-parent", ["soak", "--out", "{t}/nodir/s.json"], 2, "does not exist"),
    ("fleet-no-logs", ["fleet", "{t}/nothing-here", "--workers", "1"], 1,
     "fdi-bridge fleet: {t}/nothing-here: no such file"),
    ("fleet-workers-zero", ["fleet", "{t}", "--workers", "0"], 2, "--workers"),
    ("fleet-out-is-file", ["fleet", "{t}", "--out", "{t}/afile"], 2, "not a directory"),
    ("mavlink-no-arguments", ["mavlink"], 2, "--config"),
    ("mavlink-gcs-scheme", ["mavlink", "--gcs", "foo://bar"], 2, "unknown URL scheme"),
    ("mavlink-autopilot-port", ["mavlink", "--autopilot", "udpout:127.0.0.1:99999"], 2,
     "out of range"),
    ("mavlink-seconds-negative", ["mavlink", "--seconds", "-1"], 2, "--seconds"),
    ("doctor-missing-config", ["doctor", "--config", "{t}/nope.toml"], 1, "PROBLEM"),
    ("config-check-missing", ["config", "check", "{t}/nope.toml"], 2, "nope"),
    ("presets-bad-option", ["presets", "--bogus"], 2, "unrecognized"),
    ("unknown-command", ["bogus"], 2, "invalid choice"),
    ("sim-unknown-kind", ["sim", "bogus"], 2, "invalid choice"),
]


@pytest.fixture(scope="module")
def scratch(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("cli-errors")


@pytest.fixture(scope="module")
def results(scratch: Path) -> dict[str, subprocess.CompletedProcess[str]]:
    t = scratch
    write_run(RoverScenario(rate_hz=10.0, duration_s=20.0, seed=1), t / "run")
    (t / "afile").write_text("x")
    (t / "empty.nmea").write_bytes(b"")
    (t / "elf.bin").write_bytes(Path(sys.executable).resolve().read_bytes()[:200_000])
    env = dict(os.environ, PYTHONPATH=str(ROOT))

    def one(case: tuple[str, list[str], int, str]) -> subprocess.CompletedProcess[str]:
        argv = [a.replace("{t}", str(t)) for a in case[1]]
        return subprocess.run([sys.executable, "-m", "firmware_host.cli", *argv], cwd=t,
                              capture_output=True, text=True, timeout=120, env=env,
                              stdin=subprocess.DEVNULL)

    with ThreadPoolExecutor(max_workers=3) as pool:
        done = list(pool.map(one, CASES))
    return {case[0]: proc for case, proc in zip(CASES, done, strict=True)}


@pytest.mark.parametrize(("name", "argv", "status", "text"), CASES, ids=[c[0] for c in CASES])
def test_bad_arguments(results: dict[str, subprocess.CompletedProcess[str]], scratch: Path,
                       name: str, argv: list[str], status: int, text: str) -> None:
    proc = results[name]
    out = proc.stderr + proc.stdout
    assert "Traceback" not in out, out
    assert proc.returncode == status, out
    assert text.replace("{t}", str(scratch)) in out, out
    if status == 2:  # one line naming what was wrong (argparse's or ours), nothing else
        assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr


def test_internal_error_is_one_line_and_the_traceback_needs_v(tmp_path: Path) -> None:
    """An exception nobody foresaw: ``fdi-bridge: internal error: ...``, exit 1; -v adds the
    traceback. (A module whose run() raises, put first on the path by a real import.)"""
    pkg = tmp_path / "boom_cmd.py"
    pkg.write_text("def add_arguments(p):\n    pass\n\n"
                   "def run(args):\n    raise ZeroDivisionError('division by zero')\n")
    code = ("import sys\nfrom firmware_host import cli\n"
            "cli.COMMANDS['boom'] = ('boom_cmd', 'raises')\n"
            "sys.exit(cli.main(sys.argv[1:]))\n")
    env = dict(os.environ, PYTHONPATH=f"{ROOT}{os.pathsep}{tmp_path}")
    quiet = subprocess.run([sys.executable, "-c", code, "boom"], capture_output=True,
                           text=True, timeout=60, env=env)
    assert quiet.returncode == 1
    assert quiet.stderr.strip().splitlines() == [
        "fdi-bridge: internal error: ZeroDivisionError: division by zero (run with -v for the "
        "traceback)"]
    loud = subprocess.run([sys.executable, "-c", code, "boom", "-v"], capture_output=True,
                          text=True, timeout=60, env=env)
    assert loud.returncode == 1
    assert "Traceback" in loud.stderr and "internal error" in loud.stderr
