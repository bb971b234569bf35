"""fdi: the estimators and fault detectors of fdi-bridge, pure algorithms (no I/O, no clock).

The three methods, each after its paper (equation numbers in the modules):

* GPS rover (Zhou & Zhang 2010): :class:`RoverIsolator` with :class:`RoverDetectorParams` --
  feed :class:`FixInput` epochs (local metres), get a :class:`Decision` each (Kalman residual
  χ² test, GM(1,1) grey prediction, replacement, alarm); its parts :class:`GpsKalman`,
  :func:`gm11_predict` and the χ² gate :func:`chi2_threshold`;
* ROV compass (Zhu, Chen & Liu 2009): :class:`FaultTolerantHeading` (LMS adaptive FIR,
  :class:`DualCriterionDetector` on e² and the weight-drift SNR, the FIR output replacing the
  compass) and the :class:`HeadingPid` it steers with;
* INS/GNSS (Cai & Shao): :class:`InsGnssFilter` with :class:`InsGnssParams` and the three-zone
  χ² gate :class:`ThreeZoneGate` / :class:`ThreeZoneParams`, the persistent GNSS fault
  :class:`GnssFaultMonitor`;

and the one error tree of the project (:class:`FdiBridgeError` and its subclasses, in
:mod:`fdi.errors`, the only module of ``fdi`` the drivers import). The names are imported on
first use, so ``import fdi.errors`` stays light (no numpy).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from fdi.chi2 import threshold as chi2_threshold
    from fdi.errors import (
        CaptureFormatError,
        ConfigError,
        ConfigErrors,
        DecodeError,
        EndpointError,
        EstimatorError,
        FdiBridgeError,
        PortClosedError,
        PortError,
        UsageError,
    )
    from fdi.geodesy import LocalFrame
    from fdi.gnss_fault import GnssFaultMonitor
    from fdi.grey import gm11_predict
    from fdi.heading_ft import FaultTolerantHeading, FtConfig, HeadingDecision
    from fdi.insgnss import InsGnssFilter
    from fdi.insgnss_params import InsGnssParams
    from fdi.kalman import GpsKalman
    from fdi.lms_fir import AdaptiveFir, DetectorConfig, DualCriterionDetector
    from fdi.pid import HeadingPid, PidConfig
    from fdi.rover import Decision, FixInput, RoverDetectorParams, RoverIsolator
    from fdi.three_zone import ThreeZoneGate, ThreeZoneParams

# public name -> (module, name in it)
_EXPORTS: dict[str, tuple[str, str]] = {
    # GPS rover
    "RoverIsolator": ("fdi.rover", "RoverIsolator"),
    "RoverDetectorParams": ("fdi.rover", "RoverDetectorParams"),
    "FixInput": ("fdi.rover", "FixInput"),
    "Decision": ("fdi.rover", "Decision"),
    "GpsKalman": ("fdi.kalman", "GpsKalman"),
    "gm11_predict": ("fdi.grey", "gm11_predict"),
    "chi2_threshold": ("fdi.chi2", "threshold"),
    "LocalFrame": ("fdi.geodesy", "LocalFrame"),
    # ROV compass
    "FaultTolerantHeading": ("fdi.heading_ft", "FaultTolerantHeading"),
    "FtConfig": ("fdi.heading_ft", "FtConfig"),
    "HeadingDecision": ("fdi.heading_ft", "HeadingDecision"),
    "AdaptiveFir": ("fdi.lms_fir", "AdaptiveFir"),
    "DetectorConfig": ("fdi.lms_fir", "DetectorConfig"),
    "DualCriterionDetector": ("fdi.lms_fir", "DualCriterionDetector"),
    "HeadingPid": ("fdi.pid", "HeadingPid"),
    "PidConfig": ("fdi.pid", "PidConfig"),
    # INS/GNSS
    "InsGnssFilter": ("fdi.insgnss", "InsGnssFilter"),
    "InsGnssParams": ("fdi.insgnss_params", "InsGnssParams"),
    "ThreeZoneGate": ("fdi.three_zone", "ThreeZoneGate"),
    "ThreeZoneParams": ("fdi.three_zone", "ThreeZoneParams"),
    "GnssFaultMonitor": ("fdi.gnss_fault", "GnssFaultMonitor"),
    # the error tree
    **{name: ("fdi.errors", name) for name in (
        "FdiBridgeError", "ConfigError", "ConfigErrors", "PortError", "PortClosedError",
        "DecodeError", "CaptureFormatError", "EstimatorError", "UsageError", "EndpointError")},
}

__all__ = [
    "AdaptiveFir",
    "CaptureFormatError",
    "ConfigError",
    "ConfigErrors",
    "Decision",
    "DecodeError",
    "DetectorConfig",
    "DualCriterionDetector",
    "EndpointError",
    "EstimatorError",
    "FaultTolerantHeading",
    "FdiBridgeError",
    "FixInput",
    "FtConfig",
    "GnssFaultMonitor",
    "GpsKalman",
    "HeadingDecision",
    "HeadingPid",
    "InsGnssFilter",
    "InsGnssParams",
    "LocalFrame",
    "PidConfig",
    "PortClosedError",
    "PortError",
    "RoverDetectorParams",
    "RoverIsolator",
    "ThreeZoneGate",
    "ThreeZoneParams",
    "UsageError",
    "chi2_threshold",
    "gm11_predict",
]


def __getattr__(name: str) -> Any:
    """Import a public name's module on first use (PEP 562)."""
    try:
        module, attr = _EXPORTS[name]
    except KeyError:
        raise AttributeError(f"module 'fdi' has no attribute {name!r}") from None
    value = getattr(importlib.import_module(module), attr)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *__all__])
