"""The wheel a user installs: built from this tree, installed into a fresh venv outside it, run
from another directory with nothing of the repository on the path.

The venv is made with ``--without-pip`` and given the test interpreter's dependencies
(numpy, pyserial, pynmea2, pymavlink: already installed) through a ``.pth`` file, so no
download is needed; the wheel itself goes in with ``pip --python VENV install --no-deps``.
The wheel is built from a copy of the sources (a build writes ``build/`` and ``*.egg-info``
beside them). ``run --config rov`` gets the ROV simulator's pty through a config file beside the
run that sets only ``[rov.link.port] url``: its protocol (``protocols/outland1000.toml``, not
beside that file) must come from the wheel's packaged protocols.

Also here: the list of packages in ``pyproject.toml`` is the tree's (it is written out because
the presets are a mapped package).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import threading
import tomllib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy
import pymavlink
import pynmea2
import pytest
import serial

from drivers.outland.framecodec import load_protocol
from drivers.ptypair import PtyPair
from firmware_host.devtools.rov_sim import RovPlant, RovSimServer, serve_pty
from firmware_host.rov.config import SimConfig

ROOT = Path(__file__).resolve().parents[1]
SOURCES = ("drivers", "fdi", "firmware_host", "config", "pyproject.toml", "README.md")


def test_pyproject_lists_every_package() -> None:
    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
                 ["packages"])
    tree = {".".join(p.parent.relative_to(ROOT).parts)
            for top in ("drivers", "fdi", "firmware_host")
            for p in (ROOT / top).rglob("__init__.py")}
    assert tree <= listed, f"add to [tool.setuptools] packages: {sorted(tree - listed)}"
    assert listed - tree == {"firmware_host.presets", "firmware_host.presets.protocols"}


def _clean_env() -> dict[str, str]:
    """The environment without the repository on the path (pip would see the dev tree)."""
    return {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}


@dataclass
class Installed:
    venv: Path
    work: Path  # a directory outside the repository, the commands' cwd

    def run(self, *args: str, timeout: float = 60.0) -> subprocess.CompletedProcess[str]:
        return subprocess.run([str(self.venv / "bin" / "fdi-bridge"), *args], cwd=self.work,
                              env=_clean_env(), capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Installed]:
    base = tmp_path_factory.mktemp("wheel")
    assert ROOT not in base.parents
    src = base / "src"
    src.mkdir()
    for name in SOURCES:
        s = ROOT / name
        if s.is_dir():
            shutil.copytree(s, src / name, ignore=shutil.ignore_patterns("__pycache__"))
        else:
            shutil.copy2(s, src / name)
    dist = base / "dist"
    build = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q",
                            "--disable-pip-version-check", "-w", str(dist), str(src)],
                           capture_output=True, text=True, timeout=120, env=_clean_env(),
                           cwd=base)
    if build.returncode != 0 and "satisfies the requirement setuptools" in build.stderr:
        pytest.skip("pip cannot get the build backend (setuptools) here: no index reachable")
    assert build.returncode == 0, build.stdout + build.stderr
    wheels = list(dist.glob("fdi_bridge-*.whl"))
    assert len(wheels) == 1
    venv = base / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True,
                   timeout=60, env=_clean_env())
    inst = subprocess.run([sys.executable, "-m", "pip", "--python", str(venv / "bin" / "python"),
                           "install", "--no-deps", "--no-index", "-q",
                           "--disable-pip-version-check", str(wheels[0])],
                          capture_output=True, text=True, timeout=120, env=_clean_env(),
                          cwd=base)
    assert inst.returncode == 0, inst.stdout + inst.stderr
    # The dependencies, after the install (pip would take the dev tree's editable
    # fdi-bridge, visible there, for this one).
    site = next((venv / "lib").glob("python3*/site-packages"))
    deps = sorted({str(Path(m.__file__ or "").resolve().parents[1])
                   for m in (numpy, serial, pynmea2, pymavlink)})
    (site / "fdi_bridge_test_deps.pth").write_text("\n".join(deps) + "\n")
    work = base / "elsewhere"
    work.mkdir()
    yield Installed(venv, work)


def test_the_wheel_is_what_runs(installed: Installed) -> None:
    where = subprocess.run([str(installed.venv / "bin" / "python"), "-c",
                            "import firmware_host.runtime.config as c, firmware_host as f; "
                            "print(f.__file__); print(c.presets_dir())"],
                           cwd=installed.work, env=_clean_env(), capture_output=True, text=True,
                           check=True)
    module, presets = where.stdout.split()
    assert Path(module).is_relative_to(installed.venv)
    assert Path(presets).is_relative_to(installed.venv) and presets.endswith("presets")
    out = installed.run("--version")
    assert out.returncode == 0 and out.stdout.startswith("fdi-bridge ")
    listing = installed.run("presets", "--json")
    assert listing.returncode == 0, listing.stderr
    names = {json.loads(line)["name"] for line in listing.stdout.splitlines()}
    expected = {p.stem for p in (ROOT / "config").glob("*.toml")}
    assert names == expected
    assert "does not load" not in listing.stdout


def test_demo_replay_and_run_from_another_directory(installed: Installed) -> None:
    demo = installed.run("demo", "--out", "demo")
    assert demo.returncode == 0, demo.stderr
    assert "Traceback" not in demo.stderr
    assert re.search(r"^rover +\d+/\d+ ", demo.stdout, re.M)  # the aligned table (issue 17)
    assert (installed.work / "demo" / "rover").is_dir()

    sim = installed.run("sim", "rover", "--duration", "60", "--seed", "3", "--out", "gen")
    assert sim.returncode == 0, sim.stderr
    log = installed.work / "gen" / "rover.nmea"
    rep = installed.run("replay", "--config", "rover", str(log), "--out", "replayed")
    assert rep.returncode == 0, rep.stderr
    epochs = (installed.work / "replayed" / "epochs.jsonl").read_bytes()
    assert len(epochs.splitlines()) >= 500  # 60 s at 10 Hz
    # The same replay from the source tree gives the same bytes (the contract).
    here = subprocess.run([sys.executable, "-m", "firmware_host.cli", "replay", "--config",
                           "rover", str(log), "--out", str(installed.work / "replayed-src")],
                          cwd=ROOT, capture_output=True, text=True, timeout=60,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert here.returncode == 0, here.stderr
    assert (installed.work / "replayed-src" / "epochs.jsonl").read_bytes() == epochs

    # The preset as it ships: its port (/dev/ttyUSB0) is absent here; the bridge waits for it,
    # stops after --duration, exit 0 with a summary.
    bare = installed.run("run", "--config", "rov", "--duration", "2", "--out", "rov-bare")
    assert bare.returncode == 0, bare.stderr
    assert json.loads((installed.work / "rov-bare" / "summary.json").read_text())[
        "vehicle"] == "rov"

    # With the ROV simulator on a pty: real telemetry through the packaged protocol.
    proto = load_protocol(ROOT / "config" / "protocols" / "outland1000.toml")
    with PtyPair(link=installed.work / "rovlink") as pty:
        stop = threading.Event()
        srv = RovSimServer(RovPlant(SimConfig()), proto, "rs232", node=1, period_s=0.2)
        th = threading.Thread(target=serve_pty, args=(pty, srv, stop), daemon=True)
        th.start()
        (installed.work / "rov-here.toml").write_text(
            f'[rov.link.port]\nurl = "{pty.url}"\nbaudrate = 115200\n')
        try:
            live = installed.run("run", "--config", "rov-here.toml", "--duration", "2",
                                 "--out", "rov-live")
        finally:
            stop.set()
            th.join(2.0)
    assert live.returncode == 0, live.stderr
    summary = json.loads((installed.work / "rov-live" / "summary.json").read_text())
    assert summary["vehicle"] == "rov"
    assert summary["counts"]["telemetry"] >= 5  # 2 s at 5 Hz, after the port opens
