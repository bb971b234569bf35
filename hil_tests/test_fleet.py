"""Fleet evaluation (issue 19): the same rows serially, on a LocalCluster and on a Dask scheduler.

The scheduler and its worker are real processes started here on 127.0.0.1 (``dask scheduler``
and ``dask worker`` from the ``fleet`` extra), the logs are generated rover runs (seeded), a
damaged file, and the shared corpus's receiver logs where it is present.
"""

from __future__ import annotations

import importlib.util
import os
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from conftest import CORPUS
from fdi.errors import ConfigError
from firmware_host import cli
from firmware_host.devtools.fleet import (
    LogEntry,
    discover,
    parse_sweeps,
    point_configs,
    pooled,
    run_fleet,
)
from firmware_host.devtools.rover_sim import RoverScenario, write_run
from firmware_host.rov.config import RovConfig
from tests.processes import cmdline, descendants, leftovers

pytest.importorskip("distributed", reason="the fleet extra (Dask) is not installed")

SWEEP = ["rover.detector.gate_m=0.2,0.7,3.0"]


@pytest.fixture(scope="module")
def fleet_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("fleet")
    for seed in range(1, 21):  # 20 generated runs, 1 min each, rates 1/5/10 Hz
        rate = (1.0, 5.0, 10.0)[seed % 3]
        write_run(RoverScenario(rate_hz=rate, duration_s=60.0, seed=100 + seed),
                  root / "runs" / f"run{seed:02d}")
    (root / "runs" / "damaged.cap").write_bytes(b"\x00\x01not a capture\xff" * 40)
    (root / "runs" / "empty.log").write_bytes(b"")
    return root


def _logs(fleet_dir: Path) -> list[LogEntry]:
    places = [str(fleet_dir / "runs")]
    if (CORPUS / "gpsd").is_dir():
        places.append(str(CORPUS / "gpsd"))
    return discover(places)


def test_discover_takes_the_capture_of_a_generated_run_and_its_truth(fleet_dir: Path) -> None:
    logs = discover([str(fleet_dir / "runs")])
    runs = [lg for lg in logs if Path(lg.path).name == "rover.cap"]
    assert len(runs) == 20  # rover.cap and rover.nmea of a run are one run: the capture
    assert all(lg.kind == "capture" and lg.truth is not None for lg in runs)
    names = {Path(lg.path).name for lg in logs}
    assert {"damaged.cap", "empty.log"} <= names
    assert not any(n.endswith((".jsonl", ".json")) for n in names)


def test_sweep_points_are_the_product_and_validated_before_any_work() -> None:
    pts = parse_sweeps(["rover.detector.gate_m=0.5,1", "rover.detector.strategy=grey,combined"])
    assert [p.label for p in pts] == [
        "rover.detector.gate_m=0.5 rover.detector.strategy=grey",
        "rover.detector.gate_m=0.5 rover.detector.strategy=combined",
        "rover.detector.gate_m=1 rover.detector.strategy=grey",
        "rover.detector.gate_m=1 rover.detector.strategy=combined",
    ]
    cfgs = point_configs("rover", pts)
    assert cfgs[pts[1].label].rover.detector.strategy == "combined"
    assert cfgs[pts[2].label].rover.detector.gate_m == 1.0
    with pytest.raises(ConfigError, match="gate_m"):
        point_configs("rover", parse_sweeps(["rover.detector.gate_m=-1"]))
    with pytest.raises(ConfigError):
        point_configs("rover", parse_sweeps(["rover.detector.no_such_key=1"]))


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture(scope="module")
def scheduler() -> Iterator[str]:
    port = _free_port()
    addr = f"tcp://127.0.0.1:{port}"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    sched = subprocess.Popen(
        [sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
         "--port", str(port), "--no-dashboard"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    worker = subprocess.Popen(
        [sys.executable, "-m", "distributed.cli.dask_worker", addr, "--nworkers", "1",
         "--nthreads", "1", "--host", "127.0.0.1", "--no-dashboard"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    try:
        from dask.distributed import Client

        deadline = time.monotonic() + 60
        while True:
            try:
                with Client(addr, timeout=5) as client:
                    client.wait_for_workers(1, timeout=60)
                break
            except (OSError, TimeoutError):
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.2)
        yield addr
    finally:
        for p in (worker, sched):
            p.terminate()
        for p in (worker, sched):
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()


def test_serial_pool_localcluster_and_scheduler_give_the_same_rows(
        fleet_dir: Path, scheduler: str) -> None:
    logs = _logs(fleet_dir)
    configs = point_configs("rover", parse_sweeps(SWEEP))
    rov = RovConfig()
    before = descendants()  # the scheduler and its worker are there already
    serial = run_fleet(logs, configs, rov, workers=1)
    pool = run_fleet(logs, configs, rov, workers=2)
    local = run_fleet(logs, configs, rov, workers=2, dask=True)
    remote = run_fleet(logs, configs, rov, scheduler=scheduler)
    assert serial.executor == "serial" and pool.executor == "process pool x2"
    assert "LocalCluster" in local.executor and scheduler in remote.executor
    assert len(serial.rows) == 3 * len(logs)
    assert pool.rows == serial.rows
    assert local.rows == serial.rows
    assert remote.rows == serial.rows
    # No pool or LocalCluster worker left behind; multiprocessing's resource tracker (started
    # by Dask) serves this process until it exits: the command's test below sees it go.
    left = [cmdline(p) for p in descendants() - before]
    assert [c for c in left if "resource_tracker" not in c] == []
    # The damaged and the empty file are rows with their error; nothing else failed.
    errors = {Path(r["log"]).name: r["error"] for r in serial.rows if r["error"]}
    assert set(errors) == {"damaged.cap", "empty.log"}, errors
    assert all("no NMEA sentences" in e for e in errors.values())
    # The sweep reaches the detector: the points' replaced counts differ. Their order depends
    # on the logs: with the shared corpus a 0.2 m grey gate floor replaced more fixes than a
    # 3 m one (90 against 83), on the generated runs alone fewer (77 against 79): what a tight
    # gate replaces early, the drift and Doppler tests hold later under a loose one.
    by_point = {p: pooled([r for r in serial.rows if r["point"] == p]) for p in configs}
    tight, _, loose = (by_point[p] for p in configs)
    assert tight["scored_logs"] == loose["scored_logs"] == 20
    assert tight["epochs"] == loose["epochs"]
    assert tight["replaced"] != loose["replaced"]


def test_the_fleet_command_on_dask_leaves_no_process_running_after_it_exits(
        fleet_dir: Path) -> None:
    root = str(Path(__file__).resolve().parents[1])
    rc, left = leftovers([sys.executable, "-m", "firmware_host.cli", "fleet",
                          str(fleet_dir / "runs" / "run01"), str(fleet_dir / "runs" / "run02"),
                          "--dask", "--workers", "2", "--json"], root)
    assert rc == 0
    assert left == []


def test_fleet_command_writes_tables_json_and_reports_bad_input(
        fleet_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    rc = cli.main(["fleet", str(fleet_dir / "runs"), "--workers", "1", "--sweep", SWEEP[0],
                   "--out", str(out)])
    assert rc == 0
    text = capsys.readouterr().out
    # the console: aligned tables (issue 17); the file: Markdown
    assert "Pooled comparison" in text and "rover.detector.gate_m=3.0" in text
    assert "|---" not in text
    assert (out / "fleet.json").is_file()
    assert "## Pooled comparison" in (out / "fleet.md").read_text(encoding="utf-8")
    if importlib.util.find_spec("matplotlib") is not None:  # the plot extra
        assert (out / "fleet.png").is_file()
    assert cli.main(["fleet", str(fleet_dir / "runs"), "--workers", "1", "--sweep",
                     "rover.detector.gate_m=-1"]) == 2
    assert "rover.detector.gate_m" in capsys.readouterr().err
    assert cli.main(["fleet", str(tmp_path / "nothing-here")]) == 1
