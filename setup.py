"""An optional compiled build; everything else is in pyproject.toml.

Without ``FDI_BRIDGE_MYPYC=1`` this adds nothing: the wheel is pure Python, as always. With it,
mypyc compiles the modules of the offline replay's hot path (the NMEA codec and epoch assembly,
the rover pipeline and its records, the rover detector) into C extensions beside the Python
sources, which they shadow when imported; the results are the same (``tools/replay_identity.py
--tree``). It needs mypy (with mypyc) and a C compiler in the build environment::

    pip install mypy setuptools wheel
    FDI_BRIDGE_MYPYC=1 pip install --no-build-isolation .
"""

from __future__ import annotations

import os

from setuptools import setup

MYPYC_MODULES = [
    "drivers/gps/nmea.py",
    "drivers/gps/epochs.py",
    "drivers/gps/stream.py",
    "firmware_host/runtime/records.py",
    "firmware_host/rover/pipeline.py",
    "fdi/rover.py",
    "fdi/grey.py",
    "fdi/kalman.py",
    "fdi/drift.py",
    "fdi/level.py",
    "fdi/gate_health.py",
]

ext_modules = []
if os.environ.get("FDI_BRIDGE_MYPYC") == "1":
    from mypyc.build import mypycify

    ext_modules = mypycify(MYPYC_MODULES, opt_level="3")

setup(ext_modules=ext_modules)
