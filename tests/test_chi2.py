"""fdi.chi2: computed chi-square quantiles against the published table, closed forms and SciPy."""

from __future__ import annotations

import math

import pytest

from fdi.chi2 import chi2_cdf, chi2_ppf, threshold

# shared/FINDINGS.md, "Three-zone chi-square": quantiles at 0.90 / 0.95 / 0.99.
TABLE = {
    1: (2.7055, 3.8415, 6.6349),
    2: (4.6052, 5.9915, 9.2103),
    3: (6.2514, 7.8147, 11.3449),
}
PS = (0.001, 0.01, 0.05, 0.1, 0.5, 0.9, 0.95, 0.99, 0.999, 0.999999)


@pytest.mark.parametrize("dof", sorted(TABLE))
def test_quantiles_match_the_table(dof: int) -> None:
    for p, expected in zip((0.90, 0.95, 0.99), TABLE[dof], strict=True):
        assert abs(chi2_ppf(p, dof) - expected) < 1e-4, (p, dof)


def test_threshold_is_the_upper_tail_quantile() -> None:
    assert round(threshold(0.05, 3), 3) == 7.815  # the rover paper's T_d
    assert round(threshold(0.10, 1), 3) == 2.706  # the three-zone paper's
    assert round(threshold(0.01, 1), 3) == 6.635
    assert threshold(0.05, 3) == chi2_ppf(0.95, 3)


@pytest.mark.parametrize("dof", range(1, 21))
def test_cdf_inverts_ppf(dof: int) -> None:
    for p in PS:
        x = chi2_ppf(p, dof)
        assert x > 0.0
        assert abs(chi2_cdf(x, dof) - p) < 1e-9, (p, dof, x)


def test_closed_forms() -> None:
    # dof 2: P = 1 - exp(-x/2), so ppf = -2 ln(1 - p).  dof 1: P = erf(sqrt(x/2)).
    for p in PS:
        assert chi2_ppf(p, 2) == pytest.approx(-2.0 * math.log1p(-p), rel=1e-10)
    for x in (1e-6, 0.1, 1.0, 3.8415, 10.0, 30.0):
        assert chi2_cdf(x, 1) == pytest.approx(math.erf(math.sqrt(x / 2.0)), rel=1e-12, abs=1e-15)
        # dof 4: P = 1 - exp(-x/2) (1 + x/2); exercises both the series and the fraction
        expected = -math.expm1(-x / 2.0) - math.exp(-x / 2.0) * x / 2.0
        assert chi2_cdf(x, 4) == pytest.approx(expected, rel=1e-10, abs=1e-15)


def test_cdf_edges_and_argument_checks() -> None:
    assert chi2_cdf(0.0, 3) == 0.0
    assert chi2_cdf(-1.0, 3) == 0.0
    assert chi2_cdf(1e4, 3) == pytest.approx(1.0, abs=1e-15)
    xs = [0.5 * k for k in range(1, 60)]
    values = [chi2_cdf(x, 5) for x in xs]
    assert values == sorted(values)  # monotone across the series/fraction switch at x = a + 1
    for bad_p in (0.0, 1.0, -0.1, 1.5):
        with pytest.raises(ValueError):
            chi2_ppf(bad_p, 3)
    with pytest.raises(ValueError):
        chi2_ppf(0.5, 0)
    with pytest.raises(ValueError):
        chi2_cdf(1.0, 0)


def test_agrees_with_scipy() -> None:
    stats = pytest.importorskip("scipy.stats", reason="SciPy not installed: oracle unavailable")
    for dof in range(1, 21):
        for p in PS:
            expected = float(stats.chi2.ppf(p, dof))
            assert chi2_ppf(p, dof) == pytest.approx(expected, rel=1e-8), (p, dof)


@pytest.mark.parametrize("p", [1e-6, 1e-9])
def test_small_lower_quantiles_of_one_dof_are_relatively_accurate(p: float) -> None:
    # For 1 dof, P(x) = erf(sqrt(x/2)) = sqrt(2x/π)(1 − x/6 + …), so x = π p²/2 (1 + O(p²)).
    assert chi2_ppf(p, 1) == pytest.approx(math.pi / 2.0 * p * p, rel=1e-6, abs=0.0)
