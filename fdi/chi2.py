"""Chi-square quantiles, computed (not typed in), with no SciPy at run time.

``chi2_ppf(p, dof)`` inverts the chi-square CDF ``P(dof/2, x/2)`` (the regularized lower
incomplete gamma function, Numerical Recipes 6.2: series below ``a + 1``, continued fraction
above) by bracketing bisection refined with Newton steps. Accurate to ~1e-10 relative, which is
far below what any gate needs: ``chi2_ppf(0.95, 3) = 7.8147`` (the rover paper's 7.815),
``chi2_ppf(0.90, 1) = 2.7055`` and ``chi2_ppf(0.99, 1) = 6.6349`` (the three-zone paper's
2.706 and 6.635).
"""

from __future__ import annotations

import math
from functools import lru_cache

_EPS = 1e-15
_TINY = 1e-300


def _gammainc_lower(a: float, x: float) -> float:
    """Regularized lower incomplete gamma P(a, x)."""
    if x <= 0.0:
        return 0.0
    gln = math.lgamma(a)
    if x < a + 1.0:
        ap, total, term = a, 1.0 / a, 1.0 / a
        for _ in range(10_000):
            ap += 1.0
            term *= x / ap
            total += term
            if abs(term) < abs(total) * _EPS:
                break
        return total * math.exp(-x + a * math.log(x) - gln)
    # Continued fraction for Q(a, x) (modified Lentz).
    b = x + 1.0 - a
    c = 1.0 / _TINY
    d = 1.0 / b
    h = d
    for i in range(1, 10_000):
        an = -i * (i - a)
        b += 2.0
        d = an * d + b
        d = _TINY if abs(d) < _TINY else d
        c = b + an / c
        c = _TINY if abs(c) < _TINY else c
        d = 1.0 / d
        delta = d * c
        h *= delta
        if abs(delta - 1.0) < _EPS:
            break
    return 1.0 - math.exp(-x + a * math.log(x) - gln) * h


def chi2_cdf(x: float, dof: int) -> float:
    """P{χ²(dof) ≤ x}."""
    if dof <= 0:
        raise ValueError("dof must be positive")
    return _gammainc_lower(dof / 2.0, x / 2.0)


@lru_cache(maxsize=256)
def chi2_ppf(p: float, dof: int) -> float:
    """The ``p`` quantile of χ²(dof): the x with P{χ²(dof) ≤ x} = p (0 < p < 1)."""
    if not 0.0 < p < 1.0:
        raise ValueError("p must be in (0, 1)")
    if dof <= 0:
        raise ValueError("dof must be positive")
    lo, hi = 0.0, max(1.0, float(dof))
    while chi2_cdf(hi, dof) < p:
        hi *= 2.0
    x = 0.5 * (lo + hi)
    for _ in range(200):
        f = chi2_cdf(x, dof) - p
        if f > 0:
            hi = x
        else:
            lo = x
        # Newton step with the chi-square density; fall back to bisection outside the bracket.
        k = dof / 2.0
        log_pdf = (k - 1.0) * math.log(x) - x / 2.0 - k * math.log(2.0) - math.lgamma(k)
        pdf = math.exp(log_pdf) if x > 0 else 0.0
        nx = x - f / pdf if pdf > 0 else 0.5 * (lo + hi)
        if not lo < nx < hi:
            nx = 0.5 * (lo + hi)
        if abs(nx - x) <= 1e-13 * x:  # relative: lower-tail quantiles can be tiny
            return nx
        x = nx
    return x


def threshold(alpha: float, dof: int) -> float:
    """Detection threshold T_d with P{F > T_d} = alpha (Zhou & Zhang eq. 6)."""
    return chi2_ppf(1.0 - alpha, dof)
