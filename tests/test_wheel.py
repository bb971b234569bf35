"""The wheel a user installs: built from this tree, installed into a fresh venv outside it, run
from another directory with nothing of the repository on the path.

The venv is made with ``--without-pip`` and given the test interpreter's copies of the core
dependencies (numpy, pyserial, pynmea2, pymavlink and what they require, found from their
metadata) as symbolic links in a directory of their own named by a ``.pth`` file, so no download
is needed and nothing of the ``dev`` extra (tqdm, matplotlib, dask) is there: the product
without its developer tools. The wheel itself goes in with ``pip --python VENV install
--no-deps``.
The wheel is built from a copy of the sources (a build writes ``build/`` and ``*.egg-info``
beside them). ``run --config rov`` gets the ROV simulator's pty through a config file beside the
run that sets only ``[rov.link.port] url``: its protocol (``protocols/outland1000.toml``, not
beside that file) must come from the wheel's packaged protocols.

Also here: the list of packages in ``pyproject.toml`` is the tree's (it is written out because
the presets are a mapped package).
"""

from __future__ import annotations

import importlib.metadata
import json
import os
import re
import shutil
import subprocess
import sys
import threading
import time
import tomllib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from packaging.requirements import Requirement

from drivers.outland.framecodec import load_protocol
from drivers.ptypair import PtyPair
from firmware_host.devtools.rov_sim import RovPlant, RovSimServer, serve_pty
from firmware_host.rov.config import SimConfig

ROOT = Path(__file__).resolve().parents[1]
SOURCES = ("drivers", "fdi", "firmware_host", "config", "pyproject.toml", "README.md")
DEV_HINT = "is a developer tool: pip install 'fdi-bridge[dev]'"


def _core_distributions() -> set[str]:
    """pyproject's dependencies and what they require (no extras), as installed here."""
    todo = [Requirement(r).name for r in
            tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]]
    seen: set[str] = set()
    while todo:
        name = re.sub(r"[-_.]+", "-", todo.pop()).lower()
        if name in seen:
            continue
        seen.add(name)
        for r in importlib.metadata.distribution(name).requires or []:
            req = Requirement(r)
            if req.marker is None or req.marker.evaluate({"extra": ""}):
                todo.append(req.name)
    return seen


def _link_core_dependencies(target: Path) -> None:
    """Symbolic links in ``target`` to the installed files of the core distributions only."""
    target.mkdir()
    for name in sorted(_core_distributions()):
        dist = importlib.metadata.distribution(name)
        for top in sorted({f.parts[0] for f in dist.files or ()} - {"..", "__pycache__"}):
            src = Path(str(dist.locate_file(top)))
            if src.exists() and not (target / top).exists():
                (target / top).symlink_to(src)


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
    # The core dependencies, after the install (pip would take the dev tree's editable
    # fdi-bridge, visible in the test interpreter's site-packages, for this one).
    site = next((venv / "lib").glob("python3*/site-packages"))
    deps = base / "core-deps"
    _link_core_dependencies(deps)
    (site / "fdi_bridge_test_deps.pth").write_text(f"{deps}\n")
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


def test_the_dev_extra_is_not_installed(installed: Installed) -> None:
    probe = subprocess.run([str(installed.venv / "bin" / "python"), "-c",
                            "import importlib.util as u; print([m for m in ('tqdm', "
                            "'matplotlib', 'dask', 'numpy', 'serial', 'pymavlink') "
                            "if u.find_spec(m)])"],
                           cwd=installed.work, env=_clean_env(), capture_output=True, text=True,
                           check=True)
    assert probe.stdout.strip() == "['numpy', 'serial', 'pymavlink']"


@pytest.mark.parametrize(("argv", "name"), [
    (("demo",), "demo"), (("demo", "rov"), "demo rov"), (("sim", "rover", "--out", "x"),
                                                          "sim rover"),
    (("eval", "--help"), "eval"), (("mavlink", "--bench"), "mavlink --bench"),
    (("fleet", "logs"), "fleet"),
])
def test_a_dev_tool_says_how_to_get_the_extra(installed: Installed, argv: tuple[str, ...],
                                              name: str) -> None:
    out = installed.run(*argv)
    assert out.returncode == 2, out.stdout + out.stderr
    assert out.stderr.splitlines() == [f"fdi-bridge {name} {DEV_HINT}"]
    assert not (installed.work / "x").exists()


def test_the_documents_cover_the_product_without_the_extra(installed: Installed) -> None:
    page = installed.run("man")
    assert page.returncode == 0, page.stderr
    assert "fdi\\-bridge calibrate" in page.stdout and "\\-\\-bench" in page.stdout
    script = installed.run("completion", "bash")
    assert script.returncode == 0 and "replay" in script.stdout


@pytest.fixture(scope="module")
def nmea_log(installed: Installed) -> Path:
    """A clean 240 s drive of the rover simulator's NMEA (calibrate wants 200 s of an unbroken
    Doppler chain), written by the source tree: the dev tools are there."""
    gen = subprocess.run([sys.executable, "-m", "firmware_host.cli", "sim", "rover",
                          "--duration", "240", "--seed", "3", "--kinds=", "--out",
                          str(installed.work / "gen")],
                         cwd=ROOT, capture_output=True, text=True, timeout=120,
                         env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert gen.returncode == 0, gen.stderr
    return installed.work / "gen" / "rover.nmea"


def test_replay_and_calibrate_from_another_directory(installed: Installed,
                                                      nmea_log: Path) -> None:
    rep = installed.run("replay", "--config", "rover", str(nmea_log), "--out", "replayed")
    assert rep.returncode == 0, rep.stderr
    epochs = (installed.work / "replayed" / "epochs.jsonl").read_bytes()
    assert len(epochs.splitlines()) >= 2000  # 240 s at 10 Hz
    # The same replay from the source tree gives the same bytes (the contract).
    here = subprocess.run([sys.executable, "-m", "firmware_host.cli", "replay", "--config",
                           "rover", str(nmea_log), "--out", str(installed.work / "replayed-src")],
                          cwd=ROOT, capture_output=True, text=True, timeout=60,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert here.returncode == 0, here.stderr
    assert (installed.work / "replayed-src" / "epochs.jsonl").read_bytes() == epochs

    cal = installed.run("calibrate", str(nmea_log), "--config", "rover", "--out", "mine.toml")
    assert cal.returncode == 0, cal.stderr
    check = installed.run("config", "check", "mine.toml")
    assert check.returncode == 0, check.stdout + check.stderr


def test_record_and_doctor_on_a_pty(installed: Installed, nmea_log: Path) -> None:
    lines = nmea_log.read_bytes().splitlines(keepends=True)[:400]
    with PtyPair(link=installed.work / "gps") as pty:
        (installed.work / "gps.toml").write_text(f'[rover.port]\nurl = "{pty.url}"\n'
                                                 "baudrate = 38400\n")
        doctor = installed.run("doctor", "--config", "gps.toml")
        assert doctor.returncode == 0, doctor.stdout + doctor.stderr
        assert "no problems found" in doctor.stdout
        stop = threading.Event()

        def feed() -> None:  # the receiver: a line every 5 ms until the recording is done
            for line in lines:
                if stop.wait(0.005):
                    return
                pty.write(line)

        th = threading.Thread(target=feed, daemon=True)
        th.start()
        try:
            rec = installed.run("record", pty.url, "--baud", "38400", "--max-bytes", "2000",
                                "--duration", "20", "--out", "gps.cap")
        finally:
            stop.set()
            th.join(2.0)
    assert rec.returncode == 0, rec.stderr
    assert (installed.work / "gps.cap").stat().st_size >= 2000


def test_mavlink_and_config_from_another_directory(installed: Installed) -> None:
    t0 = time.monotonic()
    mav = installed.run("mavlink", "--autopilot", "udpin:127.0.0.1:0", "--gcs",
                        "udpout:127.0.0.1:9", "--seconds", "1", "--json")
    assert mav.returncode == 0, mav.stderr
    summary = json.loads(mav.stdout.splitlines()[-1])
    assert summary["runtime"]["stopped_by"] == "duration" and "router" in summary
    assert time.monotonic() - t0 < 30
    show = installed.run("config", "show", "rover")
    assert show.returncode == 0 and "[rover" in show.stdout, show.stderr


def test_run_from_another_directory(installed: Installed) -> None:
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
