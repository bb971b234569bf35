"""The ROV experiment step-locked in-process: plant and controller, no I/O, no clock.

The same :class:`~firmware_host.rov.control.RovController` the pty and real-vehicle modes use;
here the plant is advanced one period per step, so a 30-minute run takes about a second.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from firmware_host.devtools.rov_sim import FaultSpec, RovPlant
from firmware_host.rov.config import RovConfig
from firmware_host.rov.control import RovController, epoch_record


def run_experiment(
    cfg: RovConfig,
    faults: Sequence[FaultSpec] = (),
    duration_s: float = 120.0,
    ft: bool = True,
    seed: int | None = None,
) -> list[dict[str, Any]]:
    """Run ``duration_s`` of simulated time; one epoch record per period."""
    sim_cfg = cfg.sim if seed is None else type(cfg.sim)(**{**cfg.sim.__dict__, "seed": seed})
    plant = RovPlant(sim_cfg, faults)
    ctl = RovController(cfg, ft=ft)
    dt = cfg.period_s
    n = round(duration_s / dt)
    out: list[dict[str, Any]] = []
    for k in range(n + 1):
        if k:
            plant.advance(ctl.command.yaw_pct, dt)
        tel = plant.measure()
        meas = None if tel is None else tel.heading_deg
        cmd, dec = ctl.step(meas, dt)
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
