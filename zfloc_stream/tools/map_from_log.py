"""`zfloc-stream map-from-log LOG --exclude A:B --out DIR`: an occupancy floorplan (ROS
map_server YAML + PNG) rasterised from a Carmen laser log with poses, leaving scan
ranges out (a held-out map for a window). Wired into `zfloc-stream` by tools/cli.py."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import InputError


def register(subparsers) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "map-from-log",
        help="build a floorplan from a laser log, leaving scan ranges out",
        description="Rasterise an occupancy map (log-odds: beam ends occupied, beams free) from a Carmen "
        "laser log whose poses are ground truth, and write it as ROS map_server YAML + PNG. "
        "--exclude START:STOP leaves scans START..STOP-1 out (0-based, file order), so a window "
        "can be localized against walls seen on other passes only.",
        epilog="examples:\n  zfloc-stream map-from-log intel.log.gz --out map/\n"
        "  zfloc-stream map-from-log intel.log.gz --exclude 375:454 --resolution 0.05 --out held-out/",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("log", type=Path, metavar="LOG", help="Carmen log (.log/.clf, plain or gzipped)")
    p.add_argument("--exclude", action="append", default=[], metavar="START:STOP", help="leave scans [START, STOP) out; repeatable")
    p.add_argument("--resolution", type=float, help="metres per cell (default: datasets.mapping.resolution, 0.05)")
    p.add_argument("--out", type=Path, required=True, help="output folder for NAME.yaml + NAME.png")
    p.add_argument("--name", default="map", help="file name stem (default map)")
    p.add_argument("--config", type=Path, help="YAML settings file")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override one setting, e.g. datasets.mapping.free_range=10")
    p.set_defaults(func=run)
    return p


def run(args) -> int:
    # imported here, not at the top: `zfloc-stream --help` builds this parser and must stay fast
    from ..settings.loading import load_settings
    from ..io.datasets.carmen import read_carmen
    from ..plans.map_from_log import map_from_log, parse_exclude

    settings = load_settings(args.config, args.set)
    exclude = [parse_exclude(text) for text in args.exclude]
    if not args.name or "/" in args.name:
        raise InputError(f"--name '{args.name}' must be a plain file name stem")
    log = read_carmen(args.log, settings)
    for start, stop in exclude:
        if start >= len(log):
            raise InputError(f"--exclude {start}:{stop}: the log has only {len(log)} scans")
    floorplan = map_from_log(log, exclude, settings, resolution=args.resolution)
    yaml_path = floorplan.write_ros(args.out, args.name)
    left_out = sum(min(stop, len(log)) - start for start, stop in _merged(exclude))
    h, w = floorplan.shape
    print(f"wrote {yaml_path} ({w}x{h} cells at {floorplan.resolution:g} m; {len(log) - left_out} of {len(log)} scans used)")
    return 0


def _merged(ranges):
    """Union of [start, stop) ranges as disjoint ranges (for counting scans left out)."""
    out: list[list[int]] = []
    for start, stop in sorted(ranges):
        if out and start <= out[-1][1]:
            out[-1][1] = max(out[-1][1], stop)
        else:
            out.append([start, stop])
    return out
