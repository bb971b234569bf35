"""WGS-84 geodetic <-> local east/north/up metres around a reference point.

Exact (closed-form ECEF with an iterative inverse), so a fix converted to ENU and back returns
the same degrees to well under a millimetre. Plain floats: this runs once per epoch.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

WGS84_A = 6378137.0
WGS84_F = 1.0 / 298.257223563
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)


def lla_to_ecef(lat_deg: float, lon_deg: float, h_m: float) -> tuple[float, float, float]:
    """WGS-84 latitude and longitude (deg) and ellipsoidal height (m) to ECEF x, y, z (m)."""
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    s, c = math.sin(lat), math.cos(lat)
    n = WGS84_A / math.sqrt(1.0 - WGS84_E2 * s * s)
    return (
        (n + h_m) * c * math.cos(lon),
        (n + h_m) * c * math.sin(lon),
        (n * (1 - WGS84_E2) + h_m) * s,
    )


def ecef_to_lla(x: float, y: float, z: float) -> tuple[float, float, float]:
    """ECEF x, y, z (m) to WGS-84 latitude, longitude (deg) and ellipsoidal height (m),
    by a fixed 8 iterations on the latitude."""
    lon = math.atan2(y, x)
    p = math.hypot(x, y)
    lat = math.atan2(z, p * (1.0 - WGS84_E2))
    h = 0.0
    for _ in range(8):
        s = math.sin(lat)
        n = WGS84_A / math.sqrt(1.0 - WGS84_E2 * s * s)
        h = p / math.cos(lat) - n if abs(lat) < math.radians(89.0) else z / s - n * (1 - WGS84_E2)
        new_lat = math.atan2(z, p * (1.0 - WGS84_E2 * n / (n + h)))
        if abs(new_lat - lat) < 1e-14:
            lat = new_lat
            break
        lat = new_lat
    return math.degrees(lat), math.degrees(lon), h


@dataclass(frozen=True)
class LocalFrame:
    """East/north/up metres around ``(lat0_deg, lon0_deg, h0_m)``."""

    lat0_deg: float
    lon0_deg: float
    h0_m: float = 0.0

    def __post_init__(self) -> None:
        lat, lon = math.radians(self.lat0_deg), math.radians(self.lon0_deg)
        sl, cl, so, co = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
        x0, y0, z0 = ecef0 = lla_to_ecef(self.lat0_deg, self.lon0_deg, self.h0_m)
        for name, value in (("_sl", sl), ("_cl", cl), ("_so", so), ("_co", co),
                            ("_ecef0", ecef0)):
            object.__setattr__(self, name, value)
        # to_enu's constants: the origin and the rotation's products that do not change
        # (the same products to_enu formed each call, so the same floats)
        k = (x0, y0, z0, -so, co, -sl * co, sl * so, cl, cl * co, cl * so, sl)
        object.__setattr__(self, "_enu_k", k)

    def to_enu(self, lat_deg: float, lon_deg: float, h_m: float) -> tuple[float, float, float]:
        # lla_to_ecef, written out (once an epoch): the same operations
        """Latitude, longitude (deg) and height (m) to east, north, up (m) from the origin."""
        lat, lon = math.radians(lat_deg), math.radians(lon_deg)
        s, c = math.sin(lat), math.cos(lat)
        nh = WGS84_A / math.sqrt(1.0 - WGS84_E2 * s * s)
        x = (nh + h_m) * c * math.cos(lon)
        y = (nh + h_m) * c * math.sin(lon)
        z = (nh * (1 - WGS84_E2) + h_m) * s
        k: tuple[float, ...] = self._enu_k  # type: ignore[attr-defined]
        x0, y0, z0, m_so, co, m_sl_co, sl_so, cl, cl_co, cl_so, sl = k
        dx, dy, dz = x - x0, y - y0, z - z0
        e = m_so * dx + co * dy  # -so * dx + co * dy
        n = m_sl_co * dx - sl_so * dy + cl * dz  # -sl * co * dx - sl * so * dy + cl * dz
        u = cl_co * dx + cl_so * dy + sl * dz  # cl * co * dx + cl * so * dy + sl * dz
        return e, n, u

    def to_lla(self, e: float, n: float, u: float) -> tuple[float, float, float]:
        """East, north, up (m) from the origin to latitude, longitude (deg) and height (m)."""
        sl, cl, so, co = self._sl, self._cl, self._so, self._co  # type: ignore[attr-defined]
        x0, y0, z0 = self._ecef0  # type: ignore[attr-defined]
        dx = -so * e - sl * co * n + cl * co * u
        dy = co * e - sl * so * n + cl * so * u
        dz = cl * n + sl * u
        return ecef_to_lla(x0 + dx, y0 + dy, z0 + dz)
