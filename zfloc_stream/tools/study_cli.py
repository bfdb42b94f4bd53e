"""`zfloc-study`: success rate vs sequence length (F3Loc protocol) over datasets and seeds,
on all local cores or a dask cluster; resumable (see zfloc_stream/study/)."""

from __future__ import annotations

import argparse
import functools
import sys
from pathlib import Path

from ..errors import InputError, ZflocError
from .cli_support import CliParser, Progress, install_warning_format, one_line

EPILOG = """examples:
  zfloc-study --dataset sim:all --lengths 15,20,35,50,100 --seeds 5 --out study-sim/
  zfloc-study --dataset carmen:intel.log.gz --lengths 15,20,35,50,100 --seeds 5 --out study-intel/
  zfloc-study --dataset gibson:/data/gibson_t:test --out study-gibson/ --scheduler tcp://10.0.0.5:8786
  zfloc-study --dataset sim:rooms --lengths 15 --seeds 1 --workers 0 --out /tmp/s   # in-process, no dask

Writes results.csv (one row per chunk x seed), results.json, results.md (paper-shaped table)
and sr_vs_length.png. Re-running with the same --out resumes: finished cells are skipped.
Carmen logs are localized against maps built from the log without each window
(+- datasets.carmen.heldout_margin scans), with fixed scale.
"""


def build_parser() -> argparse.ArgumentParser:
    p = CliParser(
        prog="zfloc-study",
        description="Success rate vs sequence length: cut each sequence into chunks of L frames, localize every "
        "chunk from scratch with each seed, score the last 10 frames (success: all within X m).",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--dataset", action="append", required=True, metavar="SPEC",
                   help="sim:NAME[,NAME..]|all, gibson:ROOT[:split], carmen:LOG, mcap:FILE; repeatable (one table row each)")
    p.add_argument("--lengths", default="15,20,35,50,100", help="chunk lengths in frames (default 15,20,35,50,100)")
    p.add_argument("--seeds", type=int, default=5, help="number of seeds, 0..N-1 (default 5)")
    p.add_argument("--out", type=Path, required=True, help="output folder (re-use it to resume)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="dask scheduler to use, e.g. tcp://HOST:8786 (default: a local cluster)")
    p.add_argument("--workers", type=int, help="local worker processes (default: all cores; 0 = run in this process)")
    p.add_argument("--config", type=Path, help="YAML settings file")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override one setting, e.g. study.max_chunks_per_sequence=5")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    install_warning_format()
    try:
        from ..study import parse_lengths, run_study, user_overrides

        if args.out.exists() and not args.out.is_dir():
            raise InputError(f"--out {args.out} is a file, not a folder: name a folder (re-use it to resume)")

        lengths = parse_lengths(args.lengths)
        if args.seeds < 1:
            raise ZflocError(f"--seeds must be at least 1, got {args.seeds}")
        if args.workers is not None and args.workers < 0:
            raise ZflocError(f"--workers must be >= 0, got {args.workers}")
        if args.scheduler and args.workers is not None:
            raise ZflocError("--workers applies to the local cluster; with --scheduler the cluster decides")
        overrides = user_overrides(args.config, args.set)
        outcome = run_study(
            args.dataset, lengths, list(range(args.seeds)), args.out, overrides=overrides,
            scheduler=args.scheduler, workers=args.workers,
            progress=functools.partial(Progress, enabled=not args.no_progress),
        )
    except ZflocError as err:
        print(f"zfloc-study: error: {one_line(err)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("zfloc-study: interrupted (finished cells are kept; re-run to resume)", file=sys.stderr)
        return 130
    failed = sum(r.get("error") is not None for r in outcome.rows)
    print((outcome.out_dir / "results.md").read_text())
    print(f"{len(outcome.rows)} cells ({outcome.skipped} already done, {outcome.ran} run in {outcome.seconds:.1f} s"
          f" = {outcome.chunks_per_second:.3f} chunks/s), {failed} failed")
    print(f"wrote {outcome.out_dir}/results.csv, results.json, results.md, sr_vs_length.png")
    if failed:  # counted as failures in the table; the exit status tells scripts too
        print(f"zfloc-study: {failed} cell(s) raised (see the error column of results.csv); re-run to retry them", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
