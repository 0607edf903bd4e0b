"""Latitude/longitude to a local metric frame: the east-north tangent plane at an origin (WGS 84).

A point is taken to the Earth-centred frame on the WGS 84 ellipsoid (height 0) and projected onto
the plane that touches the ellipsoid at the origin: `east_m` along the origin's parallel, `north_m`
along its meridian. Over a building (< 1 km) the plane's distortion is below 1 mm; near the origin
one degree of latitude is M(lat) * pi / 180 metres (M the meridian's radius of curvature, 110.57 km
per degree at the equator, 111.13 km at 45 deg; a sphere of 6371 km gives 111.19 km everywhere)
and one degree of longitude N(lat) * cos(lat) * pi / 180 (N the prime vertical's radius).
Heights are ignored: a floor's height changes east/north by far less than a millimetre.
"""

from __future__ import annotations

import math

import numpy as np

from protocol.errors import InputError

WGS84_A_M = 6_378_137.0  # semi-major axis
WGS84_F = 1.0 / 298.257223563  # flattening
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)  # first eccentricity squared


def _ecef_m(latitude_deg: np.ndarray, longitude_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    latitude, longitude = np.radians(latitude_deg), np.radians(longitude_deg)
    prime_vertical_m = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * np.sin(latitude) ** 2)
    return (prime_vertical_m * np.cos(latitude) * np.cos(longitude),
            prime_vertical_m * np.cos(latitude) * np.sin(longitude),
            prime_vertical_m * (1.0 - WGS84_E2) * np.sin(latitude))


def east_north_m(latitude_deg: np.ndarray | float, longitude_deg: np.ndarray | float, origin_latitude_deg: float,
                 origin_longitude_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """(east, north) in metres of each point on the tangent plane at the origin (degrees in, WGS 84)."""
    x, y, z = _ecef_m(np.asarray(latitude_deg, dtype=float), np.asarray(longitude_deg, dtype=float))
    x0, y0, z0 = _ecef_m(np.asarray(origin_latitude_deg, dtype=float), np.asarray(origin_longitude_deg, dtype=float))
    dx, dy, dz = x - x0, y - y0, z - z0
    latitude, longitude = math.radians(origin_latitude_deg), math.radians(origin_longitude_deg)
    east = -math.sin(longitude) * dx + math.cos(longitude) * dy
    north = (-math.sin(latitude) * math.cos(longitude) * dx - math.sin(latitude) * math.sin(longitude) * dy
             + math.cos(latitude) * dz)
    return east, north


def check_lat_lon(latitude_deg: float, longitude_deg: float, where: str) -> tuple[float, float]:
    """The pair if it is a finite latitude in [-90, 90] and longitude in [-180, 180]; else InputError."""
    if not (math.isfinite(latitude_deg) and math.isfinite(longitude_deg)
            and -90.0 <= latitude_deg <= 90.0 and -180.0 <= longitude_deg <= 180.0):
        raise InputError(f"{where}: ({latitude_deg}, {longitude_deg}) is not a latitude in [-90, 90] and a "
                         "longitude in [-180, 180] (degrees)")
    return latitude_deg, longitude_deg


def parse_lat_lon(text: str, where: str) -> tuple[float, float]:
    """'LAT,LON' in decimal degrees (e.g. '40.4722,-3.3924'); InputError naming `where` otherwise."""
    parts = text.split(",")
    try:
        if len(parts) != 2:
            raise ValueError
        latitude_deg, longitude_deg = float(parts[0]), float(parts[1])
    except ValueError:
        raise InputError(f"{where}: {text!r} is not LAT,LON in decimal degrees (e.g. 40.4722,-3.3924)") from None
    return check_lat_lon(latitude_deg, longitude_deg, where)
