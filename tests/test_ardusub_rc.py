"""RC_CHANNELS_OVERRIDE as the ArduSub ROV's command output (``[rov.ardusub] output``).

Same rules as MANUAL_CONTROL: sent from ``SYSID_MYGCS`` to the vehicle, only armed in a yaw
mode, never against the pilot, not after the pilot has gone silent (ArduSub counts an
override from its GCS as pilot input, ``GCS_MAVLINK_Sub::handle_message``, so sending on would
mask ``FS_PILOT_INPUT``). Channels per ArduSub's default RCMAP (yaw 4, throttle 3, forward 5,
lateral 6), 1100..1900 around 1500; the others UINT16_MAX (1-8, ignored) or 0 (9-18,
ignored); leaving a yaw mode releases the four channels (0). Tests on 127.0.0.1 against the
simulated ArduSub.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import pytest

from firmware_host.rov.ardusub import rc_override_channels
from firmware_host.rov.config import RovConfig, load_rov_config, project_root
from firmware_host.runtime.config_rov import ArduSubConfig
from tests.ardusub_bench import BOUND_DEG, Bench, err


def _cfg(**ardusub: Any) -> RovConfig:
    c, _ = load_rov_config(project_root() / "config" / "rov.toml")
    return replace(c, heading_source="mavlink",
                   ardusub=replace(c.ardusub, output="rc_override", **ardusub))


def test_channel_mapping() -> None:
    a = ArduSubConfig()
    ch = rc_override_channels(a, (1000, -1000, 500, 250))
    assert len(ch) == 18
    assert ch[3] == 1600 and ch[4] == 1900 and ch[5] == 1100 and ch[2] == 1500  # yaw/fwd/lat/thr
    assert ch[0] == ch[1] == ch[6] == ch[7] == 0xFFFF  # pitch, roll, cameras: not touched
    assert set(ch[8:]) == {0}  # 9-18: 0 is "ignore" there
    assert rc_override_channels(a, (0, 0, 1000, 5000))[2:4] == (1900, 1900)  # clamped
    rel = rc_override_channels(a, None)
    assert (rel[2], rel[3], rel[4], rel[5]) == (0, 0, 0, 0) and rel[0] == 0xFFFF
    moved = rc_override_channels(replace(a, rc_yaw_channel=1, rc_throttle_channel=2),
                                 (0, 0, 500, 1000))
    assert moved[0] == 1900 and moved[1] == 1500 and moved[3] == 0xFFFF


def test_the_same_channel_twice_is_refused() -> None:
    with pytest.raises(ValueError, match="must differ"):
        ArduSubConfig(rc_yaw_channel=5)


@pytest.mark.parametrize("seed", [1, 2])
def test_drift_confirmed_and_held_through_rc_override(seed: int) -> None:
    b = Bench(_cfg(), ("drift:30@70",), seed=seed)
    try:
        recs = [b.period() for _ in range(100 * 5)]
    finally:
        summary = b.close()
    c = b.sim.counters
    assert c.accepted == 0 and c.refused == 0  # no MANUAL_CONTROL at all
    assert c.rc_accepted == len(recs) and c.rc_refused == 0 and c.failsafes == 0
    assert summary["rc_override_sent"] == len(recs) and "manual_control_sent" not in summary
    t_conf = next(round((k + 1) * 0.2, 3) for k, r in enumerate(recs)
                  if r["event"] == "confirmed")
    assert 70.0 < t_conf <= 71.0
    after = [abs(err(h)) for k, h in enumerate(b.true) if (k + 1) * 0.2 >= t_conf - 1e-9]
    assert max(after) < BOUND_DEG, max(after)
    assert b.sim.last_rc is not None and b.sim.last_rc[0] == 0xFFFF


def test_auto_releases_the_channels_and_a_foreign_id_is_refused() -> None:
    b = Bench(_cfg())
    try:
        for _ in range(5 * 5):
            b.period()
        b.sim.set_mode("AUTO")
        auto = [b.period() for _ in range(3 * 5)]
        b.sim.pump()
    finally:
        summary = b.close()
    assert all(r["r_sent"] is None for r in auto[5:])  # HEARTBEAT at 1 Hz
    assert b.sim.counters.rc_releases == 1 and summary["rc_releases"] == 1
    assert b.sim.last_rc is not None and b.sim.last_rc[3] == 0  # yaw back to the RC radio
    b2 = Bench(_cfg(send_without_pilot=True), pilot_system_id=42)  # no GCS 42 here
    try:
        for _ in range(3 * 5):
            b2.period()
    finally:
        b2.close()
    assert b2.sim.counters.rc_accepted == 0 and b2.sim.counters.rc_refused >= 10


def test_pilot_takeover_and_pilot_silence_let_the_failsafe_fire() -> None:
    b = Bench(_cfg())
    try:
        for _ in range(10 * 5):
            b.period((200, 0, 500, 0))
        rc_before = b.sim.counters.rc_accepted
        turn = [b.period((200, 0, 500, 700)) for _ in range(2 * 5)]
        rc_during = b.sim.counters.rc_accepted - rc_before
        back = [b.period((200, 0, 500, 0)) for _ in range(4 * 5)]
        fwd = b.sim.last_rc
        silent = [b.period() for _ in range(6 * 5)]  # the pilot stops sending
    finally:
        b.close()
    assert all(r["ardusub"] == "pilot" for r in turn) and rc_during <= 1
    assert any(r == 700 for _, r in b.sim.counters.r_log)  # the pilot's yaw reached ArduSub
    assert back[-1]["ardusub"] == "steer"
    assert fwd is not None and fwd[4] == 1580  # the pilot's x = 200 on the forward channel
    n_sent = sum(r["r_sent"] is not None for r in silent)
    assert 4 <= n_sent <= 6  # pilot_timeout_s = 1 s, then nothing
    assert silent[-1]["ardusub"] == "pilot_silent"
    assert b.sim.counters.failsafes == 1  # ArduSub's FS_PILOT_INPUT, 3 s after the last frame
    assert b.sim.counters.rc_releases == 0  # no release frame that would delay it
