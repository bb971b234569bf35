"""GM(1,1) grey one-step prediction, in a numerically stable form.

Zhou & Zhang (2010), section 2.1, equations (7)-(17). For the original sequence
``x⁰(1..n)`` (positive; eq. 7) the 1-AGO sequence is ``x¹(k) = Σ_{i≤k} x⁰(i)`` (eq. 8-9), the
background values ``z¹(k) = 0.5 x¹(k) + 0.5 x¹(k−1)`` (eq. 10-11), and the grey differential
equation ``x⁰(k) + a z¹(k) = b`` (eq. 12) is solved for ``P = [a, b]ᵀ`` by least squares
(eq. 13-14). The time response (eq. 15-16) and its inverse AGO (eq. 17) give the one-step
prediction

    x̂⁰(n+1) = (b − a·x⁰(1)) · (e^a − 1)/a · e^(−a·n)

The textbook route (``(BᵀB)⁻¹BᵀY`` on raw background values, then ``x̂¹(n+1) − x̂¹(n)`` with
``b/a``) cancels catastrophically on coordinates and divides by zero when the rover stands still
(``a → 0``); see shared/FINDINGS.md. Here the regression is done on *centred* background
values, and ``(e^a − 1)/a`` is written with ``expm1`` so ``a → 0`` reduces to a constant.

Units: whatever the sequence is in (metres here); ``shift`` (the paper's "map negative data to
positive", eq. 7 remark) is added before modelling and removed after.
"""

from __future__ import annotations

import math
from collections.abc import Sequence


def gm11_fit(x0: Sequence[float]) -> tuple[float, float]:
    """Least-squares ``(a, b)`` of eq. (12)-(14) for a positive sequence of length n ≥ 3."""
    n = len(x0)
    if n < 3:
        raise ValueError("GM(1,1) needs at least 3 values")
    # eq. (9): 1-AGO; eq. (11): background values z¹(k), k = 2..n
    x1 = x0[0]
    z: list[float] = []
    for k in range(1, n):
        prev = x1
        x1 += x0[k]
        z.append(0.5 * (x1 + prev))
    y = x0[1:]  # Y of eq. (13)
    m = n - 1
    zbar = sum(z) / m
    ybar = sum(y) / m
    szz = 0.0
    szy = 0.0
    for zk, yk in zip(z, y, strict=True):
        dz = zk - zbar
        szz += dz * dz
        szy += dz * (yk - ybar)
    # eq. (14) with centred regressors: x⁰(k) = (b − a·z̄) − a·(z¹(k) − z̄)
    a = -szy / szz if szz > 0.0 else 0.0
    b = ybar + a * zbar
    return a, b


def gm11_predict(x0: Sequence[float]) -> float:
    """One-step prediction x̂⁰(n+1) of eq. (16)-(17) (stable form; see module docstring)."""
    n = len(x0)
    a, b = gm11_fit(x0)
    g = math.expm1(a) / a if abs(a) > 1e-12 else 1.0 + 0.5 * a
    return (b - a * x0[0]) * g * math.exp(-a * n)


def gm11_predict_shifted(values: Sequence[float], shift: float) -> float:
    """GM(1,1) on ``values − min(values) + shift`` (made positive), mapped back.

    The same computation as :func:`gm11_predict`, in one pass (this runs three times an epoch).
    """
    n = len(values)
    if n < 3:
        raise ValueError("GM(1,1) needs at least 3 values")
    offset = shift - min(values)
    rest = iter(values)
    x0_1 = next(rest) + offset
    x1 = x0_1
    sz = sy = szz = szy = 0.0
    for value in rest:  # k = 2..n
        xk = value + offset
        prev = x1
        x1 += xk  # eq. (9): 1-AGO
        z = 0.5 * (x1 + prev)  # eq. (11)
        sz += z
        sy += xk
        szz += z * z
        szy += z * xk
    return _gm11_step(n - 1, n, sz, sy, szz, szy, x0_1) - offset


def gm11_predict_shifted_enu(window: Sequence[tuple[float, float, float]], shift: float
                             ) -> tuple[float, float, float]:
    """:func:`gm11_predict_shifted` of each axis of a window of (east, north, up) values,
    in one pass over the window (the same operations per axis, so the same floats)."""
    n = len(window)
    if n < 3:
        raise ValueError("GM(1,1) needs at least 3 values")
    first = window[0]
    es, ns, us = zip(*window, strict=True)
    off_e = shift - min(es)
    off_n = shift - min(ns)
    off_u = shift - min(us)
    x0e, x0n, x0u = first[0] + off_e, first[1] + off_n, first[2] + off_u
    x1e, x1n, x1u = x0e, x0n, x0u
    sze = sye = szze = szye = 0.0
    szn = syn = szzn = szyn = 0.0
    szu = syu = szzu = szyu = 0.0
    it = iter(window)
    next(it)
    for we, wn, wu in it:  # k = 2..n
        xe, xn, xu = we + off_e, wn + off_n, wu + off_u
        pe, pn, pu = x1e, x1n, x1u
        x1e += xe  # eq. (9): 1-AGO
        x1n += xn
        x1u += xu
        ze = 0.5 * (x1e + pe)  # eq. (11)
        zn = 0.5 * (x1n + pn)
        zu = 0.5 * (x1u + pu)
        sze += ze
        szn += zn
        szu += zu
        sye += xe
        syn += xn
        syu += xu
        szze += ze * ze
        szzn += zn * zn
        szzu += zu * zu
        szye += ze * xe
        szyn += zn * xn
        szyu += zu * xu
    m = n - 1
    return (_gm11_step(m, n, sze, sye, szze, szye, x0e) - off_e,
            _gm11_step(m, n, szn, syn, szzn, szyn, x0n) - off_n,
            _gm11_step(m, n, szu, syu, szzu, szyu, x0u) - off_u)


def _gm11_step(m: int, n: int, sz: float, sy: float, szz: float, szy: float, x0_1: float
               ) -> float:
    """eq. (14) (centred) and (16)-(17) from the sums of :func:`gm11_predict_shifted`."""
    zbar = sz / m
    ybar = sy / m
    var_z = szz - m * zbar * zbar
    cov_zy = szy - m * zbar * ybar
    a = -cov_zy / var_z if var_z > 0.0 else 0.0  # eq. (14), centred
    b = ybar + a * zbar
    g = math.expm1(a) / a if abs(a) > 1e-12 else 1.0 + 0.5 * a
    return (b - a * x0_1) * g * math.exp(-a * n)
