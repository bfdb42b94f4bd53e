"""`zfloc-replay`: re-run the localizer on a session file's logged inputs.

Exit codes: 0 done (with --check: every decision identical and every number within the
tolerance; with --exact: bit for bit), 1 a divergence, 2 bad input (one line on stderr,
never a traceback).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

from ..errors import InputError, SessionLogError, ZflocError
from .cli_support import CliParser, Progress, install_warning_format
from .signals import interrupted, interruption_in, terminate_as_interrupt

EPILOG = """examples:
  zfloc-replay session.mcap --check               # same decisions, numbers within tolerance? exit 0, else 1 + first divergence
  zfloc-replay session.mcap --exact               # bit for bit (on the machine that recorded it)
  zfloc-replay session.mcap --check --set replay.rtol=1e-4   # a looser tolerance (default 1e-5)
  zfloc-replay session.mcap --check --from 20 --to 40
  zfloc-replay session.mcap --set estimator.ransac.iterations=200 --out fewer-iters.mcap
  zfloc-replay session.mcap --config tuned.yaml   # side-by-side summary, new session in ./session-replay.mcap
  zfloc-replay crashed.mcap --salvage --check     # a file cut off mid-run: replay what its chunks hold
  zfloc-replay other-tool.mcap --floorplan map.yaml --out replayed.mcap

--check compares decisions exactly (frame count, statuses, reported mode and the order of
the alternatives, number of hypotheses, skipped frames and their reasons, which outputs
exist) and numbers (poses, covariances, alignments, scores, weights, BEV log-odds) within
replay.rtol / replay.atol (defaults 1e-5 / 1e-6): another CPU or BLAS may change their last
bits. It prints the largest deviation per topic, and says when the session was recorded
in another environment (versions, BLAS, SIMD features, CPU).

The engine runs with the settings logged in the file, updated by --config then --set.
--from/--to select frames [N, M). With --check the engine first runs unchecked through
frames 0..N-1 (its state at N must be the logged one); without --check a fresh engine
starts at frame N.
"""


def build_parser() -> argparse.ArgumentParser:
    p = CliParser(
        prog="zfloc-replay",
        description="Re-run the localizer on the inputs logged in a session file (MCAP): check that it "
        "reproduces the logged outputs bit for bit, or compare a run with changed settings.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("session", type=Path, help="session file (.mcap) written by zfloc-stream or another tool on the same topics")
    p.add_argument("--check", action="store_true", help="compare every logged output with the re-run: decisions exactly, numbers within "
                   "replay.rtol/replay.atol; exit 1 at the first divergence")
    p.add_argument("--exact", action="store_true", help="like --check, but numbers bit for bit (for the machine that recorded the session)")
    p.add_argument("--from", dest="start", type=int, default=0, metavar="N", help="first frame (default 0)")
    p.add_argument("--to", dest="stop", type=int, default=None, metavar="M", help="stop before frame M (default: the end)")
    p.add_argument("--config", type=Path, help="YAML settings applied over the logged settings")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override one setting, e.g. estimator.ransac.iterations=300")
    p.add_argument("--out", type=Path, help="write the re-run as a new session file (default with --config/--set and no --check: ./STEM-replay.mcap)")
    p.add_argument("--salvage", action="store_true", help="read a truncated or damaged file as far as its intact chunks go")
    p.add_argument("--floorplan", type=Path, help="floorplan (ROS map YAML) for sessions that carry none, or to replace it")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


def _fmt(v, unit: str = "", digits: int = 3) -> str:
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        return "inf" if math.isinf(v) else f"{v:.{digits}f}{unit}"
    return str(v)


def _summary_table(result, success_distance: float) -> str:
    a, b = result.logged, result.replayed
    rows = [
        ("frames", a.frames, b.frames),
        ("frames with a pose", a.with_pose, b.with_pose),
        ("final status", a.final_status, b.final_status),
        (f"success (last frames within {success_distance:g} m)", _fmt(a.success), _fmt(b.success)),
        ("mean position error", _fmt(a.mean_error, " m"), _fmt(b.mean_error, " m")),
        ("final position error", _fmt(a.final_error, " m"), _fmt(b.final_error, " m")),
        ("mean time per frame", _fmt(None if a.mean_time is None else a.mean_time * 1e3, " ms", 1),
         _fmt(None if b.mean_time is None else b.mean_time * 1e3, " ms", 1)),
    ]
    for stage in sorted(a.mean_timings.keys() | b.mean_timings.keys()):
        ta, tb = a.mean_timings.get(stage), b.mean_timings.get(stage)
        rows.append((f"  {stage}", _fmt(None if ta is None else ta * 1e3, " ms", 1), _fmt(None if tb is None else tb * 1e3, " ms", 1)))
    w0 = max(len(r[0]) for r in rows)
    w1 = max(len("logged"), *(len(str(r[1])) for r in rows))
    lines = [f"{'':<{w0}}  {'logged':>{w1}}  replay"]
    lines += [f"{r[0]:<{w0}}  {str(r[1]):>{w1}}  {r[2]}" for r in rows]
    return "\n".join(lines)


def _checked_text(result, start: int, last: int) -> str:
    """'N frames checked (A-B)', and which replayed frames had no logged outputs to check."""
    skipped = result.unchecked
    if not skipped:
        return f"{result.checked} frames checked ({start}-{last})"
    if skipped == list(range(last - len(skipped) + 1, last + 1)):  # a cut-off end: the file stops before their outputs
        end = last - len(skipped)
        checked = f"{result.checked} frames checked ({start}-{end})" if result.checked else "no frame checked"
        tail = f"frame {last}" if len(skipped) == 1 else f"frames {skipped[0]}-{last}"
        return f"{checked}; {tail} replayed but not checked: the file ends before their logged outputs"
    shown = ", ".join(map(str, skipped[:5])) + (", ..." if len(skipped) > 5 else "")
    return (f"{result.checked} of the {result.frames} frames {start}-{last} checked; {len(skipped)} without logged "
            f"outputs replayed but not checked (frames {shown})")


def run(args) -> int:
    from ..plans.loading import load_floorplan
    from ..io.session import read_session
    from ..io.session.replay import replay_session, replay_settings, require_outputs

    from ..io.session import environment
    from ..io.session.compare import EXACT, Tolerance

    args.check = args.check or args.exact
    session = read_session(args.session, salvage=args.salvage)
    settings = replay_settings(session, args.config, args.set)
    session.read_settings = settings  # the reader's limits (logging.reorder_max_mb) as given
    tolerance = EXACT if args.exact else Tolerance(settings.replay.rtol, settings.replay.atol)
    if args.check:
        require_outputs(session)
    if args.floorplan is not None:
        floorplan = load_floorplan(args.floorplan, settings=settings)
    else:
        # built as in the recorded run (its own logged settings, if any) + the same overrides
        plan_settings = settings if session.floorplan_settings is None else replay_settings(session, args.config, args.set, base=session.floorplan_settings)
        floorplan = session.load_floorplan(plan_settings)
        if floorplan is None:
            raise SessionLogError(f"{session.path}: the session carries no floorplan: pass --floorplan map.yaml")
    if session.settings is None:
        print(f"note: {session.path} carries no settings: replaying with the defaults (+ overrides)", file=sys.stderr)
    changed = bool(args.config or args.set)
    out = args.out
    if out is None and changed and not args.check:
        out = Path(f"{args.session.stem}-replay.mcap")
    if out is not None and out.resolve() == args.session.resolve():
        raise InputError(f"--out {out} would overwrite the session being replayed")

    progress = Progress(None, "replaying", "frame", enabled=not args.no_progress)
    try:
        result = replay_session(
            session, settings, floorplan, start=args.start, stop=args.stop, check=args.check, out=out,
            on_frame=lambda _i: progress.update(1), tolerance=tolerance,
        )
    finally:
        progress.close()

    for note in session.problems[:5]:
        print(f"note: {note}", file=sys.stderr)
    if len(session.problems) > 5:
        print(f"note: ... and {len(session.problems) - 5} more", file=sys.stderr)

    last = args.start + result.frames - 1
    if args.check:
        print(environment.describe(session.environment))
        damage = [p for p in session.problems if p.startswith(("damaged file", "chunk skipped"))]
        if result.divergence is not None and damage:
            # frames are missing in the middle: the replay's state cannot continue across the
            # gap, so what differs after it is the damage, not the code
            where = damage[0].removeprefix("damaged file: ")
            print(f"damaged file: {where}; the replay differs after it ({result.divergence}): not a replay difference")
            return 2
        if result.divergence is not None:
            print(f"DIVERGED at {result.divergence}")
            return 1
        if all(d.abs == 0 for d in result.deviations.values()):
            verdict = "identical"
        else:
            verdict = f"same decisions, numbers within {tolerance}"
        print(f"{verdict}: {_checked_text(result, args.start, last)}, pose, hypotheses, BEV and status (timings excluded) match the log")
        print("largest deviation per topic:")
        for topic in sorted(result.deviations):
            print(f"  {topic}: {result.deviations[topic]}")
    if changed or not args.check:
        print(_summary_table(result, settings.logging.success_distance))
    if result.out is not None:
        print(f"wrote {result.out}")
    return 0


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    install_warning_format()
    try:
        with terminate_as_interrupt():
            return run(args)
    except ZflocError as err:
        print(f"zfloc-replay: error: {str(err).splitlines()[0] if str(err) else type(err).__name__}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, SystemError) as err:  # SystemError: an interrupt inside compiled code (interruption_in)
        if (stop := interruption_in(err)) is None:
            raise
        return interrupted("zfloc-replay", stop)
    except BrokenPipeError:  # output piped into e.g. head: not an error of ours
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at exit
        return 0


if __name__ == "__main__":
    sys.exit(main())
