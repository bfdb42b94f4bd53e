"""Settings of the estimation stage: primitives (lines, circles), the minimal solvers, scoring,
refinement, RANSAC, the correlative seeds (estimation/, line_growing.py, circle_fitting.py)."""

from __future__ import annotations

import warnings
from typing import Literal

from pydantic import Field, model_validator

from .base import Section, ordered


SolverName = Literal["3L", "2L", "2C", "LC"]
ScaleMode = Literal["free", "prior", "fixed"]


class LineSettings(Section):
    """Seeded region growing (paper 3.1)."""

    gap: float = Field(0.3, gt=0, le=10)  # m, largest gap along a line before it is split
    min_points: int = Field(8, ge=2, le=100_000)
    min_length: float = Field(0.5, ge=0, le=100)  # m
    dedup_angle_deg: float = Field(5.0, ge=0, le=90)  # near-duplicate suppression
    dedup_offset: float = Field(0.15, ge=0, le=10)  # m


class CircleSettings(Section):
    """HDBSCAN clustering + 3-point RANSAC + angular checks (paper 3.1)."""

    min_radius: float = Field(0.1, gt=0, le=10)  # m
    max_radius: float = Field(1.0, gt=0, le=10)  # m

    _ordered = ordered(("min_radius", "max_radius"))


class PrimitiveSettings(Section):
    lines: LineSettings = LineSettings()
    circles: CircleSettings = CircleSettings()


class SolverSettings(Section):
    pool: list[SolverName] = Field(["3L", "2L", "2C", "LC"], min_length=1)
    scale_prior_prob: float = Field(0.8, gt=0, lt=1)  # P(|eps| <= scale_prior_window * s) = this
    scale_prior_window: float = Field(0.1, ge=0, le=1)
    min_scale: float = Field(0.5, gt=0, le=100)  # models outside [min_scale, max_scale] are discarded
    max_scale: float = Field(2.0, gt=0, le=100)
    prior_range: float = Field(0.15, gt=0, le=10)  # prior mode: scales outside prior * [1 / (1 + r), 1 + r] are discarded too (depth cameras and VIO: a few %; monocular depth networks: ~10 %)

    _ordered = ordered(("min_scale", "max_scale"))


class ScoringSettings(Section):
    tau_c: float = Field(0.1, gt=0, le=10)  # m, consistency threshold (paper)
    tau_v: float = Field(0.2, gt=0, le=10)  # m, violation threshold (paper)
    violation_weight: float = Field(1.0, ge=0, le=10)  # C = Cc - w * Cv (1 = the paper's C)
    # Cv's denominator: "free", the paper's (floorplan wall points landing in observed free
    # space), or "observed" (those landing in any observed cell, free or a BEV wall). Where
    # the map's walls mostly land on seen walls, as at the truth, the paper's denominator is
    # a handful of points (clutter, a door the map has closed) and Cv jumps to 0.4-0.6.
    violation_per: Literal["free", "observed"] = "free"
    sparse_spacing: float = Field(0.25, gt=0, le=10)  # m, spacing of BEV line samples for the coarse pass
    max_sparse_points: int = Field(128, ge=1, le=1_000_000)  # ...widened so the coarse pass uses about this many points at most
    top_k: int = Field(50, ge=1, le=100_000)  # hypotheses re-ranked with the full score
    distinct_translation: float = Field(0.5, ge=0, le=1000)  # m, hypotheses closer than this (and distinct_angle) are one
    distinct_angle_deg: float = Field(10.0, ge=0, le=180)
    # (hypotheses x points) elements per block of the torch scorer: bounds its tensors' memory
    # (the compiled kernels of the numpy backend build no temporaries and ignore it)
    chunk_size: int = Field(1_000_000, ge=1000, le=1_000_000_000)
    wall_bucket_size: float = Field(2.0, ge=0.1, le=100)  # m, Cv fetches floorplan wall points by buckets of this size (speed only)
    # where the scores are computed: "numpy" is the CPU path, scoring.py's compiled (numba)
    # kernels (the name is kept so existing configs stay valid); "torch" is the [torch] extra's
    # estimation/scoring_torch.py on scoring.device (auto: CUDA when present), equal to the
    # compiled kernels bit for bit on CPU, within one point in N per hypothesis on a GPU
    backend: Literal["numpy", "torch"] = "numpy"
    device: str = "auto"


class RefineSettings(Section):
    max_evaluations: int = Field(30, ge=1, le=10_000)  # residual evaluations per hypothesis (converges in ~10)
    max_points: int = Field(1000, ge=10, le=1_000_000)  # BEV wall points used by the refinement (evenly thinned)
    tolerance: float = Field(1e-4, gt=0, le=1)  # stop: relative cost decrease, step or gradient below this
    # m, residuals beyond this carry no weight (a truncated Huber loss): points of a room the
    # map lacks, or clutter a drawn plan leaves out, stop pulling the fit. 0: plain Huber
    # (every point pulls): on plans that drew the fit up to 1.6 deg and 0.3 m off the true
    # alignment, into the free-space violation that then lost the round (docs/plans.md).
    outlier_distance: float = Field(0.5, ge=0, le=100)


class RansacSettings(Section):
    iterations: int = Field(500, ge=1, le=1_000_000)  # BEV minimal samples per localization (solver drawn at random per sample)
    tracking_iterations: int = Field(150, ge=1, le=1_000_000)  # fewer fresh samples while one mode is tracked
    max_hypotheses: int = Field(10, ge=1, le=1000)  # ranked distinct hypotheses returned
    match_fraction: float = Field(0.03, gt=0, le=1)  # each BEV minimal sample meets this fraction (>= 1) of its pruned floorplan matches
    # guided samples near the live modes (warm start): BEV lines matched only to the
    # floorplan lines they lie on under a mode's alignment
    guided_iterations: int = Field(100, ge=0, le=1_000_000)  # per round, split over the guided modes
    guided_modes: int = Field(3, ge=0, le=100)  # the heaviest live modes sampled around
    guided_distance: float = Field(0.5, gt=0, le=100)  # m, a BEV segment's ends within this of a floorplan line match it
    guided_angle_deg: float = Field(10.0, gt=0, le=90)  # and its direction within this
    guided_shift: float = Field(2.0, gt=0, le=1000)  # m, translation change from the mode beyond which a guided model is dropped


class CorrelativeSettings(Section):
    """Exhaustive correlative seeding (estimation/correlative.py) at a known or prior scale:
    every rotation and translation on a coarse grid counted by BEV wall points near a
    floorplan wall; the best distinct placements are LM-refined and join the RANSAC pool.
    Minimal samples need the right line correspondences among thousands on a map built
    from scans; the exhaustive count does not, and costs one FFT correlation per angle."""

    enabled: bool = True  # runs in global rounds (not while confidently tracking), fixed or prior scale only
    cell: float = Field(0.25, ge=0.01, le=10)  # m, translation grid (and rasterisation of the BEV points)
    angle_step_deg: float = Field(4.0, ge=0.1, le=90)  # rotation grid
    tolerance: float = Field(0.3, gt=0, le=10)  # m, a point within this of a wall counts (coarse grid: about cell + LM basin)
    peaks: int = Field(10, ge=1, le=1000)  # distinct placements refined and added to the hypotheses
    # two placements are distinct when the BEV's centre lands farther apart than this...
    distinct_distance: float = Field(1.0, gt=0, le=1000)  # m
    distinct_angle_deg: float = Field(10.0, gt=0, le=180)  # ...or their rotations differ by more than this
    # At a scale prior, a round that follows no live mode (the first ones, or after every
    # mode was lost) searches at this many scales spread geometrically over the prior's
    # range (solvers.prior_range), not at the prior alone: a depth network's global scale
    # error of 9% moves a wall 5 m away by 0.45 m, past the tolerance, so the search at the
    # prior finds nothing near the truth. Three scales 7% apart (with the default range)
    # leave no scale within +-10% more than 3.5% from a searched one (0.18 m at 5 m).
    # Rounds with live modes search at the prior only (the modes carry their refined
    # scales); 1: the prior only, always.
    scales: int = Field(3, ge=1, le=9)


class EstimatorSettings(Section):
    # The hot loops of a round are compiled (numba) and have one implementation each, so
    # the former estimator.kernels (numpy | numba) chooses nothing: older configs and
    # session files that name it still load, with a FutureWarning, and it is dropped.
    @model_validator(mode="before")
    @classmethod
    def _drop_kernels(cls, data):
        if isinstance(data, dict) and "kernels" in data:
            data = {k: v for k, v in data.items() if k != "kernels"}
            warnings.warn("estimator.kernels is ignored: the compiled kernels are the only implementation "
                          "(remove it from the config)", FutureWarning, stacklevel=2)
        return data

    # prior: metric input (depth camera, VIO, depth network) known to about prior_range;
    # fixed: exactly metric (a laser; sources that know set it); free: any scale in
    # [min_scale, max_scale] (the paper's setting, on request).
    scale_mode: ScaleMode = "prior"
    scale_prior: float = Field(1.0, gt=0, le=100)  # expected BEV -> floorplan scale in prior mode (1 = both metric)
    solvers: SolverSettings = SolverSettings()
    correlative: CorrelativeSettings = CorrelativeSettings()
    scoring: ScoringSettings = ScoringSettings()
    refine: RefineSettings = RefineSettings()
    ransac: RansacSettings = RansacSettings()
    # Threads one round may use for its independent pieces (zfloc_stream/runtime/threads.py: the
    # correlative angles, the 3L draws, scoring and refining batches of hypotheses; the
    # compiled kernels only): the same bits with any count. 0 (auto): the cores this
    # process may use (at most threads.AUTO_MAX), on the worker beside the stream too: a
    # push needs a few ms per frame, and a round kept off the stream's core outlasted a
    # 10 Hz frame interval, so the next push waited for it (docs/performance.md).
    threads: int = Field(0, ge=0, le=256)
