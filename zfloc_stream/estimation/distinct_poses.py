"""Distinct hypotheses (paper 3.3's ranking): greedy non-maximum suppression on the pose a
model implies for the BEV's anchor point, so the re-scored top_k are not one cluster.

distinct keeps, in the given order (best first), a hypothesis unless a kept one implies an
anchor position within distinct_translation AND a heading within distinct_angle_deg;
top_distinct is rank_coarse_to_fine's choice of the top_k distinct by coarse score,
computed on a prefix of the ranking (descending_prefix) since the greedy pass never looks
ahead. The greedy pass is compiled (numba).
"""

from __future__ import annotations

import math

import numpy as np

from ..runtime.numba_support import njit
from ..runtime.ties import tie_keys
from ..settings.loading import ScoringSettings
from .views import implied_poses

# Greedy distinct-pose suppression runs on a prefix of the ranked models (it never looks
# ahead, so a prefix yields the same first survivors as the whole list). The first prefix
# holds PREFIX_PER_KEPT models per wanted survivor, at least PREFIX_MIN, and grows
# PREFIX_GROWTH-fold while it yields too few: work sizes only, the result does not depend on them.
PREFIX_MIN = 256
PREFIX_PER_KEPT = 16
PREFIX_GROWTH = 4


@njit
def _greedy_distinct_kernel(x, y, ang, max_distance, max_angle, limit, kept):
    """Greedy suppression: walks the hypotheses in order and keeps one unless a kept one
    lies within max_distance (hypot of the implied-position difference) and max_angle
    (|wrap_angle| of the heading difference), until `limit` are kept; returns how many
    (their indices in kept)."""
    two_pi = 2.0 * np.pi
    n_kept = 0
    for j in range(x.shape[0]):
        if n_kept >= limit:
            break
        alone = True
        for k in range(n_kept):
            i = kept[k]
            # wrap_angle(ang[j] - ang[i]) = (d + pi) % (2 pi) - pi
            if math.hypot(x[j] - x[i], y[j] - y[i]) < max_distance and \
                    abs((ang[j] - ang[i] + np.pi) % two_pi - np.pi) < max_angle:
                alone = False
                break
        if alone:
            kept[n_kept] = j
            n_kept += 1
    return n_kept


def descending_prefix(values: np.ndarray, length: int) -> np.ndarray:
    """The first entries, at least `length` of them (all when there are fewer values), of
    ties.descending(values), the same indices in the same order, without sorting
    everything.

    descending orders by (-tie_keys(values), index), stably. With v the length-th smallest
    key (np.partition), the indices whose key is <= v are exactly a prefix of that order
    (every other key is larger, or NaN, which sorts last), and sorting them stably, in index
    order, by key orders them as descending does. Ties at v are all taken, so the prefix
    may be longer than `length`."""
    keys = -tie_keys(values)
    if length >= len(keys):
        return np.argsort(keys, kind="stable")
    v = np.partition(keys, length - 1)[length - 1]
    if np.isnan(v):  # fewer than `length` non-NaN keys: NaNs order among themselves by index
        return np.argsort(keys, kind="stable")
    candidates = np.flatnonzero(keys <= v)
    return candidates[np.argsort(keys[candidates], kind="stable")]


def top_distinct(models: np.ndarray, coarse: np.ndarray, anchor: np.ndarray, settings) -> np.ndarray:
    """rank_coarse_to_fine's choice, order[distinct(models[order], anchor, settings,
    settings.top_k)] with order = descending(coarse), the same indices in the same order.

    Greedy suppression never looks ahead, so the first top_k survivors depend only on the
    order's prefix up to the last of them (distinct itself grows its block on that
    ground): only a prefix of the order is computed (descending_prefix), only its implied
    poses (implied_poses row by row, the same numbers as on the whole list) and the
    greedy pass runs compiled. The prefix grows 4x while it yields fewer than top_k."""
    models = np.asarray(models, dtype=float).reshape(-1, 4)
    n, limit = len(models), int(settings.top_k)
    if n == 0 or limit <= 0:
        return np.zeros(0, dtype=np.int64)
    max_angle = float(np.deg2rad(settings.distinct_angle_deg))
    length = min(n, max(PREFIX_MIN, PREFIX_PER_KEPT * limit))
    while True:
        order = descending_prefix(coarse, length)
        rows = models[order]
        pos, ang = implied_poses(rows, anchor)
        kept = np.empty(limit, dtype=np.int64)
        count = _greedy_distinct_kernel(np.ascontiguousarray(pos[:, 0]), np.ascontiguousarray(pos[:, 1]),
                                        np.ascontiguousarray(ang), float(settings.distinct_translation),
                                        max_angle, limit, kept)
        if count >= limit or len(order) >= n:
            return order[kept[:count]]
        length = min(n, PREFIX_GROWTH * len(order))


def distinct(models: np.ndarray, anchor: np.ndarray, settings: ScoringSettings, limit: int | None = None) -> np.ndarray:
    """Indices (in the given order, which must be best first) of hypotheses kept by greedy
    suppression: a hypothesis is dropped when a better kept one implies a BEV-anchor
    position within distinct_translation AND a heading within distinct_angle_deg."""
    models = np.asarray(models, dtype=float).reshape(-1, 4)
    n = len(models)
    limit = n if limit is None else int(limit)
    if n == 0 or limit <= 0:
        return np.zeros(0, dtype=np.int64)
    pos, ang = implied_poses(models, anchor)
    max_angle = np.deg2rad(settings.distinct_angle_deg)
    # Greedy suppression in order never looks ahead, so running it on a prefix gives the
    # same first survivors as on the whole list: grow the prefix only when it runs dry.
    block = min(n, max(PREFIX_MIN, PREFIX_PER_KEPT * limit))
    kept = np.empty(limit, dtype=np.int64)
    x, y, ang = (np.ascontiguousarray(a) for a in (pos[:, 0], pos[:, 1], ang))
    while True:
        count = _greedy_distinct_kernel(x[:block], y[:block], ang[:block], float(settings.distinct_translation), float(max_angle), limit, kept)
        if count >= limit or block >= n:
            return kept[:count].copy()
        block = min(n, PREFIX_GROWTH * block)
