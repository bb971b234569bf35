"""The ROV's real-vehicle loop: :func:`run_rov` runs the heading controller on the configured
Outland link (the same controller as ``fdi-bridge run --config rov``) on the one runtime.

The simulated experiment (``fdi-bridge sim rov``) and the step benchmark are developer tools:
:mod:`firmware_host.devtools.sim_rov`.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from drivers.resilient import Opener
from firmware_host.rov.config import RovConfig, load_rov_config
from firmware_host.rov.vehicle import OutlandRovVehicle
from firmware_host.runtime.runner import Runner

EpochSink = Callable[[dict[str, Any]], None]


def run_rov(
    config: RovConfig,
    clock: Callable[[], float] = time.monotonic,
    sleep: Callable[[float], None] = time.sleep,
    stop_event: threading.Event | None = None,
    *,
    base_dir: str | Path | None = None,
    ft: bool = True,
    max_steps: int | None = None,
    on_epoch: EpochSink | None = None,
    opener: Opener | None = None,
) -> dict[str, Any]:
    """Drive a real vehicle (or a pty) on ``config.link`` until ``stop_event`` is set.

    The vehicle is :class:`~firmware_host.rov.vehicle.OutlandRovVehicle` on the runtime's
    :class:`~firmware_host.runtime.runner.Runner` (the link a resilient port, reopened when
    lost). Returns the summary: the loop's timing, the link's counters, the failsafe episodes.
    ``base_dir`` resolves a relative protocol path (default: the project's ``config/``).
    """
    base = Path(base_dir) if base_dir is not None else load_rov_config(None)[1]
    vehicle = OutlandRovVehicle(config, base, ft=ft, on_epoch=on_epoch)
    runner = Runner(vehicle, clock=clock, sleep=sleep, opener=opener, handle_signals=False)
    return runner.run(max_steps=max_steps,
                      until=stop_event.is_set if stop_event is not None else None)
