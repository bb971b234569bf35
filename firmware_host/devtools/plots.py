"""Figures like the papers' (needs the ``plot`` extra: matplotlib; see :data:`HAVE_MATPLOTLIB`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

try:  # the optional ``plot`` extra: without it this module imports, and callers check
    import matplotlib  # HAVE_MATPLOTLIB before drawing

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    HAVE_MATPLOTLIB = True
except ImportError:  # pragma: no cover - depends on the install
    HAVE_MATPLOTLIB = False

import numpy as np

from fdi.geodesy import LocalFrame
from firmware_host.devtools.insgnss_sim import fault_spans


def _legend_above(ax: Any, ncol: int = 4) -> None:
    """The legend in a row above the axes: it covers no data."""
    ax.legend(loc="lower left", bbox_to_anchor=(0.0, 1.0), ncol=ncol, fontsize=8,
              frameon=False, borderaxespad=0.2)


def _shade(ax: Any, spans: list[tuple[float, float]], label: str = "injected fault",
           min_width: float = 0.0) -> None:
    """Shade the fault spans, each at least ``min_width`` wide (one 10 Hz epoch on a 10-minute
    axis would be narrower than a pixel)."""
    for k, (a, b) in enumerate(spans):
        pad = max(0.0, min_width - (b - a)) / 2
        ax.axvspan(a - pad, b + pad, color="tab:red", alpha=0.18, lw=0,
                   label=label if k == 0 else None)


def plot_rover(
    epochs: list[dict[str, Any]], truth: list[dict[str, Any]] | None, path: Path, title: str = ""
) -> Path:
    """Track (raw fixes drawn over the output, so neither hides the other); with the truth, the
    horizontal error of the raw fixes and of the output against time; the χ² statistic against
    its threshold and the grey residual against its gate (Figs. 1-5). Legends sit above or
    beside the axes; the truth's fault epochs are shaded."""
    ref = next((e for e in epochs if e.get("raw_lat") is not None), None)
    if ref is None:
        raise ValueError("no valid fix to plot")
    frame = LocalFrame(ref["raw_lat"], ref["raw_lon"], 0.0)
    raw = [frame.to_enu(e["raw_lat"], e["raw_lon"], 0.0) for e in epochs if e.get("raw_lat")]
    out = [frame.to_enu(e["lat"], e["lon"], 0.0) for e in epochs if e.get("lat") is not None]
    t0 = epochs[0]["utc"] or 0.0
    t = [(e["utc"] or t0) - t0 for e in epochs]
    by_utc = {r["utc"]: r for r in truth or []}
    spans: list[tuple[float, float]] = []
    if truth:
        tt = np.array([r["utc"] - t0 for r in truth], dtype=float)
        spans = fault_spans(tt, np.array([bool(r.get("fault")) for r in truth]))
    width = (max(t) - min(t)) / 250 if t else 0.0
    panels = 4 if truth else 3
    fig, axes = plt.subplots(panels, 1, figsize=(11, 3.2 * panels + 3.0),
                             gridspec_kw={"height_ratios": [2.2] + [1] * (panels - 1)})
    ax = axes[0]
    if truth:
        tr = [frame.to_enu(r["true_lat"], r["true_lon"], 0.0) for r in truth]
        ax.plot([p[0] for p in tr], [p[1] for p in tr], "-", color="tab:green", lw=2.0,
                alpha=0.5, label="truth", zorder=1)
    # The output as a wide light band under the raw fixes (small dark dots): both stay visible.
    ax.plot([p[0] for p in out], [p[1] for p in out], "-", color="tab:blue", lw=2.2,
            alpha=0.55, label="output", zorder=2)
    ax.plot([p[0] for p in raw], [p[1] for p in raw], ".", color="darkred", ms=0.8,
            label="raw fixes", zorder=3)
    rep = [e for e in epochs if e["action"] == "replace" and e.get("raw_lat") is not None]
    ax.plot([frame.to_enu(e["raw_lat"], e["raw_lon"], 0)[0] for e in rep],
            [frame.to_enu(e["raw_lat"], e["raw_lon"], 0)[1] for e in rep], "kx", ms=6,
            label="isolated faults (raw fix)", zorder=4)
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    ax.set_title(title or "track")
    time_axes = list(axes[1:])
    if truth:
        ax = axes[1]
        _shade(ax, spans, min_width=width)
        err_raw, err_out, te = [], [], []
        for e, tk in zip(epochs, t, strict=True):
            r = by_utc.get(e["utc"])
            if r is None or e.get("raw_lat") is None or e.get("lat") is None:
                continue
            te_k = frame.to_enu(r["true_lat"], r["true_lon"], 0.0)
            pr = frame.to_enu(e["raw_lat"], e["raw_lon"], 0.0)
            po = frame.to_enu(e["lat"], e["lon"], 0.0)
            err_raw.append(max(float(np.hypot(pr[0] - te_k[0], pr[1] - te_k[1])), 1e-3))
            err_out.append(max(float(np.hypot(po[0] - te_k[0], po[1] - te_k[1])), 1e-3))
            te.append(tk)
        ax.semilogy(te, err_raw, ".", color="tab:red", ms=2, label="raw fix")
        ax.semilogy(te, err_out, "-", color="tab:blue", lw=0.6, label="output")
        ax.set_ylabel("horizontal error (m)")
        _legend_above(ax)
    ax = time_axes[-2]
    _shade(ax, spans, min_width=width)
    ax.semilogy(t, [max(e["chi2"], 1e-3) if e["chi2"] is not None else None for e in epochs],
                "b-", lw=0.6, label="F(k) = DᵀS⁻¹D")
    ax.axhline(epochs[0]["chi2_threshold"], color="r", ls="--", label="T_d")
    ax.set_ylabel("chi-square statistic")
    _legend_above(ax)
    ax = time_axes[-1]
    _shade(ax, spans, min_width=width)
    ax.semilogy(t, [max(e["grey_res_h"], 1e-3) if e["grey_res_h"] is not None else None
                    for e in epochs], "b-", lw=0.6, label="grey residual |ε|")
    ax.plot(t, [e["grey_gate_h"] for e in epochs], "r--", lw=0.8, label="gate")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("m")
    _legend_above(ax)
    for a in time_axes[:-1]:
        a.sharex(time_axes[-1])
        a.tick_params(labelbottom=False)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
