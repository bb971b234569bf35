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

from fdi.geodesy import LocalFrame


def plot_rover(
    epochs: list[dict[str, Any]], truth: list[dict[str, Any]] | None, path: Path, title: str = ""
) -> Path:
    """Track raw vs corrected; χ² statistic vs threshold; grey residual vs gate (Figs. 1-5)."""
    ref = next((e for e in epochs if e.get("raw_lat") is not None), None)
    if ref is None:
        raise ValueError("no valid fix to plot")
    frame = LocalFrame(ref["raw_lat"], ref["raw_lon"], 0.0)
    raw = [frame.to_enu(e["raw_lat"], e["raw_lon"], 0.0) for e in epochs if e.get("raw_lat")]
    out = [frame.to_enu(e["lat"], e["lon"], 0.0) for e in epochs if e.get("lat") is not None]
    t0 = epochs[0]["utc"] or 0.0
    t = [(e["utc"] or t0) - t0 for e in epochs]
    fig, axes = plt.subplots(3, 1, figsize=(10, 12))
    ax = axes[0]
    if truth:
        tr = [frame.to_enu(r["true_lat"], r["true_lon"], 0.0) for r in truth]
        ax.plot([p[0] for p in tr], [p[1] for p in tr], "g-", lw=0.8, label="truth")
    ax.plot([p[0] for p in raw], [p[1] for p in raw], "r.", ms=2, label="raw fixes")
    ax.plot([p[0] for p in out], [p[1] for p in out], "b-", lw=0.6, label="output")
    rep = [e for e in epochs if e["action"] == "replace"]
    ax.plot([frame.to_enu(e["raw_lat"], e["raw_lon"], 0)[0] for e in rep],
            [frame.to_enu(e["raw_lat"], e["raw_lon"], 0)[1] for e in rep], "kx", ms=6,
            label="isolated faults")
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(loc="best")
    ax.set_title(title or "track")
    ax = axes[1]
    ax.semilogy(t, [max(e["chi2"], 1e-3) if e["chi2"] is not None else None for e in epochs],
                "b-", lw=0.6, label="F(k) = DᵀS⁻¹D")
    ax.axhline(epochs[0]["chi2_threshold"], color="r", ls="--", label="T_d")
    ax.set_ylabel("chi-square statistic")
    ax.legend(loc="upper right")
    ax = axes[2]
    ax.plot(t, [e["grey_res_h"] for e in epochs], "b-", lw=0.6, label="grey residual |ε| (m)")
    ax.plot(t, [e["grey_gate_h"] for e in epochs], "r--", lw=0.8, label="gate")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("m")
    ax.set_yscale("symlog", linthresh=0.1)
    ax.legend(loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
