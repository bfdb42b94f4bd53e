"""`zfloc-stream`: the demo on a built-in scene, runs on recorded inputs, map building."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..config import dump_settings, load_settings
from ..errors import ZflocError

EPILOG = """examples:
  zfloc-stream demo                                   # apartment scene, seed 0, into ./zfloc-demo
  zfloc-stream demo --scene office --seed 3 --out /tmp/office
  zfloc-stream run --floorplan map.yaml --input session.mcap --out out/
  zfloc-stream run --floorplan map.yaml --input intel.log.gz --odometry-noise 0.02 --out out/
  zfloc-stream run --input phone.mcap --depth-model depth-anything/Depth-Anything-V2-Metric-Indoor-Small-hf \
      --seg-model nvidia/segformer-b0-finetuned-ade-512-512 --out out/     # plain RGB camera ([torch] extra)
  zfloc-stream map-from-log intel.log.gz --exclude 375:454 --out held-out-map/
  zfloc-stream config > my.yaml                       # the default settings, to edit
"""


def _add_settings_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", type=Path, help="YAML settings file (overrides the defaults)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override one setting, e.g. estimator.ransac.iterations=300")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="zfloc-stream",
        description="Online zero-shot floorplan localization.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    demo = sub.add_parser(
        "demo",
        help="simulate a built-in scene and localize online",
        description="Simulate a camera walking through a built-in scene and localize it online. Writes "
        "trajectory.csv, overlay.png and session.mcap; prints the final error and success (all of the last "
        "10 frames within 1 m).",
        epilog="examples:\n  zfloc-stream demo\n  zfloc-stream demo --scene symmetric --frames 60 --out /tmp/sym",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    demo.add_argument("--scene", default="apartment", help="built-in scene: rooms, apartment, office, symmetric, hall (default apartment)")
    demo.add_argument("--seed", type=int, default=0, help="seed of the scene, the walk and the localizer (default 0)")
    demo.add_argument("--frames", type=int, default=100, help="number of frames (default 100)")
    demo.add_argument("--out", type=Path, default=Path("zfloc-demo"), help="output folder (default ./zfloc-demo)")
    _add_settings_args(demo)

    run = sub.add_parser(
        "run",
        help="localize recorded inputs against a floorplan",
        description="Localize a recorded session (MCAP, Gibson(t) scene folder or Carmen log, detected by content) "
        "against a floorplan. Writes trajectory.csv, overlay.png and session.mcap.",
        epilog="examples:\n  zfloc-stream run --floorplan map.yaml --input session.mcap --out out/\n"
        "  zfloc-stream run --floorplan map.png --resolution 0.05 --origin -10 -10 --input log.gz --out out/",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    run.add_argument("--floorplan", type=Path, help="ROS map_server YAML, or an image with --resolution and --origin "
                     "(optional for MCAP sessions that carry their floorplan)")
    run.add_argument("--resolution", type=float, help="metres per pixel of an image floorplan")
    run.add_argument("--origin", type=float, nargs=2, metavar=("X", "Y"), help="metric position of the image's lower-left corner")
    run.add_argument("--input", type=Path, required=True, help="session.mcap, a Gibson(t) scene folder, or a Carmen log")
    run.add_argument("--odometry-noise", type=float, default=0.0, metavar="FRAC", help="synthetic odometry drift for Carmen logs (default 0)")
    run.add_argument("--out", type=Path, default=Path("zfloc-run"), help="output folder (default ./zfloc-run)")
    run.add_argument("--depth-model", metavar="ID_OR_DIR", help="metric depth network for RGB frames: a local folder or a "
                     "Hugging Face hub id in the local cache (sets backbones.depth_model; needs the [torch] extra)")
    run.add_argument("--seg-model", metavar="ID_OR_DIR", help="semantic segmentation network for wall/floor/ceiling labels "
                     "(sets backbones.seg_model; needs the [torch] extra)")
    _add_settings_args(run)

    config = sub.add_parser("config", help="print the settings (defaults, or a file with overrides) as YAML")
    config.add_argument("--config", type=Path, help="YAML settings file")
    config.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")

    from .map_from_log import register as register_map_from_log

    register_map_from_log(sub)
    return parser


def _settings(args):
    return load_settings(args.config, args.set)


def _run_settings(args, base_overrides: dict | None = None):
    """Settings of `run`: defaults, the source's needs, --config, --set, then the
    --depth-model / --seg-model flags."""
    settings = load_settings(args.config, args.set, base_overrides=base_overrides)
    models = {k: v for k, v in (("depth_model", args.depth_model), ("seg_model", args.seg_model)) if v is not None}
    if not models:
        return settings
    return settings.model_copy(update={"backbones": settings.backbones.model_copy(update=models)})


def cmd_demo(args) -> int:
    from ..sim import SimSettings, build_scene, simulate
    from .session_runner import run_session

    settings = load_settings(args.config, args.set, base_overrides={"seed": args.seed})
    if args.frames < 1:
        raise ZflocError("--frames must be at least 1")
    scene = build_scene(args.scene, seed=args.seed)
    sequence = simulate(scene, SimSettings(), seed=args.seed, n_frames=args.frames)
    outcome = run_session(
        scene.floorplan, iter(sequence), settings, args.out, total=args.frames,
        progress=not args.no_progress, description=f"demo {args.scene}",
    )
    _report(outcome)
    return 0


def cmd_run(args) -> int:
    from ..backbones import Perception
    from ..datasets import detect_source
    from ..floorplan import Floorplan
    from .session_runner import run_session

    settings = _run_settings(args)
    floorplan = None
    if args.floorplan is not None:
        floorplan = Floorplan.load(args.floorplan, resolution=args.resolution, origin=args.origin, settings=settings)
    sequence = detect_source(args.input, floorplan=floorplan, odometry_noise=args.odometry_noise, seed=settings.seed, settings=settings)
    if sequence.settings_overrides:
        settings = _run_settings(args, sequence.settings_overrides)
    perception = Perception.from_settings(settings.backbones)  # loads now: a bad model fails before any output
    if sequence.needs_depth_network and (perception is None or perception.depth is None):
        raise ZflocError(f"{args.input} holds RGB camera frames without depth: name a depth network with --depth-model ID_OR_DIR")
    outcome = run_session(
        sequence.floorplan, sequence.frames(), settings, args.out, total=sequence.n_frames,
        progress=not args.no_progress, description=f"run {args.input.name}", perception=perception,
    )
    _report(outcome)
    return 0


def _report(outcome) -> None:
    last = outcome.estimates[-1] if outcome.estimates else None
    print(f"wrote {outcome.out_dir}/trajectory.csv, overlay.png, session.mcap ({len(outcome.estimates)} frames)")
    if last is not None:
        print(f"final status: {last.status}, score {last.score:.3f}, scale {last.scale:.3f}")
    errors = outcome.final_errors()
    if errors is not None and len(errors):
        ok = bool((errors <= 1.0).all())
        print(f"final position error: {errors[-1]:.3f} m; last-10 max {errors.max():.3f} m; success@1m: {'yes' if ok else 'no'}")


def cmd_config(args) -> int:
    sys.stdout.write(dump_settings(_settings(args)))
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        if args.command == "demo":
            return cmd_demo(args)
        if args.command == "run":
            return cmd_run(args)
        if args.command == "config":
            return cmd_config(args)
        return args.func(args)
    except ZflocError as err:
        print(f"zfloc-stream: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("zfloc-stream: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
