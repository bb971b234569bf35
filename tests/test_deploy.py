"""The systemd unit in deploy/: starts on boot, restarts on failure, logs to the journal,
runs `fdi-bridge run` and stops it with SIGTERM (which the run loop handles cleanly)."""

from __future__ import annotations

import configparser
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_unit_file() -> None:
    unit = configparser.ConfigParser(strict=False, interpolation=None)
    unit.optionxform = str  # type: ignore[assignment,method-assign]
    unit.read(ROOT / "deploy" / "fdi-bridge.service")
    svc = unit["Service"]
    assert unit["Install"]["WantedBy"] == "multi-user.target"
    assert svc["Restart"] == "on-failure"
    assert svc["StandardOutput"] == svc["StandardError"] == "journal"
    assert " run --config " in svc["ExecStart"]
    assert svc["KillSignal"] == "SIGTERM"
    assert unit["Unit"]["StartLimitIntervalSec"] == "0"
    assert (ROOT / "docs" / "deployment.md").read_text().count("fdi-bridge.service") >= 1
