#!/usr/bin/env python3
"""A camera path for a planet atlas: from ALTITUDE km above a point down to LOW metres above its
ground and back up, the height falling and rising geometrically, looking ahead along the surface
(north) with the local up radial. Writes the JSON that `gimlod render --path` and `gimlod view
--path` read.

  scripts/planet_flight.py --lon 85.3 --lat 28.2 --ground 3810 --frames 240 -o flight.json
  (the ground height: e.g. `gdallocationinfo -valonly -geoloc DEM LON LAT`)
"""
import argparse
import json
import math


def direction(lon, lat):
    lon, lat = math.radians(lon), math.radians(lat)
    return [math.cos(lat) * math.cos(lon), math.cos(lat) * math.sin(lon), math.sin(lat)]


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--lon", type=float, required=True)
    p.add_argument("--lat", type=float, required=True)
    p.add_argument("--ground", type=float, default=0.0, help="the ground's height there, metres")
    p.add_argument("--radius", type=float, default=6371008.8)
    p.add_argument("--altitude", type=float, default=20000.0, help="the highest, km above the ground")
    p.add_argument("--low", type=float, default=100.0, help="the lowest, metres above the ground")
    p.add_argument("--frames", type=int, default=240)
    p.add_argument("--fov", type=float, default=60.0)
    p.add_argument("-o", "--output", required=True)
    a = p.parse_args()
    if a.frames < 2 or not (a.low > 0 and a.altitude * 1000 > a.low):
        p.error("need 2 frames or more and 0 < low < altitude")
    half = (a.frames - 1) / 2.0
    frames = []
    for i in range(a.frames):
        t = abs(i - half) / half  # 1 at the ends, 0 at the bottom
        height = a.low * (a.altitude * 1000.0 / a.low) ** t
        # Look ahead: from straight at the planet high up to a few kilometres ahead low down.
        ahead = min(math.degrees(3.0 * height / a.radius), 30.0)
        up = direction(a.lon, a.lat)
        eye = [(a.radius + a.ground + height) * c for c in up]
        target = [(a.radius + a.ground) * c for c in direction(a.lon, min(a.lat + ahead, 89.9))]
        frames.append({"eye": eye, "target": target, "up": up, "fov_deg": a.fov})
    with open(a.output, "w") as f:
        json.dump({"frames": frames}, f, indent=1)


if __name__ == "__main__":
    main()
