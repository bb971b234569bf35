"""Typed configuration of the ROV heading hold: the ``[rov]`` table of ``config/rov.toml``.

The schema is :mod:`firmware_host.runtime.config_rov` (re-exported here) and the one loader
:func:`firmware_host.runtime.config.load_bridge_file`; :func:`load_rov_config` is the ROV's view
of a file.
"""

from __future__ import annotations

from pathlib import Path

from firmware_host.runtime.config import load_bridge_file, resolve_protocol, rov_config
from firmware_host.runtime.config_rov import LinkConfig as LinkConfig
from firmware_host.runtime.config_rov import Plant as Plant
from firmware_host.runtime.config_rov import RovConfig as RovConfig
from firmware_host.runtime.config_rov import SimConfig as SimConfig
from firmware_host.runtime.config_rov import Wiring as Wiring


def project_root() -> Path:
    return Path(__file__).resolve().parents[2]


def load_rov_config(path: str | Path | None) -> tuple[RovConfig, Path]:
    """Load a file or preset (``None``: the built-in defaults); returns the ROV's config and the
    directory protocol paths are relative to (the loader has already made ``link.protocol``
    absolute: beside the file, else the packaged one)."""
    return rov_config(load_bridge_file(path))


def protocol_path(cfg: RovConfig, base: Path) -> Path:
    """The protocol file of ``cfg``: beside ``base``, else among the packaged ones."""
    return resolve_protocol(cfg.link.protocol, base)
