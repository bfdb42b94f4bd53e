"""ROS 2 bags (rosbag2 MCAP, CDR messages) read through mcap-ros2-support, no ROS install:
`ros2:/bags/run1.mcap` or `zfloc-stream run --input run1.mcap [--topic scan=/front/scan]`.

Frames come from one sensor topic: a `sensor_msgs/LaserScan`, or else a depth
`sensor_msgs/Image` (16UC1 millimetres or 32FC1 metres, labelled by the geometric labeller)
with its `sensor_msgs/CameraInfo`. Each frame's pose in the odometry frame is

    T_odom_sensor(t) = T_odom_base(t) @ T_base_sensor

where T_odom_base(t) comes from `nav_msgs/Odometry` (or, without one, the dynamic `/tf`
link above the sensor) interpolated at the frame's header stamp (pose_interpolation.py),
and T_base_sensor is the chain of `/tf_static` transforms from the sensor's frame_id up
to that base frame. Sensors publish at their own rates and in any order; a frame outside
the odometry's time span (or in a long gap) is skipped with its reason in a warning.

Topics are found by message type; `topics={"scan": "/front/scan"}` (CLI: `--topic
scan=/front/scan`) picks one where several match. Keys: scan, depth, camera_info, odom,
tf, tf_static. Bags carry no ground truth; a floorplan must be passed.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from ...settings.loading import Settings
from ..drops import DropCounter
from ...errors import FrameError, InputError, SessionLogError
from ...frames import CameraFrame, LaserFrame
from ...frontend import lens
from ..messages import depth_in_metres, matrix_from_quaternion
from ...geometry.pose_interpolation import PoseTrack
from ..session.ordering import MIB, held_at_once
from .base import Sequence, register

# role -> accepted schema names (rosbag2 writes "pkg/msg/Type"; older tools "pkg/Type")
ROLE_TYPES = {
    "scan": "sensor_msgs/LaserScan",
    "depth": "sensor_msgs/Image",
    "camera_info": "sensor_msgs/CameraInfo",
    "odom": "nav_msgs/Odometry",
    "tf": "tf2_msgs/TFMessage",
    "tf_static": "tf2_msgs/TFMessage",
}
ROLES = tuple(ROLE_TYPES)
DEPTH_ENCODINGS = ("16UC1", "32FC1", "mono16")


def _type_name(schema_name: str) -> str:
    return schema_name.replace("/msg/", "/")


def _stamp_ns(header) -> int:
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def _transform_matrix(translation, rotation) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = matrix_from_quaternion([rotation.x, rotation.y, rotation.z, rotation.w])
    T[:3, 3] = [translation.x, translation.y, translation.z]
    return T


def is_ros2_mcap(path) -> bool:
    """True when an MCAP file holds CDR (ROS 2) channels. Unreadable summaries answer False
    (the session reader then reports what is wrong with the file)."""
    try:
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
    except Exception:  # noqa: BLE001 - damaged or truncated: not ours to diagnose here
        return False
    return summary is not None and any(c.message_encoding == "cdr" for c in summary.channels.values())


def parse_topic_overrides(items) -> dict[str, str]:
    """['scan=/front/scan', ...] -> {'scan': '/front/scan'}; InputError on a bad item."""
    out = {}
    for item in items or ():
        role, sep, topic = str(item).partition("=")
        if not sep or not topic.strip():
            raise InputError(f"--topic '{item}' must look like ROLE=/topic (roles: {', '.join(ROLES)})")
        if role not in ROLE_TYPES:
            raise InputError(f"--topic '{item}': unknown role '{role}' (roles: {', '.join(ROLES)})")
        out[role] = topic.strip()
    return out


def find_topics(path: Path, channels: dict[str, str], overrides: dict[str, str]) -> dict[str, str]:
    """role -> topic from the bag's channels ({topic: type}), overrides applied."""
    topics: dict[str, str] = {}
    for role, wanted in ROLE_TYPES.items():
        if role in overrides:
            topic = overrides[role]
            if topic not in channels:
                raise InputError(f"{path}: --topic {role}={topic}: no such topic (topics: {', '.join(sorted(channels))})")
            if channels[topic] != wanted:
                raise InputError(f"{path}: --topic {role}={topic} carries {channels[topic]}, expected {wanted}")
            topics[role] = topic
            continue
        found = sorted(t for t, ty in channels.items() if ty == wanted)
        if role in ("tf", "tf_static"):
            found = [t for t in found if t.rstrip("/").endswith("/" + role)]
        elif role == "depth" and len(found) > 1:
            found = [t for t in found if "depth" in t] or found  # RGB images share the type
        if len(found) > 1:
            raise InputError(f"{path}: several {wanted} topics ({', '.join(found)}): choose one with --topic {role}=TOPIC")
        if found:
            topics[role] = found[0]
    if "scan" in topics and "depth" in topics and "scan" not in overrides and "depth" not in overrides:
        del topics["depth"]  # both sensors: the laser, unless the user picks the camera
        warnings.warn(f"{path}: both a laser and a depth image topic: using the laser {topics['scan']} (--topic depth=... for the camera)", stacklevel=3)
    if "scan" not in topics and "depth" not in topics:
        raise InputError(f"{path}: no sensor_msgs/LaserScan or depth sensor_msgs/Image topic (topics: {', '.join(sorted(channels)) or 'none'})")
    if "depth" in topics and "camera_info" not in topics:
        raise InputError(f"{path}: depth images {topics['depth']} need a sensor_msgs/CameraInfo topic (--topic camera_info=TOPIC)")
    if "odom" not in topics and "tf" not in topics:
        raise InputError(f"{path}: no nav_msgs/Odometry topic and no /tf: every frame needs its odometry pose")
    return topics


@dataclass
class _Motion:
    """Everything small that the frames need: poses over time, static transforms, intrinsics."""

    odometry: PoseTrack | None = None  # nav_msgs/Odometry: T_odom_child
    odom_child: str = ""
    dynamic: dict[str, tuple[str, PoseTrack]] = field(default_factory=dict)  # /tf child -> (parent, track)
    static: dict[str, tuple[str, np.ndarray]] = field(default_factory=dict)  # child -> (parent, T_parent_child)
    camera_info: tuple[np.ndarray, int, int] | None = None
    distortion: tuple[str, tuple[float, ...]] = ("", ())  # CameraInfo distortion_model, d
    frame_stamps: list[int] = field(default_factory=list)  # header stamps of the sensor topic, file order
    sensor_frame: str = ""

    def static_chain(self, frame: str) -> list[tuple[str, np.ndarray]]:
        """[(frame, T_frame_sensor)] walking /tf_static up from the sensor frame."""
        chain, T, seen = [(frame, np.eye(4))], np.eye(4), {frame}
        while frame in self.static:
            parent, T_parent_child = self.static[frame]
            if parent in seen:
                break  # a loop in /tf_static: stop where it closes
            T = T_parent_child @ T
            frame = parent
            seen.add(frame)
            chain.append((frame, T))
        return chain

    def sensor_track(self, path: Path) -> tuple[PoseTrack, np.ndarray]:
        """(track of T_odom_base, T_base_sensor) for the sensor frame."""
        if not self.sensor_frame:  # no frame_id on the sensor: take it as mounted at the odometry's body
            warnings.warn(f"{path}: the sensor messages carry no frame_id: taking the sensor as the odometry's body frame", stacklevel=3)
            if self.odometry is not None:
                return self.odometry, np.eye(4)
        chain = self.static_chain(self.sensor_frame)
        if self.odometry is not None:
            child = self.odom_child or chain[-1][0]  # an empty child_frame_id: the chain's root
            for frame, T in chain:
                if frame == child:
                    return self.odometry, T
            raise InputError(
                f"{path}: no /tf_static chain from the sensor frame '{self.sensor_frame}' to the odometry's "
                f"child frame '{child}' (chain: {' -> '.join(f for f, _ in chain)})"
            )
        for frame, T in chain:
            if frame in self.dynamic:
                return self.dynamic[frame][1], T
        raise InputError(f"{path}: no /tf transform moves the sensor frame '{self.sensor_frame}' or a frame above it "
                         f"(chain: {' -> '.join(f for f, _ in chain)})")


class Ros2Bag:
    """One rosbag2 MCAP file: topics, motion (read once), frames (read lazily)."""

    def __init__(self, path, settings: Settings, topics: dict[str, str] | None = None):
        self.path = Path(path)
        self.settings = settings
        channels = self._channels()
        self.topics = find_topics(self.path, channels, dict(topics or {}))
        self.kind = "scan" if "scan" in self.topics else "depth"
        self.motion = self._read_motion()
        if not self.motion.frame_stamps:
            raise InputError(f"{self.path}: topic {self.topics[self.kind]} holds no message")
        self.track, self.T_base_sensor = self.motion.sensor_track(self.path)
        # frames in stamp order (a bag is in log-time order; header stamps may not be)
        order = np.argsort(np.asarray(self.motion.frame_stamps, dtype=np.int64), kind="stable")
        self.usable: list[tuple[int, int]] = []  # (position in file, stamp), stamp order
        self.skipped: list[str] = []
        self.notes: set[str] = set()  # changes made to the data (millimetres converted...), warned once
        for i in order:
            stamp = self.motion.frame_stamps[i]
            _, reason = self.track.at(stamp)
            if reason is None:
                self.usable.append((int(i), stamp))
            else:
                self.skipped.append(f"{self.topics[self.kind]} frame {reason}")
        if self.skipped:
            warnings.warn(f"{self.path}: skipped {len(self.skipped)} of {len(order)} frame(s) without odometry (first: {self.skipped[0]})", stacklevel=2)
        if not self.usable:
            raise InputError(f"{self.path}: no frame has an odometry pose ({self.skipped[0]})")

    # --- reading ---------------------------------------------------------------------------
    def _open(self):
        try:
            return open(self.path, "rb")
        except OSError as err:
            raise InputError(f"cannot read ROS 2 bag {self.path}: {err.strerror or err}") from None

    def _channels(self) -> dict[str, str]:
        with self._open() as f:
            try:
                summary = make_reader(f).get_summary()
            except (McapError, ValueError, OSError) as err:
                raise SessionLogError(f"{self.path}: damaged MCAP summary ({type(err).__name__}: {err})") from None
        if summary is None:
            raise SessionLogError(f"{self.path}: the bag has no MCAP summary (a recording cut off?)")
        return {c.topic: _type_name(summary.schemas[c.schema_id].name) for c in summary.channels.values()
                if c.message_encoding == "cdr" and c.schema_id in summary.schemas}

    def _decoded(self, roles):
        """(role, decoded message) for the given roles, in log-time order where the bag has
        a chunk index (a bag written grouped by topic or shuffled then holds one chunk per
        topic, or what logging.reorder_max_mb allows, at a time), else in file order."""
        by_topic = {self.topics[r]: r for r in roles if r in self.topics}
        with self._open() as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            try:
                in_order = self._check_reorder(reader.get_summary(), by_topic)
                for _, channel, _, msg in reader.iter_decoded_messages(topics=list(by_topic), log_time_order=in_order):
                    yield by_topic[channel.topic], msg
            except (McapError, ValueError, OSError, EOFError, KeyError) as err:
                raise SessionLogError(f"{self.path}: cannot decode the bag ({type(err).__name__}: {err})") from None

    def _check_reorder(self, summary, topics) -> bool:
        """Whether to read in log-time order (a chunk index to merge the chunks by); refuses
        a merge that would hold more than logging.reorder_max_mb at once."""
        if summary is None or not summary.chunk_indexes:
            return False  # (without an index a log-time read would load the whole file)
        ids = {cid for cid, c in summary.channels.items() if c.topic in topics}
        chunks = [c for c in summary.chunk_indexes if not c.message_index_offsets or ids & set(c.message_index_offsets)]
        need, limit = held_at_once(chunks), self.settings.logging.reorder_max_mb
        if need > limit * MIB:
            raise InputError(f"{self.path}: its messages are far out of log-time order: reading them in order holds "
                             f"{need / MIB:.0f} MiB of chunks at once, over the limit of {limit} MiB "
                             "(logging.reorder_max_mb; raise it, or rewrite the bag in log-time order)")
        return True

    def _read_motion(self) -> _Motion:
        gap = self.settings.datasets.ros2.max_odometry_gap
        m = _Motion()
        for role, msg in self._decoded(("odom", "tf", "tf_static", "camera_info", self.kind)):
            try:
                if role == self.kind:
                    m.frame_stamps.append(_stamp_ns(msg.header))
                    m.sensor_frame = m.sensor_frame or msg.header.frame_id
                elif role == "odom":
                    if m.odometry is None:
                        m.odometry, m.odom_child = PoseTrack(f"odometry {self.topics['odom']}", gap), msg.child_frame_id
                    p = msg.pose.pose
                    m.odometry.add(_stamp_ns(msg.header), _transform_matrix(p.position, p.orientation))
                elif role == "camera_info" and m.camera_info is None:
                    K = np.array(msg.k, dtype=float).reshape(3, 3)
                    m.camera_info = (K, int(msg.width), int(msg.height))
                    D = tuple(float(v) for v in msg.d)
                    if not np.isfinite(D).all():
                        raise SessionLogError(f"distortion coefficients {list(D)} contain NaN or inf")
                    m.distortion = (str(msg.distortion_model), D)
                elif role in ("tf", "tf_static"):
                    for tr in msg.transforms:
                        T = _transform_matrix(tr.transform.translation, tr.transform.rotation)
                        child = tr.child_frame_id
                        if role == "tf_static":
                            m.static[child] = (tr.header.frame_id, T)
                        else:
                            if child not in m.dynamic:
                                m.dynamic[child] = (tr.header.frame_id, PoseTrack(f"/tf {tr.header.frame_id}->{child}", gap))
                            m.dynamic[child][1].add(_stamp_ns(tr.header), T)
            except SessionLogError as err:  # a transform that is not a rotation
                raise InputError(f"{self.path}: {self.topics[role]}: {err}") from None
        if self.kind == "depth":
            if m.camera_info is None:
                raise InputError(f"{self.path}: no CameraInfo message on {self.topics['camera_info']}")
            K = m.camera_info[0]
            if not (np.isfinite(K).all() and K[0, 0] > 0 and K[1, 1] > 0 and np.allclose(K[2], [0, 0, 1])):
                raise InputError(f"{self.path}: {self.topics['camera_info']}: K {K.ravel().tolist()} is not a camera calibration (uncalibrated camera?)")
        return m

    # --- frames ------------------------------------------------------------------------------
    def frames(self, start: int, stop: int):
        """Frames [start, stop) in stamp order (the sensor topic is read once per call)."""
        wanted = {pos: k for k, (pos, _) in enumerate(self.usable[start:stop], start=start)}
        pending: dict[int, object] = {}
        next_k, pos = start, -1
        drops = DropCounter(str(self.path))  # unusable frames: one warning per cause, counted
        for role, msg in self._decoded((self.kind,)):
            pos += 1
            if pos not in wanted:
                continue
            pending[wanted[pos]] = msg
            while next_k in pending:  # yield in stamp order, buffering only out-of-order ones
                frame = self._frame(pending.pop(next_k), self.usable[next_k][1], drops)
                next_k += 1
                if frame is not None:
                    yield frame
        drops.summary()

    def _frame(self, msg, stamp: int, drops: DropCounter):
        T_odom_base, _ = self.track.at(stamp)
        T = T_odom_base @ self.T_base_sensor
        t = stamp / 1e9
        try:
            if self.kind == "scan":
                return LaserFrame(np.asarray(msg.ranges, dtype=float), float(msg.angle_min), float(msg.angle_increment),
                                  float(msg.range_min), float(msg.range_max), T, t)
            if msg.is_bigendian:
                raise FrameError("big-endian depth images are not supported")
            encoding = "16UC1" if msg.encoding == "mono16" else msg.encoding
            if encoding not in DEPTH_ENCODINGS:
                raise FrameError(f"depth image encoding '{msg.encoding}' is not a depth encoding ({', '.join(DEPTH_ENCODINGS)})")
            msg.encoding = encoding
            depth, note = depth_in_metres(msg)
            K, width, height = self.motion.camera_info
            if (width, height) != (0, 0) and (height, width) != depth.shape:
                raise FrameError(f"CameraInfo is for {width}x{height} images but depth is {depth.shape[1]}x{depth.shape[0]}")
            model, D = self.motion.distortion
            if lens.is_distorted(D):
                if lens.supported(model):
                    depth = lens.undistort([depth], K, model, D)[0]
                else:
                    note = note or (f"{self.topics['camera_info']} distortion model '{model}' is not supported "
                                    f"({', '.join(lens.MODELS)}): its coefficients {list(D)} ignored, depth used as it is")
            if note is not None and note.split(" (")[0] not in self.notes:
                self.notes.add(note.split(" (")[0])
                warnings.warn(f"{self.path}: {self.topics[self.kind]}: {note} (first at t={t:.6f})", stacklevel=3)
            return CameraFrame(depth, None, K, T, t)
        except (SessionLogError, FrameError) as err:  # one unusable frame: skip it, say why
            self.skipped.append(f"{self.topics[self.kind]} frame at t={t:.6f} skipped: {err}")
            drops.note(f"{self.topics[self.kind]}: {err}", f"t={t:.6f}")
            return None


def bag_sequence(path, settings: Settings, floorplan=None, topics: dict[str, str] | None = None) -> Sequence:
    bag = Ros2Bag(path, settings, topics)
    n = len(bag.usable)
    seq = Sequence(
        name=bag.path.stem,
        frame_source=bag.frames,
        n_frames=n,
        ground_truth=np.full((n, 3), np.nan),
        floorplan=floorplan,
        settings_overrides={"estimator": {"scale_mode": "fixed"}},  # laser, depth and wheel odometry are metric
        source=f"ros2:{bag.path}",
    )
    seq.skipped = bag.skipped
    seq.topics = dict(bag.topics)  # role -> topic, as found or given (run prints them)
    return seq


@register("ros2")
def load_ros2(args: str, settings: Settings) -> list[Sequence]:
    return [bag_sequence(p, settings) for p in args.split(",") if p]
