#!/usr/bin/env python3
"""Reference values from pyproj for insgen's CRS layer and geoid tests (tests/it/geo_pyproj.rs).

Reads one JSON request on stdin, writes one JSON answer on stdout (one process for all codes):

request  = {
  "seed": 20240601,              # points are drawn from random.Random(f"{seed}:{code}")
  "n_points": 100,               # per CRS
  "codes": [4326, 6697, ...],    # EPSG codes
  "extra_data_dirs": ["/usr/share/proj"],  # appended to pyproj's data dirs (same grids as insgen's PROJ)
  "geoid": {"grid": "/usr/share/proj/egm96_15.gtx", "points": [[lat, lon], ...]},  # optional
  "geoids": [{"grid": "target/geoid/synthetic.tif", "points": [[lat, lon], ...]}, ...],  # optional, several
  "compound": {"code": 6697, "points": [[lon_or_e, lat_or_n, H], ...]}   # optional: PROJ's own heights
}
answer   = {
  "pyproj_version": "3.7.2", "proj_version": "9.5.1",
  "crs": [{
     "code": 6697, "name": ..., "type": "compound|geographic2d|...", "horizontal_code": 6668,
     "area_of_use": [w, s, e, n],
     "height_factor": 1.0,       # metres per unit of the third coordinate (as insgen's rule)
     "operations": {"<description>": count, ...},   # operation pyproj used, per point
     "points": [{
        "authority": [a, b, h],   # source coordinates in the CRS's authority axis order
        "east_north": [x, y, h],  # the same point, easting/longitude first
        "lat_deg": ..., "lon_deg": ..., "h_m": ...,   # pyproj's WGS 84 (EPSG:4326) result, h passed through
        "ecef_m": [X, Y, Z]       # pyproj: (lat, lon, h) through EPSG:4979 -> EPSG:4978
     }, ...]
  }, ...],
  "geoid": {"undulation_m": [...]},  # PROJ vgridshift +multiplier=1 at the given points
  "geoids": [{"undulation_m": [...]}, ...],   # the same, per grid
  "compound": {"operation": "...", "grids": ["jp_gsi_gsigeo2011.tif"],
               "points": [{"lat_deg", "lon_deg", "h_m", "ecef_m": [X, Y, Z]}, ...]}
               # Transformer.from_crs(code, EPSG:4979, always_xy=True): PROJ's own vertical
               # transformation (a geoid grid when installed in the data directories), then 4979 -> 4978
}

How points are made: latitude/longitude uniformly inside the CRS's area of use (inset by 2 % of its
size), height uniform in [-100, 4000] m, projected to the source CRS with pyproj (always_xy for the
east/north form, authority order for the other). The reference WGS 84 position is then computed
*from the source coordinates* (source -> EPSG:4326, always_xy=True), the same direction insgen goes.
Compound CRSs: the horizontal sub-CRS is used and the height passes through (converted to metres
by the vertical axis unit); geocentric CRSs go EPSG:4979 <-> source in 3D.
"""

import json
import math
import random
import sys

import pyproj
from pyproj import CRS, Transformer
from pyproj.enums import PJType


def horizontal_part(crs):
    """(horizontal CRS, metres per height unit, kind) per insgen's rule."""
    if crs.is_compound:
        h, v = crs.sub_crs_list[0], crs.sub_crs_list[1]
        return h, v.axis_info[0].unit_conversion_factor, "compound"
    if crs.type_name.startswith("Geocentric") or crs.is_geocentric:
        return crs, crs.axis_info[0].unit_conversion_factor, "geocentric"
    if crs.is_geographic:
        if len(crs.axis_info) == 3:
            return crs, crs.axis_info[2].unit_conversion_factor, "geographic3d"
        return crs, 1.0, "geographic2d"
    if crs.is_projected:
        if len(crs.axis_info) == 3:
            return crs, crs.axis_info[2].unit_conversion_factor, "projected3d"
        return crs, crs.axis_info[0].unit_conversion_factor, "projected2d"
    raise ValueError(f"EPSG:{crs.to_epsg()} is {crs.type_name}")


def last_operation(t):
    """Description of the operation a transformer used for its last point."""
    try:
        return t.get_last_used_operation().description
    except Exception:  # a single operation (no alternatives): PROJ keeps no "last used" one
        return t.description


def area_of(crs):
    a = crs.area_of_use
    if a is None:
        return [-180.0, -90.0, 180.0, 90.0]
    return [a.west, a.south, a.east, a.north]


def sample_lat_lon(rng, area):
    w, s, e, n = area
    if e < w:  # crosses the antimeridian
        e += 360.0
    dx, dy = (e - w) * 0.02, (n - s) * 0.02
    lon = rng.uniform(w + dx, e - dx)
    if lon > 180.0:
        lon -= 360.0
    lat = rng.uniform(s + dy, n - dy)
    return lat, lon


def crs_entry(code, seed, n_points):
    crs = CRS.from_epsg(code)
    hcrs, height_factor, kind = horizontal_part(crs)
    area = area_of(crs)
    rng = random.Random(f"{seed}:{code}")
    to_ecef = Transformer.from_crs(4979, 4978, always_xy=True)
    points = []
    ops = {}
    if kind == "geocentric":
        fwd = Transformer.from_crs(4979, crs, always_xy=True)
        inv = Transformer.from_crs(crs, 4979, always_xy=True)
        for _ in range(n_points):
            lat, lon = sample_lat_lon(rng, area)
            h = rng.uniform(-100.0, 4000.0)
            x, y, z = fwd.transform(lon, lat, h)
            lon2, lat2, h2 = inv.transform(x, y, z)
            ops[inv.description] = ops.get(inv.description, 0) + 1
            ex, ey, ez = to_ecef.transform(lon2, lat2, h2)
            points.append(dict(authority=[x, y, z], east_north=[x, y, z], lat_deg=lat2, lon_deg=lon2,
                               h_m=h2, ecef_m=[ex, ey, ez]))
    else:
        fwd_xy = Transformer.from_crs(4326, hcrs, always_xy=True)
        fwd_auth = Transformer.from_crs(4326, hcrs, always_xy=False)
        inv = Transformer.from_crs(hcrs, 4326, always_xy=True)
        # Same operation list seen from the authority-order side (for the consistency check below).
        inv_auth = Transformer.from_crs(hcrs, 4326, always_xy=False)
        for _ in range(n_points):
            lat, lon = sample_lat_lon(rng, area)
            h_units = rng.uniform(-100.0, 4000.0) / height_factor
            x, y = fwd_xy.transform(lon, lat)
            a, b = fwd_auth.transform(lat, lon)  # 4326 authority input is (lat, lon)
            lon2, lat2 = inv.transform(x, y)
            lat3, lon3 = inv_auth.transform(a, b)
            if not (math.isclose(lat2, lat3, abs_tol=1e-9) and math.isclose(lon2, lon3, abs_tol=1e-9)):
                raise RuntimeError(f"EPSG:{code}: pyproj's two axis orders disagree at {(a, b)}")
            desc = last_operation(inv)
            ops[desc] = ops.get(desc, 0) + 1
            h_m = h_units * height_factor
            ex, ey, ez = to_ecef.transform(lon2, lat2, h_m)
            points.append(dict(authority=[a, b, h_units], east_north=[x, y, h_units], lat_deg=lat2,
                               lon_deg=lon2, h_m=h_m, ecef_m=[ex, ey, ez]))
    hcode = hcrs.to_epsg(min_confidence=100)
    return dict(code=code, name=crs.name, type=kind, horizontal_code=hcode, area_of_use=area,
                height_factor=height_factor, operations=ops, points=points)


def geoid_entry(req):
    grid = req["grid"]
    t = Transformer.from_pipeline(f"+proj=vgridshift +grids={grid} +multiplier=1")
    out = []
    for lat, lon in req["points"]:
        _, _, n = t.transform(lon, lat, 0.0)
        out.append(n)
    return dict(undulation_m=out, description=t.description)


def compound_entry(req):
    t = Transformer.from_crs(req["code"], 4979, always_xy=True)
    to_ecef = Transformer.from_crs(4979, 4978, always_xy=True)
    points = []
    for x, y, h in req["points"]:
        lon, lat, hh = t.transform(x, y, h)
        ex, ey, ez = to_ecef.transform(lon, lat, hh)
        points.append(dict(lat_deg=lat, lon_deg=lon, h_m=hh, ecef_m=[ex, ey, ez]))
    try:
        op = t.get_last_used_operation()
    except Exception:  # a single operation: PROJ keeps no "last used" one
        op = t
    # The grids the operation's PROJ pipeline opens (+grids=… of vgridshift/hgridshift steps).
    grids = [g for step in op.definition.split() if step.startswith("grids=") for g in step[6:].split(",")]
    description = op.description
    return dict(operation=description, grids=grids, points=points)


def main():
    req = json.load(sys.stdin)
    pyproj.network.set_network_enabled(False)
    for d in req.get("extra_data_dirs", []):
        pyproj.datadir.append_data_dir(d)
    seed = req.get("seed", 1)
    n = req.get("n_points", 100)
    out = dict(pyproj_version=pyproj.__version__, proj_version=pyproj.proj_version_str,
               crs=[crs_entry(c, seed, n) for c in req.get("codes", [])])
    if req.get("geoid"):
        out["geoid"] = geoid_entry(req["geoid"])
    out["geoids"] = [geoid_entry(g) for g in req.get("geoids", [])]
    if req.get("compound"):
        out["compound"] = compound_entry(req["compound"])
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main()
