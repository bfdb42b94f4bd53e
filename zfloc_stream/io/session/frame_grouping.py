"""Messages grouped into frames by timestamp: a frame is every input message of one
stamp, released once every input topic has moved past it; calibration is the latest at or
before the stamp; odometry at its own rate is kept for interpolation at the frames' stamps.
Real logs repeat stamps (printed with few digits): the n-th message of each topic at one
stamp belongs to the n-th frame of that stamp."""

from __future__ import annotations

from collections.abc import Iterator

from ...settings.loading import Settings
from ...errors import SessionLogError
from ...geometry.pose_interpolation import PoseTrack
from . import schemas as S

# the input topics whose progress releases a stamp (calibration and odometry may run at
# their own rates)
PROGRESS_TOPICS = (S.TOPIC_IMAGE, S.TOPIC_DEPTH, S.TOPIC_SCAN, S.TOPIC_LABELS, S.TOPIC_ODOMETRY, S.TOPIC_GROUND_TRUTH, S.TOPIC_STATUS)
MAX_PENDING_STAMPS = 16  # stamps held at most; the oldest are released beyond it


class FrameGrouper:
    """Collects messages per timestamp; a timestamp is released once every input topic
    seen so far has moved past it (or at the end of the file)."""

    def __init__(self, session):
        self.session = session
        # Frames are keyed (stamp, occurrence): real logs repeat stamps (printed with few
        # digits), so the n-th message of each topic at one stamp belongs to the n-th frame.
        self.pending: dict[tuple[int, int], dict] = {}
        self.progress: dict[str, tuple[int, int]] = {}
        self.seen: dict[tuple[str, int], int] = {}  # (topic, stamp) -> messages so far
        self.calibrations: list[tuple[int, object]] = []  # (stamp, message), in file order
        self.released_up_to = (-1, 0)
        self.session_warned_repeats = False
        # the caller's settings first (a dataset spec's, run --set), as for the reorder limit
        gap = (session.read_settings or session.settings or Settings()).datasets.ros2.max_odometry_gap
        self.odometry = PoseTrack(S.TOPIC_ODOMETRY, gap)  # every odometry pose, for frames between its stamps

    def stamps(self, messages) -> Iterator[tuple[int, dict]]:
        for topic, stamp, msg, meta in messages:
            if topic == S.TOPIC_CALIBRATION:
                self.calibrations.append((stamp, msg))
                continue
            if topic == S.TOPIC_ODOMETRY:
                try:
                    self.odometry.add(stamp, S.matrix_from_pose(msg.pose))
                except SessionLogError:
                    pass  # a broken pose: reported when a frame of that stamp is assembled
            occurrence = self.seen.get((topic, stamp), 0)
            self.seen[(topic, stamp)] = occurrence + 1
            key = (stamp, occurrence)
            if key <= self.released_up_to:
                self.session.problems.append(f"{topic} message at t={S.ns_to_seconds(stamp):.9f} arrived after its frame and was dropped")
                continue
            if occurrence == 1 and not self.session_warned_repeats:
                self.session.problems.append(f"repeated timestamps (first at t={S.ns_to_seconds(stamp):.9f}): frames kept in file order")
                self.session_warned_repeats = True
            self.pending.setdefault(key, {})[topic] = (msg, meta)
            if topic in PROGRESS_TOPICS:
                self.progress[topic] = max(key, self.progress.get(topic, (-1, 0)))
            yield from self._release(min(self.progress.values()) if self.progress else (-1, 0))
        yield from self._release(None)

    def _release(self, before: int | None) -> Iterator[tuple[int, dict]]:
        """Release stamps < before (all when None), oldest first; and the oldest ones
        beyond the pending bound."""
        for key in sorted(self.pending):
            if before is not None and key >= before and len(self.pending) <= MAX_PENDING_STAMPS:
                break
            parts = self.pending.pop(key)
            stamp = key[0]
            self.released_up_to = key
            self.seen = {k: n for k, n in self.seen.items() if k[1] >= stamp}
            self.odometry.drop_before(stamp)  # later frames have later stamps
            calib = self._calibration_at(stamp)
            if calib is not None:
                parts[S.TOPIC_CALIBRATION] = (calib, {})
            yield stamp, parts

    def _calibration_at(self, stamp: int):
        """Latest calibration at or before the stamp (else the first one: published late)."""
        best = None
        for s, msg in self.calibrations:
            if s <= stamp and (best is None or s >= best[0]):
                best = (s, msg)
        if best is None:
            return self.calibrations[0][1] if self.calibrations else None
        # older calibrations can no longer be the latest for a later stamp
        self.calibrations = [(s, m) for s, m in self.calibrations if s >= best[0]]
        return best[1]
