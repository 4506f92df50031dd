"""Flat-earth conversion between a local north-east offset and latitude/longitude, in one place.

The SITL reports its position around its home with these (GLOBAL_POSITION_INT, GPS_RAW_INT), flies
uploaded waypoints with their inverse, and the log's map track (``foxglove.LocationFix``) uses them
where only a local position is known.  An equirectangular projection about the reference point:
exact enough for the few hundred metres a quadrotor flies from home (error below 1 mm at 1 km).
"""

from __future__ import annotations

import math

__all__ = ["EARTH_RADIUS_M", "geodetic_from_local", "local_from_geodetic"]

EARTH_RADIUS_M = 6378137.0  # WGS-84 equatorial radius


def geodetic_from_local(ref_lat_deg: float, ref_lon_deg: float, north_m: float, east_m: float) -> tuple[float, float]:
    """Latitude and longitude [deg] of the point ``north_m``/``east_m`` from the reference point."""
    lat = ref_lat_deg + math.degrees(north_m / EARTH_RADIUS_M)
    lon = ref_lon_deg + math.degrees(east_m / (EARTH_RADIUS_M * math.cos(math.radians(ref_lat_deg))))
    return lat, lon


def local_from_geodetic(ref_lat_deg: float, ref_lon_deg: float, lat_deg: float, lon_deg: float) -> tuple[float, float]:
    """North and east offsets [m] of ``lat_deg``/``lon_deg`` from the reference point (inverse of the above)."""
    north = math.radians(lat_deg - ref_lat_deg) * EARTH_RADIUS_M
    east = math.radians(lon_deg - ref_lon_deg) * EARTH_RADIUS_M * math.cos(math.radians(ref_lat_deg))
    return north, east
