"""Shared fixtures: the project root and the shared corpus (read in place, never copied); the
test tiers.

Tiers (markers registered in pyproject.toml; the default command runs them all, as CI does):

* ``integration``: real ptys, sockets on 127.0.0.1, subprocesses of the CLI: every test in
  ``hil_tests/`` and in the ``tests/`` files named in :data:`INTEGRATION_FILES` (a file is
  named when most of its tests do such I/O); marked here, by file, in one place;
* ``slow``: the long seed harnesses and the other heavy tests, marked where they are defined;
* everything else: unit tests, in-process and fast.

``pytest -m "not slow"`` runs the fast tiers; ``pytest -m "not slow and not integration"`` the
unit tests alone.
"""

from __future__ import annotations

import logging
import shutil
import signal
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent
CORPUS = ROOT.parent / "shared" / "corpus"


@pytest.fixture
def corpus() -> Path:
    if not CORPUS.is_dir():
        pytest.skip(f"shared corpus not found at {CORPUS} (a fresh clone without shared/)")
    return CORPUS


_OUR_LOGGERS = ("fdi_bridge", "firmware_host", "drivers", "fdi")


@pytest.fixture(autouse=True)
def _logger_levels() -> Iterator[None]:
    """Every test starts with the project's logger levels as the last test found them, and
    leaves them so: commands run in-process (bench, eval, fleet, the harnesses, demo insgnss)
    set ``fdi_bridge.rover`` to ERROR for their run, and a later test in the same worker that
    expects a warning then saw none (4 failures with a CPU hog beside the suite, where xdist
    gave the files to the workers in another order)."""
    manager = logging.Logger.manager
    saved = {name: lg.level for name, lg in manager.loggerDict.items()
             if isinstance(lg, logging.Logger) and name.startswith(_OUR_LOGGERS)}
    yield
    for name, lg in list(manager.loggerDict.items()):
        if isinstance(lg, logging.Logger) and name.startswith(_OUR_LOGGERS):
            lg.setLevel(saved.get(name, logging.NOTSET))


@pytest.fixture
def key_dir() -> Iterator[Path]:
    """A private directory for a signing key, outside any git working tree (the router refuses
    a key inside one, and pytest's own tmp_path follows TMPDIR, which may be in a checkout):
    under /tmp, and removed after the test, so no key is left behind."""
    d = Path(tempfile.mkdtemp(prefix="fdi-key-", dir="/tmp"))
    try:
        yield d
    finally:
        shutil.rmtree(d, ignore_errors=True)


def pytest_configure(config: pytest.Config) -> None:
    """A shell without job control starts a background command with SIGINT ignored, and every
    process it starts inherits that: the tests that send a command ^C (SIGINT) then saw it
    ignored (``(pytest ... &)`` in a script: 2 failures). The default is put back, so the
    commands under test get Python's KeyboardInterrupt as a user's terminal gives it."""
    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


INTEGRATION_FILES = frozenset({
    "test_ardusub_pilot_rules.py", "test_ardusub_replay.py", "test_ardusub_tlog.py",
    "test_cli_errors.py", "test_cli_permission.py", "test_config_bounds.py", "test_doctor.py",
    "test_epochs_kill.py", "test_insgnss_align.py", "test_insgnss_coast.py",
    "test_insgnss_live.py", "test_mavlink_config.py", "test_mavlink_doctor.py",
    "test_out_diskfull.py", "test_param_bounds.py", "test_port_exclusive.py",
    "test_reconnect.py", "test_recorder_diskfull.py", "test_replay_signals.py",
    "test_rov_replay.py", "test_run_dispatch.py", "test_runner.py", "test_transport_read.py",
    "test_wheel.py",
})


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The ``integration`` tier: ``hil_tests/`` and :data:`INTEGRATION_FILES`."""
    hil = ROOT / "hil_tests"
    for item in items:
        path = item.path
        if path.is_relative_to(hil) or (path.parent == ROOT / "tests"
                                        and path.name in INTEGRATION_FILES):
            item.add_marker(pytest.mark.integration)
