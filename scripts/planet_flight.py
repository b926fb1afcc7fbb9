#!/usr/bin/env python3
"""A camera path for a planet atlas: from ALTITUDE km above a point down to LOW metres above its
ground and back up, the height falling and rising geometrically, looking ahead along the surface
(north) with the local up radial. Writes the JSON that `gimlod render --path` and `gimlod view
--path` read.

  scripts/planet_flight.py --lon 85.3 --lat 28.2 --ground 3810 --frames 240 -o flight.json
  (the ground height: e.g. `gdallocationinfo -valonly -geoloc DEM LON LAT`)

For an atlas built with `--ellipsoid WGS84`, pass `--ellipsoid WGS84` here too: the path then
follows the ellipsoid's normal at the point (geodetic latitude), as the atlas places it.
"""
import argparse
import json
import math


# Equatorial radius and flattening, as core/planet.h's kEllipsoids.
ELLIPSOIDS = {"WGS84": (6378137.0, 1.0 / 298.257223563), "GRS80": (6378137.0, 1.0 / 298.257222101)}


def direction(lon, lat):
    lon, lat = math.radians(lon), math.radians(lat)
    return [math.cos(lat) * math.cos(lon), math.cos(lat) * math.sin(lon), math.sin(lat)]


def position(radius, flattening, lon, lat, h):
    """The planet-centred position of (lon, lat) at height h along the surface's normal."""
    e2 = flattening * (2.0 - flattening)
    n = radius / math.sqrt(1.0 - e2 * math.sin(math.radians(lat)) ** 2)
    d = direction(lon, lat)
    return [(n + h) * d[0], (n + h) * d[1], (n * (1.0 - e2) + h) * d[2]]


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--lon", type=float, required=True)
    p.add_argument("--lat", type=float, required=True)
    p.add_argument("--ground", type=float, default=0.0, help="the ground's height there, metres")
    p.add_argument("--radius", type=float, default=6371008.8, help="the sphere's radius, metres")
    p.add_argument("--ellipsoid", choices=sorted(ELLIPSOIDS), help="the atlas's ellipsoid, instead of a sphere")
    p.add_argument("--altitude", type=float, default=20000.0, help="the highest, km above the ground")
    p.add_argument("--low", type=float, default=100.0, help="the lowest, metres above the ground")
    p.add_argument("--frames", type=int, default=240)
    p.add_argument("--fov", type=float, default=60.0)
    p.add_argument("-o", "--output", required=True)
    a = p.parse_args()
    if a.frames < 2 or not (a.low > 0 and a.altitude * 1000 > a.low):
        p.error("need 2 frames or more and 0 < low < altitude")
    radius, flattening = ELLIPSOIDS[a.ellipsoid] if a.ellipsoid else (a.radius, 0.0)
    half = (a.frames - 1) / 2.0
    frames = []
    for i in range(a.frames):
        t = abs(i - half) / half  # 1 at the ends, 0 at the bottom
        height = a.low * (a.altitude * 1000.0 / a.low) ** t
        # Look ahead: from straight at the planet high up to a few kilometres ahead low down.
        ahead = min(math.degrees(3.0 * height / radius), 30.0)
        up = direction(a.lon, a.lat)
        eye = position(radius, flattening, a.lon, a.lat, a.ground + height)
        target = position(radius, flattening, a.lon, min(a.lat + ahead, 89.9), a.ground)
        frames.append({"eye": eye, "target": target, "up": up, "fov_deg": a.fov})
    with open(a.output, "w") as f:
        json.dump({"frames": frames}, f, indent=1)


if __name__ == "__main__":
    main()
