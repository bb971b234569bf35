"""``fdi-bridge sim insgnss-report``: the measured tables of ``docs/insgnss.md``, as a command.

Default: every paper scenario of :mod:`firmware_host.devtools.insgnss_sim` for each preset and
seed through the five strategies, printed as aligned tables (``--out`` writes them as
Markdown): the 3-D position RMS per run, seed 1 per axis, and the ``paper-deviation`` (the
easier Table 2 scenario) three-zone ranges per seed against the paper's Table 2.
``--sweep-sigma-v`` also reruns ``paper-deviation`` with the vertical GNSS noise (generator and
filter R alike) set to each value.

``--done-means`` (issue 15, meant for ``--seeds 1-50``): per preset, ``paper-continuous`` for
the preset's strategy (or ``--strategy``) against no robust filtering, with the coast bound
(:func:`~firmware_host.devtools.insgnss_sim.run_coast`), and the other three scenarios against
plain down-weighting. ``--table2-calibrated``: the calibrated Table 2
(``config/insgnss-table2.toml``) beside the easier scenario.

Each filter run takes about 0.6 s on an idle machine: ``--done-means --seeds 1-50`` makes 700
runs per preset, ``--table2-calibrated --seeds 1-50`` 400 (measured 17 and 12 minutes under
load, niced).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from fdi.errors import UsageError
from fdi.insgnss import INS_STRATEGIES, InsGnssStrategy
from firmware_host.commands.checks import (
    input_file_arg,
    output_file_arg,
    positive_float_list,
    seed_list,
)
from firmware_host.commands.tables import (
    Block,
    Table,
    jsonable,
    report_console,
    report_markdown,
)
from firmware_host.devtools.insgnss_sim import (
    CONFIG_DIR,
    InsGnssSetup,
    MethodRun,
    Scenario,
    generate,
    load_setup,
    run_coast,
    run_method,
    run_scenario,
)
from firmware_host.devtools.progress import Progress

AXES = ("east", "north", "up")
# Cai & Shao, Table 2 (20 m faults), with robust filtering: (min, max) per axis, m
PAPER_TABLE2: dict[str, tuple[float, float]] = {
    "east": (-11.8, 6.06), "north": (-6.64, 7.54), "up": (-2.62, 2.57),
}
# ... and without robust filtering (Table 2's first column)
PAPER_TABLE2_NONE: dict[str, tuple[float, float]] = {
    "east": (-25.8, 32.6), "north": (-20.5, 34.9), "up": (-7.9, 13.9),
}
# §2.2: a 25 m error is above T2 = 6.635 96 % of the time: σ_S = 25 / (z_0.96 + √T2), m
PAPER_SIGMA_S_M = 25.0 / (1.7507 + 2.5758)
PAPER_SCENARIOS: tuple[Scenario, ...] = (
    "paper-random", "paper-single", "paper-continuous", "paper-deviation")
TABLE2_PRESET = CONFIG_DIR / "insgnss-table2.toml"
TABLE2_METHODS: tuple[InsGnssStrategy, ...] = ("none", "downweight", "three_zone", "fault_state")
SPAN_TOLERANCE = 0.25  # the calibration: spans without robust filtering within 25 %
GOAL = 0.7  # "our goal is 30 % tighter than the paper": span at most 0.7 of Table 2's


def with_sigma_v(setup: InsGnssSetup, sigma_v_m: float) -> InsGnssSetup:
    """``setup`` with the vertical GNSS noise set in the generator and in the filter's R."""
    return dataclasses.replace(
        setup,
        sim=dataclasses.replace(setup.sim, gnss_sigma_v_m=sigma_v_m),
        filter=dataclasses.replace(setup.filter, gnss_sigma_v_m=sigma_v_m),
    )


def range_verdict(pos: dict[str, dict[str, float]], axis: str) -> str:
    """``min … max`` with "in Table 2" / "30 % goal" marks for the three-zone ranges."""
    lo, hi = PAPER_TABLE2[axis]
    mn, mx = pos[axis]["min"], pos[axis]["max"]
    mark = ""
    if lo <= mn and mx <= hi:
        mark = " ✓" + ("✓" if mx - mn <= GOAL * (hi - lo) else "")
    return f"{mn:.2f} … {mx:.2f}{mark}"


def report(presets: Sequence[tuple[str, InsGnssSetup]], seeds: Sequence[int],
           sweep: Sequence[float], scenarios: Sequence[Scenario] = PAPER_SCENARIOS,
           progress: Callable[[str], None] | None = None,
           runs: list[dict[str, Any]] | None = None) -> list[Block]:
    """The report (Markdown for a file, aligned tables for the console); ``progress(label)``
    after each run (a progress bar); each run's summary appended to ``runs`` (``--json``).
    ^C: the tables of the runs done so far, the first line starting with :data:`PARTIAL`
    (the command exits 130)."""
    kept = runs if runs is not None else []
    done = progress or (lambda label: None)
    rows: list[tuple[str, str, int, dict[str, Any]]] = []
    interrupted = False
    try:
        for name, setup in presets:
            for scenario in scenarios:
                for seed in seeds:
                    summary, _data, _runs = run_scenario(setup, scenario, seed)
                    done(f"{name} {scenario} seed {seed}")
                    rows.append((name, scenario, seed, summary["methods"]))
                    kept.append({"preset": name, "scenario": scenario, "seed": seed,
                                 "methods": summary["methods"]})
    except KeyboardInterrupt:
        interrupted = True
    rms = Table(["preset", "scenario", "seed", *INS_STRATEGIES, "three_zone max horiz. (m)",
                 "fault_state max horiz. (m)"], right=range(3, 5 + len(INS_STRATEGIES)))
    for name, scen, seed, m in rows:
        rms.add(name, scen, str(seed),
                *(f"{m[k]['position_rms_3d_m']:.2f}" for k in INS_STRATEGIES),
                f"{m['three_zone']['max_horizontal_error_m']:.1f}",
                f"{m['fault_state']['max_horizontal_error_m']:.1f}")
    first = seeds[0]
    axes = Table(["preset", "scenario", "method", *AXES])
    for name, scen, seed, m in rows:
        if seed != first:
            continue
        for method, v in m.items():
            p = v["position_m"]
            axes.add(name, scen, method,
                     *(f"{p[a]['min']:.2f} / {p[a]['max']:.2f} / {p[a]['rms']:.2f}"
                       for a in AXES))
    ranges = Table(["preset", "seed", *AXES, "up, no robust filtering"])
    for name, scen, seed, m in rows:
        if scen != "paper-deviation":
            continue
        tz, none = m["three_zone"]["position_m"], m["none"]["position_m"]
        ranges.add(name, str(seed), *(range_verdict(tz, a) for a in AXES),
                   f"{none['up']['min']:.2f} … {none['up']['max']:.2f}")
    out: list[Block] = [
        "### 3-D position RMS (m), every seed", "", rms,
        "", f"### Seed {first}, per axis: min / max / RMS (m)", "", axes,
        "", "### paper-deviation, three_zone ranges per seed (m) against Table 2", "",
        "✓ inside Table 2's robust range, ✓✓ and at least 30 % tighter.", "", ranges]
    if sweep and not interrupted:
        name, setup = presets[0]
        swept = Table(["σ up (m)", "seed", "three_zone up", "no robust filtering, up",
                       "three_zone up RMS", "none up RMS"], right=(0, 4, 5))
        out += ["", f"### paper-deviation up range against the vertical GNSS noise ({name})", "",
                swept]
        try:
            for sv in sweep:
                for seed in seeds:
                    summary, _d, _r = run_scenario(with_sigma_v(setup, sv), "paper-deviation",
                                                   seed, ("none", "three_zone"))
                    done(f"sigma_v {sv:g} seed {seed}")
                    kept.append({"preset": name, "scenario": "paper-deviation", "seed": seed,
                                 "sigma_v_m": sv, "methods": summary["methods"]})
                    tz = summary["methods"]["three_zone"]["position_m"]
                    none = summary["methods"]["none"]["position_m"]
                    swept.add(f"{sv:g}", str(seed), range_verdict(tz, "up"),
                              f"{none['up']['min']:.2f} … {none['up']['max']:.2f}",
                              f"{tz['up']['rms']:.2f}", f"{none['up']['rms']:.2f}")
        except KeyboardInterrupt:
            interrupted = True
    if interrupted:
        out = [f"{PARTIAL} only the runs done before ^C are in these tables "
               f"({len(rows)} scenario runs).", "", *out]
    return [*out, ""]


PARTIAL = "**Partial (interrupted):**"


def is_partial(blocks: Sequence[Block]) -> bool:
    """Whether :func:`report` was interrupted (its first line says so)."""
    return bool(blocks) and isinstance(blocks[0], str) and blocks[0].startswith(PARTIAL)

FAULT_ROWS = slice(9, 200)  # paper-continuous: epochs 10..200 (pos_err row k is epoch k + 1)
OTHER_SCENARIOS: tuple[Scenario, ...] = ("paper-random", "paper-single", "paper-deviation")


def _rms(values: Sequence[float]) -> float:
    """Pooled RMS of per-run RMS values (each run has the same number of epochs)."""
    return math.sqrt(math.fsum(v * v for v in values) / len(values))


def _max_horizontal(err: Any) -> float:
    return float(np.hypot(err[:, 0], err[:, 1]).max())


def done_means_steps(seeds: Sequence[int]) -> int:
    """How many times :func:`done_means` calls ``progress``."""
    return len(seeds) * (1 + len(OTHER_SCENARIOS))


def done_means(name: str, setup: InsGnssSetup, seeds: Sequence[int],
               progress: Callable[[str], None] | None = None) -> list[Block]:
    """The issue-15 checks over ``seeds``: ``paper-continuous`` per seed for the preset's own
    strategy against no robust filtering, and the other three scenarios against plain
    down-weighting. ``progress(label)`` after each seed of each scenario. ^C: the seeds and
    scenarios done so far, the first line starting with :data:`PARTIAL`."""
    done = progress or (lambda label: None)
    interrupted = False
    strat = setup.filter.strategy
    per_seed = Table(["seed", "3-D RMS (m)", "none 3-D RMS (m)",
                      "max horiz. during the fault (m)", "coast bound (m)",
                      "coast, realised (m)", "downweight 3-D RMS (m)",
                      "three_zone 3-D RMS (m)"], right=range(1, 8))
    out: list[Block] = [
        f"### {name}: paper-continuous, strategy `{strat}` against no robust filtering", "",
        "Coast: the plain filter told the fault (position fixes withheld on its epochs); "
        "bound = its horizontal 3σ at the fault's end, `3 sqrt(P_EE + P_NN)`.", "", per_seed]
    others: dict[InsGnssStrategy, list[float]] = {"downweight": [], "three_zone": []}
    rms: list[float] = []
    nones: list[float] = []
    horiz: list[float] = []
    over_bound = 0
    try:
        for seed in seeds:
            data = generate(setup, "paper-continuous", seed)
            run = run_method(data, setup.filter, strat)
            none = run_method(data, setup.filter, "none")
            coast = run_coast(data, setup.filter)
            r3 = float(np.sqrt(np.mean(np.sum(run.pos_err**2, axis=1))))
            n3 = float(np.sqrt(np.mean(np.sum(none.pos_err**2, axis=1))))
            h = _max_horizontal(run.pos_err[FAULT_ROWS])
            bound = 3.0 * float(coast.sigma_h[FAULT_ROWS].max())
            rms_of = {method: float(np.sqrt(np.mean(np.sum(
                (run if method == strat else run_method(data, setup.filter, method)).pos_err
                ** 2, axis=1)))) for method in others}
            # the seed's numbers together (a ^C above leaves none of them)
            over_bound += h > bound
            rms.append(r3)
            nones.append(n3)
            horiz.append(h)
            for method, lst in others.items():
                lst.append(rms_of[method])
            per_seed.add(str(seed), f"{r3:.2f}", f"{n3:.2f}", f"{h:.1f}", f"{bound:.1f}",
                         f"{_max_horizontal(coast.pos_err[FAULT_ROWS]):.1f}",
                         f"{others['downweight'][-1]:.2f}", f"{others['three_zone'][-1]:.2f}")
            done(f"{name} paper-continuous seed {seed}")
    except KeyboardInterrupt:
        interrupted = True
    if not rms:
        return [f"{PARTIAL} {name}: no seed done before ^C.", ""]
    med = float(np.median(rms))
    worst = int(np.argmax(rms))
    out += ["", f"Median 3-D RMS {med:.2f} m; worst seed {seeds[worst]} {rms[worst]:.2f} m "
            f"({rms[worst] / med:.2f}x the median); seeds above 3x the median: "
            f"{sum(r > 3 * med for r in rms)}; seeds above no robust filtering: "
            f"{sum(r > n for r, n in zip(rms, nones, strict=True))}; largest horizontal error "
            f"during the fault {max(horiz):.1f} m (seed {seeds[int(np.argmax(horiz))]}); "
            f"seeds above the coast bound: {over_bound}. Median 3-D RMS of downweight "
            f"{np.median(others['downweight']):.2f} m (worst {max(others['downweight']):.2f}), "
            f"of three_zone {np.median(others['three_zone']):.2f} m "
            f"(worst {max(others['three_zone']):.2f}).", ""]
    if interrupted:
        return [f"{PARTIAL} {name}: {len(rms)} of {len(seeds)} seeds of paper-continuous done "
                "before ^C.", "", *out, ""]
    against = Table(["scenario", "seeds", "pooled RMS", "downweight pooled RMS", "ratio",
                     "worst seed ratio", "three_zone pooled RMS",
                     "three_zone / downweight, worst seed"], right=range(2, 8))
    out += [f"### {name}: strategy `{strat}` against plain down-weighting, 3-D RMS (m)", "",
            against]
    for scenario in OTHER_SCENARIOS:
        a: list[float] = []
        b: list[float] = []
        c: list[float] = []
        try:
            for seed in seeds:
                data = generate(setup, scenario, seed)
                for lst, method in ((a, strat), (b, "downweight"), (c, "three_zone")):
                    r = run_method(data, setup.filter, method)
                    lst.append(float(np.sqrt(np.mean(np.sum(r.pos_err**2, axis=1)))))
                done(f"{name} {scenario} seed {seed}")
        except KeyboardInterrupt:
            done_rows = len(against.rows)
            return [f"{PARTIAL} {name}: {done_rows} of {len(OTHER_SCENARIOS)} scenarios "
                    "against down-weighting done before ^C.", "", *out, ""]
        ratios = [x / y for x, y in zip(a, b, strict=True)]
        k = int(np.argmax(ratios))
        tz = [x / y for x, y in zip(c, b, strict=True)]
        kt = int(np.argmax(tz))
        against.add(scenario, f"{seeds[0]}-{seeds[-1]}", f"{_rms(a):.3f}", f"{_rms(b):.3f}",
                    f"{_rms(a) / _rms(b):.3f}", f"{ratios[k]:.2f} (seed {seeds[k]})",
                    f"{_rms(c):.3f}", f"{tz[kt]:.2f} (seed {seeds[kt]})")
    return [*out, ""]


def _span(lo_hi: tuple[float, float]) -> float:
    return lo_hi[1] - lo_hi[0]


def table2_runs(setup: InsGnssSetup, scenario: Scenario, seeds: Sequence[int],
                methods: Sequence[InsGnssStrategy] = TABLE2_METHODS,
                progress: Callable[[str], None] | None = None,
                ) -> dict[str, list[MethodRun]]:
    """Every method on ``scenario`` for each seed (the same data per seed); ``progress(label)``
    after each seed."""
    out: dict[str, list[MethodRun]] = {m: [] for m in methods}
    for seed in seeds:
        data = generate(setup, scenario, seed)
        for m in methods:
            out[m].append(run_method(data, setup.filter, m))
        if progress is not None:
            progress(f"{scenario} seed {seed}")
    return out


def table2_steps(seeds: Sequence[int]) -> int:
    """How many times :func:`table2_calibrated` calls ``progress``."""
    return 2 * len(seeds)


def span_stats(runs: Sequence[MethodRun]) -> dict[str, dict[str, float]]:
    """Per axis over the runs: median min, median max, median / lowest / highest span (m)."""
    out = {}
    for i, axis in enumerate(AXES):
        mins = np.array([float(r.pos_err[:, i].min()) for r in runs])
        maxs = np.array([float(r.pos_err[:, i].max()) for r in runs])
        spans = maxs - mins
        out[axis] = {"min": float(np.median(mins)), "max": float(np.median(maxs)),
                     "span": float(np.median(spans)), "span_lo": float(spans.min()),
                     "span_hi": float(spans.max())}
    return out


def table2_calibrated(seeds: Sequence[int], setup: InsGnssSetup | None = None,
                      easier: InsGnssSetup | None = None,
                      progress: Callable[[str], None] | None = None) -> list[Block]:
    """The calibrated reproduction of Table 2 (``table2-calibrated`` on
    ``config/insgnss-table2.toml``), beside the easier scenario (``paper-deviation`` on the
    paper preset). ``progress(label)`` after each seed. ^C: the sections done so far, the
    first line starting with :data:`PARTIAL`."""
    setup = setup if setup is not None else load_setup(TABLE2_PRESET)
    easier = easier if easier is not None else load_setup(CONFIG_DIR / "insgnss-paper.toml")
    out: list[Block] = []
    for title, stp, scen in (
        ("calibrated: `table2-calibrated`, config/insgnss-table2.toml", setup,
         "table2-calibrated"),
        ("easier (uncalibrated): `paper-deviation`, config/insgnss-paper.toml", easier,
         "paper-deviation"),
    ):
        try:
            runs = table2_runs(stp, scen, seeds, progress=progress)  # type: ignore[arg-type]
        except KeyboardInterrupt:
            sections = sum(1 for b in out if isinstance(b, Table))
            return [f"{PARTIAL} {sections} of 2 Table 2 sections done before ^C.", "", *out]
        none = span_stats(runs["none"])
        sig = np.nanmedian([r.innovation_sigma[0] for r in runs["none"]])
        out += [f"### Table 2, {title}, seeds {seeds[0]}-{seeds[-1]}", "",
                f"East innovation 1σ without robust filtering (median): {sig:.2f} m; the "
                f"paper's §2.2 implies {PAPER_SIGMA_S_M:.2f} m.", "",
                "Median min … max per axis (m), and the median span (lowest-highest over the "
                "seeds) against the paper's span.", ""]
        tab = Table(["method", *AXES, "span E / paper", "span N / paper", "span U / paper"],
                    right=(4, 5, 6))
        out.append(tab)
        for label, (lo_hi_t) in (("paper, no robust filtering", PAPER_TABLE2_NONE),
                                 ("paper, robust", PAPER_TABLE2)):
            tab.add(f"*{label}*", *(f"{lo_hi_t[a][0]:.2f} … {lo_hi_t[a][1]:.2f}" for a in AXES),
                    *(f"{_span(lo_hi_t[a]):.1f}" for a in AXES))
        for method, rs in runs.items():
            st = span_stats(rs)
            ref = PAPER_TABLE2_NONE if method == "none" else PAPER_TABLE2
            tab.add(method, *(f"{st[a]['min']:.2f} … {st[a]['max']:.2f}" for a in AXES),
                    *(f"{st[a]['span']:.1f} ({st[a]['span_lo']:.1f}-{st[a]['span_hi']:.1f}) / "
                      f"{_span(ref[a]):.1f} = {st[a]['span'] / _span(ref[a]):.2f}"
                      for a in AXES))
        within = [
            all(abs((float(r.pos_err[:, i].max() - r.pos_err[:, i].min()))
                    / _span(PAPER_TABLE2_NONE[a]) - 1.0) <= SPAN_TOLERANCE
                for i, a in enumerate(AXES))
            for r in runs["none"]
        ]
        med_ok = all(abs(none[a]["span"] / _span(PAPER_TABLE2_NONE[a]) - 1.0) <= SPAN_TOLERANCE
                     for a in AXES)
        out += ["", f"No robust filtering against the paper's first column: median span within "
                f"{SPAN_TOLERANCE:.0%} on every axis: {'yes' if med_ok else 'no'}; seeds with "
                f"every axis within: {sum(within)}/{len(within)}.", ""]
    return out


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--seeds", type=seed_list, default=[1, 2, 3, 4, 5],
                        help="seeds, like 1-5 or 1,3 (default 1-5)")
    parser.add_argument(
        "--config", type=input_file_arg, action="append", default=None,
        help="preset TOML, repeatable (default: config/insgnss-paper.toml and "
             "config/insgnss.toml)")
    parser.add_argument("--sweep-sigma-v", type=positive_float_list, default=[],
                        help="also run paper-deviation on the first preset with these vertical "
                             "GNSS noises, m (like 1.15,2,3,5)")
    parser.add_argument("--scenario", choices=PAPER_SCENARIOS, action="append", default=None,
                        help="only these scenarios, repeatable (default: the four paper ones)")
    parser.add_argument("--out", type=output_file_arg, default=None,
                        help="also write the report to this file, as Markdown")
    parser.add_argument("--table2-calibrated", action="store_true",
                        help="only the calibrated Table 2 reproduction (config/insgnss-table2."
                             "toml) beside the easier paper-deviation scenario")
    parser.add_argument("--strategy", choices=INS_STRATEGIES, default=None,
                        help="--done-means: run this strategy instead of each preset's own")
    parser.add_argument("--json", action="store_true",
                        help="print every run's summary as JSON instead of the tables (the "
                             "default report; --out still writes the Markdown)")
    parser.add_argument("--done-means", action="store_true",
                        help="only the issue-15 checks per preset: paper-continuous against no "
                             "robust filtering, the others against down-weighting (use 1-50)")


def run(args: argparse.Namespace) -> int:
    paths: list[Path] = args.config or [CONFIG_DIR / "insgnss-paper.toml",
                                        CONFIG_DIR / "insgnss.toml"]
    presets = [(p.stem, load_setup(p)) for p in paths]
    if args.strategy is not None:
        presets = [(name, dataclasses.replace(
            st, filter=dataclasses.replace(st.filter, strategy=args.strategy)))
            for name, st in presets]
    if args.json and (args.done_means or args.table2_calibrated):
        raise UsageError("--json is for the default report (not --done-means or "
                         "--table2-calibrated)")
    if args.done_means or args.table2_calibrated:
        steps = (table2_steps(args.seeds) if args.table2_calibrated else 0) + (
            len(presets) * done_means_steps(args.seeds) if args.done_means else 0)
        parts: list[list[Block]] = []
        with Progress(steps, "insgnss-report", unit="seed") as bar:
            if args.table2_calibrated:
                parts.append(table2_calibrated(args.seeds, progress=bar.step))
            if args.done_means:
                for name, setup in presets:
                    if parts and is_partial(parts[-1]):
                        break  # ^C: no new part
                    parts.append(done_means(name, setup, args.seeds, progress=bar.step))
        partial = any(is_partial(p) for p in parts)
        if partial and not is_partial(parts[0]):  # the file says so on its first line
            parts.insert(0, [f"{PARTIAL} only the parts done before ^C are here.", ""])
        if args.out is not None:
            args.out.write_text("\n".join(report_markdown(p) for p in parts), encoding="utf-8")
        sys.stdout.write("\n".join(report_console(p) for p in parts))
        if partial:
            where = f" ({args.out}, marked partial)" if args.out is not None else ""
            print(f"fdi-bridge sim insgnss-report: interrupted: partial report written{where}",
                  file=sys.stderr)
            return 130
        return 0
    scenarios = tuple(args.scenario) if args.scenario else PAPER_SCENARIOS
    runs = len(presets) * len(scenarios) * len(args.seeds) + len(args.sweep_sigma_v) * len(
        args.seeds)
    with Progress(runs, "insgnss-report", unit="run") as bar:
        runs_done: list[dict[str, Any]] = []
        blocks = report(presets, args.seeds, args.sweep_sigma_v, scenarios, progress=bar.step,
                        runs=runs_done)
    if args.out is not None:
        args.out.write_text(report_markdown(blocks), encoding="utf-8")
    if args.json:
        print(json.dumps(jsonable({"partial": is_partial(blocks), "runs": runs_done})))
    else:
        sys.stdout.write(report_console(blocks))
    if is_partial(blocks):
        where = f" ({args.out}, marked partial)" if args.out is not None else ""
        print(f"fdi-bridge sim insgnss-report: interrupted: partial report written{where}",
              file=sys.stderr)
        return 130
    return 0
