"""`zfloc-stream`: the demo on a built-in scene, runs on recorded inputs, map building."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..errors import InputError, ZflocError
from .prior_options import add_prior_options, prior_overrides
from .cli_support import CliParser, install_warning_format, one_line, prepare_out_dir, print_warning
from .signals import interrupted, interruption_in, terminate_as_interrupt

EPILOG = """examples:
  zfloc-stream demo                                   # apartment scene, seed 0, into ./zfloc-demo
  zfloc-stream demo --scene office --seed 3 --out /tmp/office
  zfloc-stream run --floorplan map.yaml --input session.mcap --out out/
  zfloc-stream run --floorplan map.yaml --input intel.log.gz --odometry-noise 0.02 --out out/
  zfloc-stream run --floorplan plan.dxf --input robot.mcap --topic scan=/front/scan --out out/   # a ROS 2 bag
  zfloc-stream run --floorplan map.yaml --input robot.mcap --groundtruth gt.tum --ros2 --out out/   # + errors, ROS 2 messages
  zfloc-stream run --input session.mcap --live 8765 --realtime --out out/   # watch it in Foxglove as recorded (ws://127.0.0.1:8765)
  zfloc-stream demo --floorplan plan.dxf              # a simulated walk through your own building
  zfloc-stream export out/session.mcap --tum out.txt  # the logged trajectory for evo
  zfloc-stream run --input phone.mcap --depth-model depth-anything/Depth-Anything-V2-Metric-Indoor-Small-hf \
      --seg-model nvidia/segformer-b0-finetuned-ade-512-512 --out out/     # plain RGB camera ([torch] extra)
  zfloc-stream map-from-log intel.log.gz --exclude 375:454 --out held-out-map/
  zfloc-stream run --floorplan held-out-map/map.yaml --input intel.log.gz --scans 375:454 --out out/
  zfloc-stream config > my.yaml                       # the default settings, to edit
"""


def _add_settings_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", type=Path, help="YAML settings file (overrides the defaults)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override one setting, e.g. estimator.ransac.iterations=300")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def _add_floorplan_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--scale", type=float, metavar="M_PER_UNIT", help="vector plans: metres per drawing unit (SVG: required; DXF: overrides the header's units)")
    p.add_argument("--layers", help="DXF plans: comma-separated layers to use (default all)")
    p.add_argument("--skip-layers", help="DXF plans: comma-separated layers to leave out (furniture, text, ...)")
    p.add_argument("--tum", type=Path, metavar="PATH", help="also write the trajectory as a TUM file for evo (default OUT/trajectory.tum)")
    p.add_argument("--live", nargs="?", type=int, const=8765, default=None, metavar="PORT",
                   help="serve the session's topics live to Foxglove on ws://127.0.0.1:PORT (default 8765; the [live] extra); "
                   "after the run it keeps serving until Ctrl-C")
    p.add_argument("--live-linger", type=float, metavar="S", help="with --live: after the run serve S more seconds, then exit")
    p.add_argument("--realtime", action="store_true", help="pace the run to the input's timestamps (as it was recorded)")
    p.add_argument("--rate", type=float, metavar="X", help="pace the run at X times real time (implies --realtime)")
    p.add_argument("--ros2", action="store_true", help="also write OUT/ros2.mcap: ROS 2 messages (PoseWithCovarianceStamped /zfloc/pose, "
                   "map->odom->base_link on /tf, OccupancyGrid /zfloc/floorplan, /zfloc/groundtruth) for ROS tools and evo")


def _split(text: str | None) -> list[str] | None:
    return None if not text else [t.strip() for t in text.split(",") if t.strip()]


def load_floorplan(args, settings):
    """The --floorplan of a command: a ROS map YAML, an image, or a DXF/SVG/GeoJSON drawing."""
    from ..plans.loading import load_floorplan as load_plan
    from ..plans.vector import VECTOR_SUFFIXES, load_vector_floorplan

    if args.floorplan.suffix.lower() in VECTOR_SUFFIXES:
        return load_vector_floorplan(args.floorplan, settings, scale=args.scale, layers=_split(args.layers), skip_layers=_split(args.skip_layers))
    if args.scale is not None or args.layers or args.skip_layers:
        raise ZflocError(f"--scale, --layers and --skip-layers apply to DXF/SVG/GeoJSON floorplans, not {args.floorplan.name}")
    return load_plan(args.floorplan, resolution=getattr(args, "resolution", None), origin=getattr(args, "origin", None), settings=settings)


def build_parser() -> argparse.ArgumentParser:
    parser = CliParser(
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
        epilog="examples:\n  zfloc-stream demo\n  zfloc-stream demo --scene symmetric --frames 60 --out /tmp/sym\n"
        "  zfloc-stream demo --floorplan plan.dxf --skip-layers FURNITURE,TEXT\n  zfloc-stream demo --floorplan plan.svg --scale 0.01",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    demo.add_argument("--scene", default="apartment", help="built-in scene: rooms, apartment, office, symmetric, hall, offices (default apartment)")
    demo.add_argument("--floorplan", type=Path, help="walk through your own plan instead (ROS map YAML, DXF, SVG, GeoJSON)")
    demo.add_argument("--seed", type=int, default=0, help="seed of the scene, the walk and the localizer (default 0)")
    demo.add_argument("--frames", type=int, default=100, help="number of frames (default 100)")
    demo.add_argument("--out", type=Path, default=Path("zfloc-demo"), help="output folder (default ./zfloc-demo)")
    _add_floorplan_options(demo)
    _add_settings_args(demo)

    run = sub.add_parser(
        "run",
        help="localize recorded inputs against a floorplan",
        description="Localize a recorded session (MCAP session, ROS 2 bag, Gibson(t) scene folder or Carmen log, detected by content) "
        "against a floorplan. Writes trajectory.csv, trajectory.tum, overlay.png and session.mcap.",
        epilog="examples:\n  zfloc-stream run --floorplan map.yaml --input session.mcap --out out/\n"
        "  zfloc-stream run --floorplan map.png --resolution 0.05 --origin -10 -10 --input log.gz --out out/\n"
        "  zfloc-stream run --floorplan map.yaml --input run.mcap --groundtruth gt.csv --scans 0:200 --ros2 --out out/\n"
        "  zfloc-stream run --input session.mcap --live --out out/          # open ws://127.0.0.1:8765 in Foxglove\n"
        "  zfloc-stream run --floorplan map.yaml --input intel.log.gz --live --rate 4 --live-linger 60 --out out/   # 4x real time\n"
        "  zfloc-stream run --floorplan map.yaml --input run.mcap --initial-pose 12.5,-3,90,3,30 --out out/   # near the lift, facing +y, +-3 m\n"
        "  zfloc-stream run --floorplan map.yaml --input run.mcap --region 0,0,20,15 --out out/   # somewhere in this wing (or --region wing.geojson)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    run.add_argument("--floorplan", type=Path, help="ROS map_server YAML, an image with --resolution and --origin, or a "
                     "DXF/SVG/GeoJSON drawing (optional for MCAP sessions that carry their floorplan)")
    run.add_argument("--resolution", type=float, help="metres per pixel of an image floorplan")
    run.add_argument("--origin", type=float, nargs=2, metavar=("X", "Y"), help="metric position of the image's lower-left corner")
    run.add_argument("--input", type=Path, required=True, help="session.mcap, a ROS 2 bag (.mcap), a Gibson(t) scene folder, or a Carmen log")
    run.add_argument("--groundtruth", type=Path, metavar="FILE", help="ground truth for any input: a TUM file (matched by "
                     "timestamp) or a CSV with x,y,theta columns (+ frame or timestamp; else one row per input frame); "
                     "replaces the input's own where it has a pose; a warning says how many frames it covers")
    run.add_argument("--scans", metavar="START:STOP", help="localize input frames [START, STOP) only (0-based; for a Carmen "
                     "log the scans map-from-log --exclude START:STOP leaves out)")
    run.add_argument("--topic", action="append", default=[], metavar="ROLE=TOPIC",
                     help="ROS 2 bags: the topic for a role (scan, depth, camera_info, odom, tf, tf_static), e.g. scan=/front/scan")
    run.add_argument("--odometry-noise", type=float, default=None, metavar="FRAC", help="synthetic odometry drift for Carmen logs and Gibson(t) scenes, refused for MCAP inputs (recorded odometry) (default: datasets.odometry.noise = 0.02 plus 5 mm / 0.3 deg per step; 0 = exact relative motion)")
    run.add_argument("--out", type=Path, default=Path("zfloc-run"), help="output folder (default ./zfloc-run)")
    run.add_argument("--depth-model", metavar="ID_OR_DIR", help="metric depth network for RGB frames: a local folder or a "
                     "Hugging Face hub id in the local cache (sets backbones.depth_model; needs the [torch] extra)")
    run.add_argument("--seg-model", metavar="ID_OR_DIR", help="semantic segmentation network for wall/floor/ceiling labels "
                     "(sets backbones.seg_model; needs the [torch] extra)")
    run.add_argument("--salvage", action="store_true", help="an MCAP session cut off by a crash (or damaged): read it as far as its intact chunks go")
    add_prior_options(run)
    _add_floorplan_options(run)
    _add_settings_args(run)

    export = sub.add_parser(
        "export",
        help="write the trajectory logged in a session file as TUM (for evo)",
        description="Write the estimates logged in a session.mcap (/zfloc/status) as a TUM trajectory "
        "(timestamp tx ty tz qx qy qz qw), readable by evo_traj / evo_ape.",
        epilog="examples:\n  zfloc-stream export out/session.mcap --tum out.txt\n  evo_traj tum out.txt --plot",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    export.add_argument("session", type=Path, help="a session.mcap written by zfloc-stream run/demo or zfloc-replay")
    export.add_argument("--tum", type=Path, required=True, metavar="PATH", help="TUM file to write")
    export.add_argument("--salvage", action="store_true", help="a session cut off by a crash (or damaged): read it as far as its intact chunks go")

    config = sub.add_parser(
        "config",
        help="print the settings (defaults, or a file with overrides) as YAML",
        description="Print the settings as YAML: the defaults, updated by --config then --set. Edit the output "
        "and pass it back with --config to any command.",
        epilog="examples:\n  zfloc-stream config > my.yaml                    # the defaults, to edit\n"
        "  zfloc-stream config --config my.yaml --set seed=3  # what a run with these overrides would use\n"
        "  zfloc-stream run --config my.yaml --input session.mcap --out out/",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    config.add_argument("--config", type=Path, help="YAML settings file (overrides the defaults)")
    config.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override one setting, e.g. estimator.ransac.iterations=300")

    from .map_from_log import register as register_map_from_log

    register_map_from_log(sub)
    return parser


def load_settings(*args, **kwargs):
    """settings.loading.load_settings, imported on first use (pydantic is not needed for --help)."""
    from ..settings.loading import load_settings as load

    return load(*args, **kwargs)


def _settings(args):
    return load_settings(args.config, args.set)


def _run_settings(args, base_overrides: dict | None = None):
    """Settings of `run`: defaults, the source's needs, --config, --set, then the
    --depth-model / --seg-model flags and the prior of --initial-pose / --region."""
    settings = load_settings(args.config, args.set, base_overrides=base_overrides)
    prior = prior_overrides(args)
    if prior is not None:
        settings = settings.model_copy(update={"prior": settings.prior.model_copy(update=prior)})
    models = {k: v for k, v in (("depth_model", args.depth_model), ("seg_model", args.seg_model)) if v is not None}
    if not models:
        return settings
    return settings.model_copy(update={"backbones": settings.backbones.model_copy(update=models)})


def _check_live_options(args) -> None:
    """--live-linger, --realtime and --rate, checked before any work."""
    import math

    if args.rate is not None and not (math.isfinite(args.rate) and args.rate > 0):
        raise InputError(f"--rate must be a positive number (times real time), got {args.rate:g}")
    if args.live_linger is not None:
        if args.live is None:
            raise InputError("--live-linger applies to --live")
        if not (math.isfinite(args.live_linger) and args.live_linger >= 0):
            raise InputError(f"--live-linger must be a number of seconds >= 0, got {args.live_linger:g}")


def _start_live(args):
    if args.live is None:
        return None
    from .live import LiveServer

    server = LiveServer(args.live)
    print(f"live view: {server.url} (Foxglove or Lichtblick: Open connection -> Foxglove WebSocket)", flush=True)
    return server


def _paced(args, frames):
    """The frames, paced to their timestamps under --realtime / --rate X."""
    if args.rate is None and not args.realtime:
        return frames
    from .pacing import paced

    return paced(frames, rate=1.0 if args.rate is None else args.rate)


def _linger(args, live) -> None:
    """After the run: --live serves on until Ctrl-C, or --live-linger S seconds."""
    if live is None:
        return
    until = "Ctrl-C to stop" if args.live_linger is None else f"for {args.live_linger:g} s"
    print(f"live view: run done; still serving {live.url} ({until})", flush=True)
    live.linger(args.live_linger)


def cmd_demo(args) -> int:
    if args.frames < 1:
        raise InputError("--frames must be at least 1")
    _check_live_options(args)
    prepare_out_dir(args.out, create=False)
    from ..sim import SimSettings, build_scene, simulate
    from .session_runner import run_session

    settings = load_settings(args.config, args.set, base_overrides={"seed": args.seed})
    if args.floorplan is not None:
        from ..sim import build_scene_from_floorplan

        scene = build_scene_from_floorplan(load_floorplan(args, settings), seed=args.seed)
    else:
        scene = build_scene(args.scene, seed=args.seed)
    sequence = simulate(scene, SimSettings(), seed=args.seed, n_frames=args.frames)
    live = _start_live(args)
    try:
        outcome = run_session(
            scene.floorplan, _paced(args, iter(sequence)), settings, args.out, total=args.frames,
            progress=not args.no_progress, description=f"demo {scene.name}", tum=args.tum, live=live, ros2=args.ros2,
        )
        _report(outcome, settings)
        _linger(args, live)
    finally:
        if live is not None:
            live.close()
    return 0


def _topics_line(args, sequence) -> str:
    kind, _, _ = sequence.source.partition(":")
    names = {"mcap": "MCAP session", "ros2": "ROS 2 bag", "carmen": "Carmen log", "gibson": "Gibson(t) scene"}
    text = f"input: {names.get(kind, kind)} {args.input}"
    topics = getattr(sequence, "topics", None)
    if topics:
        # a bag's topics are found by type: say which role each one plays
        text += "; topics: " + ", ".join(topic if kind == "mcap" else f"{role}={topic}" for role, topic in topics.items())
    return text


def cmd_run(args) -> int:
    _check_live_options(args)
    prepare_out_dir(args.out, create=False)
    from ..backbones import Perception
    from ..io.datasets import detect_source
    from ..io.datasets.ros2 import parse_topic_overrides
    from .session_runner import run_session

    settings = _run_settings(args)
    topics = parse_topic_overrides(args.topic)
    window = None
    if args.scans is not None:
        from ..plans.map_from_log import parse_exclude

        window = parse_exclude(args.scans, "--scans")
    groundtruth = None
    if args.groundtruth is not None:
        from ..io.groundtruth import load_groundtruth

        groundtruth = load_groundtruth(args.groundtruth, max_gap=settings.datasets.ros2.max_odometry_gap)
    floorplan = None
    if args.floorplan is not None:
        floorplan = load_floorplan(args, settings)
    sequence = detect_source(args.input, floorplan=floorplan, odometry_noise=args.odometry_noise, seed=settings.seed,
                             settings=settings, topics=topics, salvage=args.salvage)
    if sequence.settings_overrides:
        settings = _run_settings(args, sequence.settings_overrides)
    start, stop = 0, sequence.n_frames
    if window is not None:
        start, stop = window
        if start >= sequence.n_frames:
            raise InputError(f"--scans {args.scans}: {args.input} has only {sequence.n_frames} frames")
        stop = min(stop, sequence.n_frames)
    print(_topics_line(args, sequence) + (f"; frames {start}-{stop - 1} of {sequence.n_frames}" if window else f"; {sequence.n_frames} frames"), flush=True)
    if floorplan is None and sequence.floorplan_source:
        print(f"floorplan: {sequence.floorplan_source}", flush=True)
    if floorplan is None and sequence.source.startswith("carmen:"):
        if window is not None:
            print_warning(f"no --floorplan: the map is built from this log without scans {start}-{stop - 1} "
                          "(+- datasets.carmen.heldout_margin), the held-out map of map-from-log --exclude")
        else:
            print_warning(
                "no --floorplan: the map is built from this log's own scans, the very scans being localized "
                "(a self-test, not a result). For a fair test build a held-out map: "
                "zfloc-stream map-from-log LOG --exclude A:B --out DIR, then run --scans A:B"
            )
    plan = sequence.floorplan_for(start, stop) if window is not None and floorplan is None else sequence.floorplan
    perception = Perception.from_settings(settings.backbones)  # loads now: a bad model fails before any output
    if sequence.needs_depth_network and (perception is None or perception.depth is None):
        raise InputError(f"{args.input} holds RGB camera frames without depth: name a depth network with --depth-model ID_OR_DIR")
    live = _start_live(args)
    try:
        outcome = run_session(
            plan, _paced(args, sequence.frames(start, stop)), settings, args.out, total=stop - start,
            progress=not args.no_progress, description=f"run {args.input.name}", tum=args.tum, perception=perception,
            groundtruth=groundtruth, first_index=start, live=live, ros2=args.ros2,
        )
        if groundtruth is not None and outcome.estimates:  # a file that covers only part of the input (or none) is said
            note = groundtruth.coverage_note(len(outcome.estimates), outcome.truth_from_file, outcome.truth_kept, start,
                                             (outcome.estimates[0].timestamp, outcome.estimates[-1].timestamp))
            if note:
                print_warning(note)
        _report(outcome, settings)
        _linger(args, live)
    finally:
        if live is not None:
            live.close()
    return 0


def _report(outcome, settings) -> None:
    from ..io.tum import moved_note
    from .run_summary import report_lines

    extra = "".join(f", {p.name}" for p in (outcome.truth_tum_path, outcome.ros2_path) if p is not None)
    print(f"wrote {outcome.out_dir}/trajectory.csv, overlay.png, session.mcap{extra} ({len(outcome.estimates)} frames); "
          f"TUM: {outcome.tum_path} ({outcome.tum_rows} poses)")
    note = moved_note(outcome.tum_path, outcome.tum_moved, outcome.tum_rows)
    if note:
        print(f"note: {note}")
    for line in report_lines(outcome, settings.logging.success_distance):
        print(line)


def cmd_export(args) -> int:
    from ..io.tum import export_session_tum, moved_note

    out = export_session_tum(args.session, args.tum, salvage=args.salvage)
    print(f"wrote {args.tum} ({out.rows} poses)")
    note = moved_note(args.tum, out.moved, out.rows)
    if note:
        print(f"note: {note}")
    return 0


def cmd_config(args) -> int:
    from ..settings.loading import dump_settings

    sys.stdout.write(dump_settings(_settings(args)))
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    install_warning_format()
    try:
        with terminate_as_interrupt():  # SIGTERM closes the outputs as Ctrl-C does
            if args.command == "demo":
                return cmd_demo(args)
            if args.command == "run":
                return cmd_run(args)
            if args.command == "config":
                return cmd_config(args)
            if args.command == "export":
                return cmd_export(args)
            return args.func(args)
    except ZflocError as err:
        print(f"zfloc-stream: error: {one_line(err)}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, SystemError) as err:  # SystemError: an interrupt inside compiled code (interruption_in)
        if (stop := interruption_in(err)) is None:
            raise
        return interrupted("zfloc-stream", stop)
    except BrokenPipeError:  # output piped into e.g. head: not an error of ours
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":
    sys.exit(main())
