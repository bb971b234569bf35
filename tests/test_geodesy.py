"""fdi.geodesy: WGS-84 geodetic <-> ECEF <-> local east/north/up."""

from __future__ import annotations

import math
import random

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fdi.geodesy import WGS84_A, WGS84_E2, WGS84_F, LocalFrame, ecef_to_lla, lla_to_ecef

WGS84_B = WGS84_A * (1.0 - WGS84_F)  # 6356752.314245 m


def lon_diff(a: float, b: float) -> float:
    """Smallest difference between two longitudes, degrees."""
    return abs((a - b + 180.0) % 360.0 - 180.0)


@pytest.mark.parametrize(
    ("lla", "xyz"),
    [
        ((0.0, 0.0, 0.0), (WGS84_A, 0.0, 0.0)),
        ((0.0, 90.0, 0.0), (0.0, WGS84_A, 0.0)),
        ((0.0, 180.0, 0.0), (-WGS84_A, 0.0, 0.0)),
        ((0.0, -90.0, 100.0), (0.0, -(WGS84_A + 100.0), 0.0)),
        ((90.0, 0.0, 0.0), (0.0, 0.0, WGS84_B)),
        ((-90.0, 0.0, 10.0), (0.0, 0.0, -(WGS84_B + 10.0))),
    ],
)
def test_ecef_of_known_points(lla: tuple[float, float, float], xyz: tuple[float, ...]) -> None:
    got = lla_to_ecef(*lla)
    for g, e in zip(got, xyz, strict=True):
        assert g == pytest.approx(e, abs=1e-6)  # 1 µm (sin/cos of 90° are not exact zeros)
    assert abs(WGS84_B - 6356752.314245) < 1e-6


def test_ecef_back_to_lla_at_known_points() -> None:
    lat, lon, h = ecef_to_lla(WGS84_A + 50.0, 0.0, 0.0)
    assert (lat, lon) == (0.0, 0.0)
    assert h == pytest.approx(50.0, abs=1e-6)
    lat, lon, h = ecef_to_lla(0.0, 0.0, WGS84_B + 5.0)  # the pole (the |lat| > 89° branch)
    assert lat == pytest.approx(90.0, abs=1e-12)
    assert h == pytest.approx(5.0, abs=1e-6)


def test_ecef_of_a_mid_latitude_point_matches_the_formula() -> None:
    # 45° N, 45° E, h = 0: N = a / sqrt(1 − e² sin²φ); x = y = N cos²45°, z = N(1 − e²) sin 45°.
    n = WGS84_A / math.sqrt(1.0 - WGS84_E2 * 0.5)
    x, y, z = lla_to_ecef(45.0, 45.0, 0.0)
    assert x == pytest.approx(n * 0.5, abs=1e-6)
    assert y == pytest.approx(n * 0.5, abs=1e-6)
    assert z == pytest.approx(n * (1.0 - WGS84_E2) * math.sqrt(0.5), abs=1e-6)
    assert x == pytest.approx(3194419.145, abs=1e-3)  # N(45°) = 6388838.29 m


def test_one_arc_minute_north_is_a_nautical_mile() -> None:
    frame = LocalFrame(45.0, 10.0, 0.0)
    e, n, u = frame.to_enu(45.0 + 1.0 / 60.0, 10.0, 0.0)
    assert n == pytest.approx(1852.0, rel=0.005)
    # Sharper: the meridian radius of curvature M = a(1 − e²)/(1 − e² sin²φ)^1.5 at the midpoint.
    phi = math.radians(45.0 + 0.5 / 60.0)
    m = WGS84_A * (1.0 - WGS84_E2) / (1.0 - WGS84_E2 * math.sin(phi) ** 2) ** 1.5
    assert n == pytest.approx(m * math.radians(1.0 / 60.0), rel=1e-6)
    assert abs(e) < 1e-6
    assert u == pytest.approx(-(n**2) / (2.0 * 6.37e6), rel=0.01)  # the Earth curves away


def test_the_origin_is_zero() -> None:
    frame = LocalFrame(32.0206, 118.8, 12.0)
    assert frame.to_enu(32.0206, 118.8, 12.0) == pytest.approx((0.0, 0.0, 0.0), abs=1e-9)
    assert frame.to_lla(0.0, 0.0, 0.0) == pytest.approx((32.0206, 118.8, 12.0), abs=1e-9)


@settings(max_examples=300, deadline=None, derandomize=True, database=None)
@given(
    lat0=st.floats(-80.0, 80.0),
    lon0=st.floats(-180.0, 180.0),
    h0=st.floats(-100.0, 3000.0),
    east=st.floats(-7000.0, 7000.0),
    north=st.floats(-7000.0, 7000.0),
    up=st.floats(-500.0, 500.0),
)
def test_round_trip_within_10_km(
    lat0: float, lon0: float, h0: float, east: float, north: float, up: float
) -> None:
    frame = LocalFrame(lat0, lon0, h0)
    # ENU -> LLA -> ENU
    lat, lon, h = frame.to_lla(east, north, up)
    assert abs(lat - lat0) < 0.1  # it is a nearby point (10 km is 0.09° of latitude)
    e, n, u = frame.to_enu(lat, lon, h)
    assert abs(e - east) < 1e-6
    assert abs(n - north) < 1e-6
    assert abs(u - up) < 1e-6
    # LLA -> ENU -> LLA
    lat2, lon2, h2 = frame.to_lla(*frame.to_enu(lat, lon, h))
    assert abs(lat2 - lat) < 1e-9
    assert lon_diff(lon2, lon) < 1e-9
    assert abs(h2 - h) < 1e-6


@settings(max_examples=200, deadline=None, derandomize=True, database=None)
@given(
    lat0=st.floats(80.0, 89.9),
    south=st.booleans(),
    lon0=st.floats(-180.0, 180.0),
    east=st.floats(-7000.0, 7000.0),
    north=st.floats(-7000.0, 7000.0),
    up=st.floats(-500.0, 500.0),
)
def test_round_trip_near_the_poles(
    lat0: float, south: bool, lon0: float, east: float, north: float, up: float
) -> None:
    # 1/cos(lat) in the height formula costs precision up to the 89° branch switch: measured
    # 3.3 µm at 88.9°, so 10 µm here (the module promises "well under a millimetre").
    frame = LocalFrame(-lat0 if south else lat0, lon0, 0.0)
    e, n, u = frame.to_enu(*frame.to_lla(east, north, up))
    assert math.dist((e, n, u), (east, north, up)) < 1e-5


def test_to_enu_is_the_rotation_of_the_ecef_difference_bit_for_bit() -> None:
    """to_enu's precomputed rotation gives the floats the plain formula gives (issue 19:
    the same floats, not just close ones)."""
    rng = random.Random(19)
    for _ in range(2000):
        lat0, lon0, h0 = rng.uniform(-89, 89), rng.uniform(-180, 180), rng.uniform(-100, 3000)
        f = LocalFrame(lat0, lon0, h0)
        lat, lon = lat0 + rng.uniform(-0.1, 0.1), lon0 + rng.uniform(-0.1, 0.1)
        h = h0 + rng.uniform(-50, 50)
        x, y, z = lla_to_ecef(lat, lon, h)
        x0, y0, z0 = lla_to_ecef(lat0, lon0, h0)
        sl, cl = math.sin(math.radians(lat0)), math.cos(math.radians(lat0))
        so, co = math.sin(math.radians(lon0)), math.cos(math.radians(lon0))
        dx, dy, dz = x - x0, y - y0, z - z0
        assert f.to_enu(lat, lon, h) == (
            -so * dx + co * dy,
            -sl * co * dx - sl * so * dy + cl * dz,
            cl * co * dx + cl * so * dy + sl * dz,
        )
