"""Scan-to-BEV matching: a frame's wall hits aligned to the walls already in the BEV
before they are fused, so odometry drift does not smear the map.

Odometry drifts (a real robot's wheel odometry, or the benchmark's 2% of each step plus
0.3 deg per step): a BEV fused from raw odometry poses holds the same wall several
times, a little rotated each time, and after a few tens of frames on a turning path the
alignment that fits the whole BEV is off where the sensor is now (on the real Intel log,
20 frames in, the true alignment at the current frame explained 20% of the BEV wall
points). A robot's SLAM front end corrects this by matching each scan to the map built so
far; this module is that step, for the BEV: the scan's hits are aligned to the distance
field of the BEV's wall cells around them (rigid, Levenberg-Marquardt with a truncated
Huber loss, so walls seen for the first time do not pull) about the sensor position, and
the correction is kept only when it is a small step (odometry is good over one frame),
lowers the robust cost by at least MIN_GAIN (a smaller gain is the grid's
quantisation and the range noise being fitted) and does not lower the share of hits on BEV
walls. The floorplan is never involved: a wrong
localization hypothesis cannot bend the map toward itself.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..settings.loading import BevSettings, RefineSettings
from ..estimation.field_fit import field_value_and_gradient, huber_cost, refine_batch, thin_points
from ..runtime.numba_support import njit
from ..geometry.grid import Grid
from ..geometry.sim2 import wrap_angle


@dataclass(frozen=True)
class GridField:
    """A distance field on a grid crop, in the layout refine_batch reads."""

    distance_field: np.ndarray
    origin: np.ndarray
    resolution: float


# m, a hit this close to a BEV wall is on it (three 0.05 m cells; was bev.scan_match_inlier_distance)
INLIER_DISTANCE = 0.15
# The fit's loss in units of INLIER_DISTANCE: quadratic (Huber) up to half of
# it, so a hit on a wall pulls in proportion to its miss; a hit beyond twice it is furniture
# or a wall the BEV has not seen yet and does not pull at all.
HUBER_DELTA_PER_INLIER = 0.5
OUTLIER_PER_INLIER = 2.0
# The matcher's effort and its bar (were bev.scan_match_*; every recorded result used these:
# the replay samples' laser run and eval_real's laser windows). What a user sets is which
# frames are matched and how far one may move (bev.scan_match, scan_match_max_shift, ...).
MIN_WALLS = 50  # BEV wall cells near the scan (and scan hits) needed to match; on fewer no match is tried
MAX_POINTS = 200  # hits used (evenly thinned): a one-frame step needs few; the cost grows with them
MAX_EVALUATIONS = 15  # LM cost evaluations per frame: a one-frame step from a good start converges in a few
ANGLE_STEP_DEG = 0.5  # the coarse rotation search's step before the LM (at 15 m half a step moves a hit 0.065 m, inside INLIER_DISTANCE)
MIN_GAIN = 0.2  # a correction must lower the hits' robust cost by this fraction (else it fits the grid's quantisation, not drift)

def step_bounds(last_odometry, odometry, settings: BevSettings) -> tuple[float, float]:
    """The largest correction (metres, radians) scan matching may make to a frame whose
    odometry plane pose is `odometry` (x, y, yaw), `last_odometry` the previous matched
    frame's (None: the first). Odometry errs in proportion to the motion it measures, so the
    bounds grow with the step and the turn since that frame: a sparse log (1 m and 15-75 deg
    between scans) needs wider bounds than a 10 Hz stream, and a sensor standing still
    (or carried off while its odometry stands still) gets only the base bounds."""
    shift, angle = settings.scan_match_max_shift, np.deg2rad(settings.scan_match_max_angle_deg)
    if last_odometry is None:
        return shift, angle
    step = float(np.hypot(odometry[0] - last_odometry[0], odometry[1] - last_odometry[1]))
    turn = abs(float(wrap_angle(odometry[2] - last_odometry[2])))
    return shift + settings.scan_match_shift_per_step * step, angle + settings.scan_match_angle_per_turn * turn


def match_scan(wall_mask: np.ndarray, crop_origin: np.ndarray, resolution: float, hits: np.ndarray,
               centre: np.ndarray, max_shift: float, max_angle: float) -> tuple[float, np.ndarray] | None:
    """Rigid correction (dtheta, dt) that moves the hits (plane frame) onto the walls of
    wall_mask (a BEV crop whose cell (0, 0) has its corner at crop_origin), as
    x' = R(dtheta) (x - centre) + centre + dt; None when the crop holds too few walls to
    match against or the step is refused."""
    if wall_mask.sum() < MIN_WALLS or len(hits) < MIN_WALLS:
        return None
    # distance (m) from every crop cell to the nearest wall cell, about the sensor
    # (the 3x3 L2 approximation: a few percent off the exact distance, 4x cheaper on a
    # 600x600 crop, and the loss is cut at 2 x INLIER_DISTANCE anyway)
    field = cv2.distanceTransform((~wall_mask).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_3)
    grid = GridField(field.astype(np.float64) * resolution, np.asarray(crop_origin, float) - centre, resolution)
    points = thin_points(hits - centre, MAX_POINTS)
    near = INLIER_DISTANCE
    delta = HUBER_DELTA_PER_INLIER * near
    refine = RefineSettings(outlier_distance=OUTLIER_PER_INLIER * near, max_points=MAX_POINTS, max_evaluations=MAX_EVALUATIONS)
    # LM from the odometry and from the best rotation; the rotated start wins only when it
    # fits clearly better (by MIN_GAIN, like any correction): where both fit
    # about as well the odometry is believed
    theta = _best_rotation(grid.distance_field, grid.origin, resolution, points, delta,
                           refine.outlier_distance, max_angle, np.deg2rad(ANGLE_STEP_DEG))
    starts = np.array([[0.0, 0.0, 0.0, 1.0], [0.0, 0.0, theta, 1.0]][: 1 + (theta != 0.0)])

    def cost(p: np.ndarray) -> float:  # the fit's robust cost of hits placed at p
        return huber_cost(_residuals(grid, p), delta, refine.outlier_distance)

    keep = 1.0 - MIN_GAIN  # a correction must bring the cost below this share
    models = refine_batch(grid, points, starts, refine, "fixed", huber_delta=delta)
    moved_by = [_moved(points, m) for m in models]
    costs = [cost(p) for p in moved_by]
    k = len(models) - 1 if costs[-1] < keep * costs[0] else 0
    model, moved = models[k], moved_by[k]
    dt, dtheta = model[:2], float(model[2])
    if not np.isfinite(model).all() or np.hypot(*dt) > max_shift or abs(dtheta) > max_angle:
        return None
    # A step that fits the hits only a little better is fitting the grid's quantisation and
    # the range noise, not drift: taken, such steps would random-walk a perfect odometry
    # away. Drift of a few centimetres on hits that sit within a cell of their walls halves
    # the cost; noise fitting gains a few percent.
    if costs[k] > keep * cost(points):
        return None
    if _share_near(grid, moved, near) < _share_near(grid, points, near):
        return None
    return dtheta, dt


def _moved(points: np.ndarray, model: np.ndarray) -> np.ndarray:
    """The points under a rigid model row (tx, ty, theta, 1)."""
    c, s = np.cos(model[2]), np.sin(model[2])
    return points @ np.array([[c, s], [-s, c]]) + model[:2]


def _residuals(grid: GridField, points: np.ndarray) -> np.ndarray:
    return field_value_and_gradient(grid, points)[0]


def _share_near(grid: GridField, points: np.ndarray, distance: float) -> float:
    row, col, inside = Grid(grid.origin, grid.resolution, grid.distance_field.shape).cells(points)
    d = np.full(len(points), np.inf)
    d[inside] = grid.distance_field[row[inside], col[inside]]
    return float(np.mean(d < distance))


@njit
def _best_rotation(field, origin, resolution, points, delta, cutoff, max_angle, angle_step):
    """The rotation about the sensor, every angle_step within +-max_angle, whose hits cost
    least by the fit's truncated Huber loss, each hit read at its nearest cell; ties go to
    the smaller angle. The LM starts there as well as at the odometry: from the odometry
    alone it cannot see a wall more than the loss's cutoff away, and a few degrees of
    heading error put the hits at a few metres' range that far off. Rotation only: the
    translation error of one step stays inside the LM's reach, and a shift search finds
    the repeats of a corridor (the built-in office: 0.25-0.3 m jumps along it)."""
    h, w = field.shape
    n_angles = int(np.floor(max_angle / angle_step + 1e-9))
    best, best_cost = 0.0, np.inf
    for step in range(0, 2 * n_angles + 1):
        # 0, +1, -1, +2, -2, ...: a strictly lower cost is needed to move away from zero
        ia = (step + 1) // 2 if step % 2 else -(step // 2)
        theta = ia * angle_step
        c, s = np.cos(theta), np.sin(theta)
        cost = 0.0
        for k in range(len(points)):
            col = int(np.floor((c * points[k, 0] - s * points[k, 1] - origin[0]) / resolution))
            row = int(np.floor((s * points[k, 0] + c * points[k, 1] - origin[1]) / resolution))
            a = cutoff
            if 0 <= col < w and 0 <= row < h:
                a = min(field[row, col], cutoff)
            cost += 0.5 * a * a if a <= delta else delta * (a - 0.5 * delta)
            if cost >= best_cost:
                break
        if cost < best_cost:
            best, best_cost = theta, cost
    return best
