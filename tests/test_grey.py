"""fdi.grey: GM(1,1) one-step prediction (Zhou & Zhang 2010, eq. 7-17), stable form."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest

from fdi.grey import gm11_fit, gm11_predict, gm11_predict_shifted, gm11_predict_shifted_enu

NORTHING_M = 3_512_345.678  # a UTM northing: large offset, tiny changes


def textbook_gm11(x0: list[float]) -> tuple[float, float, float]:
    """Reference: the paper's equations with NumPy float64, written the textbook way.

    (9) x¹ = cumsum x⁰; (11) z¹(k) = ½(x¹(k) + x¹(k−1)); (13) B = [−z¹, 1], Y = x⁰(2..n);
    (14) P = (BᵀB)⁻¹BᵀY = [a, b]; (15)-(16) x̂¹(k+1) = (x⁰(1) − b/a)e^{−ak} + b/a;
    (17) x̂⁰(n+1) = x̂¹(n+1) − x̂¹(n).  Returns (a, b, x̂⁰(n+1)).
    """
    x = np.asarray(x0, dtype=np.float64)
    n = len(x)
    x1 = np.cumsum(x)
    z = 0.5 * (x1[1:] + x1[:-1])
    B = np.column_stack([-z, np.ones(n - 1)])
    Y = x[1:]
    a, b = np.linalg.inv(B.T @ B) @ B.T @ Y

    def x1_hat(k: int) -> float:
        return float((x[0] - b / a) * np.exp(-a * k) + b / a)

    return float(a), float(b), x1_hat(n) - x1_hat(n - 1)


@pytest.mark.parametrize("r", [0.9, 0.98, 1.02, 1.1])
@pytest.mark.parametrize("n", [4, 6, 12])
def test_geometric_sequence(r: float, n: int) -> None:
    c = 5.0
    x0 = [c * r**k for k in range(1, n + 1)]
    # On x⁰(k) = c·rᵏ the grey equation (12) holds exactly with a = −2(r−1)/(r+1) and
    # b = 2cr/(r+1) (the trapezoid background values make e^{−a} ≈ r, not = r), so the
    # fit and the prediction have closed forms:
    a_exact = -2.0 * (r - 1.0) / (r + 1.0)
    b_exact = 2.0 * c * r / (r + 1.0)
    a, b = gm11_fit(x0)
    assert a == pytest.approx(a_exact, rel=1e-9)
    assert b == pytest.approx(b_exact, rel=1e-9)
    predicted = (b_exact - a_exact * x0[0]) * math.expm1(a_exact) / a_exact * math.exp(-a_exact * n)
    assert gm11_predict(x0) == pytest.approx(predicted, rel=1e-10)
    # ... and that is close to the true next term: within 0.2 % for |r − 1| ≤ 10 %.
    assert gm11_predict(x0) == pytest.approx(c * r ** (n + 1), rel=2e-3)


@pytest.mark.parametrize("value", [1e-3, 5.0, 100.0, NORTHING_M])
def test_constant_sequence_predicts_the_constant(value: float) -> None:
    x0 = [value] * 12
    a, _ = gm11_fit(x0)
    assert abs(a) < 1e-15  # a → 0: a rover standing still
    assert gm11_predict(x0) == pytest.approx(value, rel=1e-9, abs=0.0)
    assert gm11_predict_shifted(x0, 100.0) == pytest.approx(value, rel=1e-9, abs=0.0)


def test_textbook_form_fails_on_a_constant_sequence() -> None:
    # The reason for the stable form: with a ≈ 1e-16 the textbook b/a route loses everything.
    x0 = [5.0] * 8
    a, _, textbook = textbook_gm11(x0)
    assert abs(a) < 1e-12
    assert abs(textbook - 5.0) > 0.1  # it predicts 4.0 here (NumPy 2.x)
    assert gm11_predict(x0) == pytest.approx(5.0, rel=1e-9, abs=0.0)


@pytest.mark.parametrize("step_m", [-0.2, -0.1, 0.1, 0.2])  # 1-2 m/s at 10 Hz
@pytest.mark.parametrize("n", range(4, 13))
def test_straight_line_on_a_utm_northing_with_shift(step_m: float, n: int) -> None:
    values = [NORTHING_M + step_m * k for k in range(n)]
    expected = NORTHING_M + step_m * n  # the linear continuation
    assert abs(gm11_predict_shifted(values, 100.0) - expected) < 0.01  # 1 cm
    # The stable form does not even need the shift on a straight line (textbook: metres off).
    assert abs(gm11_predict(values) - expected) < 0.01


def test_agrees_with_textbook_equations_on_well_conditioned_data() -> None:
    rng = np.random.default_rng(20100601)
    for _ in range(200):
        n = int(rng.integers(4, 13))
        trend = rng.uniform(-0.1, 0.1)
        x0 = [float(v) for v in rng.uniform(2.0, 5.0, n) * np.exp(trend * np.arange(n))]
        a_ref, b_ref, pred_ref = textbook_gm11(x0)
        a, b = gm11_fit(x0)
        assert a == pytest.approx(a_ref, rel=1e-9)
        assert b == pytest.approx(b_ref, rel=1e-9)
        assert gm11_predict(x0) == pytest.approx(pred_ref, rel=1e-9)


def test_fit_needs_three_values() -> None:
    with pytest.raises(ValueError):
        gm11_fit([1.0, 2.0])


def test_enu_window_is_each_axis_bit_for_bit() -> None:
    """The three-axis pass gives exactly the per-axis floats (replay output byte-identical)."""
    rng = random.Random(7)
    for n in (3, 4, 12, 20):
        for _ in range(200):
            w = [(rng.uniform(-50, 50), rng.gauss(0, 0.3), rng.choice((0.0, rng.gauss(5, 1))))
                 for _ in range(n)]
            got = gm11_predict_shifted_enu(w, 100.0)
            want = tuple(gm11_predict_shifted([x[k] for x in w], 100.0) for k in range(3))
            assert got == want
