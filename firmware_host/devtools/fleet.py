"""``fdi-bridge fleet``: what a configuration would have done on a whole season of logs.

A fleet's recordings (captures, plain NMEA logs, ROV ``.tlog`` dives) are replayed through the
detectors, once per point of an optional sweep over any configuration key, and the results are
written as one table per sweep point, a pooled comparison (Markdown and JSON) and a plot of the
trade-off (detection against false alarms) when truth files are there.

* **One job = one log at one sweep point.** A rover log is replayed in-process (no pty, the
  same :class:`~firmware_host.rover.pipeline.RoverPipeline` as ``replay``); with a truth file it
  is scored as ``fdi-bridge eval`` scores a run (:func:`~firmware_host.devtools.score.score_rover`),
  without one the counts are reported (epochs, faults, alarms, replaced, gate health). A ``.tlog``
  dive runs the ROV compass detector in detect-only mode (:mod:`firmware_host.rov.tlog`); the
  sweep applies to the rover configuration, so a dive's row is the same at every point.
* **Deterministic.** A replay depends only on its input bytes, so the rows are the same whichever
  executor ran them (wall-clock figures such as processing times are left out of the rows).
* **Parallel by default, distributed when asked**: by default a local process pool
  (:class:`concurrent.futures.ProcessPoolExecutor`, workers forked from this process, no
  scheduler) of ``--workers N`` processes (default: the cores) runs the jobs; ``--workers 1``
  runs them in this process. Dask (the ``fleet`` extra) only when asked: ``--dask`` runs an
  embedded ``LocalCluster`` of N single-threaded worker processes, ``--scheduler
  tcp://HOST:8786`` uses an existing cluster. Every executor gives the same rows, and none
  leaves a worker process behind when the command ends (^C included). A log that cannot be
  read is a row with its error; it never stops the others.
* **Sweeps.** ``--sweep rover.detector.gate_sigmas=4,6,8`` (repeatable: the cartesian product of
  all sweeps) changes one key of the ``--config`` file per point; every point is validated by the
  one config loader before any work starts, so a bad key or value fails at once (exit 2).
"""

from __future__ import annotations

import argparse
import concurrent.futures
import contextlib
import itertools
import json
import logging
import math
import multiprocessing
import os
import sys
import time
import tomllib
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Literal, TextIO, cast

from drivers.capture import is_capture
from drivers.configload import read_toml
from fdi.errors import ConfigError, FdiBridgeError
from firmware_host.commands.checks import input_path_arg, output_dir_arg, positive_int
from firmware_host.commands.replay import load_input
from firmware_host.commands.tables import Block, Table, report_console, report_markdown
from firmware_host.devtools.progress import Progress as Bar
from firmware_host.devtools.score import score_rover
from firmware_host.rov.config import RovConfig, load_rov_config
from firmware_host.rov.tlog import load_dive, replay
from firmware_host.rover.pipeline import EpochOutcome, RoverPipeline
from firmware_host.runtime.config import (
    BridgeConfig,
    bridge_config,
    parse_bridge_file,
    resolve_config_path,
)

LogKind = Literal["capture", "nmea", "tlog"]

#: File endings taken as logs when a directory is searched (a capture is also found by content).
LOG_SUFFIXES = {".cap": "capture", ".nmea": "nmea", ".log": "nmea", ".txt": "nmea",
                ".tlog": "tlog"}


@dataclass(frozen=True)
class LogEntry:
    """One recorded run: its path, what it is, and its truth file if there is one."""

    path: str
    kind: LogKind
    truth: str | None = None


@dataclass(frozen=True)
class SweepPoint:
    """One configuration of a sweep: its label and the keys it changes."""

    label: str
    overrides: tuple[tuple[str, Any], ...] = ()


@dataclass(frozen=True)
class Job:
    """What a worker needs: the log, the point's label and its validated configurations."""

    log: LogEntry
    point: str
    rover: BridgeConfig
    rov: RovConfig
    quiet: bool = True  # per-epoch log lines of the run under test off (they are counted)


@dataclass
class FleetResult:
    rows: list[dict[str, Any]] = field(default_factory=list)
    points: list[str] = field(default_factory=list)
    executor: str = "serial"
    seconds: float = 0.0
    jobs: int = 0  # how many were asked for (rows: how many were done)
    partial: bool = False  # ^C: the rows of the jobs done before it


# --------------------------------------------------------------------------- discovery


def _kind_of(p: Path) -> LogKind | None:
    if p.suffix.lower() in (".chk", ".json", ".jsonl", ".toml", ".md", ".png"):
        return None
    try:
        if is_capture(p):
            return "capture"
    except OSError:
        return "nmea"  # unreadable: let the job report the error
    kind = LOG_SUFFIXES.get(p.suffix.lower())
    return kind  # type: ignore[return-value]


def _truth_for(p: Path, truth_dir: Path | None) -> str | None:
    names = [f"{p.stem}.truth.jsonl", "truth.jsonl"]
    places = [p.parent] if truth_dir is None else [truth_dir / p.parent.name, truth_dir]
    if truth_dir is not None:
        names.insert(0, f"{p.parent.name}.truth.jsonl")
    for place in places:
        for name in names:
            cand = place / name
            if cand.is_file():
                return str(cand)
    return None


def discover(patterns: Sequence[str], truth_dir: Path | None = None) -> list[LogEntry]:
    """Every log named by ``patterns`` (files, directories searched recursively, or globs).

    A capture and a plain log with the same name in one folder are one run (the generator
    writes both): the capture is used. The list is sorted by path, so every executor sees the
    same order.
    """
    found: dict[Path, LogKind] = {}
    for pat in patterns:
        p = Path(pat)
        if p.is_dir():
            cands: Iterable[Path] = (c for c in p.rglob("*") if c.is_file())
        elif p.exists():
            cands = [p]
        else:
            matches = sorted(Path().glob(pat)) if not p.is_absolute() else sorted(
                Path(p.anchor).glob(str(p.relative_to(p.anchor))))
            if not matches:
                raise FdiBridgeError(f"fleet: {pat}: no such file, directory or match")
            cands = [m for m in matches if m.is_file()]
        for c in cands:
            kind = _kind_of(c)
            if kind is not None:
                found[c.resolve()] = kind
    for path, kind in list(found.items()):
        if kind == "nmea" and found.get(path.with_suffix(".cap")) == "capture":
            del found[path]
    return [LogEntry(str(path), kind, _truth_for(path, truth_dir))
            for path, kind in sorted(found.items())]


# --------------------------------------------------------------------------- sweeps


def _parse_value(text: str) -> Any:
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def parse_sweeps(specs: Sequence[str]) -> list[SweepPoint]:
    """``["a.b=1,2", "c=x,y"]`` -> the four points of the product (no sweep: one point)."""
    axes: list[list[tuple[str, Any]]] = []
    for spec in specs:
        key, sep, values = spec.partition("=")
        key = key.strip()
        if not sep or not key or not values.strip():
            raise ConfigError("--sweep", spec, "KEY=V1,V2,...", spec)
        axes.append([(key, _parse_value(v.strip())) for v in values.split(",") if v.strip()])
    if not axes:
        return [SweepPoint("config")]
    points = []
    for combo in itertools.product(*axes):
        label = " ".join(f"{k}={v}" for k, v in combo)
        points.append(SweepPoint(label, tuple(combo)))
    return points


def _set_key(table: dict[str, Any], key: str, value: Any) -> None:
    parts = key.split(".")
    node = table
    for part in parts[:-1]:
        nxt = node.setdefault(part, {})
        if not isinstance(nxt, dict):
            raise ConfigError("--sweep", key, "a key inside a table", f"{part} is a value")
        node = nxt
    node[parts[-1]] = value


def point_configs(config: str | None, points: Sequence[SweepPoint]) -> dict[str, BridgeConfig]:
    """Each point's configuration, validated by the one loader (a bad point fails here)."""
    path = resolve_config_path(config) if config is not None else None
    base = read_toml(path) if path is not None else {"rover": {}}
    out: dict[str, BridgeConfig] = {}
    for pt in points:
        table = json.loads(json.dumps(base))  # a deep copy of plain TOML data
        for key, value in pt.overrides:
            _set_key(table, key, value)
        where = str(path) if path is not None else "(built-in defaults)"
        if pt.overrides:
            where += f" [sweep {pt.label}]"
        out[pt.label] = bridge_config(parse_bridge_file(table, where, path))
    return out


# --------------------------------------------------------------------------- one job

#: Loggers of the detectors and drivers, whose per-epoch lines a fleet run counts instead.
QUIET_LOGGERS = ("fdi_bridge", "drivers", "firmware_host", "distributed")


def _quiet_logs() -> None:
    """Raise the detectors' (and Dask's) loggers to ERROR in this process (a worker too)."""
    for name in QUIET_LOGGERS:
        logging.getLogger(name).setLevel(logging.ERROR)


@contextlib.contextmanager
def _levels_kept() -> Iterator[None]:
    """The levels of :data:`QUIET_LOGGERS` as they were, once the block is done: an in-process
    caller (the CLI's tests, a notebook) gets its log output back."""
    saved = {name: logging.getLogger(name).level for name in QUIET_LOGGERS}
    try:
        yield
    finally:
        for name, level in saved.items():
            logging.getLogger(name).setLevel(level)


_SCORE_KEYS = ("faulty", "detected", "faulty_min", "detected_min", "clean", "false_alarms",
               "events", "events_detected", "alarms", "raw_rms_all_m", "out_rms_all_m",
               "out_rms_clean_m", "out_max_all_m", "delays_s")


def _round(x: Any) -> Any:
    if isinstance(x, float):
        return None if math.isnan(x) else round(x, 4)
    if isinstance(x, (list, tuple)):
        return [_round(v) for v in x]
    return x


class _KeptRecords:
    """An output that keeps each epoch's record, the dict the pipeline builds for
    ``epochs.jsonl`` (what ``json.loads`` of its line gives back, without the round trip)."""

    def __init__(self) -> None:
        self.records: list[dict[str, Any]] = []

    def emit(self, out: EpochOutcome) -> None:
        self.records.append(out.record)

    def close(self) -> None:
        pass


class _NoFile:
    """A ``jsonl`` that writes nothing: the pipeline builds the records, the job keeps them."""

    def write(self, text: str) -> int:
        return len(text)


def replay_rover(cfg: BridgeConfig, data: bytes, records: bool
                 ) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """The rover pipeline (no pty) on ``data``: its records (only when ``records``: scoring
    needs them, counting does not) and its summary. The records are those of
    :func:`~firmware_host.devtools.eval.run_ours` (tests/test_fleet_pool.py compares them)."""
    kept = _KeptRecords()
    pipe = RoverPipeline(cfg.rover, jsonl=cast("TextIO", _NoFile()) if records else None,
                         sinks=[kept] if records else None)
    pipe.feed(data)
    pipe.finish()
    return kept.records, pipe.summary()


def _rover_row(job: Job) -> dict[str, Any]:
    inp = load_input(job.log.path)
    data = inp.data()
    records, summary = replay_rover(job.rover, data, records=job.log.truth is not None)
    counters = summary["input"]
    if counters["sentences"] == 0 and not counters["ignored"]:
        raise FdiBridgeError(
            f"no NMEA sentences found ({summary['input']['bytes_in']} bytes, "
            f"{summary['input']['rejected_total']} lines rejected)")
    row: dict[str, Any] = {
        "epochs": summary["epochs"],
        "faults": summary["faults"],
        "alarms": summary["alarms"],
        "replaced": summary["actions"].get("replace", 0),
        "no_fix": summary["actions"].get("no_fix", 0),
        "rejected_lines": summary["input"]["rejected_total"],
        "gate_health": summary["gate_health"]["status"],
        "notes": list(inp.notes),
    }
    if summary["epochs"] == 0:
        row["notes"].append("no position sentences (only " + ", ".join(
            sorted(counters["ignored"])[:5]) + ")")
    if job.log.truth is not None:
        truth = [json.loads(line) for line in
                 Path(job.log.truth).read_text(encoding="utf-8").splitlines() if line.strip()]
        sc = asdict(score_rover(records, truth))
        row["score"] = {k: _round(sc[k]) for k in _SCORE_KEYS}
    return row


def _tlog_row(job: Job) -> dict[str, Any]:
    dive = load_dive(job.log.path, job.rov.period_s)
    decisions = replay(dive, job.rov)
    return {
        "epochs": len(decisions),
        "faults": sum(1 for d in decisions if d.event == "confirmed"),
        "alarms": 0,
        "suspects": sum(1 for d in decisions if d.event == "suspect"),
        "replaced": 0,
        "no_fix": sum(1 for d in decisions if d.heading_used is None),
        "gate_health": "",
        "notes": [],
    }


def evaluate_log(job: Job) -> dict[str, Any]:
    """One log at one sweep point -> a plain row (picklable; the same on every executor).

    Any error of the log (unreadable, damaged, not a log at all) becomes the row's ``error``.
    """
    if job.quiet:
        _quiet_logs()
    row: dict[str, Any] = {"point": job.point, "log": job.log.path, "kind": job.log.kind,
                           "truth": job.log.truth is not None, "error": None}
    try:
        row.update(_tlog_row(job) if job.log.kind == "tlog" else _rover_row(job))
    except (FdiBridgeError, OSError, ValueError, KeyError, IndexError, StopIteration) as err:
        row["error"] = f"{type(err).__name__}: {err}"
    return row


# --------------------------------------------------------------------------- executors

Progress = Callable[[int, int], None]


def run_serial(jobs: Sequence[Job], progress: Progress | None = None,
               into: list[dict[str, Any]] | None = None) -> list[dict[str, Any]]:
    """The jobs in this process, in order; each row also appended to ``into`` as it is done
    (what a ^C leaves)."""
    rows = into if into is not None else []
    for i, job in enumerate(jobs, 1):
        rows.append(evaluate_log(job))
        if progress is not None:
            progress(i, len(jobs))
    return rows


def run_pool(jobs: Sequence[Job], workers: int, progress: Progress | None = None,
             into: list[dict[str, Any]] | None = None) -> list[dict[str, Any]]:
    """The jobs on a local pool of ``workers`` processes (forked where the system can: a worker
    starts with this process's modules already imported), one job per task; the rows in job
    order, appended to ``into`` when all are done or at ^C (the rows done by then). The pool is
    shut down before this returns, its queued jobs cancelled: no worker outlives the call."""
    methods = multiprocessing.get_all_start_methods()
    ctx = multiprocessing.get_context("fork" if "fork" in methods else None)
    rows: list[dict[str, Any] | None] = [None] * len(jobs)
    pool = concurrent.futures.ProcessPoolExecutor(max_workers=workers, mp_context=ctx)
    try:
        index = {pool.submit(evaluate_log, job): i for i, job in enumerate(jobs)}
        for done, fut in enumerate(concurrent.futures.as_completed(index), 1):
            rows[index[fut]] = fut.result()
            if progress is not None:
                progress(done, len(jobs))
    finally:  # ^C too: the rows done, in job order, and the workers joined
        pool.shutdown(wait=True, cancel_futures=True)
        out = into if into is not None else []
        out.extend(r for r in rows if r is not None)
    return out


def run_dask(jobs: Sequence[Job], *, workers: int | None = None, scheduler: str | None = None,
             progress: Progress | None = None,
             into: list[dict[str, Any]] | None = None) -> list[dict[str, Any]]:
    """The jobs on a Dask cluster: an embedded ``LocalCluster`` of ``workers`` processes, or the
    scheduler at ``scheduler`` (``tcp://HOST:PORT``)."""
    try:
        from dask.distributed import Client, LocalCluster, as_completed
    except ImportError as err:  # the optional extra
        raise FdiBridgeError(
            "fleet: Dask is not installed (pip install 'fdi-bridge[dev]'); "
            "without --dask and --scheduler the fleet runs without it") from err
    _quiet_logs()  # importing distributed set its own levels
    cluster = None
    if scheduler is None:
        cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1,
                               processes=True, host="127.0.0.1",
                               dashboard_address="127.0.0.1:0")
        client = Client(cluster)
    else:
        try:
            client = Client(scheduler, timeout=10)
        except (OSError, TimeoutError) as err:
            raise FdiBridgeError(f"fleet: no Dask scheduler at {scheduler}: {err}") from err
    try:
        futures = client.map(evaluate_log, list(jobs), pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        rows: list[dict[str, Any] | None] = [None] * len(futures)
        try:
            for done, fut in enumerate(as_completed(futures), 1):
                rows[index[fut.key]] = fut.result()
                if progress is not None:
                    progress(done, len(futures))
        finally:  # ^C too: the rows done, in job order
            out = into if into is not None else []
            out.extend(r for r in rows if r is not None)
        return out
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def run_fleet(logs: Sequence[LogEntry], configs: dict[str, BridgeConfig], rov: RovConfig, *,
              workers: int | None = None, scheduler: str | None = None, dask: bool = False,
              progress: Progress | None = None) -> FleetResult:
    """Every log at every point: on the Dask scheduler at ``scheduler``, else on a Dask
    ``LocalCluster`` of ``workers`` processes when ``dask``, else on a local process pool of
    ``workers`` (default: the cores), or in this process when that is 1 (or there is one
    job)."""
    jobs = [Job(log, label, cfg, rov) for label, cfg in configs.items() for log in logs]
    n = workers if workers is not None else (os.cpu_count() or 1)
    t0 = time.perf_counter()
    rows: list[dict[str, Any]] = []
    partial = False
    if scheduler is not None:
        executor = f"dask {scheduler}"
    elif dask:
        executor = f"dask LocalCluster x{n}"
    else:
        n = min(n, len(jobs))
        executor = "serial" if n <= 1 else f"process pool x{n}"
    try:
        with _levels_kept():
            if executor.startswith("dask"):
                run_dask(jobs, workers=n, scheduler=scheduler, progress=progress, into=rows)
            elif executor == "serial":
                run_serial(jobs, progress, into=rows)
            else:
                run_pool(jobs, n, progress, into=rows)
    except KeyboardInterrupt:
        partial = True
    return FleetResult(rows, list(configs), executor, time.perf_counter() - t0, len(jobs),
                       partial)


# --------------------------------------------------------------------------- tables


def pooled(rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Totals over the rows of one point; with truth, detection and false alarms pooled over
    epochs and events, RMS over the scored epochs of every log."""
    ok = [r for r in rows if r["error"] is None]
    out: dict[str, Any] = {
        "logs": len(rows), "errors": len(rows) - len(ok),
        "epochs": sum(r["epochs"] for r in ok), "faults": sum(r["faults"] for r in ok),
        "alarms": sum(r["alarms"] for r in ok), "replaced": sum(r["replaced"] for r in ok),
    }
    scored = [r["score"] for r in ok if "score" in r]
    out["scored_logs"] = len(scored)
    if scored:
        faulty = sum(s["faulty_min"] for s in scored)
        clean = sum(s["clean"] for s in scored)
        events = sum(s["events"] for s in scored)
        delays = [d for s in scored for d in s["delays_s"]]
        n_all = [s["faulty"] + s["clean"] for s in scored]

        def rms(key: str) -> float | None:
            pairs = [(n, s[key]) for n, s in zip(n_all, scored, strict=True)
                     if s[key] is not None]
            total = sum(n for n, _ in pairs)
            return round(math.sqrt(sum(n * v * v for n, v in pairs) / total), 4) if total else None

        out.update({
            "detected_pct": round(100 * sum(s["detected_min"] for s in scored) / faulty, 3)
            if faulty else None,
            "false_alarm_pct": round(100 * sum(s["false_alarms"] for s in scored) / clean, 4)
            if clean else None,
            "events": events,
            "events_detected": sum(s["events_detected"] for s in scored),
            "mean_delay_s": round(sum(delays) / len(delays), 3) if delays else None,
            "raw_rms_m": rms("raw_rms_all_m"),
            "out_rms_m": rms("out_rms_all_m"),
        })
    return out


def _cell(x: Any) -> str:
    if x is None:
        return "–"
    if isinstance(x, float):
        return f"{x:.3f}" if abs(x) < 100 else f"{x:.1f}"
    return str(x)


def point_tab(rows: Sequence[dict[str, Any]], root: str = "") -> Table:
    """One row per log of one sweep point (a log that failed: its error as the note)."""
    tab = Table(["log", "kind", "epochs", "faults", "alarms", "replaced", "detected %",
                 "false alarms %", "raw RMS (m)", "out RMS (m)", "note"])
    for r in rows:
        name = os.path.relpath(r["log"], root) if root else r["log"]
        if r["error"] is not None:
            tab.add(name, r["kind"], *[""] * 8, f"**{r['error']}**")
            continue
        s = r.get("score")
        det = fa = raw = out = None
        if s is not None:
            det = 100 * s["detected_min"] / s["faulty_min"] if s["faulty_min"] else None
            fa = 100 * s["false_alarms"] / s["clean"] if s["clean"] else None
            raw, out = s["raw_rms_all_m"], s["out_rms_all_m"]
        note = "; ".join(r["notes"]) or (f"gate {r['gate_health']}" if r["gate_health"] else "")
        tab.add(name, r["kind"], str(r["epochs"]), str(r["faults"]), str(r["alarms"]),
                str(r["replaced"]), _cell(det), _cell(fa), _cell(raw), _cell(out), note)
    return tab


def point_table(rows: Sequence[dict[str, Any]], root: str = "") -> str:
    """:func:`point_tab` as Markdown."""
    return point_tab(rows, root).markdown()


def comparison_tab(result: FleetResult) -> Table:
    """One row per sweep point: the totals and pooled scores over the fleet."""
    tab = Table(["point", "logs", "errors", "epochs", "faults", "alarms", "replaced",
                 "detected %", "false alarms %", "events", "mean delay (s)", "raw RMS (m)",
                 "out RMS (m)"])
    for label in result.points:
        p = pooled([r for r in result.rows if r["point"] == label])
        tab.add(label, *(str(p[k]) for k in ("logs", "errors", "epochs", "faults", "alarms",
                                              "replaced")),
                _cell(p.get("detected_pct")), _cell(p.get("false_alarm_pct")),
                f"{_cell(p.get('events_detected'))}/{_cell(p.get('events'))}",
                _cell(p.get("mean_delay_s")), _cell(p.get("raw_rms_m")),
                _cell(p.get("out_rms_m")))
    return tab


def comparison_table(result: FleetResult) -> str:
    """:func:`comparison_tab` as Markdown."""
    return comparison_tab(result).markdown()


def report(result: FleetResult, root: str = "") -> list[Block]:
    """The fleet report: a title, the pooled comparison, one table per sweep point."""
    parts: list[Block] = [
        f"# Fleet evaluation: {len({r['log'] for r in result.rows})} logs, "
        f"{len(result.points)} point(s), {result.executor}, {result.seconds:.1f} s",
        "", "## Pooled comparison", "", comparison_tab(result)]
    if result.partial:
        parts[1:1] = ["", f"{PARTIAL} {len(result.rows)} of {result.jobs} jobs done before ^C."]
    for label in result.points:
        parts += ["", f"## {label}", "",
                  point_tab([r for r in result.rows if r["point"] == label], root)]
    return parts


PARTIAL = "**Partial (interrupted):**"


def markdown(result: FleetResult, root: str = "") -> str:
    """:func:`report` as Markdown (``fleet.md``)."""
    return report_markdown(report(result, root)) + "\n"


def console(result: FleetResult, root: str = "") -> str:
    """:func:`report` as aligned console tables."""
    return report_console(report(result, root))


def plot_tradeoff(result: FleetResult, path: Path) -> bool:
    """Detection against false alarms, one marker per point (needs matplotlib and truth)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    pts = [(label, pooled([r for r in result.rows if r["point"] == label]))
           for label in result.points]
    pts = [(lbl, p) for lbl, p in pts if p.get("detected_pct") is not None]
    if not pts:
        return False
    fig = tradeoff_figure(plt, pts)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return True


def tradeoff_figure(plt: Any, pts: Sequence[tuple[str, dict[str, Any]]]) -> Any:
    """The trade-off figure: each point's marker numbered, its label in the legend (labels
    written beside close markers, all near 100 %, overprinted each other), the axes kept to
    what a percentage can be (0-100 %, a little margin)."""
    fig, ax = plt.subplots(figsize=(6, 4.5))
    for i, (label, p) in enumerate(pts, 1):
        ax.plot(p["false_alarm_pct"], p["detected_pct"], "o", label=f"{i}: {label}")
        ax.annotate(str(i), (p["false_alarm_pct"], p["detected_pct"]), fontsize=7,
                    xytext=(3, 3), textcoords="offset points")
    lo, hi = ax.get_ylim()
    ax.set_ylim(max(lo, -0.5), min(hi, 100.5))
    lo, hi = ax.get_xlim()
    ax.set_xlim(max(lo, -0.05 * max(hi, 0.01)), hi)
    ax.set_xlabel("clean epochs flagged (%)")
    ax.set_ylabel("faulty epochs detected (%)")
    ax.set_title("Detection against false alarms, pooled over the fleet")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    return fig


# --------------------------------------------------------------------------- CLI


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("logs", nargs="+",
                        help="log files, directories (searched recursively) or globs")
    parser.add_argument("--truth-dir", type=input_path_arg, default=None,
                        help="truth files: DIR/<run>.truth.jsonl or DIR/<folder>/truth.jsonl "
                             "(default: a truth.jsonl beside each log)")
    parser.add_argument("--config", default="rover",
                        help="rover config file or preset (default: rover)")
    parser.add_argument("--rov-config", default="rov",
                        help="ROV config for .tlog dives (default: rov)")
    parser.add_argument("--sweep", action="append", default=[], metavar="KEY=V1,V2,...",
                        help="a config key and its values (repeatable: all combinations), "
                             "e.g. rover.detector.gate_sigmas=4,6,8")
    parser.add_argument("--workers", type=positive_int, default=None,
                        help="worker processes of the local pool (or of --dask's "
                             "LocalCluster); default: the cores; 1 = in this process")
    parser.add_argument("--dask", action="store_true",
                        help="run on an embedded Dask LocalCluster instead of the local "
                             "process pool (the fleet extra)")
    parser.add_argument("--scheduler", default=None,
                        help="an existing Dask scheduler, e.g. tcp://127.0.0.1:8786 (the "
                             "logs' paths must be readable by its workers)")
    parser.add_argument("--compare-serial", action="store_true",
                        help="also run serially, check the rows are identical, print the ratio")
    parser.add_argument("--out", type=output_dir_arg, default=None,
                        help="write fleet.md, fleet.json and fleet.png here")
    parser.add_argument("--json", action="store_true",
                        help="print the results (fleet.json's document) as JSON instead of "
                             "the tables")


def _progress(bar: Bar) -> Progress:
    """``run_fleet``'s ``progress(done, total)`` drawn as a tqdm bar (only on a terminal)."""
    def show(done: int, total: int) -> None:
        if bar.bar.total != total:
            bar.total(total)
        bar.step(n=done - bar.bar.n)
    return show


def run(args: argparse.Namespace) -> int:
    with _levels_kept():
        return _run(args)


def _run(args: argparse.Namespace) -> int:
    _quiet_logs()
    if args.workers is not None and args.workers < 1:
        raise ConfigError("--workers", "workers", "a whole number >= 1", str(args.workers))
    if args.out is not None and args.out.exists() and not args.out.is_dir():
        raise FdiBridgeError(f"fleet: --out {args.out} exists and is not a directory")
    configs = point_configs(args.config, parse_sweeps(args.sweep))
    rov, _ = load_rov_config(resolve_config_path(args.rov_config))
    logs = discover(args.logs, args.truth_dir)
    if not logs:
        raise FdiBridgeError("fleet: no logs found (captures, .nmea/.log/.txt, .tlog)")
    workers = args.workers if args.workers is not None else (os.cpu_count() or 1)
    with Bar(len(logs), "fleet", unit="job") as bar:
        result = run_fleet(logs, configs, rov, workers=workers, scheduler=args.scheduler,
                           dask=args.dask, progress=_progress(bar))
    doc: dict[str, Any] = {
        "executor": result.executor, "seconds": round(result.seconds, 3),
        "points": {label: pooled([r for r in result.rows if r["point"] == label])
                   for label in result.points},
        "rows": result.rows}
    if result.partial:
        doc["partial"] = True
    say = sys.stderr if args.json else sys.stdout  # --json: stdout is the JSON alone
    if args.json:
        print(json.dumps(doc))
    else:
        print(console(result, os.path.commonpath([lg.path for lg in logs]) if len(logs) > 1
                      else ""))
    if args.compare_serial and result.executor != "serial" and not result.partial:
        with Bar(len(logs), "fleet, serial", unit="job") as bar:
            serial = run_fleet(logs, configs, rov, workers=1, progress=_progress(bar))
        same = serial.rows == result.rows
        print(f"serial {serial.seconds:.2f} s, {result.executor} {result.seconds:.2f} s: "
              f"ratio {result.seconds / serial.seconds:.3f}; rows identical: {same}", file=say)
        if not same:
            return 1
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "fleet.md").write_text(markdown(result), encoding="utf-8")
        (args.out / "fleet.json").write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
        plotted = plot_tradeoff(result, args.out / "fleet.png")
        print(f"wrote {args.out / 'fleet.md'}, fleet.json" + (", fleet.png" if plotted else ""),
              file=say)
    if result.partial:
        where = f" ({args.out}, marked partial)" if args.out is not None else ""
        print(f"fdi-bridge fleet: interrupted: the {len(result.rows)} of {result.jobs} jobs "
              f"done are written{where}", file=sys.stderr)
        return 130
    return 0
