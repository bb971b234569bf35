"""Is ``epochs.jsonl`` byte-identical to a reference commit's? (issue 19: speed without change)

    python tools/replay_identity.py [--ref REV] [--tree DIR] [--corpus DIR] [--keep DIR]

Exports ``REV`` (default ``HEAD``) with ``git archive`` into a temporary directory (the
repository's branches and worktrees are not touched), generates rover runs with the
reference's simulator (several seeds, error models, rates, GST/ZDA on and off), then replays
every generated run (plain NMEA and capture) and every NMEA log of the corpus with the
reference tree and with this working tree, through a real pty as ``fdi-bridge replay`` does,
under the default configuration and the paper presets, and compares the two ``epochs.jsonl``
byte for byte. Exits 1 and names the first differing line of each differing file.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
# (seed, error model, rate Hz, duration s, extra sim flags)
RUNS = [
    (1, "gm", 10.0, 120.0, []),
    (2, "dgps", 10.0, 120.0, ["--gst"]),
    (3, "multipath", 5.0, 120.0, ["--zda", "--kinds", "jump,burst,ramp,frozen,outage,multipath"]),
    (4, "coarse", 1.0, 300.0, ["--gst", "--zda"]),
    (5, "gm", 10.0, 120.0, ["--kinds", "ramp,frozen,outage"]),
    (6, "dgps", 1.0, 300.0, ["--kinds", "multipath,jump"]),
]
CONFIGS = [None, "rover-paper", "rover-three-zone-paper", "rover-combined-paper"]


def _cli(tree: Path, *args: str) -> subprocess.CompletedProcess[bytes]:
    # Run in the tree: ``python -m`` puts the working directory first on sys.path, before
    # PYTHONPATH, so run from another checkout both "trees" imported that checkout's code.
    env = dict(os.environ, PYTHONPATH=str(tree))
    return subprocess.run([sys.executable, "-m", "firmware_host.cli", *args], env=env,
                          cwd=tree, capture_output=True, check=False)


def _first_diff(a: bytes, b: bytes) -> str:
    la, lb = a.splitlines(), b.splitlines()
    for i, (x, y) in enumerate(zip(la, lb, strict=False)):
        if x != y:
            return f"line {i + 1}:\n  ref: {x[:300]!r}\n  new: {y[:300]!r}"
    return f"lengths differ: {len(la)} against {len(lb)} lines"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ref", default="HEAD", help="reference revision (default: HEAD)")
    ap.add_argument("--corpus", type=Path, default=ROOT.parent / "shared" / "corpus")
    ap.add_argument("--keep", type=Path, default=None, help="keep the outputs here")
    ap.add_argument("--tree", type=Path, default=ROOT,
                    help="the tree to check (default: this one)")
    args = ap.parse_args(argv)
    work = (args.keep or Path(tempfile.mkdtemp(prefix="replay-identity-"))).resolve()
    args.tree, args.corpus = args.tree.resolve(), args.corpus.resolve()
    ref = work / "ref-tree"
    ref.mkdir(parents=True, exist_ok=True)
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", args.ref], check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(ref)], input=archive, check=True)
    inputs: list[Path] = []
    for seed, model, rate, dur, extra in RUNS:
        d = work / "runs" / f"s{seed}-{model}-{rate:g}hz"
        if not (d / "rover.nmea").exists():
            p = _cli(ref, "sim", "rover", "--seed", str(seed), "--error-model", model,
                     "--rate", str(rate), "--duration", str(dur), *extra, "--out", str(d))
            if p.returncode != 0:
                print(p.stderr.decode(errors="replace"), file=sys.stderr)
                return 2
        inputs += [d / "rover.nmea", d / "rover.cap"]
    corpus = sorted((args.corpus / "gpsd").glob("*.log")) + sorted(
        (args.corpus / "ardusub").glob("nmea*"))
    if not corpus:
        print(f"replay_identity: no corpus logs under {args.corpus}", file=sys.stderr)
    inputs += corpus
    bad = 0
    n = 0
    for inp in inputs:
        for cfg in CONFIGS:
            if cfg is not None and inp.suffix == ".cap":
                continue  # the presets on the plain logs are enough
            tag = f"{inp.parent.name}-{inp.name}-{cfg or 'default'}"
            outs = {}
            for name, tree in (("ref", ref), ("new", args.tree)):
                out = work / name / tag
                cmd = ["replay", str(inp), "--out", str(out)]
                if cfg is not None:
                    cmd += ["--config", cfg]
                p = _cli(tree, *cmd)
                if p.returncode not in (0, 1):
                    print(f"{tag}: {name} replay exited {p.returncode}: "
                          f"{p.stderr.decode(errors='replace')[-400:]}", file=sys.stderr)
                outs[name] = (out / "epochs.jsonl").read_bytes() if (
                    out / "epochs.jsonl").exists() else b""
            n += 1
            if outs["ref"] != outs["new"]:
                bad += 1
                print(f"DIFFERENT {tag}: {_first_diff(outs['ref'], outs['new'])}")
    print(f"{n - bad} of {n} replays byte-identical to {args.ref} ({work})")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
