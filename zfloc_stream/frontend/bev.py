"""RollingBEV: frames fused into a bounded log-odds bird's-eye view in the plane frame.

Plane frame: the gravity-aligned odometry frame (gravity.py; for 2D lasers the odometry
plane itself). Per cell the grid keeps
  - log-odds occupancy: + logodds_hit for a cell holding an obstacle point, + logodds_free
    for a cell crossed by a ray (each at most once per frame), clamped;
  - wall evidence: number of frames that put a (refined) wall point / laser hit there,
    and hits: number of frames that put any obstacle point there. A wall cell needs
    wall evidence in at least wall_min_ratio of the frames that hit it: furniture
    mislabelled as wall passes the wall mask only from a few viewpoints.

Free space is ray cast in 2D: per frame the rays from the sensor's plane position to its
observed points form a star-shaped polygon (one vertex per laser beam, or per azimuth bin
for cameras), filled with cv2.fillPoly; the frame's own hit cells are never freed.

Bounded: the grid is a fixed-size square of half-side window_radius + recenter_distance
that scrolls (content shifted, the part leaving dropped) whenever the sensor leaves a box
of half-side recenter_distance around its centre. It therefore always holds the disc of
radius window_radius around the sensor, and the cost of an update or of a scroll does not
grow with session length.

Cameras before gravity is known: frames wait in a bounded buffer (gravity settings) while
their floor points feed the GravityEstimator; once gravity is frozen they are fused in
order.

The grid's storage and scrolling are scrolling_grid.py's; a frozen grid and the step from
it to a BevObservation are bev_snapshot.py's; the scan matcher is scan_match.py.
"""

from __future__ import annotations

import copy
from collections import deque

import cv2
import numpy as np

from ..settings.loading import Settings
from ..errors import ConfigError, FrameError, InputError
from ..frames import CEILING, FLOOR, WALL, CameraFrame, LaserFrame
from ..observation import BevObservation
from ..runtime.rng import make_rng
from ..geometry.sim2 import Sim2
from .bev_snapshot import BevSnapshot, wall_cells
from .gravity import GravityEstimator, plane_pose
from .labeller import bootstrap_floor_mask, depth_normals, label_frame
from .scan_match import match_scan, step_bounds
from .scrolling_grid import ScrollingGrid, increment
from .wallmask import refine_wall_points, upright_rotation

_SHIFT = 4  # cv2.fillPoly sub-cell precision: coordinates in 1/16 cell

# Scan matching reads the wall grid on a crop around the frame's hits, widened by this many
# times the largest correction allowed (scan_match.step_bounds): points moved by up to that
# correction still see the walls they may match; a crop under SCAN_MATCH_MIN_CROP_CELLS on a side has no interior for
# the distance field's gradient, so the frame is fused uncorrected.
SCAN_MATCH_CROP_MARGIN_SHIFTS = 2
SCAN_MATCH_MIN_CROP_CELLS = 3

# The per-intrinsics ray tables are dropped once more than this many are held: cameras rarely
# change their intrinsics, so a few suffice.
RAY_CACHE_SIZE = 4
# The grid's update and memory (were bev.*; every recorded result used these). A ray's
# evidence is weaker than a hit's (bev.logodds_hit 0.85), so a wall stands after one
# crossing ray; from the clamp, 3 hits make a free cell occupied and 9 rays stop an
# occupied one being occupied, so old evidence can be overturned.
LOGODDS_FREE = -0.4  # added to a cell crossed by a ray (once per frame)
LOGODDS_MIN, LOGODDS_MAX = -2.0, 3.5  # the clamp
FREE_MARGIN = 0.1  # m, rays stop this short of the obstacle they hit (two cells: range noise does not free a wall)
MIN_WALL_POINTS_PER_CELL = 3  # camera: wall points one frame must put in a cell to count (isolated noisy points do not; laser: 1)
AZIMUTH_BIN_DEG = 0.5  # camera free space: one ray per azimuth bin (at 10 m a bin is 0.09 m, under two cells)
TRAJECTORY_LENGTH = 10000  # plane poses kept (a ring buffer: bounded memory, 1000 s at 10 Hz)


class RollingBEV:
    """Bounded BEV of the last window_radius metres around the sensor.

    add(frame) fuses a CameraFrame or LaserFrame; observation(rng) snapshots it as a
    BevObservation (raises InputError while it has no wall cell); plane_pose(frame) is the
    sensor's (x, y, yaw) in the plane frame.
    """

    def __init__(self, settings: Settings | None = None):
        self.settings = settings or Settings()
        b, f = self.settings.bev, self.settings.frontend
        if b.resolution <= 0 or b.window_radius <= 0 or b.recenter_distance < 0:
            raise ConfigError("bev: resolution and window_radius must be > 0, recenter_distance >= 0")
        if f.pixel_stride < 0 or f.target_pixels < 1 or f.max_depth <= 0:
            raise ConfigError("frontend: pixel_stride must be >= 0, target_pixels >= 1 and max_depth > 0")
        half = int(np.ceil((b.window_radius + b.recenter_distance) / b.resolution))
        self.grid = ScrollingGrid(2 * half, b.resolution)
        self._slack = int(np.floor(b.recenter_distance / b.resolution))
        self.gravity = GravityEstimator(f.gravity, make_rng(self.settings.seed, "gravity"))
        self._pending: deque[CameraFrame] = deque()
        self._trajectory = np.zeros((TRAJECTORY_LENGTH, 3))  # ring buffer: fixed memory
        self._trajectory_count = 0
        self._ray_cache: dict = {}
        self.frames_added = 0
        self.frames_fused = 0
        self.frames_dropped = 0  # camera frames dropped from a full gravity buffer
        self.last_wall_hits = np.zeros((0, 2))  # wall points of the last fused frame (plane frame)
        self.last_contradiction = 0.0  # of the last fused frame (_contradiction)
        self.last_known_hits = 0  # of its wall hits, those on cells older frames saw (0 under monitor_min_points)
        # scan matching's rigid correction of the laser odometry plane (theta, t): plane = R x + t
        self._correction = Sim2()  # odometry plane -> the plane the BEV is fused in
        self._last_odometry: tuple | None = None  # the last matched frame's odometry plane pose (x, y, yaw)

    # ------------------------------------------------------------------------------
    # public API
    def add(self, frame: CameraFrame | LaserFrame) -> None:
        if isinstance(frame, LaserFrame):
            self._add_laser(frame)
        elif isinstance(frame, CameraFrame):
            self._add_camera(frame)
        else:
            raise FrameError(f"RollingBEV.add expects a CameraFrame or LaserFrame, got {type(frame).__name__}")
        self.frames_added += 1

    def plane_pose(self, frame: CameraFrame | LaserFrame) -> tuple[float, float, float]:
        """(x, y, yaw) of the frame's sensor in the plane frame (camera: optical axis yaw;
        laser: x axis yaw). Before gravity is frozen, a provisional gravity is used."""
        if isinstance(frame, LaserFrame):
            return self._corrected(*plane_pose(frame.T_odom_sensor, np.eye(3), "x"))
        if isinstance(frame, CameraFrame):
            return self._corrected(*plane_pose(frame.T_odom_cam, self.gravity.provisional_R(), "z"))
        raise FrameError(f"plane_pose expects a CameraFrame or LaserFrame, got {type(frame).__name__}")

    @property
    def trajectory(self) -> np.ndarray:
        """(K, 3) plane poses of the last fused frames, oldest first."""
        n = len(self._trajectory)
        k = self._trajectory_count
        if k <= n:
            return self._trajectory[:k].copy()
        return np.roll(self._trajectory, -(k % n), axis=0)

    def _record_pose(self, pose) -> None:
        self._trajectory[self._trajectory_count % len(self._trajectory)] = pose
        self._trajectory_count += 1

    def clear_map(self) -> None:
        """Forget the map (e.g. after the odometry jumped: old and new evidence would
        disagree); gravity and the trajectory stay."""
        self.grid = ScrollingGrid(self.grid.n, self.grid.res)
        self.last_wall_hits = np.zeros((0, 2))
        self._correction = Sim2()  # odometry plane -> the plane the BEV is fused in
        self._last_odometry = None

    def forget_before(self, stamp: int) -> None:
        """Keep only what frames from this stamp on touched (the sensor was carried off:
        the place older frames saw is not where it is now); unlike clear_map, the plane
        frame (scan matching's correction) stays, so alignments to the floorplan stay valid."""
        self.grid.forget_before(stamp)

    @property
    def pending_frames(self) -> int:
        return len(self._pending)

    def memory_bytes(self) -> int:
        """Bytes held by the grid, buffers and trajectory (for the flat-memory check)."""
        g = self.grid
        pending = sum(f.depth.nbytes + (0 if f.labels is None else f.labels.nbytes) for f in self._pending)
        rays = sum(r.nbytes for r in self._ray_cache.values())
        grid = g.logodds.nbytes + g.wall.nbytes + g.hits.nbytes + g.seen.nbytes
        return grid + pending + rays + self._trajectory.nbytes + self.gravity.buffered_bytes

    def observation(self, rng: np.random.Generator) -> BevObservation:
        return self.snapshot(copy=False).observation(rng)

    @property
    def stamp(self) -> int:
        """Frames fused into the grid so far (the stamp of the latest)."""
        return self.grid.stamp

    def snapshot(self, copy: bool = True, since: int = 0) -> "BevSnapshot":
        """What observation() reads, frozen: a pipelined round extracts its observation on a
        worker while this BEV keeps fusing frames (copy=True copies the grid, ~3 MB at the
        defaults, well under a millisecond). since: only what frames from this stamp on
        touched."""
        g = self.grid
        if g.ix0 is None:
            raise InputError("BEV is empty: no frame fused yet")
        arrays = (g.logodds, g.wall, g.hits, g.seen)
        if copy:
            arrays = tuple(a.copy() for a in arrays)
        return BevSnapshot(*arrays, g.ix0, g.iy0, self.trajectory, self.settings, g.stamp, since)

    # ------------------------------------------------------------------------------
    # lasers
    def _add_laser(self, frame: LaserFrame) -> None:
        T = frame.T_odom_sensor
        valid = frame.valid
        a, r = frame.angles, frame.ranges
        beams = np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], axis=1) @ T[:3, :3].T  # odom directions
        hits = (beams[valid] * r[valid, None] + T[:3, 3])[:, :2]
        flat = beams[:, :2] / np.maximum(np.linalg.norm(beams[:, :2], axis=1, keepdims=True), 1e-12)
        odom = plane_pose(T, np.eye(3), "x")
        if self.settings.bev.scan_match != "none":
            self._match(hits, odom)
        # the odometry plane as corrected by scan matching (identity without it)
        hits, flat = self._correct_points(hits), self._correct_points(flat, rotate_only=True)
        x, y, yaw = self._corrected(*odom)
        # free polygon: one vertex per beam (in beam order, whatever the mounting), stopping
        # short of the hit; no-returns give none
        centre = np.array([x, y])
        free_r = np.where(valid, np.maximum(r - FREE_MARGIN, 0.0), 0.0)
        self._fuse(centre, centre + free_r[:, None] * flat, hits, hits, min_wall_points=1)
        self._record_pose((x, y, yaw))
        self.frames_fused += 1

    def _corrected(self, x: float, y: float, yaw: float) -> tuple[float, float, float]:
        """An odometry-plane pose in the plane frame the BEV is fused in (scan matching)."""
        corr = self._correction
        if corr == Sim2():
            return x, y, yaw
        px, py = corr.apply(np.array([x, y]))
        return float(px), float(py), float(yaw + corr.theta)

    def _correct_points(self, xy: np.ndarray, rotate_only: bool = False) -> np.ndarray:
        corr = self._correction
        if corr == Sim2():
            return xy
        return Sim2(1.0, corr.theta).apply(xy) if rotate_only else corr.apply(xy)

    def _match(self, hits_odom: np.ndarray, odom_pose) -> None:
        """Scan matching: update the correction so this frame's wall hits (uncorrected
        plane frame) lie on the BEV walls."""
        g, b = self.grid, self.settings.bev
        last, self._last_odometry = self._last_odometry, tuple(odom_pose)
        if g.ix0 is None or len(hits_odom) == 0:
            return
        max_shift, max_angle = step_bounds(last, odom_pose, b)
        hits = self._correct_points(hits_odom)
        centre = np.array(self._corrected(*odom_pose)[:2])
        margin = SCAN_MATCH_CROP_MARGIN_SHIFTS * max_shift
        lo = np.floor((hits.min(axis=0) - margin) / g.res).astype(int) - [g.ix0, g.iy0]
        hi = np.ceil((hits.max(axis=0) + margin) / g.res).astype(int) - [g.ix0, g.iy0]
        c0, r0 = np.clip(lo, 0, g.n)
        c1, r1 = np.clip(hi, 0, g.n)
        if c1 - c0 < SCAN_MATCH_MIN_CROP_CELLS or r1 - r0 < SCAN_MATCH_MIN_CROP_CELLS:
            return
        mask = wall_cells(g.wall[r0:r1, c0:c1], g.hits[r0:r1, c0:c1], g.logodds[r0:r1, c0:c1], b)
        origin = np.array([(g.ix0 + c0) * g.res, (g.iy0 + r0) * g.res])
        step = match_scan(mask, origin, g.res, hits, centre, max_shift, max_angle)
        if step is None:
            return
        dtheta, dt = step
        # the step x' = R_d (x - c) + c + dt about the sensor c, after the correction so far
        turn = Sim2(1.0, dtheta)
        self._correction = Sim2(1.0, dtheta, centre + dt - turn.apply(centre)) @ self._correction

    # ------------------------------------------------------------------------------
    # cameras
    def _add_camera(self, frame: CameraFrame) -> None:
        if self.gravity.ready:
            self._fuse_camera(frame)
            return
        self._feed_gravity(frame)
        if len(self._pending) >= max(self.settings.frontend.gravity.max_pending_frames, 1):
            self._pending.popleft()  # bounded: the oldest waiting frame is given up
            self.frames_dropped += 1
        self._pending.append(_own_copy(frame))  # read when gravity is known: the caller may refill its buffers
        if self.gravity.ready:
            while self._pending:
                self._fuse_camera(self._pending.popleft())

    def pixel_stride(self, shape: tuple[int, int]) -> int:
        """Camera pixel stride: the configured one, or (0) about target_pixels per frame, so
        the fusion cost does not grow with the image resolution."""
        f = self.settings.frontend
        if f.pixel_stride > 0:
            return f.pixel_stride
        return max(1, int(np.sqrt(shape[0] * shape[1] / f.target_pixels)))

    def _strided(self, frame: CameraFrame):
        """Every stride-th pixel: depth, labels, K of that sub-image, unit-depth rays."""
        s = self.pixel_stride(frame.shape)
        o = s // 2
        depth = frame.depth[o::s, o::s]
        labels = None if frame.labels is None else frame.labels[o::s, o::s]
        K = frame.K.copy()
        K[0, :] /= s
        K[1, :] /= s
        K[0, 2] -= o / s
        K[1, 2] -= o / s
        key = (depth.shape, K.tobytes())
        rays = self._ray_cache.get(key)
        if rays is None:
            if len(self._ray_cache) > RAY_CACHE_SIZE:  # bounded: intrinsics rarely change
                self._ray_cache.clear()
            v, u = np.mgrid[0 : depth.shape[0], 0 : depth.shape[1]]
            pix = np.stack([u.ravel(), v.ravel(), np.ones(u.size)])
            # float32: the per-frame products stay cheap (sub-micrometre at 10 m)
            rays = (np.linalg.inv(K) @ pix).T.reshape(depth.shape + (3,)).astype(np.float32)
            self._ray_cache[key] = rays
        valid = np.isfinite(depth) & (depth > 0) & (depth <= self.settings.frontend.max_depth)
        return depth, labels, K, rays, valid

    def _feed_gravity(self, frame: CameraFrame) -> None:
        depth, labels, K, rays, valid = self._strided(frame)
        cam = rays * np.where(valid, depth, 0.0)[..., None]
        if labels is not None:
            floor = valid & (labels == FLOOR)
        else:  # no labels: floor candidates from depth normals and the camera's own up axis
            floor = valid & bootstrap_floor_mask(cam, self.settings.frontend.labeller)
        T = frame.T_odom_cam
        self.gravity.add_floor_points(cam[floor] @ T[:3, :3].T + T[:3, 3], T[:3, 3])

    def _fuse_camera(self, frame: CameraFrame) -> None:
        f = self.settings.frontend
        grav = self.gravity
        depth, labels, K, rays, valid = self._strided(frame)
        T = frame.T_odom_cam
        R_plane = grav.R_plane_odom
        R, t = R_plane @ T[:3, :3], R_plane @ T[:3, 3]  # camera -> plane frame
        if labels is None:  # the labeller needs the organised cloud
            organised = (rays * np.where(valid, depth, 0)[..., None]) @ R.T.astype(np.float32) + t.astype(np.float32)
            normals = depth_normals(organised, depth, valid, f.labeller.normal_step)
            labels = label_frame(organised[..., 2] - grav.floor_height, normals, valid, f.labeller)
        # from here on only the valid pixels, flattened
        idx = np.flatnonzero(valid)
        d = depth.reshape(-1)[idx]
        ray = rays.reshape(-1, 3)[idx]
        lab = labels.reshape(-1)[idx]
        pts = ((ray * d[:, None]) @ R.T.astype(np.float32)).astype(float) + t
        is_floor, is_wall_label = lab == FLOOR, lab == WALL
        if is_floor.any():  # track slow vertical drift of the odometry
            grav.observe_floor_heights(pts[is_floor, 2])
        height = pts[:, 2] - grav.floor_height
        R_up_cam = upright_rotation(T[:3, :3], -grav.up_odom)
        wall = refine_wall_points(ray, d, is_wall_label, K, R_up_cam, f.wall_mask)
        above = height >= f.min_obstacle_height
        obstacle = above & (height <= f.max_obstacle_height) & ~is_floor & (lab != CEILING)
        wall &= above
        sensor = plane_pose(T, R_plane, "z")
        xy = pts[:, :2]
        if self.settings.bev.scan_match == "all":
            self._match(xy[wall], sensor)
        xy, sensor = self._correct_points(xy), self._corrected(*sensor)
        centre = np.array(sensor[:2])
        # free space: rays to floor points end there, rays to walls stop FREE_MARGIN short
        ray_end = is_floor | is_wall_label
        angles, ranges = self._azimuth_bins(centre, sensor[2], xy[ray_end], is_wall_label[ray_end])
        ends = centre + ranges[:, None] * np.stack([np.cos(angles), np.sin(angles)], axis=1)
        # a wall stacks many pixels onto one cell; isolated (noisy) wall points do not count
        self._fuse(centre, ends, xy[obstacle | wall], xy[wall], MIN_WALL_POINTS_PER_CELL)
        self._record_pose(sensor)
        self.frames_fused += 1

    def _azimuth_bins(self, centre, yaw, xy, is_wall):
        """One ray per azimuth bin: the farthest free range among the bin's points."""
        if len(xy) == 0:
            return np.zeros(0), np.zeros(0)
        rel = (xy - centre).astype(np.float32)  # float32: bins are 0.5 deg wide
        dist = np.hypot(rel[:, 0], rel[:, 1])
        dist = np.where(is_wall, np.maximum(dist - FREE_MARGIN, 0.0), dist)
        ang = (np.arctan2(rel[:, 1], rel[:, 0]) - yaw + np.pi) % (2 * np.pi) - np.pi  # relative to heading
        width = np.deg2rad(AZIMUTH_BIN_DEG)
        b = np.floor(ang / width).astype(np.int64)
        b0 = b.min()
        free = np.zeros(b.max() - b0 + 1)
        np.maximum.at(free, b - b0, dist.astype(float))
        angles = yaw + (np.arange(len(free)) + b0 + 0.5) * width
        return angles, free

    def _contradiction(self, wall_hits: np.ndarray) -> float:
        """Of the frame's wall hits that land on cells older frames saw, the share landing
        where they saw open space, no occupied cell within localizer.monitor_distance: a
        sensor carried off sees walls cut through what it saw before, one walking on does
        not (0 with fewer than localizer.monitor_min_points such hits)."""
        lc = self.settings.localizer
        known, lonely = self.grid.open_without_wall_near(
            wall_hits, self.settings.bev.free_threshold, self.settings.bev.occupied_threshold,
            max(1, int(round(lc.monitor_distance / self.grid.res))), lc.monitor_min_points)
        self.last_known_hits = known
        return lonely / known if known else 0.0

    # ------------------------------------------------------------------------------
    # the shared update
    def _fuse(
        self,
        centre: np.ndarray,
        free_ends: np.ndarray,
        hits: np.ndarray,
        wall_hits: np.ndarray,
        min_wall_points: int,
    ) -> None:
        b = self.settings.bev
        g = self.grid
        self.last_wall_hits = wall_hits  # the localizer checks each frame against the tracked alignment
        g.centre_on(centre, self._slack)
        self.last_contradiction = self._contradiction(wall_hits)
        g.stamp += 1
        hit_flat = g.unique_flat(hits)
        # free polygon, drawn on a crop around it only
        # (free_ends: (K, 2) polygon vertices ordered by angle around the centre)
        if len(free_ends):
            poly = np.concatenate([centre[None], free_ends]) / b.resolution - [g.ix0, g.iy0]  # cell units
            lo_c = np.clip(np.floor(poly.min(axis=0)).astype(int) - 1, 0, g.n)
            hi_c = np.clip(np.ceil(poly.max(axis=0)).astype(int) + 2, 0, g.n)
            if (hi_c > lo_c).all():
                mask = np.zeros((hi_c[1] - lo_c[1], hi_c[0] - lo_c[0]), dtype=np.uint8)
                # cv2 pixel (c, r) is the centre of cell (r, c), which sits at +0.5 in cell units
                pts = np.round((poly - lo_c - 0.5) * (1 << _SHIFT)).astype(np.int32)
                cv2.fillPoly(mask, [pts], 1, lineType=cv2.LINE_8, shift=_SHIFT)
                region = g.logodds[lo_c[1] : hi_c[1], lo_c[0] : hi_c[0]]
                hr, hc = np.divmod(hit_flat, g.n)
                inside = (hr >= lo_c[1]) & (hr < hi_c[1]) & (hc >= lo_c[0]) & (hc < hi_c[0])
                mask[hr[inside] - lo_c[1], hc[inside] - lo_c[0]] = 0  # a frame never frees its own hits
                # in place on the crop (a view of the grid); the clamp touches only the crop
                np.add(region, np.float32(LOGODDS_FREE), out=region, where=mask.view(bool))
                np.maximum(region, np.float32(LOGODDS_MIN), out=region)
                seen = g.seen[lo_c[1] : hi_c[1], lo_c[0] : hi_c[0]]
                np.copyto(seen, np.int32(g.stamp), where=mask.view(bool))
        flat_lo = g.logodds.reshape(-1)
        flat_lo[hit_flat] = np.minimum(flat_lo[hit_flat] + b.logodds_hit, LOGODDS_MAX)
        increment(g.hits, hit_flat)
        g.seen.reshape(-1)[hit_flat] = g.stamp
        increment(g.wall, g.unique_flat(wall_hits, min_wall_points))




def _own_copy(frame: CameraFrame) -> CameraFrame:
    """The frame with copies of the arrays a waiting frame is read from later: the caller may
    refill its buffers as soon as push returns (issue 44: a reused depth buffer moved the
    poses by up to 6 cm). A shallow copy with fresh arrays: the frame was validated."""
    kept = copy.copy(frame)
    for name in ("depth", "labels", "K", "T_odom_cam"):
        value = getattr(frame, name)
        if value is not None:
            object.__setattr__(kept, name, np.array(value))
    return kept
