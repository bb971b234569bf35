"""The rover's detector parameters as MAVLink parameters: every numeric key gets its own name.

Names are ``FDI_`` + the key, cut to 16 characters (firmware_host/mavlink/params.py); two keys
that share their first 12 characters would collide, and the router would refuse to start
(``drift_watch_s`` and ``drift_watch_sigmas`` did, as FDI_DRIFT_WATCH)."""

from __future__ import annotations

import dataclasses

from fdi.rover import RoverDetectorParams
from firmware_host.mavlink.params import ParamStore


def test_every_numeric_rover_key_has_its_own_parameter() -> None:
    params = RoverDetectorParams()
    names = ParamStore().register_dataclass("FDI", params)
    numeric = [f.name for f in dataclasses.fields(params)
               if isinstance(getattr(params, f.name), int | float)
               and not isinstance(getattr(params, f.name), bool)]
    assert sorted(names) == sorted(numeric)
    assert len(set(names.values())) == len(numeric)
    assert names["ramp_window_s"] == "FDI_RAMP_WINDOW" and names["stale_p"] == "FDI_STALE_P"
