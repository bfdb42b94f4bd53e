"""`run --initial-pose` and `--region`: the caller's prior (prior.py) as settings.prior
overrides, so the session log records it and a replay reproduces the run."""

from __future__ import annotations

import argparse
import csv
import json
import math
from pathlib import Path

from ..errors import InputError

INITIAL_POSE_HELP = ("the first frame's pose in the floorplan frame: X,Y in metres, THETA in degrees (counter-clockwise "
                     "from the floorplan's x axis), optional SIGMA_XY (m, default 1) and SIGMA_THETA (deg, default 15); "
                     "the search, the seeding and the tracker prefer poses within 2.5 sigma, and say so with a warning "
                     "when the frames contradict it (AMCL's initial pose)")
REGION_HELP = ("the first frame lies inside this region: a box X0,Y0,X1,Y1 (metres, floorplan frame), or a polygon file: "
               "GeoJSON (a Polygon, or the first Polygon of a Feature / FeatureCollection) or CSV (one x,y vertex per row)")


def add_prior_options(p: argparse.ArgumentParser) -> None:
    group = p.add_argument_group("where the sensor starts (a prior; default: a global search)")
    group.add_argument("--initial-pose", metavar="X,Y,THETA[,SIGMA_XY,SIGMA_THETA]", help=INITIAL_POSE_HELP)
    group.add_argument("--region", metavar="X0,Y0,X1,Y1|FILE", help=REGION_HELP)


def _numbers(text: str, option: str, counts: tuple[int, ...]) -> list[float]:
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise InputError(f"{option} {text!r}: expected {' or '.join(map(str, counts))} comma-separated numbers") from None
    if len(values) not in counts:
        raise InputError(f"{option} {text!r}: expected {' or '.join(map(str, counts))} comma-separated numbers, got {len(values)}")
    if not all(math.isfinite(v) for v in values):
        raise InputError(f"{option} {text!r}: the numbers must be finite")
    return values


def _region_file(path: Path) -> list[list[float]]:
    if not path.is_file():
        raise InputError(f"--region {path}: no such file (a box is X0,Y0,X1,Y1)")
    text = path.read_text(errors="replace")
    if path.suffix.lower() in (".json", ".geojson"):
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as err:
            raise InputError(f"--region {path}: not valid JSON ({err.msg}, line {err.lineno})") from None
        geometry = doc
        if isinstance(doc, dict) and doc.get("type") == "FeatureCollection":
            geometry = next((f.get("geometry") for f in doc.get("features", []) if isinstance(f, dict)
                             and isinstance(f.get("geometry"), dict) and f["geometry"].get("type") == "Polygon"), None)
        elif isinstance(doc, dict) and doc.get("type") == "Feature":
            geometry = doc.get("geometry")
        if not (isinstance(geometry, dict) and geometry.get("type") == "Polygon" and geometry.get("coordinates")):
            raise InputError(f"--region {path}: no GeoJSON Polygon in it")
        ring = geometry["coordinates"][0]
        try:
            return [[float(v[0]), float(v[1])] for v in ring]
        except (TypeError, ValueError, IndexError):
            raise InputError(f"--region {path}: the Polygon's outer ring is not a list of [x, y] numbers") from None
    rows = [r for r in csv.reader(text.splitlines()) if r and any(c.strip() for c in r) and not r[0].lstrip().startswith("#")]
    vertices = []
    for k, row in enumerate(rows):
        try:
            vertices.append([float(row[0]), float(row[1])])
        except (ValueError, IndexError):
            if k == 0:
                continue  # a header line (x,y)
            raise InputError(f"--region {path}: row {k + 1} is not x,y numbers: {','.join(row)!r}") from None
    return vertices


def prior_overrides(args) -> dict | None:
    """The settings.prior fields of --initial-pose / --region (None when neither is given);
    a bad value is one InputError line."""
    from ..prior import Prior, box_polygon

    if args.initial_pose is None and args.region is None:
        return None
    update: dict = {}
    pose = None
    sigma_xy, sigma_deg = 1.0, 15.0  # settings.prior's defaults, where --initial-pose gives none
    if args.initial_pose is not None:
        values = _numbers(args.initial_pose, "--initial-pose", (3, 5))
        x, y, theta_deg = values[:3]
        if len(values) == 5:
            sigma_xy, sigma_deg = values[3:]
        if sigma_xy <= 0 or sigma_deg <= 0:
            raise InputError(f"--initial-pose {args.initial_pose!r}: SIGMA_XY and SIGMA_THETA must be positive")
        pose = (x, y, math.radians(theta_deg))
        update.update(pose=[x, y, theta_deg], sigma_xy=sigma_xy, sigma_theta_deg=sigma_deg)
    region = None
    if args.region is not None:
        if "," in args.region and not Path(args.region).exists():
            x0, y0, x1, y1 = _numbers(args.region, "--region", (4,))
            try:
                region = box_polygon(x0, y0, x1, y1)
            except InputError as err:
                raise InputError(f"--region {args.region!r}: {str(err).removeprefix('prior: ')}") from None
        else:
            region = _region_file(Path(args.region))
    try:  # the prior's own checks: a polygon with area, finite numbers
        checked = Prior(pose, sigma_xy, math.radians(sigma_deg), region)
    except InputError as err:
        raise InputError(f"--region {args.region}: {str(err).removeprefix('prior: ')}") from None
    if checked.region is not None:
        update["region"] = checked.region.tolist()
    return update
