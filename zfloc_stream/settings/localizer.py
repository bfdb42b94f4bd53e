"""Settings of the pipeline: when rounds run and where, the consistency monitor, the
evidence a round needs (stream/localizer.py)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from .base import Section, ordered


class LocalizerSettings(Section):
    every_k_frames: int = Field(5, ge=1, le=10_000)  # a RANSAC round every k fused frames
    min_wall_points: int = Field(100, ge=1, le=10_000_000)  # BEV wall cells needed before the first round
    min_primitives: int = Field(3, ge=1, le=1000)  # lines + circles needed before the first round
    # Per-frame consistency monitor: while tracking, each fused frame's wall points are
    # checked against the tracked alignment. A run of monitor_frames frames the map does
    # not explain is a part of the building the floorplan lacks, clutter, or another place
    # (a kidnap, an odometry jump, a wrong mode); the monitor cannot tell them apart, so it
    # drops neither the track nor the BEV: it starts a kidnap test (stream/recovery.py), whose
    # own filter bank must find a place that explains those frames better, or asks for a
    # global search (kidnap_contradiction).
    monitor_distance: float = Field(0.3, gt=0, le=100)  # m, a wall point within this of a floorplan wall is consistent
    monitor_min_consistency: float = Field(0.05, ge=0, le=1)  # fraction of consistent points below which a frame is inconsistent (a jump gives ~0)
    monitor_min_points: int = Field(30, ge=1, le=1_000_000)  # frames with fewer wall points are not judged
    monitor_max_points: int = Field(400, ge=1, le=1_000_000)  # wall points checked per frame (subsampled)
    monitor_frames: int = Field(4, ge=1, le=10_000)  # consecutive inconsistent frames before a global search
    # a frame explaining less than this fraction of the tracked mode's usual share (the median
    # over its last monitor_reference_frames consistent frames) is inconsistent too
    monitor_relative_share: float = Field(0.5, ge=0, le=1)
    # after an inconsistent frame, the bar a frame must reach to be reported consistent
    # again (hysteresis on what is reported, not on the kidnap run; monitor.py)
    monitor_recovery_share: float = Field(0.7, ge=0, le=1)
    monitor_reference_frames: int = Field(20, ge=1, le=10_000)
    # a monitor run starts a kidnap test (stream/recovery.py) only if a frame of the last
    # local_frames cut through what older frames saw: this share of its wall hits landed
    # where they saw open space (RollingBEV._contradiction); else it asks for a global
    # search. Carried off, the first frame there puts 0.5-0.99 of its hits in the old
    # place's open space (the Carmen laser logs spliced), 0.24 on the built-in apartment's
    # camera; walking into a part the map lacks, under 0.01 (the built-in office with walls
    # erased), where a place 12.7 m away explains those frames better
    kidnap_contradiction: float = Field(0.15, ge=0, le=1)
    # the audit: carried to a place that looks like the old one (identical offices
    # along a corridor), the frames do not contradict the BEV and the old place still explains
    # 0.90-0.95 of each frame's hits, so neither the monitor nor the contradiction starts a
    # kidnap test. While a mode is tracked, each round tick also runs a global search on what
    # the last audit_frames frames saw alone (0: off); when it scores another place at least
    # audit_margin above the tracked one and those frames saw open space through at least
    # audit_min_violation of the tracked place's walls (its Cv), a kidnap test starts on
    # those frames (no `tracking` while it runs), adopted when its bank tracks a place its
    # round still finds so (recovery.Places.outscored). A score gap alone is no evidence: on the
    # held-out laser windows a 10-frame round prefers another place by >= 0.1 in 4.6% of
    # the audits of a correct track. To start a test (not to adopt), no violation is asked
    # when the round also scores the tracked place below audit_doubt_share of its usual
    # audit score (a camera sees little open space through walls; Audit._seen_through)
    audit_frames: int = Field(10, ge=0, le=10_000)
    audit_margin: float = Field(0.05, ge=0, le=10)
    audit_min_violation: float = Field(0.05, ge=0, le=1)
    # the audit's doubt: an audit whose round scores the tracked place below
    # audit_doubt_share of its usual audit score (the median of its earlier audits), and
    # another place at least as high, says the recent frames fit elsewhere as well; the
    # place is not `tracking` until an audit no longer finds so (also after a kidnap test
    # on it ended without adopting another place). Carried along the built-in offices, the
    # old place's audits fell to 0.59-0.80 of usual while it was still `tracking`. 0: off
    audit_doubt_share: float = Field(0.8, ge=0, le=1)
    # local refinement: odometry drifts, so a BEV of many frames is a smeared picture and the
    # alignment that fits all of it can sit off where the sensor is now. After each round
    # (and every local_every_k_frames frames) the tracked mode's alignment is refined (LM,
    # its scale kept, a truncated Huber loss so walls the map lacks do not pull) on the wall
    # hits of the last local_frames frames alone, continuing from the last accepted local
    # fit; poses use it while it fits those hits at least as well.
    local_frames: int = Field(10, ge=0, le=10_000)  # 0: off
    local_max_step: float = Field(0.2, gt=0, le=1000)  # m per fused frame since the last local refinement: a refinement that moves the recent hits farther is refused (drift is slow)
    local_max_points: int = Field(2000, ge=10, le=1_000_000)  # recent hits used (subsampled)
    local_every_k_frames: int = Field(0, ge=0, le=10_000)  # also refine locally every k fused frames between rounds (0: after rounds only)
    # What scale the odometry's translations have, at a scale prior (estimator.scale_mode
    # prior; free and fixed scales are always shared): "shared", one unknown scale for depth and
    # odometry (a monocular reconstruction; the built-in scenes), so the alignment's scale
    # maps the trajectory too; "metric", the odometry is metric (VIO, wheels) and only the
    # depth may be off (a monocular depth network): the trajectory maps at
    # estimator.scale_prior and the alignment's scale rescales each frame's hits about its
    # own camera (estimation/local_refinement.py).
    odometry_scale: Literal["shared", "metric"] = "shared"
    local_outlier_distance: float = Field(0.0, ge=0, le=100)  # m, refine.outlier_distance of the local fit (0: plain Huber)
    # after a round, hand the allocator's free pages back to the OS (glibc malloc_trim,
    # ~2 ms; heap.py) once resident memory has grown release_memory_growth MiB since the
    # last time: without it resident memory drifts by tens of MB over long sessions; after
    # every round (0), the push after it faults the stream's freed pages back in
    release_memory: bool = True
    release_memory_growth: float = Field(32.0, ge=0, le=1_000_000)  # MiB
    # glibc malloc arenas for the whole process, set when a Localizer is built (heap.py):
    # per-thread arenas let resident memory grow up to ~20 MiB per 1,000 frames with the rounds on
    # the worker thread; 0 leaves glibc's choice (8 per core)
    malloc_arenas: int = Field(2, ge=0, le=1024)
    # Where a round runs (stream/scheduler.py). online (default, the Localizer API and `run`):
    # on one worker beside the stream, applied exactly join_delay frames later; while no pose
    # exists, a preview round (first_fix_preview) gives the first pose at the frame where
    # inline gives it. Where a round runs is decided by the state at its start frame, so a
    # run replays bit for bit. inline: inside the push
    # of the frame that starts it, applied at once (studies: offline, no latency to hide).
    # pipelined: every round on the worker, applied join_delay frames later (push blocks
    # there if the worker is late), so push costs about one fusion. delayed: computed inline
    # but applied join_delay frames later: bit for bit what pipelined gives, without a worker.
    pipeline: Literal["online", "inline", "pipelined", "delayed"] = "online"
    # frames from a round's start to its result (online / pipelined / delayed); 0 = every_k_frames.
    # 1: a round started at frame i is applied at frame i + 1, so a push blocks only when a
    # round takes longer than one frame interval (~50-90 ms against 100 ms at 10 Hz). With
    # every_k_frames (5) a correction landed 5 frames late and cost real-building and scene
    # windows at #20 / #35 / #100 (docs/kernels.md); at 1 no length is below inline.
    join_delay: int = Field(1, ge=0, le=10_000)
    # online, while there is no pose and no round in flight: a preview round starts one fused
    # frame before each k-th frame, on the worker, and its best mode is reported at the k-th
    # frame, where inline reports the first fix, so no push runs a whole round. The k-th
    # frame's own round then runs on the worker like every later one and lands at the next
    # frame. The tracker never sees a preview, and a preview frame is never `tracking`. A
    # preview that gives no pose (too little evidence on one frame fewer) leaves the k-th
    # frame's round inline, so the first pose is never later than inline gives it.
    # false: that round runs inline in the k-th frame's push instead.
    first_fix_preview: bool = True
    worker: Literal["thread", "process"] = "thread"  # pipelined: where the round runs (a process has its own GIL, but pays start-up and copies)

    _ordered = ordered(("monitor_min_points", "monitor_max_points", "<="))

    @property
    def round_delay(self) -> int:
        """Frames between the start of a round and the frame its result is applied at (online:
        of the rounds that start once a pose exists; the others are inline)."""
        if self.pipeline == "inline":
            return 0
        return self.join_delay or self.every_k_frames
