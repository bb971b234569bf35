"""Figures like the papers' (needs the ``plot`` extra: matplotlib; see :data:`HAVE_MATPLOTLIB`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

try:  # the optional ``plot`` extra: without it this module imports, and callers check
    import matplotlib  # HAVE_MATPLOTLIB before drawing

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    HAVE_MATPLOTLIB = True
except ImportError:  # pragma: no cover - depends on the install
    HAVE_MATPLOTLIB = False

import numpy as np

from fdi.geodesy import LocalFrame
from firmware_host.devtools.insgnss_sim import fault_spans

ENU = tuple[float, float, float]


class _PerEpoch:
    """Per epoch (``None`` where missing): raw fix, output and truth in local metres, whether
    the fix was replaced, the raw fix's horizontal error."""

    def __init__(self) -> None:
        self.raw: list[ENU | None] = []
        self.out: list[ENU | None] = []
        self.truth: list[ENU | None] = []
        self.replaced: list[bool] = []
        self.raw_err: list[float | None] = []


def _per_epoch(epochs: list[dict[str, Any]], frame: LocalFrame,
               by_utc: dict[Any, dict[str, Any]]) -> _PerEpoch:
    pe = _PerEpoch()
    for e in epochs:
        raw = frame.to_enu(e["raw_lat"], e["raw_lon"], 0.0) if e.get("raw_lat") else None
        out = frame.to_enu(e["lat"], e["lon"], 0.0) if e.get("lat") is not None else None
        r = by_utc.get(e["utc"])
        tru = frame.to_enu(r["true_lat"], r["true_lon"], 0.0) if r is not None else None
        pe.raw.append(raw)
        pe.out.append(out)
        pe.truth.append(tru)
        pe.replaced.append(e.get("action") == "replace")
        ref = tru or out
        pe.raw_err.append(None if raw is None or ref is None
                          else float(np.hypot(raw[0] - ref[0], raw[1] - ref[1])))
    return pe


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


ZOOM_PAD_S = 1.0  # seconds of track before and after a fault period in its zoom
ZOOM_MIN_HALF_M = 1.0  # the smallest half-width of a zoom window, m
TRACK_WIDTH = 0.6  # of the figure's plotting width: the zooms take the rest of the track row


def _zoom_periods(spans: list[tuple[float, float]], t: list[float], raw_err: list[float | None],
                  ) -> list[tuple[str, tuple[float, float]]]:
    """Up to three fault periods to zoom into, in time order, each with why it was chosen: the
    one of largest raw horizontal error, the longest, and the one of smallest error (the
    subtle fault, where output and raw fixes are closest)."""
    scored = []
    for a, b in spans:
        errs = [e for tk, e in zip(t, raw_err, strict=True)
                if e is not None and a - 1e-6 <= tk <= b + 1e-6]
        if errs:
            scored.append((max(errs), b - a, a, b))
    if not scored:
        return []
    picks: dict[tuple[float, float], str] = {}
    for why, best in (("largest", max(scored)), ("longest", max(scored, key=lambda x: x[1:])),
                      ("smallest", min(scored))):
        picks.setdefault((best[2], best[3]), why)
    return sorted(((why, period) for period, why in picks.items()), key=lambda x: x[1])


def _draw_zoom(ax: Any, zoom: Any, k: int, why: str, period: tuple[float, float],
               t: list[float],
               raw: list[ENU | None], out: list[ENU | None], truth: list[ENU | None],
               replaced: list[bool]) -> None:
    """Zoom ``k`` (numbered on the track): the epochs of ``period`` and ``ZOOM_PAD_S`` around
    it; each raw fix joined to the output of its epoch, so the correction is visible."""
    a, b = period
    idx = [i for i, tk in enumerate(t) if a - ZOOM_PAD_S <= tk <= b + ZOOM_PAD_S]

    def pts(seq: list[ENU | None]) -> list[ENU]:
        return [p for p in (seq[i] for i in idx) if p is not None]

    tr, ou, rw = pts(truth), pts(out), pts(raw)
    centre_src = [truth[i] or out[i] for i in idx if a - 1e-6 <= t[i] <= b + 1e-6]
    centre = next((c for c in centre_src if c is not None), (ou or rw)[0])
    half = max(ZOOM_MIN_HALF_M, *(1.15 * max(abs(p[0] - centre[0]), abs(p[1] - centre[1]))
                                   for p in (*tr, *ou, *rw)))
    if tr:
        zoom.plot([p[0] for p in tr], [p[1] for p in tr], "-", color="tab:green", lw=2.0,
                  alpha=0.5, zorder=1)
    for i in idx:
        r, o = raw[i], out[i]
        if r is not None and o is not None and replaced[i]:
            zoom.plot([r[0], o[0]], [r[1], o[1]], "-", color="0.55", lw=0.6, zorder=2)
    # Raw fixes as small crosses under the output's open circles: a cross in a circle is a fix
    # passed through; a cross (x) joined by a line to a circle, a replaced one.
    zoom.plot([p[0] for p in rw], [p[1] for p in rw], "+", color="darkred", ms=4, mew=0.8,
              zorder=3)
    zoom.plot([p[0] for p in ou], [p[1] for p in ou], "-o", color="tab:blue", lw=0.8, ms=5,
              mfc="none", mew=0.8, zorder=4)
    rep_pts = [p for p in (raw[i] for i in idx if replaced[i]) if p is not None]
    zoom.plot([p[0] for p in rep_pts], [p[1] for p in rep_pts], "kx", ms=5, zorder=5)
    zoom.set_xlim(centre[0] - half, centre[0] + half)
    zoom.set_ylim(centre[1] - half, centre[1] + half)
    zoom.set_aspect("equal", adjustable="box")
    zoom.tick_params(labelsize=7)
    zoom.set_title(f"{k}: {why} fault, t = {a:.1f}-{b:.1f} s\n{2 * half:.1f} m across",
                   fontsize=8, loc="left")
    zoom.grid(True, lw=0.3, alpha=0.5)
    ax.add_patch(Rectangle((centre[0] - half, centre[1] - half), 2 * half, 2 * half,
                           fill=False, ec="k", lw=0.8, zorder=6))
    ax.annotate(str(k), (centre[0] + half, centre[1] + half), fontsize=8, fontweight="bold",
                xytext=(2, 2), textcoords="offset points", zorder=6)


def plot_rover(
    epochs: list[dict[str, Any]], truth: list[dict[str, Any]] | None, path: Path, title: str = ""
) -> Path:
    """Track (raw fixes drawn over the output, so neither hides the other) with zooms beside it
    into three fault periods (:func:`_zoom_periods`: at field scale a fault of a metre is half
    a millimetre on the page; in a zoom each raw fix, the output and, for a replaced fix, the
    line between them show the correction); with the
    truth, the horizontal error of the raw fixes and of the output against time; the χ²
    statistic against its threshold and the grey residual against its gate (Figs. 1-5).
    Legends sit above or beside the axes; the truth's fault epochs are shaded (without a
    truth, the epochs the detector flagged are zoomed)."""
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
    _legend_above(ax, ncol=4)
    ax.set_title(title or "track", pad=22)
    # Zooms beside the track (child axes: outside the data, and not among the figure's panels).
    per_epoch = _per_epoch(epochs, frame, by_utc)
    zoom_spans = spans or fault_spans(np.array(t, dtype=float),
                                      np.array([bool(e.get("fault")) for e in epochs]))
    periods = _zoom_periods(zoom_spans, t, per_epoch.raw_err)
    n = max(len(periods), 1)
    gap = 0.13
    height = (1.0 - gap * (n - 1)) / n
    zooms = []
    for k, (why, period) in enumerate(periods, 1):
        # in the track's axes coordinates, right of it (placed once the layout is done)
        zoom = ax.inset_axes((1.12, 1.0 - k * height - (k - 1) * gap,
                              1.0 / TRACK_WIDTH - 1.14, height))
        zoom.set_in_layout(False)
        zoom.set_anchor("W")
        zooms.append(zoom)
        _draw_zoom(ax, zoom, k, why, period, t, per_epoch.raw, per_epoch.out, per_epoch.truth,
                   per_epoch.replaced)
    if zooms:
        zooms[-1].set_xlabel("+ raw fix, o output, x replaced raw fix\n(grey: to its output)",
                             fontsize=7, loc="left")
    track = ax
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
    if zooms:  # the track keeps the left of its row, the zooms the right
        pos = track.get_position()
        track.set_position((pos.x0, pos.y0, pos.width * TRACK_WIDTH, pos.height))
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
