"""Hybrid RANSAC over the four minimal solvers (paper 3.2-3.4) -> ranked distinct hypotheses.

One iteration = one minimal sample of BEV primitives for a solver chosen at random from
the enabled pool. Without descriptors the floorplan side of a correspondence has to be
enumerated (paper 3.2, "correspondences must be enumerated exhaustively"); the pruning
makes that affordable, with lookup tables built once per floorplan (correspondences.py):

  (i)   lines are deduplicated (floorplan: by Floorplan.lines; BEV: correspondences.BevSamples);
  (ii)  floorplan triplets / pairs are a line and its spatial neighbours
        (Floorplan.line_neighbours), BEV samples likewise (same distance, divided by the
        scale prior); all-parallel triplets and parallel pairs are never sampled;
  (iii) normal consistency: floorplan tuples are binned by the angles of their lines
        relative to the anchor line, so the tuples whose normals can agree with a BEV
        sample (|cos| > tau_p once the anchor fixes the rotation) are a handful of
        contiguous index ranges; the exact test runs in the solver before solving.

Each BEV sample then meets ceil(match_fraction x n) floorplan tuples drawn uniformly from
its n pruned candidates (all of them for match_fraction >= 1). Drawing a fraction instead
of all keeps the cost of one iteration proportional to the floorplan's ambiguity while the
probability that the true correspondence is tried somewhere in the run stays
1 - exp(-iterations_per_solver * match_fraction * P(good BEV sample)), independent of the
floorplan's size. Everything is drawn vectorised and grouped by solver.

Circle samples: 2C pairs floorplan centre pairs whose distance ratio lies in
[min_scale, max_scale]; LC pairs a line with a circle within the neighbour distance.

Scale modes reduce the pool (see solvers.py): free -> 3L, 2C, LC; prior -> all four;
fixed -> one rigid two-line solver (labelled "2L", standing in for both 3L and 2L), 2C, LC.
Solvers whose primitives are missing (no circles -> no 2C / LC) are dropped.

Scoring is coarse to fine (scoring.py: a coarse Cc for every model, the full C for the
top_k distinct ones); the REFINED_HYPOTHESES best of those are refined (field_fit.py: LM +
Huber, truncated at refine.outlier_distance, on the wall-face field), rescored with the
full C (a refinement is kept only if it does not lower C), and the list re-ranked and
de-duplicated.

Input: a BEV with neither lines nor circles is an InputError. A BEV whose primitives
suit no enabled solver (e.g. two lines at free scale) is not an error: the result simply
holds no hypothesis (besides re-scored warm starts), as early in a stream.

The candidate tables are correspondences.py's, model generation per solver
model_generation.py's, the result types results.py's; this module runs a round.
"""

from __future__ import annotations

import numpy as np

import time
from typing import Sequence

from ..runtime import threads
from ..settings.loading import EstimatorSettings
from ..errors import InputError
from .field_fit import refine_batch
from ..observation import BevObservation
from ..geometry.sim2 import Sim2
from ..runtime.ties import descending, tie_keys
from .correspondences import BevSamples, floorplan_matches, settings_of
from .model_generation import correlative_seeds, guided_models, models_2c, models_2l, models_3l, models_lc, solver_pool
from .results import CORRELATIVE, GUIDED, WARM, Hypothesis, LocalizationResult, alignment_of, model_rows
from .distinct_poses import distinct
from .scoring import floorplan_scorer, rank_coarse_to_fine, score_hypotheses, sparse_line_points
from .views import BevView
from ..prior import PRIOR, BoundPrior

# The best-ranked hypotheses LM-refined per round (field_fit.refine_batch): each costs up
# to refine.max_evaluations passes over up to refine.max_points points, so only the best
# few are refined; 10, as many as a round returns by default (ransac.max_hypotheses).
# Was estimator.refine.top_n; every recorded result used 10.
REFINED_HYPOTHESES = 10


def _missing_warm_starts(floorplan, obs, view, warm, kept: np.ndarray, anchor, cfg: EstimatorSettings) -> list[tuple]:
    """Refined, fully scored rows for the warm starts that no kept hypothesis stands for
    (same implied pose at the BEV anchor), so the tracker can judge every live mode."""
    models = model_rows(warm)
    field = floorplan_scorer(floorplan, cfg.scoring).face_field
    models = refine_batch(field, obs.wall_points, models, cfg.refine, cfg.scale_mode, (cfg.solvers.min_scale, cfg.solvers.max_scale))
    scores = score_hypotheses(floorplan, view, models, cfg.scoring)
    rows = []
    for i, m in enumerate(models):
        both = np.vstack([m[None], kept]) if len(kept) else m[None]
        if len(distinct(both, anchor, cfg.scoring)) == len(both):  # not suppressed by any kept one
            rows.append((m, scores.total[i], scores.consistency[i], scores.violation[i], WARM))
    return rows


def _usable(alignments: Sequence[Sim2]) -> list[Sim2]:
    """The finite Sim2s of a caller's warm starts or revisits (anything else is skipped)."""
    return [a for a in alignments if isinstance(a, Sim2) and a.is_finite()]


def _labels_of(labels: list[tuple[str, int]], index: np.ndarray) -> list[str]:
    """The solver (or WARM, GUIDED, CORRELATIVE) of each model in `index`, from the
    per-block (label, count) list: a round holds ~10^5 models and keeps a few dozen, so
    labels are looked up for those only."""
    block = np.searchsorted(np.cumsum([count for _, count in labels]), index, side="right")
    return [labels[b][0] for b in block]


def _ranked_rows(floorplan, obs, view, models, labels, sparse, anchor, cfg: EstimatorSettings, clock: list,
                 part: np.ndarray | None = None) -> tuple[list[tuple], np.ndarray]:
    """Coarse-to-fine ranking, LM refinement of the REFINED_HYPOTHESES best and de-duplication of the models
    (those indexed by `part`, all by default): (model, C, Cc, Cv, label) rows best first,
    and the kept model rows. clock: [wall, cpu] moved on by the ranking's time (the
    round's "scoring" stage; the rest is its "refinement")."""
    sub = models if part is None else models[part]
    t0, c0 = time.perf_counter(), time.thread_time()
    ranking = rank_coarse_to_fine(floorplan, view, sub, sparse, anchor, cfg.scoring)
    clock[0] += time.perf_counter() - t0
    clock[1] += time.thread_time() - c0
    top = ranking.index
    cand = sub[top].copy()
    total = ranking.scores.total.copy()
    cc = ranking.scores.consistency.copy()
    cv = ranking.scores.violation.copy()
    n_refine = min(REFINED_HYPOTHESES, len(top))
    scale_bounds = (cfg.solvers.min_scale, cfg.solvers.max_scale)
    if n_refine:
        field = floorplan_scorer(floorplan, cfg.scoring).face_field
        refined = refine_batch(field, obs.wall_points, cand[:n_refine], cfg.refine, cfg.scale_mode, scale_bounds)
        rescored = score_hypotheses(floorplan, view, refined, cfg.scoring)
        better = tie_keys(rescored.total) >= tie_keys(total[:n_refine])  # keep a refinement only if it does not hurt C
        cand[:n_refine][better] = refined[better]
        total[:n_refine][better] = rescored.total[better]
        cc[:n_refine][better] = rescored.consistency[better]
        cv[:n_refine][better] = rescored.violation[better]
    order = descending(total)
    keep = order[distinct(cand[order], anchor, cfg.scoring, cfg.ransac.max_hypotheses)]
    index = top[keep] if part is None else part[top[keep]]
    rows = [(cand[i], total[i], cc[i], cv[i], label) for i, label in zip(keep, _labels_of(labels, index))]
    return rows, cand[keep]


def _best_first(rows: list[tuple]) -> None:
    """Sort (model, C, Cc, Cv, label) rows in place, best C first (tie_keys: ties stable)."""
    rows.sort(key=lambda row: -float(tie_keys(np.array([row[1]]))[0]))


def _validate(obs, scale_prior: float, iterations: int) -> None:
    if not isinstance(obs, BevObservation):
        raise InputError(f"localize expects a BevObservation, got {type(obs).__name__}")
    if len(obs.lines) == 0 and len(obs.circles) == 0:
        raise InputError("BEV observation has no lines and no circles: nothing to align to the floorplan")
    if not (np.isfinite(scale_prior) and scale_prior > 0):
        raise InputError(f"scale_prior must be a positive finite number, got {scale_prior}")
    if iterations < 0:
        raise InputError(f"iterations must be >= 0, got {iterations}")


def localize(
    floorplan,
    obs: BevObservation,
    settings: EstimatorSettings,
    rng: np.random.Generator,
    *,
    scale_prior: float = 1.0,
    warm_start: Sequence[Sim2] = (),
    iterations: int | None = None,
    global_search: bool = True,
    prior: BoundPrior | None = None,
    revisit: Sequence[Sim2] = (),
) -> LocalizationResult:
    """Align the BEV observation to the floorplan; hypotheses ranked best first.

    global_search: also seed with the exhaustive correlative search (fixed or prior
    scale, estimator.correlative.enabled); a round that only follows a tracked mode
    passes False.

    prior: a pose prior (prior.py) adds seeds over its gate to a global search, and the
    hypotheses inside and outside it are ranked apart (each up to max_hypotheses), so the
    places it names are never crowded out and the best place elsewhere is still known.

    revisit: alignments scored again beside the warm starts, without sampling around them
    (the previous round's runners-up): each comes back refined and scored unless a kept
    hypothesis stands for it.

    Runs its independent pieces on estimator.threads threads (threads.py), unless the
    caller set the round's thread count already (stream/scheduler.py's run_round)."""
    with threads.limit(threads.resolve(settings.threads), unless_set=True):
        return _localize(floorplan, obs, settings, rng, scale_prior, warm_start, iterations, global_search, prior, revisit)


def _localize(floorplan, obs: BevObservation, settings: EstimatorSettings, rng: np.random.Generator, scale_prior: float,
              warm_start: Sequence[Sim2], iterations: int | None, global_search: bool,
              prior: BoundPrior | None = None, revisit: Sequence[Sim2] = ()) -> LocalizationResult:
    cfg = settings
    iterations = cfg.ransac.iterations if iterations is None else int(iterations)
    _validate(obs, scale_prior, iterations)
    if cfg.scale_mode == "prior":  # the prior bounds every solver, the refinement and the seeds
        lo, hi = scale_prior / (1.0 + cfg.solvers.prior_range), scale_prior * (1.0 + cfg.solvers.prior_range)
        bounded = {"min_scale": max(cfg.solvers.min_scale, lo), "max_scale": min(cfg.solvers.max_scale, hi)}
        cfg = cfg.model_copy(update={"solvers": cfg.solvers.model_copy(update=bounded)})
    t0, c0 = time.perf_counter(), time.thread_time()

    # ---- model estimation ------------------------------------------------------------
    full_cfg = settings_of(floorplan)
    fp = floorplan_matches(floorplan, cfg.solvers)
    bev = BevSamples(obs, full_cfg.primitives.lines, cfg.solvers, full_cfg.floorplan.neighbour_distance / scale_prior)
    pool = solver_pool(cfg, bev, fp)
    warm = _usable(warm_start)
    blocks, labels = [], []  # labels: (solver, model count) per block, in block order
    if pool and iterations > 0:
        counts = np.bincount(rng.integers(len(pool), size=iterations), minlength=len(pool))
        for name, n in zip(pool, counts):
            if n == 0:
                continue
            if name == "3L":
                m = models_3l(bev, fp, int(n), cfg, rng)
            elif name == "2L":
                m = models_2l(bev, fp, int(n), cfg, rng, scale_prior)
            elif name == "LC":
                m = models_lc(bev, fp, int(n), cfg, rng)
            else:
                m = models_2c(bev, fp, int(n), cfg, rng)
            blocks.append(m)
            labels.append((name, len(m)))
    if warm:
        blocks.append(model_rows(warm))
        labels.append((WARM, len(warm)))
        guided_modes = warm[: cfg.ransac.guided_modes]
        per_mode = cfg.ransac.guided_iterations // max(1, len(guided_modes))
        for w in guided_modes:
            m = guided_models(bev, fp, w, per_mode, cfg, rng, scale_prior)
            blocks.append(m)
            labels.append((GUIDED, len(m)))
    if global_search and cfg.correlative.enabled and cfg.scale_mode != "free":
        seeds = correlative_seeds(floorplan, obs, cfg, scale_prior, across_prior=not warm)
        blocks.append(seeds)
        labels.append((CORRELATIVE, len(seeds)))
    if prior is not None and global_search:
        seeds = prior.seeds(scale_prior if cfg.scale_mode != "fixed" else 1.0)
        blocks.append(seeds)
        labels.append((PRIOR, len(seeds)))
    models = np.concatenate(blocks) if blocks else np.zeros((0, 4))
    t1, c1 = time.perf_counter(), time.thread_time()

    # ---- scoring -----------------------------------------------------------------------
    anchor = obs.wall_points.mean(axis=0)
    if len(models) == 0:
        zero = {"scoring": 0.0, "refinement": 0.0}
        return LocalizationResult([], {"model_estimation": t1 - t0, **zero}, 0, {"model_estimation": c1 - c0, **zero})
    sparse = sparse_line_points(bev.lines, cfg.scoring.sparse_spacing, cfg.scoring.max_sparse_points)
    view = BevView.of(obs, cfg.scoring.tau_v)
    ranking_clock = [time.perf_counter(), time.thread_time()]  # "scoring" ends here plus each ranking's own time
    if prior is None:
        rows, kept = _ranked_rows(floorplan, obs, view, models, labels, sparse, anchor, cfg, ranking_clock)
    else:  # inside and outside the prior apart: neither crowds the other out
        inside = prior.inside(models)
        rows, kept = [], []
        for part in (np.flatnonzero(inside), np.flatnonzero(~inside)):
            if len(part):
                r, k = _ranked_rows(floorplan, obs, view, models, labels, sparse, anchor, cfg, ranking_clock, part)
                rows, kept = rows + r, kept + [k]
        _best_first(rows)
        kept = np.concatenate(kept) if kept else np.zeros((0, 4))
    t2, c2 = ranking_clock
    # every live mode (and each runner-up to revisit) gets its fresh score, even when it ranks below max_hypotheses
    again = warm + _usable(revisit)
    if again:
        rows += _missing_warm_starts(floorplan, obs, view, again, kept, anchor, cfg)
        _best_first(rows)
    t3, c3 = time.perf_counter(), time.thread_time()

    hypotheses = [Hypothesis(alignment_of(m), float(c), float(a), float(v), label) for m, c, a, v, label in rows]
    timings = {"model_estimation": t1 - t0, "scoring": t2 - t1, "refinement": t3 - t2}
    cpu = {"model_estimation": c1 - c0, "scoring": c2 - c1, "refinement": c3 - c2}
    return LocalizationResult(hypotheses, timings, int(len(models)), cpu)
