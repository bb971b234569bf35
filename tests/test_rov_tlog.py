"""The ROV detector on a real BlueROV2 dive (ArduSub tlog), replayed offline."""

from __future__ import annotations

import pytest

from firmware_host.rov.config import load_rov_config, project_root

TLOG = project_root().parent / "shared" / "corpus" / "ardusub" / "small.tlog"


@pytest.fixture(scope="module")
def dive():  # type: ignore[no-untyped-def]
    if not TLOG.exists():
        pytest.skip(f"real dive not found at {TLOG} (../shared/corpus relative to the project)")
    from firmware_host.rov.tlog import load_dive

    return load_dive(TLOG)


def test_dive_is_long_and_has_yaw_commands(dive) -> None:  # type: ignore[no-untyped-def]
    assert dive.t_s[-1] > 250.0
    assert min(dive.yaw_pct) < -10.0 and max(dive.yaw_pct) > 10.0


def test_clean_dive_no_confirmed_fault(dive) -> None:  # type: ignore[no-untyped-def]
    from firmware_host.rov.tlog import replay

    cfg, _ = load_rov_config(project_root() / "config" / "rov.toml")
    dec = replay(dive, cfg)
    assert not any(d.fault for d in dec)
    assert max(d.e2 for d in dec) < cfg.detector.theta_deg2


@pytest.mark.parametrize("at_s", [60.0, 150.0, 200.0])
def test_drift_20_confirmed_within_2_s(dive, at_s: float) -> None:  # type: ignore[no-untyped-def]
    from firmware_host.rov.tlog import replay

    cfg, _ = load_rov_config(project_root() / "config" / "rov.toml")
    dec = replay(dive, cfg, drift_deg=20.0, drift_at_s=at_s)
    t_conf = next(t for t, d in zip(dive.t_s, dec, strict=True) if d.event == "confirmed")
    assert at_s <= t_conf <= at_s + 2.0
    assert not any(d.fault for t, d in zip(dive.t_s, dec, strict=True) if t < at_s)
