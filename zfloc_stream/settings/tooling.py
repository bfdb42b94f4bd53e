"""Settings of the tools around the pipeline: the session log, studies, replay."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from .base import Section, ordered


class LoggingSettings(Section):
    """MCAP session logs (zfloc_stream/session): what is written, how it is chunked, and
    how files from other tools are read. Never affects the estimates."""

    compression: Literal["zstd", "lz4", "none"] = "zstd"  # per-chunk compression
    chunk_size: int = Field(1048576, ge=1024, le=1 << 30)  # bytes; a chunk is closed once its records exceed this...
    # ...or once it holds this many complete frames (closed right after the frame's
    # estimate): what a killed process can lose besides the frame in flight. 1 measured
    # cheap (360-beam laser frames: +0.5 ms written and +19 % bytes per frame against 10;
    # 240x320 camera frames: no cost) and it loses nothing (benchmarks/bench_signals.py:
    # 10 kills, 0 frames lost; with 10, up to 8)
    chunk_max_frames: int = Field(1, ge=1, le=1_000_000)
    bev_every_n_frames: int = Field(10, ge=0, le=1_000_000)  # publish /zfloc/bev every n frames (0 = never)
    background: bool = True  # compress + write on a worker thread (the caller only serializes)
    max_pending_batches: int = Field(4, ge=1, le=10_000)  # batches (2 per frame) queued for the worker; a crash loses them too
    foreign_scan_range_min: float = Field(0.01, ge=0, le=1000)  # m, LaserScan without zfloc range metadata
    foreign_scan_range_max: float = Field(100.0, gt=0, le=10_000)  # m
    # MiB of chunks a read may hold at once to hand messages on in log-time order: a file
    # in order holds one chunk, one grouped by topic one per topic (session/ordering.py)
    reorder_max_mb: int = Field(2048, ge=1, le=1 << 20)
    success_distance: float = Field(1.0, gt=0, le=1000)  # m, replay summary: SR@1m as in the paper...
    success_last_frames: int = Field(10, ge=1, le=1_000_000)  # ...every one of the final frames within the distance

    _ordered = ordered(("foreign_scan_range_min", "foreign_scan_range_max"))


class StudySettings(Section):
    """SR-vs-length studies (F3Loc protocol)."""

    eval_frames: int = Field(10, ge=1, le=1_000_000)  # success/RMSE look at this many final frames of a chunk
    thresholds: list[Annotated[float, Field(gt=0, le=1000)]] = Field([1.0, 0.5], min_length=1)  # m, success thresholds reported (<= counts as success)
    max_chunks_per_sequence: int = Field(20, ge=1, le=1_000_000)  # consecutive non-overlapping chunks kept per sequence and length
    connect_timeout_s: float = Field(10.0, gt=0, le=86_400)  # s, waiting for a remote dask scheduler (--scheduler)


class ReplaySettings(Section):
    """zfloc-replay --check: decisions (statuses, modes, hypothesis counts, skips) must
    match exactly; numbers within atol + rtol * max(|logged|, |replayed|), because another
    CPU or BLAS may change their last bits (--exact: bit for bit). Never affects the estimates."""

    # relative tolerance on logged numbers: chained LM fits (scan matching corrects every
    # frame's pose from the last one's, the local refinement continues from its last
    # result) carry a last-bit difference on; measured with a perturbed BLAS and numpy
    # SIMD off: up to 4e-6 relative (2.7e-7 m on a lower-ranked hypothesis' pose)
    rtol: float = Field(1e-5, ge=0, le=1)
    atol: float = Field(1e-6, ge=0, le=1)  # absolute tolerance (numbers near zero; 1 micrometre)
