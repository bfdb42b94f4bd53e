"""The pose prior: what the caller knows of where the sensor is (AMCL's initial pose).

A Prior is a pose (x, y, heading in radians, floorplan frame) with standard deviations,
a region (a polygon the position lies in), or both. It describes one frame: the first
one at construction (settings.prior), the next pushed one after
Localizer.set_initial_pose. Bound to that frame's odometry-plane pose (BoundPrior) it
becomes a gate on alignments: an alignment agrees with the prior when the pose it implies
for that frame lies within prior.gate_sigmas sigmas (position and heading apart) and
inside the region. Odometry carries the frame's pose along, so the gate holds at any
later round.

Who uses it:
- the round's search (estimation/ransac.py): a pose prior adds a grid of seeds over its
  gate, and the hypotheses inside and outside the gate are ranked apart, so the places the
  prior names are never crowded out by better-looking ones elsewhere, and the best place
  elsewhere is still known;
- the localizer (PriorWatch, below): while the prior holds, the hypotheses outside it are
  pruned before the tracker sees them, those inside enter with the prior's log density
  added (divided by tracking.weight_gain: the tracker's weights become the posterior's), a mode born inside it in a round whose best
  hypothesis lies inside is confirmed sooner (confirm_rounds), and a round whose best
  hypothesis outside scores more than contradiction_gap above the best inside (or that
  has none inside) contradicts it: after
  contradiction_rounds such rounds the prior is dropped (a round whose best outside leads by
  more than doubt_gap only withholds `tracking`: the prior chose, the frames do not back it), the tracker starts over on the
  evidence alone and the Estimate says so (Estimate.prior == "contradicted"). The prior is
  let go ("released") once a mode inside it was tracked release_rounds rounds and the
  round's evidence alone singles it out (after_round).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from .errors import InputError
from .settings.prior import PriorSettings
from .geometry.sim2 import Sim2, wrap_angle

PRIOR = "prior"  # the solver label of the seeds a pose prior adds (estimation.results.Hypothesis.solver)
# m: two rounds' best places outside the prior are one place when the poses they imply for
# the prior's frame are this close (a place found again is refined to within a few cm; the
# spurious winners of a small BEV where the map lacks the place jump by metres from round to
# round: held-out windows, /work/notes measurements in docs/measurements/prior.md)
SAME_PLACE = 1.0
# an unverified pose (the prior's own) never reaches a confidence threshold of this or above
PRIOR_POSE_MAX_CONFIDENCE = 0.5


def _finite(values, what: str) -> np.ndarray:
    try:
        out = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"prior: {what} must be numbers, got {values!r}") from None
    if not np.isfinite(out).all():
        raise InputError(f"prior: {what} must be finite numbers, got {values!r}")
    return out


def polygon_area(vertices: np.ndarray) -> float:
    x, y = vertices[:, 0], vertices[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def inside_polygon(points: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """Even-odd rule: which points lie inside the polygon (vertices (N, 2), not closed)."""
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    x, y = points[:, 0:1], points[:, 1:2]
    a, b = vertices, np.roll(vertices, -1, axis=0)
    crosses = (a[:, 1] > y) != (b[:, 1] > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        at = a[:, 0] + (y - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1])
    return (crosses & (x < at)).sum(axis=1) % 2 == 1


@dataclass(frozen=True, eq=False)
class Prior:
    """Where the sensor is, as the caller knows it: a pose with standard deviations
    (heading and sigma_theta in radians), a region (polygon vertices, metres), or both."""

    pose: tuple[float, float, float] | None = None
    sigma_xy: float = 1.0
    sigma_theta: float = math.radians(15.0)
    region: np.ndarray | None = None

    def __post_init__(self):
        if self.pose is None and self.region is None:
            raise InputError("prior: give a pose, a region or both")
        if self.pose is not None:
            pose = _finite(self.pose, "the pose (x, y, theta)").ravel()
            if pose.shape != (3,):
                raise InputError(f"prior: the pose must be 3 numbers (x, y, theta), got {len(pose)}")
            object.__setattr__(self, "pose", tuple(float(v) for v in pose))
        for name in ("sigma_xy", "sigma_theta"):
            value = float(_finite(getattr(self, name), name))
            if value <= 0:
                raise InputError(f"prior: {name} must be positive, got {value:g}")
            object.__setattr__(self, name, value)
        if self.region is not None:
            region = _finite(self.region, "the region's vertices")
            if region.ndim != 2 or region.shape[1] != 2 or len(region) < 3:
                raise InputError(f"prior: the region must be at least 3 vertices (x, y), got shape {region.shape}")
            if np.allclose(region[0], region[-1]) and len(region) > 3:
                region = region[:-1]  # a closed ring (GeoJSON) repeats its first vertex
            if polygon_area(region) <= 0:
                raise InputError("prior: the region encloses no area")
            object.__setattr__(self, "region", region.copy())

    @classmethod
    def at(cls, x: float, y: float, theta: float, sigma_xy: float = 1.0, sigma_theta: float = math.radians(15.0),
           region=None) -> "Prior":
        """A pose prior, heading and sigma_theta in radians."""
        return cls((x, y, theta), sigma_xy, sigma_theta, None if region is None else np.asarray(region, dtype=float))

    @classmethod
    def within(cls, region) -> "Prior":
        """A region prior: a polygon ((N, 2) vertices), or a box (x0, y0, x1, y1)."""
        region = _finite(region, "the region")
        if region.shape == (4,):
            region = box_polygon(*region)
        return cls(region=region)

    @classmethod
    def from_settings(cls, s: PriorSettings) -> "Prior | None":
        if s.pose is None and s.region is None:
            return None
        pose = None if s.pose is None else (s.pose[0], s.pose[1], math.radians(s.pose[2]))
        return cls(pose, s.sigma_xy, math.radians(s.sigma_theta_deg), None if s.region is None else np.asarray(s.region, dtype=float))

    def settings_update(self) -> dict:
        """The PriorSettings fields that record this prior (degrees, as the settings hold them)."""
        pose = None if self.pose is None else [self.pose[0], self.pose[1], math.degrees(self.pose[2])]
        region = None if self.region is None else self.region.tolist()
        return {"pose": pose, "sigma_xy": self.sigma_xy, "sigma_theta_deg": math.degrees(self.sigma_theta), "region": region}

    def bind(self, plane_pose, s: PriorSettings) -> "BoundPrior":
        return BoundPrior(self, np.asarray(plane_pose, dtype=float).reshape(3).copy(), s.gate_sigmas, s.seed_step,
                          math.radians(s.seed_angle_step_deg), s.max_seeds)


def box_polygon(x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    if not (x1 > x0 and y1 > y0):
        raise InputError(f"prior: a region box needs X0 < X1 and Y0 < Y1, got {x0:g},{y0:g},{x1:g},{y1:g}")
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=float)


@dataclass(frozen=True, eq=False)
class BoundPrior:
    """A prior tied to the odometry-plane pose (x, y, yaw) of the frame it describes: a
    gate on alignments (model rows (tx, ty, theta, s))."""

    prior: Prior
    anchor: np.ndarray  # (3,) the frame's plane pose
    gate_sigmas: float = 2.5
    seed_step: float = 0.25  # m
    seed_angle_step: float = math.radians(5.0)
    max_seeds: int = 100_000

    def implied(self, models: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The frame's floorplan position (K, 2) and heading (K,) under each model row."""
        m = np.asarray(models, dtype=float).reshape(-1, 4)
        c, s = np.cos(m[:, 2]), np.sin(m[:, 2])
        ax, ay, yaw = self.anchor
        xy = np.column_stack([m[:, 3] * (c * ax - s * ay) + m[:, 0], m[:, 3] * (s * ax + c * ay) + m[:, 1]])
        return xy, wrap_angle(m[:, 2] + yaw)

    def inside(self, models: np.ndarray) -> np.ndarray:
        """Which model rows agree with the prior (see the module docstring)."""
        xy, heading = self.implied(models)
        ok = np.ones(len(xy), dtype=bool)
        p = self.prior
        if p.pose is not None:
            # (a hair of slack: the seeds on the gate's edge stay inside it)
            ok &= np.hypot(xy[:, 0] - p.pose[0], xy[:, 1] - p.pose[1]) <= self.gate_sigmas * p.sigma_xy * (1 + 1e-9)
            ok &= np.abs(wrap_angle(heading - p.pose[2])) <= self.gate_sigmas * p.sigma_theta * (1 + 1e-9)
        if p.region is not None:
            ok &= inside_polygon(xy, p.region)
        return ok

    def alignment(self, scale: float) -> Sim2 | None:
        """The alignment (odometry plane -> floorplan) that puts the prior's frame at the
        prior's pose, at the given scale; None for a region alone."""
        p = self.prior
        if p.pose is None:
            return None
        theta = float(wrap_angle(p.pose[2] - self.anchor[2]))
        c, s = math.cos(theta), math.sin(theta)
        ax, ay = self.anchor[:2]
        return Sim2(scale, theta, (p.pose[0] - scale * (c * ax - s * ay), p.pose[1] - scale * (s * ax + c * ay)))

    def log_density(self, models: np.ndarray) -> np.ndarray:
        """log p of each model row's implied pose under a pose prior, up to a constant
        (-d^2 / 2, d the Mahalanobis distance in position and heading; 0 for a region)."""
        p = self.prior
        if p.pose is None:
            return np.zeros(len(np.asarray(models).reshape(-1, 4)))
        xy, heading = self.implied(models)
        d2 = ((xy[:, 0] - p.pose[0]) ** 2 + (xy[:, 1] - p.pose[1]) ** 2) / p.sigma_xy**2
        d2 += (wrap_angle(heading - p.pose[2]) / p.sigma_theta) ** 2
        return -0.5 * d2

    def seeds(self, scale: float) -> np.ndarray:
        """Model rows at the given scale whose implied poses cover a pose prior's gate on a
        seed_step x seed_angle_step grid (coarsened to max_seeds); none for a region alone
        (the global search covers a region: its inside hypotheses are ranked apart)."""
        p = self.prior
        if p.pose is None or self.max_seeds == 0:
            return np.zeros((0, 4))
        radius = self.gate_sigmas * p.sigma_xy
        half_turn = min(self.gate_sigmas * p.sigma_theta, math.pi)
        step, angle_step = self.seed_step, self.seed_angle_step
        count = (math.pi * (radius / step + 1) ** 2) * (2 * half_turn / angle_step + 1)
        if count > self.max_seeds:  # coarsen both grids alike
            factor = (count / self.max_seeds) ** (1 / 3)
            step, angle_step = step * factor, angle_step * factor
        n = int(math.floor(radius / step))
        offsets = np.arange(-n, n + 1) * step
        gx, gy = np.meshgrid(offsets, offsets, indexing="ij")
        disc = np.hypot(gx, gy) <= radius
        positions = np.column_stack([gx[disc], gy[disc]]) + np.array(p.pose[:2])
        if p.region is not None:
            positions = positions[inside_polygon(positions, p.region)]
        k = int(math.floor(half_turn / angle_step))
        headings = p.pose[2] + np.arange(-k, k + 1) * angle_step
        if 2 * half_turn >= 2 * math.pi - 1e-9:
            headings = headings[: max(1, int(round(2 * math.pi / angle_step)))]  # a full turn once
        theta = np.repeat(wrap_angle(headings - self.anchor[2]), len(positions))
        xy = np.tile(positions, (len(headings), 1))
        c, s = np.cos(theta), np.sin(theta)
        ax, ay = self.anchor[:2]
        t = xy - scale * np.column_stack([c * ax - s * ay, s * ax + c * ay])
        return np.column_stack([t, theta, np.full(len(theta), float(scale))])


def _rows(alignments) -> np.ndarray:
    """Model rows (tx, ty, theta, s) of Sim2 alignments (estimation.results.model_rows)."""
    return np.array([[a.t[0], a.t[1], a.theta, a.s] for a in alignments], dtype=float).reshape(-1, 4)


# --------------------------------------------------------------------------------------
# the localizer's side
# --------------------------------------------------------------------------------------
PENDING, ACTIVE, RELEASED, CONTRADICTED = "pending", "active", "released", "contradicted"


@dataclass
class Weighed:
    """A round's hypotheses as the tracker is to see them under the prior."""

    hypotheses: list  # those inside the prior while it holds (all of them otherwise)
    head_start: list[int] | None  # extra hits at birth per hypothesis (tracking.HypothesisTracker.update)
    contradicted: bool = False  # this round dropped the prior


@dataclass
class PriorWatch:
    """The localizer's prior through the stream: bound at the first fused frame after it
    was given, it weighs each round's hypotheses until it is released or contradicted
    (module docstring). state: None (no prior), pending, active, released, contradicted."""

    prior: Prior | None
    settings: PriorSettings
    confirm_rounds: int  # tracking.confirm_rounds: hits a mode needs without the prior
    weight_gain: float = 15.0  # tracking.weight_gain: a score unit is this much log weight
    bound: BoundPrior | None = None
    state: str | None = None
    against: int = 0  # contradicting rounds in a row (naming one place: _count_against)
    against_at: np.ndarray | None = None  # the position their leading place implies for the prior's frame
    since_frame: int = field(default=-1)  # the frame the prior describes (-1: not bound yet)
    margin: float = -np.inf  # the latest weighed round's best score inside the prior minus the best outside

    def __post_init__(self):
        self.state = None if self.prior is None else PENDING

    @classmethod
    def of(cls, prior: Prior | None, settings) -> "PriorWatch":
        """The watch of a localizer with these settings (settings.loading.Settings)."""
        return cls(prior, settings.prior, settings.tracking.confirm_rounds, settings.tracking.weight_gain)

    def bind(self, frame: int, plane_pose) -> None:
        """The first fused frame after the prior was given: the one it describes."""
        if self.state == PENDING:
            self.bound, self.state, self.since_frame = self.prior.bind(plane_pose, self.settings), ACTIVE, frame

    def release(self) -> None:
        """Let go of an active prior whose bound frame no longer exists (the map it was
        bound in was cleared after an odometry jump): what it said of that place cannot be
        carried to the new map frame. A pending prior is kept: it describes a frame to come."""
        if self.state == ACTIVE:
            self.bound, self.state = None, RELEASED

    @property
    def for_round(self) -> BoundPrior | None:
        """The prior a round's search uses (only while active)."""
        return self.bound if self.state == ACTIVE else None

    def weigh(self, hypotheses, judge: bool = True) -> Weighed:
        """The round's hypotheses as the tracker sees them. judge: the round counts toward a
        contradiction (a preview on fewer frames does not)."""
        if self.state != ACTIVE or not hypotheses:
            return Weighed(list(hypotheses), None)
        rows = _rows([h.alignment for h in hypotheses])
        inside = self.bound.inside(rows)
        scores = np.array([float(h.score) for h in hypotheses])
        best_in = scores[inside].max(initial=-np.inf)
        best_out = scores[~inside].max(initial=-np.inf)
        gap = self.settings.contradiction_gap
        self.margin = best_in - best_out
        if judge:
            self._count_against(rows[~inside][np.argmax(scores[~inside])] if best_out - best_in > gap else None)
            if self.against >= self.settings.contradiction_rounds:
                self.state = CONTRADICTED
                return Weighed(list(hypotheses), None, contradicted=True)
        # the prior holds: the places it rules out are pruned (none scores clearly better), and
        # those it keeps are weighed by it: the tracker's weights are softmax(weight_gain x
        # score), so adding log p(pose) / weight_gain makes them the posterior's (AMCL's
        # particles start from the initial pose's Gaussian)
        log_prior = self.bound.log_density(rows)
        kept = [replace(h, score=float(h.score) + float(lp) / self.weight_gain)
                for h, ok, lp in zip(hypotheses, inside, log_prior) if ok]
        head = max(0, self.confirm_rounds - self.settings.confirm_rounds) if best_in >= best_out else 0
        return Weighed(kept, [head] * len(kept))

    def _count_against(self, leader_outside: np.ndarray | None) -> None:
        """One judged round: leader_outside, the model row of the best place outside when
        it leads the best inside by contradiction_gap (None: the round does not contradict).
        Contradicting rounds count in a row only while they name one place (SAME_PLACE):
        a handful of frames where the map lacks the place fits some place far off, a
        different one each round; a prior that is wrong is beaten by the same place again."""
        if leader_outside is None:
            self.against, self.against_at = 0, None
            return
        place = self.bound.implied(leader_outside)[0][0]
        same = self.against_at is not None and float(np.hypot(*(place - self.against_at))) <= SAME_PLACE
        self.against, self.against_at = (self.against + 1 if same else 1), place

    def stand_in(self, plane_pose, estimator) -> tuple[Sim2, np.ndarray, np.ndarray, float] | None:
        """While a pose prior holds and no place the map explains is reported (before the
        first round, or where the map lacks what the frames see): the prior's own pose,
        carried by odometry, stands in, as AMCL reports its initial pose before its particles
        converge. (alignment, pose, covariance, confidence) at the frame's plane pose, or
        None. The confidence is the prior's own chance of lying within 1 m (a 2D Gaussian:
        1 - exp(-1 / (2 sigma^2))), at most PRIOR_POSE_MAX_CONFIDENCE: nothing verified it.
        estimator: EstimatorSettings (the odometry's scale, as the prior's seeds take it)."""
        if self.state != ACTIVE or self.prior.pose is None:
            return None
        p = self.prior
        alignment = self.bound.alignment(estimator.scale_prior if estimator.scale_mode != "fixed" else 1.0)
        covariance = np.diag([p.sigma_xy**2, p.sigma_xy**2, p.sigma_theta**2])
        confidence = min(PRIOR_POSE_MAX_CONFIDENCE, 1.0 - math.exp(-0.5 / p.sigma_xy**2))
        return alignment, np.array(alignment.apply_pose(*plane_pose)), covariance, confidence

    @property
    def doubted(self) -> bool:
        """The prior holds but the latest round's best outside it scored more than
        doubt_gap above the best inside: its place is not reported `tracking`."""
        return self.state == ACTIVE and self.margin < -self.settings.doubt_gap

    def holds(self, alignment) -> bool:
        """Does an alignment (Sim2) agree with the bound prior?"""
        if self.bound is None:
            return False
        return bool(self.bound.inside(_rows([alignment]))[0])

    def after_round(self, tracked_alignment, tracked_rounds: int) -> None:
        """Release the prior once the evidence alone singles out what it chose: a mode
        inside it tracked release_rounds rounds, and the latest round's best hypothesis
        inside scoring more than contradiction_gap above every one outside (in a symmetric
        building the prior holds until the frames see what tells the halves apart)."""
        if self.state == ACTIVE and tracked_alignment is not None and tracked_rounds >= self.settings.release_rounds \
                and self.margin > self.settings.contradiction_gap and self.holds(tracked_alignment):
            self.state = RELEASED
