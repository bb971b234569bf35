"""The simulated ArduSub's yaw against the real one: the captures' commands replayed through
:class:`~firmware_host.devtools.ardusub_sim.SubYawModel`, compared with SIMSTATE's true yaw.

``../shared/corpus/ardusub-sitl`` holds two runs of the bridge steering ArduPilot's own ArduSub
(SOURCES.md there): ``X.cap``, the bridge's recording (each step's ATTITUDE frames and the
MANUAL_CONTROL ``r`` it sent), and ``X-yaw.csv``, the simulator's true yaw (``SIMSTATE``, 4 Hz)
keyed by the ``ATTITUDE.time_boot_ms`` it follows. Two clocks are joined:

* the bridge's step time -> ArduSub's ``time_boot_ms``: the first turn (r = 1000 from rest)
  starts when its command arrives; its onset is the first moving ATTITUDE sample less its yaw
  change over its rate (the rate is flat at 77 deg/s there), so ``offset = onset - t_step``;
* a SIMSTATE row is sent 0-150 ms after the ATTITUDE it is keyed by (the two streams beat
  against each other). Where the vehicle turns at 20 deg/s or more, its time is found on the
  ATTITUDE trace (the EKF's yaw plus the constant frame offset, measured at rest, equals the
  true yaw within 0.2 deg); elsewhere it is taken as key + 75 ms (at most 75 ms off, under
  1.5 deg below 20 deg/s, and ~0.1 deg at the 1-2 deg/s of a hold).

Two measures of the model on a capture, both from the first command on:

* **1 s ahead**: from each SIMSTATE sample (yaw and rate), the model runs the captured commands
  to the sample 4 later (~1 s, five of the bridge's periods) and its yaw is compared with that
  sample: what a closed loop at 5 Hz sees of the plant;
* **free run**: from rest, the whole capture's commands in one run: the errors add up (a command
  at the dead band's edge either kicks the vehicle at ~7 deg/s or does not, a few degrees each
  time), so this measures the drift of an open-loop replay, not the closed loop.

``fdi-bridge sim ardusub-calib [--corpus DIR] [--fit att|raw] [--iters N]`` prints both measures
for both captures with the model in force (:data:`~firmware_host.devtools.ardusub_sim.SUB_YAW`)
and, with ``--fit``, fits the model's seven numbers on that capture (Nelder-Mead on the 1 s
ahead RMS) and prints them with both captures' measures (fit on one, check on the other).
"""

from __future__ import annotations

import argparse
import bisect
import csv
import json
import math
from collections.abc import Callable, Sequence
from dataclasses import astuple, dataclass
from pathlib import Path

from drivers.capture import CaptureReader
from drivers.mavlink import io as mio
from firmware_host.commands.checks import positive_int
from firmware_host.devtools.ardusub_sim import SUB_YAW, SubYawModel
from firmware_host.rov.ardusub import RX, TICK, TX
from firmware_host.rov.config import project_root
from firmware_host.rov.replay import recorded_steps

CAPTURES = ("att", "raw")
AHEAD_SAMPLES = 4  # SIMSTATE at 4 Hz: ~1 s
ALIGN_MIN_DPS = 20.0  # a SIMSTATE row is placed on the ATTITUDE trace at this rate or more
UNALIGNED_LAG_MS = 75.0  # the middle of a SIMSTATE row's 0-150 ms lag after its key
FIRST_TURN_DPS = 50.0  # the first turn's samples (r = 1000: 77 deg/s)
SUBSTEP_S = 0.01


@dataclass(frozen=True)
class Capture:
    """One capture, on ArduSub's clock (ms since boot)."""

    name: str
    commands: list[tuple[float, int]]  # (time the command arrives, MANUAL_CONTROL r)
    truth: list[tuple[float, float, float]]  # (time, true yaw unwrapped deg, true rate deg/s)
    clock_offset_ms: float  # ArduSub's time_boot_ms at the bridge's step time 0
    frame_offset_deg: float  # the true yaw less ATTITUDE's yaw (the SITL's declination)
    aligned_rows: int  # SIMSTATE rows placed on the ATTITUDE trace


def _wrap(x: float) -> float:
    return (x + 180.0) % 360.0 - 180.0


def _unwrap(yaws: Sequence[float]) -> list[float]:
    out: list[float] = []
    for y in yaws:
        out.append(y if not out else out[-1] + _wrap(y - out[-1]))
    return out


def _interp(xs: Sequence[float], ys: Sequence[float], x: float) -> float:
    i = bisect.bisect_right(xs, x)
    if i <= 0:
        return ys[0]
    if i >= len(xs):
        return ys[-1]
    f = (x - xs[i - 1]) / (xs[i] - xs[i - 1])
    return ys[i - 1] + f * (ys[i] - ys[i - 1])


def load_capture(corpus: Path, name: str) -> Capture:
    """``corpus/ardusub-sitl/NAME.cap`` and ``NAME-yaw.csv`` on one clock (module docstring)."""
    d = corpus / "ardusub-sitl"
    steps: list[tuple[float, int | None]] = []
    att: list[tuple[int, float, float]] = []  # (time_boot_ms, yaw deg, yaw rate deg/s)
    for st in recorded_steps(CaptureReader(d / f"{name}.cap"), {}, (TICK, RX, TX)):
        for raw in st.rx:
            m = mio.decode_packet(raw)
            if m is not None and m.get_type() == "ATTITUDE":
                att.append((int(m.time_boot_ms), math.degrees(m.yaw), math.degrees(m.yawspeed)))
        r = None
        for line in st.tx.decode("utf-8", errors="replace").splitlines():
            if line.strip():
                r = int(json.loads(line)["mc"][3])
        steps.append((st.t, r))
    att.sort()
    ta = [float(a[0]) for a in att]
    ya = _unwrap([a[1] for a in att])
    # the bridge's clock on ArduSub's: the first turn's onset
    k0 = next(i for i, s in enumerate(steps) if s[1])
    t_cmd = steps[k0][0] * 1000.0
    first = next(i for i, a in enumerate(att) if a[2] > FIRST_TURN_DPS)
    onset = ta[first] - (ya[first] - ya[first - 1]) / att[first][2] * 1000.0
    offset = onset - t_cmd
    commands = [(t * 1000.0 + offset, r) for t, r in steps if r is not None]
    rows = [(int(r["time_boot_ms"]), float(r["yaw_deg"]), float(r["yaw_rate_deg_s"]))
            for r in csv.DictReader((d / f"{name}-yaw.csv").open(encoding="utf-8"))
            if r["source"] == "SIMSTATE"]
    rest = [_wrap(y - _interp(ta, ya, k)) for k, y, rt in rows if ta[0] <= k < onset - 500.0]
    frame = sorted(rest)[len(rest) // 2]
    truth: list[tuple[float, float, float]] = []
    aligned = 0
    for k, y, rt in rows:
        t = k + UNALIGNED_LAG_MS
        if abs(rt) >= ALIGN_MIN_DPS and ta[0] < k < ta[-1] - 300:
            best = min(range(-100, 300), key=lambda dt: abs(
                _wrap(_interp(ta, ya, k + dt) + frame - y)))
            if abs(_wrap(_interp(ta, ya, k + best) + frame - y)) < 0.2:
                t = k + best
                aligned += 1
        truth.append((t, y, rt))
    truth.sort()
    yu = _unwrap([y for _, y, _ in truth])
    truth = [(t, y, rt) for (t, _, rt), y in zip(truth, yu, strict=True)]
    return Capture(name, commands, truth, offset, frame, aligned)


def _command_at(times: Sequence[float], cap: Capture, t: float) -> int:
    i = bisect.bisect_right(times, t) - 1
    return cap.commands[i][1] if i >= 0 else 0


def _run(model: SubYawModel, cap: Capture, times: Sequence[float], t0: float, psi: float,
         r: float, t1: float) -> tuple[float, float]:
    """The model from (``t0``, ``psi``, ``r``) to ``t1`` (ms) on the captured commands."""
    t = t0
    while t < t1 - 1e-9:
        h = min(SUBSTEP_S, (t1 - t) / 1000.0)
        accel = model.thrust(_command_at(times, cap, t))
        r1 = model.step_rate(r, accel, h)
        psi += 0.5 * (r + r1) * h
        r, t = r1, t + h * 1000.0
    return psi, r


@dataclass(frozen=True)
class Fit:
    """The model's errors on one capture (deg), and how many samples."""

    ahead_rms: float
    ahead_max: float
    ahead_n: int
    free_rms: float
    free_max: float
    free_n: int


def ahead_errors(model: SubYawModel, cap: Capture) -> list[float]:
    """The 1 s-ahead yaw errors (module docstring), from the first command on."""
    times = [c[0] for c in cap.commands]
    start = cap.commands[0][0] - 1000.0
    errs = []
    for j in range(len(cap.truth) - AHEAD_SAMPLES):
        t0, y0, r0 = cap.truth[j]
        if t0 < start:
            continue
        t1, y1, _ = cap.truth[j + AHEAD_SAMPLES]
        psi, _ = _run(model, cap, times, t0, y0, r0, t1)
        errs.append(psi - y1)
    return errs


def free_errors(model: SubYawModel, cap: Capture) -> list[float]:
    """The free run's yaw errors at every SIMSTATE sample from the first command on."""
    times = [c[0] for c in cap.commands]
    start = cap.commands[0][0] - 1000.0
    j0 = next(j for j, row in enumerate(cap.truth) if row[0] >= start)
    t, psi, r = cap.truth[j0]
    errs = []
    for t1, y1, _ in cap.truth[j0:]:
        psi, r = _run(model, cap, times, t, psi, r, t1)
        t = t1
        errs.append(psi - y1)
    return errs


def _rms(xs: Sequence[float]) -> float:
    return math.sqrt(sum(x * x for x in xs) / len(xs)) if xs else 0.0


def measure(model: SubYawModel, cap: Capture) -> Fit:
    a = ahead_errors(model, cap)
    f = free_errors(model, cap)
    return Fit(_rms(a), max(map(abs, a)), len(a), _rms(f), max(map(abs, f)), len(f))


def nelder_mead(f: Callable[[list[float]], float], x0: Sequence[float],
                steps: Sequence[float], iters: int) -> tuple[list[float], float]:
    """Nelder and Mead's simplex (1965), the textbook coefficients (1, 2, 0.5, 0.5)."""
    pts = [list(x0)] + [[x + (s if i == j else 0.0) for j, x in enumerate(x0)]
                        for i, s in enumerate(steps)]
    vals = [f(p) for p in pts]
    for _ in range(iters):
        order = sorted(range(len(pts)), key=vals.__getitem__)
        pts, vals = [pts[i] for i in order], [vals[i] for i in order]
        n = len(pts) - 1
        cen = [sum(p[j] for p in pts[:-1]) / n for j in range(len(x0))]
        refl = [c + (c - w) for c, w in zip(cen, pts[-1], strict=True)]
        fr = f(refl)
        if fr < vals[0]:
            exp = [c + 2.0 * (c - w) for c, w in zip(cen, pts[-1], strict=True)]
            fe = f(exp)
            pts[-1], vals[-1] = (exp, fe) if fe < fr else (refl, fr)
        elif fr < vals[-2]:
            pts[-1], vals[-1] = refl, fr
        else:
            con = [c + 0.5 * (w - c) for c, w in zip(cen, pts[-1], strict=True)]
            fc = f(con)
            if fc < vals[-1]:
                pts[-1], vals[-1] = con, fc
            else:
                best = pts[0]
                pts = [best] + [[b + 0.5 * (x - b) for b, x in zip(best, p, strict=True)]
                                for p in pts[1:]]
                vals = [vals[0]] + [f(p) for p in pts[1:]]
    i = min(range(len(pts)), key=vals.__getitem__)
    return pts[i], vals[i]


def fit(cap: Capture, start: SubYawModel = SUB_YAW, iters: int = 150) -> SubYawModel:
    """The model's seven numbers fitted on ``cap`` (the 1 s-ahead RMS, Nelder-Mead)."""
    def cost(x: list[float]) -> float:
        if x[0] <= 0 or x[1] <= 0 or x[2] <= 0 or x[3] <= 0 or x[4] <= 0 or x[5] < 1 \
                or x[6] < 0:
            return 1e9
        return _rms(ahead_errors(SubYawModel(*x), cap))

    x0 = list(astuple(start))
    steps = [3.0, 3.0, 0.1 * x0[2], 0.2, 0.1 * x0[4], 0.2, 0.01]
    best, _ = nelder_mead(cost, x0, steps, iters)
    return SubYawModel(*best)


def report(model: SubYawModel, caps: Sequence[Capture]) -> str:
    lines = ["capture  1 s ahead: RMS  max (deg), n  | free run: RMS  max (deg), n  | "
             "clock offset ms, frame offset deg, aligned SIMSTATE rows"]
    for cap in caps:
        m = measure(model, cap)
        lines.append(f"{cap.name:8} {m.ahead_rms:9.2f} {m.ahead_max:6.2f} {m.ahead_n:5d}   | "
                     f"{m.free_rms:13.2f} {m.free_max:6.2f} {m.free_n:5d}  | "
                     f"{cap.clock_offset_ms:.0f}, {cap.frame_offset_deg:.2f}, "
                     f"{cap.aligned_rows}")
    return "\n".join(lines)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--corpus", type=Path, default=None,
                        help="the corpus folder (default: ../shared/corpus beside the project)")
    parser.add_argument("--fit", choices=CAPTURES, default=None,
                        help="fit the model on this capture, then check it on both")
    parser.add_argument("--iters", type=positive_int, default=150,
                        help="Nelder-Mead iterations")


def run(args: argparse.Namespace) -> int:
    corpus = args.corpus or project_root().parent / "shared" / "corpus"
    if not (corpus / "ardusub-sitl").is_dir():
        print(f"ardusub-calib: no ardusub-sitl captures under {corpus}")
        return 2
    caps = [load_capture(corpus, n) for n in CAPTURES]
    print(f"model in force: {SUB_YAW}")
    print(report(SUB_YAW, caps))
    if args.fit:
        model = fit(next(c for c in caps if c.name == args.fit), SUB_YAW, args.iters)
        print(f"\nfitted on {args.fit}: {model}")
        print(report(model, caps))
    return 0
