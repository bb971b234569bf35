"""The field's fault stream at rest through the live INS/GNSS vehicle, beside the plain rover.

Issue G's run on a real ArduRover: a stationary NMEA receiver with jumps, bursts, position
walks at zero speed and a 20 s outage, the autopilot's IMU drifting as ArduPilot's simulated
one. Here the same stream on the project's simulated autopilot
(:mod:`firmware_host.devtools.insgnss_live`, real ptys):

* the vehicle at rest for ``rest_s`` (the live example's filter and IMU model, ArduPilot's
  gyro drift 0.05 deg/s per minute, RAW_IMU, ATTITUDE 1 deg off for the heading);
* the receiver's error a DGPS receiver's, as ``sim rover``'s ``gm`` model: a first-order
  Gauss-Markov process per axis (σ 0.35 m horizontal, 0.7 m up, τ 60 s);
* its faults (:func:`field_faults`): single-epoch jumps of 3-6 m, bursts of 4-6 epochs of 3-6 m
  in random directions, two walks at zero reported speed (0.2 m/s east and 0.15 m/s south,
  25 s each, then back), and the outage (no-fix epochs, :data:`OUTAGE`).

:func:`compare_field` returns, per epoch, the INS's horizontal error (its output) and the
plain rover's (the rover detector's output on the same epoch: the vehicle runs it on every fix
and records it, the same pipeline as ``RoverVehicle``). The rover sends nothing during the
outage (no-fix), the INS coasts then sends no-fix past its limit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import numpy.typing as npt

from firmware_host.devtools import insgnss_sim as sim
from firmware_host.devtools.insgnss_live import UTC0, LiveRun, frame_of, run_live
from firmware_host.runtime.config import CONFIG_DIR, insgnss_setup, load_bridge_file
from firmware_host.runtime.config_insgnss import InsGnssSetup

FloatArray = npt.NDArray[np.float64]
REST_S = 300  # s at rest before the take-off roll (trajectory t = -320 .. -20)
OUTAGE = (-70.0, -50.0)  # the 20 s GNSS outage (trajectory time)
JUMPS_T = (-250.0, -240.0, -200.0, -120.0)
BURSTS = ((-230.0, 4), (-150.0, 6))  # (start, epochs)
WALKS = ((-190.0, 25.0, (0.2, 0.0)), (-110.0, 25.0, (0.0, -0.15)))  # (start, s, m/s E, N)
GM_SIGMA_M = (0.35, 0.35, 0.7)
GM_TAU_S = 60.0
# The filter's white rest of the receiver's error (E/N 1σ, up twice that) beside its
# Gauss-Markov state: the simulated receiver has none (its error is the Gauss-Markov process
# alone); a DGPS fix's epoch-to-epoch noise of a decimetre is assumed, not measured (0.3 m:
# worst excess 0.61 m against 0.53 m on seeds 1-8, docs/insgnss-live.md).
WHITE_SIGMA_M = 0.1


def field_setup(gnss_sigma_h_m: float | None = None, *,
                model_receiver: bool = True) -> InsGnssSetup:
    """The live example's filter and IMU at rest for :data:`REST_S` with ArduPilot's gyro
    drift; the simulator's own GNSS noise off (:func:`field_data` adds a receiver's).

    ``model_receiver``: the filter configured for the simulated DGPS receiver, as a vehicle's
    is for its own: the receiver's correlated error as the filter's Gauss-Markov state with
    the receiver's σ and τ (:data:`GM_SIGMA_M`, :data:`GM_TAU_S`; ``gnss_gm_*``), R its
    white rest (``gnss_sigma_h_m``, default :data:`WHITE_SIGMA_M`). False: the example's
    filter (R white, ``gnss_sigma_h_m`` default the example's 3 m). Up: R twice E/N."""
    ex = insgnss_setup(load_bridge_file(CONFIG_DIR / "insgnss-live-example.toml"))
    base = sim.load_setup(None)
    if model_receiver and gnss_sigma_h_m is None:
        gnss_sigma_h_m = WHITE_SIGMA_M
    filt = ex.filter if gnss_sigma_h_m is None else replace(
        ex.filter, gnss_sigma_h_m=gnss_sigma_h_m, gnss_sigma_v_m=2.0 * gnss_sigma_h_m)
    if model_receiver:
        filt = replace(filt, gnss_gm_sigma_m=GM_SIGMA_M[0], gnss_gm_sigma_up_m=GM_SIGMA_M[2],
                       gnss_gm_tau_s=GM_TAU_S)
    return replace(base, filter=filt, live=ex.live,
                   sim=replace(base.sim, epochs=20, rest_s=REST_S, random_faults=0,
                               imu=ex.sim.imu, gyro_drift_deg_s_per_min=0.05,
                               gnss_sigma_h_m=0.0, gnss_sigma_v_m=0.0,
                               gnss_sigma_vel_m_s=0.03))


def field_faults(t: FloatArray, rng: np.random.Generator) -> FloatArray:
    """The faults (E, N, U m) at the GNSS epochs ``t``: jumps, bursts, walks (module doc)."""
    f = np.zeros((len(t), 3))

    def at(a: float, b: float) -> npt.NDArray[np.bool_]:
        return (t >= a) & (t < b)

    def kick() -> FloatArray:
        ang, size = rng.uniform(0.0, 2.0 * math.pi), rng.uniform(3.0, 6.0)
        return size * np.array([math.cos(ang), math.sin(ang)])

    for tj in JUMPS_T:
        f[at(tj, tj + 1.0), :2] += kick()
    for tb, n in BURSTS:
        for k in range(n):
            f[at(tb + k, tb + k + 1.0), :2] += kick()
    for tw, dur, (ve, vn) in WALKS:
        w = at(tw, tw + dur)
        f[w, 0] += ve * (t[w] - tw)
        f[w, 1] += vn * (t[w] - tw)
    return f


def field_data(setup: InsGnssSetup, seed: int) -> sim.NavData:
    """The simulator's clean run plus a DGPS receiver's error and :func:`field_faults`."""
    data = sim.generate(setup, "clean", seed)
    rng = np.random.default_rng(seed)
    t = data.gnss_t
    sg = np.array(GM_SIGMA_M)
    phi = math.exp(-1.0 / GM_TAU_S)  # 1 Hz epochs
    gm = np.zeros((len(t), 3))
    gm[0] = rng.normal(0.0, 1.0, 3) * sg
    for k in range(1, len(t)):  # x_k = φ x_{k-1} + sqrt(1 - φ²) σ w_k
        gm[k] = phi * gm[k - 1] + math.sqrt(1.0 - phi * phi) * sg * rng.normal(0.0, 1.0, 3)
    f = field_faults(np.asarray(t, dtype=np.float64), rng)
    return replace(data, gnss_p=data.gnss_p + gm + f, fault=data.fault + f)


@dataclass(frozen=True)
class FieldEpoch:
    """One epoch at rest: the INS's output error (None: no fix sent), the rover's (None: its
    detector sent nothing), the coast's time and the accuracy sent (m); the receiver's fix
    less the truth (E, N m; None: no fix), whether :func:`field_faults` moved it, and whether
    the INS drove the output (False: before its alignment)."""

    t: float
    ins_err_m: float | None
    rover_err_m: float | None
    coast_s: float | None
    acc_h_m: float | None
    raw_en_m: tuple[float, float] | None = None
    faulty: bool = False
    aligned: bool = False


@dataclass
class FieldRun:
    epochs: list[FieldEpoch]
    run: LiveRun

    def excess(self) -> list[tuple[float, float]]:
        """(t, INS error − rover error) on every epoch both sent a position."""
        return [(e.t, e.ins_err_m - e.rover_err_m) for e in self.epochs
                if e.ins_err_m is not None and e.rover_err_m is not None]

    def oracle_excess(self) -> list[tuple[float, float]]:
        """The bound's floor: (t, oracle error − rover error) on the epochs of :meth:`excess`.
        The oracle is told which fixes are faulty and skips them; otherwise it is the
        minimum-variance estimate of a point at rest from the simulated receiver's own model
        (the position constant, its error g Gauss-Markov :data:`GM_SIGMA_M`, :data:`GM_TAU_S`,
        white rest :data:`WHITE_SIGMA_M`; E and N apart), started at the first INS epoch's fix
        as the filter is ((G4) of fdi/insgnss.py). What it loses against the rover is the
        rover's luck (its fix or held prediction nearer the truth than the receiver's model
        allows), not fault handling."""
        sg, sw = GM_SIGMA_M[0], WHITE_SIGMA_M
        phi = math.exp(-1.0 / GM_TAU_S)  # 1 Hz epochs
        F = np.diag([1.0, phi])
        Q = np.diag([0.0, (1.0 - phi * phi) * sg * sg])
        H = np.array([1.0, 1.0])  # z = p + g + v
        x: list[FloatArray] = []
        P: list[FloatArray] = []
        out: list[tuple[float, float]] = []
        for e in self.epochs:
            if not x:
                if e.aligned and e.raw_en_m is not None:
                    x = [np.array([e.raw_en_m[a], 0.0]) for a in range(2)]
                    P = [np.array([[sg * sg + sw * sw, -sg * sg], [-sg * sg, sg * sg]])
                         for _ in range(2)]
                continue
            for a in range(2):
                x[a] = F @ x[a]
                P[a] = F @ P[a] @ F.T + Q
                if e.raw_en_m is not None and not e.faulty:
                    k = P[a] @ H / (H @ P[a] @ H + sw * sw)
                    x[a] = x[a] + k * (e.raw_en_m[a] - H @ x[a])
                    P[a] = P[a] - np.outer(k, H @ P[a])
            if e.ins_err_m is not None and e.rover_err_m is not None:
                out.append((e.t, math.hypot(x[0][0], x[1][0]) - e.rover_err_m))
        return out


def compare_field(setup: InsGnssSetup, seed: int, out_dir: Path, *,
                  mavlink_url: str = "") -> FieldRun:
    """Play :func:`field_data` to the live vehicle (RAW_IMU, ATTITUDE 1 deg off) with the
    outage; each epoch at rest as a :class:`FieldEpoch`."""
    data = field_data(setup, seed)
    lr = run_live(setup, data, out_dir, seed=seed, imu_message="RAW_IMU",
                  attitude_error_deg=1.0, outage=OUTAGE, mavlink_url=mavlink_url)
    frame = frame_of(setup.filter.latitude_deg)
    rate = setup.sim.imu_rate_hz
    day0 = UTC0 % 86400.0
    out: list[FieldEpoch] = []
    for r in lr.records:
        t = float(r["t"]) - day0
        if t > -float(setup.sim.takeoff_s) - 1.0:
            break  # the take-off roll
        p = data.traj.p[round((t - float(data.traj.t[0])) * rate)]
        ins = r.get("ins") if r.get("mode") == "ins" else None
        ins_err = rover_err = coast = acc = None
        if isinstance(ins, dict) and "lla" in ins and ins.get("output") != "no fix":
            e, n, _ = frame.to_enu(*ins["lla"])
            ins_err = float(np.hypot(e - p[0], n - p[1]))
            acc = float(ins["acc_h_m"])
        if isinstance(ins, dict) and "coast_s" in ins:
            coast = float(ins["coast_s"])
        if r.get("lat") is not None and r.get("action") != "alarm":
            e, n, _ = frame.to_enu(float(r["lat"]), float(r["lon"]), 0.0)
            rover_err = float(np.hypot(e - p[0], n - p[1]))
        if r.get("mode") != "ins":
            ins_err = rover_err  # before the alignment the rover's output is the vehicle's
        raw = None
        if r.get("raw_lat") is not None:
            e, n, _ = frame.to_enu(float(r["raw_lat"]), float(r["raw_lon"]), 0.0)
            raw = (float(e - p[0]), float(n - p[1]))
        k = min(int(np.searchsorted(data.gnss_t, t - 1e-6)), len(data.gnss_t) - 1)
        faulty = bool(np.any(data.fault[k, :2] != 0.0))
        out.append(FieldEpoch(t, ins_err, rover_err, coast, acc, raw, faulty,
                              r.get("mode") == "ins"))
    return FieldRun(out, lr)


def main(argv: list[str] | None = None) -> int:
    """``python -m firmware_host.devtools.insgnss_field [--sigma R] [--white] [--seeds 1-8]
    [--oracle]``: one line a seed (the table of docs/insgnss-live.md), and the worst over the
    seeds."""
    import argparse
    import tempfile

    parser = argparse.ArgumentParser(prog="insgnss_field", description=__doc__.split("\n")[0])
    parser.add_argument("--sigma", type=float, default=None,
                        help="the filter's gnss_sigma_h_m (default: 0.1 m, the white rest "
                             "beside the receiver's modelled error; --white: the example's)")
    parser.add_argument("--white", action="store_true",
                        help="the example's filter: the receiver's error taken as white")
    parser.add_argument("--seeds", default="1-8", help="first-last")
    parser.add_argument("--oracle", action="store_true",
                        help="also the floor: the excess of a filter told which fixes are "
                             "faulty (FieldRun.oracle_excess)")
    args = parser.parse_args(argv)
    first, _, last = args.seeds.partition("-")
    worst_all = (-math.inf, 0)
    oracle_all = (-math.inf, 0)
    for seed in range(int(first), int(last or first) + 1):
        with tempfile.TemporaryDirectory() as d:
            fr = compare_field(field_setup(args.sigma, model_receiver=not args.white), seed,
                               Path(d))
        t, worst = max(fr.excess(), key=lambda x: x[1])
        coast = [e for e in fr.epochs if e.coast_s is not None and e.ins_err_m is not None
                 and e.acc_h_m]
        ratio = max((e.ins_err_m or 0.0) / (e.acc_h_m or 1.0) for e in coast) if coast else 0.0
        ins_max = max(e.ins_err_m for e in fr.epochs if e.ins_err_m is not None)
        rover_max = max(e.rover_err_m for e in fr.epochs if e.rover_err_m is not None)
        worst_all = max(worst_all, (worst, seed))
        label = "example, white" if args.white else "receiver modelled"
        print(f"{label} sigma {args.sigma or 'default'} seed {seed}: worst excess over the rover "
              f"{worst:.2f} m at t = {t:.0f} s; INS max {ins_max:.2f} m, rover max "
              f"{rover_max:.2f} m; coast error / accuracy at most {ratio:.2f} "
              f"({len(coast)} coast epochs sent)", flush=True)
        if args.oracle:
            t_o, worst_o = max(fr.oracle_excess(), key=lambda x: x[1])
            oracle_all = max(oracle_all, (worst_o, seed))
            print(f"  seed {seed}: a filter told the faults: worst excess {worst_o:.2f} m at "
                  f"t = {t_o:.0f} s", flush=True)
    print(f"worst excess over the rover {worst_all[0]:.2f} m (seed {worst_all[1]})")
    if args.oracle:
        print(f"a filter told the faults: worst excess {oracle_all[0]:.2f} m "
              f"(seed {oracle_all[1]})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
