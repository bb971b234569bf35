"""The ROV experiment step-locked in-process: plant and controller, no I/O, no clock.

The same :class:`~firmware_host.rov.control.RovController` the pty and real-vehicle modes use;
here the plant is advanced one period per step, so a 30-minute run takes about a second.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any

from firmware_host.devtools.rov_sim import FaultSpec, make_plant
from firmware_host.rov.config import RovConfig
from firmware_host.rov.control import RovController, epoch_record


def run_experiment(
    cfg: RovConfig,
    faults: Sequence[FaultSpec] = (),
    duration_s: float = 120.0,
    ft: bool = True,
    seed: int | None = None,
    gyro: bool = False,
) -> list[dict[str, Any]]:
    """Run ``duration_s`` of simulated time; one epoch record per period.

    ``cfg.sim.plant`` chooses the plant; ``gyro``: the controller also gets the plant's yaw-rate
    gyro (in-process: the Outland frame of ``config/protocols/`` has no rate field).
    ``cfg.sim.turn_every_s`` > 0: the setpoint alternates between ``cfg.setpoint_deg`` and
    ``+ turn_deg`` every that many seconds (the first turn at ``turn_every_s``).
    """
    sim_cfg = cfg.sim if seed is None else replace(cfg.sim, seed=seed)
    plant = make_plant(sim_cfg, faults)
    ctl = RovController(cfg, ft=ft)
    dt = cfg.period_s
    n = round(duration_s / dt)
    turn_steps = round(sim_cfg.turn_every_s / dt) if sim_cfg.turn_every_s > 0 else 0
    base = ctl.setpoint_deg
    out: list[dict[str, Any]] = []
    for k in range(n + 1):
        if k:
            c = ctl.command
            plant.advance(c.yaw_pct, dt, 0.5 * (c.port_pct + c.starboard_pct))
        if turn_steps and k and k % turn_steps == 0:
            odd = (k // turn_steps) % 2 == 1
            ctl.setpoint_deg = (base + (sim_cfg.turn_deg if odd else 0.0)) % 360.0
        tel = plant.measure()
        meas = None if tel is None else tel.heading_deg
        rate = plant.gyro_dps() if gyro else None
        cmd, dec = ctl.step(meas, dt, rate)
        out.append(epoch_record(k * dt, plant.heading_true, meas, ctl.setpoint_deg, cmd, dec,
                                ctl.action))
    return out


def summarize(epochs: Sequence[dict[str, Any]], faults: Sequence[FaultSpec] = ()) -> dict[str, Any]:
    """Detection times and heading error statistics (the core of ``summary.json``)."""

    def err(e: dict[str, Any]) -> float:
        return (e["heading_true"] - e["setpoint"] + 180.0) % 360.0 - 180.0

    first_suspect = next((e["t"] for e in epochs if e["event"] == "suspect"), None)
    first_fault = next((e["t"] for e in epochs if e["fault"]), None)
    out: dict[str, Any] = {
        "epochs": len(epochs),
        "faults": [f"{f.kind}:{f.magnitude:g}@{f.start_s:g}" + (f"-{f.end_s:g}" if f.end_s else "")
                   for f in faults],
        "suspects": sum(1 for e in epochs if e["event"] == "suspect"),
        "confirmations": sum(1 for e in epochs if e["event"] in ("confirmed", "stuck")),
        "dismissed": sum(1 for e in epochs if e["event"] == "dismissed"),
        "first_suspect_t": first_suspect,
        "first_fault_t": first_fault,
        "fault_epochs": sum(1 for e in epochs if e["fault"]),
        "dropout_epochs": sum(1 for e in epochs if e["heading_meas"] is None),
        "neutral_epochs": sum(1 for e in epochs if e["action"] == "neutral"),
    }
    if first_fault is not None:
        after = [abs(err(e)) for e in epochs if e["t"] >= first_fault]
        out["max_abs_err_after_fault_deg"] = max(after)
    tail = [err(e) for e in epochs[-len(epochs) // 5 :]]
    out["final_mean_err_deg"] = sum(tail) / len(tail)
    return out
