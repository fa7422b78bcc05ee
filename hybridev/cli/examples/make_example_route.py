"""Write ``example_route.gpx``: a synthetic 62 km route over a pass, for ``hybridev route``.

Run from the repository root (deterministic; rewrites the file next to this script)::

    python hybridev/cli/examples/make_example_route.py

The route is invented, not surveyed: a town start (50 km/h), a rural road (100 km/h),
a climb of about 700 m to a pass at 80 km/h (grades up to about 6 %), the descent, a
rural stretch and a town finish. Points every ~200 m carry latitude, longitude and
elevation (``<ele>``, m) and, as a GPX extension element ``speed_limit_kmh``, the speed
limit from that point on. No times: a planned route.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

OUT = Path(__file__).resolve().parent / "example_route.gpx"
SEED = 31
STEP_KM = 0.2
# (end km, speed limit km/h, elevation at the end m): the stretches in order
STRETCHES = ((6.0, 50, 560.0), (20.0, 100, 610.0), (33.0, 80, 1290.0), (45.0, 80, 720.0),
             (58.0, 100, 640.0), (62.0, 50, 600.0))
START = (47.262, 11.394, 575.0)  # lat, lon (degrees), elevation (m)
M_PER_DEG_LAT = 111_195.0


def route_points() -> list[tuple[float, float, float, int]]:
    """(lat, lon, elevation_m, speed_limit_kmh) every STEP_KM along the stretches."""
    rng = np.random.default_rng(SEED)
    d = np.arange(0.0, STRETCHES[-1][0] + 1e-9, STEP_KM)
    ends = np.array([0.0, *(s[0] for s in STRETCHES)])
    elev_knots = np.array([START[2], *(s[2] for s in STRETCHES)])
    # smooth profile through the stretch ends, plus gentle bumps on the flat stretches
    elev = np.interp(d, ends, elev_knots) + 8.0 * np.sin(d / 1.7) * (np.abs(np.gradient(
        np.interp(d, ends, elev_knots), d)) < 20.0)
    elev += np.convolve(rng.normal(0.0, 1.0, d.size), np.ones(5) / 5.0, mode="same")
    limit = np.array([next(s[1] for s in STRETCHES if x <= s[0] + 1e-9) for x in d])
    # heading wanders: switchbacks on the climb and the descent
    heading = np.cumsum(rng.normal(0.0, 0.08, d.size)) + 0.6
    climb = (d > 20.0) & (d < 45.0)
    heading[climb] += 0.9 * np.sign(np.sin(d[climb] * 1.3))
    step_m = STEP_KM * 1000.0
    north = np.cumsum(np.r_[0.0, step_m * np.cos(heading[1:])])
    east = np.cumsum(np.r_[0.0, step_m * np.sin(heading[1:])])
    lat = START[0] + north / M_PER_DEG_LAT
    lon = START[1] + east / (M_PER_DEG_LAT * np.cos(np.radians(START[0])))
    return list(zip(lat.tolist(), lon.tolist(), elev.tolist(), limit.tolist(), strict=True))


def gpx_text(points) -> str:
    pts = "\n".join(
        f'      <trkpt lat="{la:.6f}" lon="{lo:.6f}"><ele>{el:.1f}</ele>'
        f"<extensions><hev:speed_limit_kmh>{lim:d}</hev:speed_limit_kmh></extensions></trkpt>"
        for la, lo, el, lim in points)
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<gpx version="1.1" creator="hybridev make_example_route.py"
     xmlns="http://www.topografix.com/GPX/1/1"
     xmlns:hev="https://hybridev.invalid/gpx/1">
  <metadata><name>hybridev example route: over the pass (synthetic)</name></metadata>
  <trk>
    <name>example route</name>
    <trkseg>
{pts}
    </trkseg>
  </trk>
</gpx>
"""


def main() -> int:
    OUT.write_text(gpx_text(route_points()), encoding="utf-8")
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
