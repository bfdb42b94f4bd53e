"""What a ROS / Foxglove user reads from a run (issue 41): ros2.mcap read back with rosbags
(message types, -1 for the map's unknown cells, the 6x6 covariance, map -> odom ->
base_link on /tf), session.mcap's frame tree (every published frame connected to `map`),
one frame naming in both logs, and the Foxglove layout shipped with the package."""

import dataclasses
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from zfloc_stream.geometry import frame_tree as F
from zfloc_stream.settings.loading import Settings
from zfloc_stream.plans.loading import load_floorplan
from zfloc_stream.io.ros2_output import UNOBSERVED_VARIANCE
from zfloc_stream.io.session import SessionWriter, read_session
from zfloc_stream.io.session import schemas as S
from zfloc_stream.sim import build_scene, simulate_laser
from zfloc_stream.tools.cli import main
from zfloc_stream.io.tum import tum_line

rosbags = pytest.importorskip("rosbags", reason="rosbags (the [test] extra) reads the ROS 2 output back")
N = 16
LAYOUT = Path(__file__).resolve().parents[1] / "zfloc_stream" / "tools" / "foxglove_layout.json"


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A laser walk localized on a map_server plan whose margin is grey (unknown), with
    --ros2 and ground truth from a TUM file: (out dir, plan dir, truth)."""
    tmp = tmp_path_factory.mktemp("ros2")
    scene = build_scene("rooms", seed=0)
    seq = simulate_laser(scene, seed=0, n_frames=N)
    plan = scene.floorplan.write_ros(tmp / "plan")
    img = cv2.imread(str(tmp / "plan" / "map.png"), cv2.IMREAD_GRAYSCALE)
    margin = np.zeros(img.shape, dtype=bool)
    margin[:6], margin[-6:], margin[:, :6], margin[:, -6:] = True, True, True, True
    img[margin & (img > 128)] = 205  # map_server's unknown grey, where the plan is not a wall
    cv2.imwrite(str(tmp / "plan" / "map.png"), img)
    with SessionWriter(tmp / "inputs.mcap", Settings(), scene.floorplan) as log:
        for i, frame in enumerate(seq.frames):
            log.write_frame(i, dataclasses.replace(frame, ground_truth=None))
    (tmp / "gt.tum").write_text("".join(tum_line(f.timestamp, *f.ground_truth) for f in seq.frames))
    out = tmp / "out"
    assert main(["run", "--floorplan", str(plan), "--input", str(tmp / "inputs.mcap"), "--groundtruth", str(tmp / "gt.tum"),
                 "--ros2", "--out", str(out), "--no-progress"]) == 0
    return out, tmp / "plan", np.array([f.ground_truth for f in seq.frames])


def _bag(path) -> dict:
    """topic -> (message type, [deserialized messages]) of a ROS 2 MCAP, read with rosbags."""
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    out = {}
    with Reader(path) as reader:
        for conn, _, raw in reader.messages():
            out.setdefault(conn.topic, (conn.msgtype, []))[1].append(store.deserialize_cdr(raw, conn.msgtype))
    return out


def _stamp(header) -> int:
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


def _planar(translation, rotation) -> np.ndarray:
    return F.planar_matrix(translation.x, translation.y, 2 * np.arctan2(rotation.z, rotation.w))


def _estimates(session_path) -> list:
    return [S.estimate_from_status(rec.outputs.status) for rec in read_session(session_path).records()]


def test_ros2_output_types_unknown_cells_covariance_and_tf_chain(run):
    out, plan_dir, truth = run
    bag = _bag(out / "ros2.mcap")
    assert {t: v[0] for t, v in bag.items()} == {
        "/zfloc/floorplan": "nav_msgs/msg/OccupancyGrid", "/zfloc/pose": "geometry_msgs/msg/PoseWithCovarianceStamped",
        "/zfloc/groundtruth": "geometry_msgs/msg/PoseStamped", "/tf": "tf2_msgs/msg/TFMessage"}
    # the map: -1 exactly where map_server reads grey, 100 walls, 0 free; row 0 = lowest y
    plan = load_floorplan(plan_dir / "map.yaml")
    grey = (cv2.imread(str(plan_dir / "map.png"), cv2.IMREAD_GRAYSCALE) == 205)[::-1]
    (grid,) = bag["/zfloc/floorplan"][1]
    data = np.asarray(grid.data).reshape(grid.info.height, grid.info.width)
    assert grid.header.frame_id == "map" and grey.sum() > 1000
    assert np.array_equal(data == -1, grey) and np.array_equal(data == 100, plan.occupied)
    assert np.array_equal(data == 0, ~grey & ~plan.occupied)
    # the pose with its covariance: x, y, yaw as estimated, z / roll / pitch unobserved
    posed = [e for e in _estimates(out / "session.mcap") if e.pose is not None]
    poses = bag["/zfloc/pose"][1]
    assert len(poses) == len(posed) > N // 2
    for msg, est in zip(poses, posed):
        assert msg.header.frame_id == "map"
        p, q = msg.pose.pose.position, msg.pose.pose.orientation
        np.testing.assert_allclose([p.x, p.y, 2 * np.arctan2(q.z, q.w)], est.pose, atol=1e-9)
        cov = np.asarray(msg.pose.covariance).reshape(6, 6)
        np.testing.assert_allclose(cov[np.ix_([0, 1, 5], [0, 1, 5])], est.covariance, rtol=1e-12, atol=1e-18)
        assert np.all(np.diag(cov)[2:5] == UNOBSERVED_VARIANCE) and np.count_nonzero(cov[2:5, :]) == 3
        assert np.array_equal(cov, cov.T) and np.all(np.linalg.eigvalsh(cov) > 0)
    # /tf: map -> odom -> base_link at each pose's stamp composes to that pose
    tfs = bag["/tf"][1]
    assert len(tfs) == len(poses)
    for tf, pose in zip(tfs, poses):
        (a, b) = tf.transforms
        assert [(t.header.frame_id, t.child_frame_id) for t in (a, b)] == [("map", "odom"), ("odom", "base_link")]
        assert _stamp(a.header) == _stamp(b.header) == _stamp(pose.header)
        T = _planar(a.transform.translation, a.transform.rotation) @ _planar(b.transform.translation, b.transform.rotation)
        p, q = pose.pose.pose.position, pose.pose.pose.orientation
        np.testing.assert_allclose(T, _planar(p, q), atol=1e-9)
    # the truth on its own topic, at the estimates' stamps
    gt = bag["/zfloc/groundtruth"][1]
    assert len(gt) == N and gt[0].header.frame_id == "map"
    np.testing.assert_allclose([[m.pose.position.x, m.pose.position.y] for m in gt], truth[:, :2], atol=1e-9)


def _protobuf_messages(path, topics=None):
    """(topic, log time, decoded message) of a session log's protobuf channels."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    decoders, factory = {}, DecoderFactory()
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages(topics=topics):
            if channel.message_encoding == "protobuf":
                decode = decoders.setdefault(channel.id, factory.decoder_for(channel.message_encoding, schema))
                yield channel.topic, message.log_time, decode(message.data)


def _frame_ids(path) -> tuple[dict, list]:
    """topic -> frame ids used on it, and the /tf (parent, child) pairs, of a session log."""
    frames, edges = {}, []
    for topic, _, msg in _protobuf_messages(path):
        if topic == S.TOPIC_TF:
            edges += [(t.parent_frame_id, t.child_frame_id) for t in msg.transforms]
        elif hasattr(msg, "frame_id"):
            frames.setdefault(topic, set()).add(msg.frame_id)
    return frames, edges


def test_session_log_names_frames_as_the_ros2_output_and_connects_them_with_frame_transforms(run):
    out, _, _ = run
    frames, edges = _frame_ids(out / "session.mcap")
    assert frames[S.TOPIC_POSE] == frames[S.TOPIC_HYPOTHESES] == frames[S.TOPIC_GROUND_TRUTH] == frames[S.TOPIC_FLOORPLAN] == {"map"}
    assert frames[S.TOPIC_BEV] == frames[S.TOPIC_ODOMETRY] == {"odom"} and frames[S.TOPIC_SCAN] == {"laser"}
    tree = dict((child, parent) for parent, child in edges)  # each frame has one parent
    assert tree == {"floorplan": "map", "odom": "map", "base_link": "odom", "laser": "base_link"}

    def root(frame):
        while frame in tree:
            frame = tree[frame]
        return frame

    for topic, ids in frames.items():  # every frame a Foxglove panel draws reaches `map`
        assert all(root(f) == "map" for f in ids), (topic, ids)


def test_session_frame_transforms_compose_to_the_pose_and_place_the_sensor(run):
    out, _, _ = run
    by_stamp = {}
    for topic, log_time, msg in _protobuf_messages(out / "session.mcap", [S.TOPIC_TF, S.TOPIC_POSE]):
        by_stamp.setdefault(log_time, {})[topic] = msg
    assert sum(S.TOPIC_TF in v for v in by_stamp.values()) == sum(S.TOPIC_POSE in v for v in by_stamp.values()) > 0
    for both in by_stamp.values():
        if S.TOPIC_POSE not in both:
            continue
        T = {}
        for t in both[S.TOPIC_TF].transforms:
            T[t.child_frame_id] = np.eye(4)
            T[t.child_frame_id][:3, :3] = S.matrix_from_quaternion([t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w])
            T[t.child_frame_id][:3, 3] = [t.translation.x, t.translation.y, t.translation.z]
        np.testing.assert_allclose(T["odom"] @ T["base_link"], S.matrix_from_pose(both[S.TOPIC_POSE].pose), atol=1e-9)
        np.testing.assert_allclose(T["laser"], np.eye(4), atol=1e-9)  # a level 2D laser is its footprint
        np.testing.assert_array_equal(T["floorplan"], np.eye(4))


def test_a_camera_mount_turns_the_optical_axis_onto_base_link_x():
    """base_link -> camera: the optical z axis along base_link x, the height kept, a pitch
    of the camera kept as its tilt."""
    pitch, yaw = 0.2, 1.0
    level = np.array([[0.0, 0, 1], [-1, 0, 0], [0, -1, 0]])  # optical axes of a level camera looking along x
    tilt = np.array([[1, 0, 0], [0, np.cos(pitch), -np.sin(pitch)], [0, np.sin(pitch), np.cos(pitch)]])  # about optical x
    T = F.planar_matrix(3.0, -2.0, yaw)
    T[:3, :3] = T[:3, :3] @ level @ tilt
    T[2, 3] = 1.4
    mount = F.base_to_sensor(T, "z")
    np.testing.assert_allclose(mount[:3, 3], [0, 0, 1.4], atol=1e-12)
    np.testing.assert_allclose(mount[:3, :3], level @ tilt, atol=1e-12)
    assert F.base_to_sensor(F.planar_matrix(1.0, 2.0, 0.5), "x") == pytest.approx(np.eye(4))


def test_unknown_cells_survive_the_session_attachment(run):
    out, plan_dir, _ = run
    plan = load_floorplan(plan_dir / "map.yaml")
    logged = read_session(out / "session.mcap").floorplan
    assert plan.unknown is not None and np.array_equal(logged.unknown, plan.unknown)
    assert np.array_equal(logged.occupied, plan.occupied)


def test_the_foxglove_layout_shows_what_the_session_log_publishes(run):
    """The shipped layout parses, draws topics the log has, and follows a frame of its tree."""
    out, _, _ = run
    layout = json.loads(LAYOUT.read_text())
    frames, edges = _frame_ids(out / "session.mcap")
    panels = layout["configById"]
    three_d = [c for k, c in panels.items() if k.startswith("3D!")]
    assert len(three_d) == 1
    assert three_d[0]["followTf"] in {c for _, c in edges} | {"map"}
    shown = {t for t, c in three_d[0]["topics"].items() if c.get("visible")}
    assert {S.TOPIC_FLOORPLAN, S.TOPIC_BEV, S.TOPIC_SCAN, S.TOPIC_POSE, S.TOPIC_HYPOTHESES} <= shown <= set(frames)
    paths = [p["value"] for k, c in panels.items() if k.startswith(("Plot!", "StateTransitions!")) for p in c["paths"]]
    status = read_session(out / "session.mcap")
    fields = next(iter(status.records())).outputs.status
    for path in paths:  # every plotted field is one /zfloc/status has
        topic, _, field = path.partition(".")
        assert topic == S.TOPIC_STATUS and field in fields, path

    def leaves(node):
        return [node] if isinstance(node, str) else leaves(node["first"]) + leaves(node["second"])

    assert sorted(leaves(layout["layout"])) == sorted(panels)


def test_an_older_log_named_floorplan_replays_identically_and_rewrites_as_map(tmp_path):
    """replay/office-laser.mcap was written with the map frame called `floorplan`: its
    replay still matches it (decisions exactly, numbers within the stated tolerance: the
    file was recorded on another CPU), and the log a replay writes says `map` throughout."""
    from zfloc_stream.io.session.compare import Tolerance
    from zfloc_stream.io.session.replay import replay_session, replay_settings

    sample = read_session(Path(__file__).resolve().parents[1] / "replay" / "office-laser.mcap")
    old, _ = _frame_ids(sample.path)
    assert old[S.TOPIC_POSE] == old[S.TOPIC_GROUND_TRUTH] == {"floorplan"}
    settings = replay_settings(sample)
    result = replay_session(sample, settings, sample.load_floorplan(settings), check=True, out=tmp_path / "new.mcap",
                            tolerance=Tolerance())
    assert result.divergence is None and result.checked == result.frames
    frames, edges = _frame_ids(tmp_path / "new.mcap")
    assert frames[S.TOPIC_POSE] == frames[S.TOPIC_GROUND_TRUTH] == frames[S.TOPIC_HYPOTHESES] == {"map"}
    assert ("map", "odom") in edges and ("base_link", "laser") in edges


def test_covariance_without_an_estimate_and_unknown_masks_that_do_not_fit():
    from zfloc_stream.errors import FloorplanError
    from zfloc_stream.plans.floorplan import Floorplan
    from zfloc_stream.io.ros2_output import covariance_6x6

    for cov in (None, np.full((3, 3), np.nan)):  # no covariance: every axis unknown, none certain
        np.testing.assert_array_equal(np.reshape(covariance_6x6(cov), (6, 6)), np.eye(6) * UNOBSERVED_VARIANCE)
    occ = np.zeros((20, 20), dtype=bool)
    occ[5, :] = True
    with pytest.raises(FloorplanError, match=r"unknown-cell mask has shape \(3, 3\), the grid \(20, 20\)"):
        Floorplan(occ, 0.1, (0.0, 0.0), unknown=np.ones((3, 3), dtype=bool))
    plan = Floorplan(occ, 0.1, (0.0, 0.0), unknown=np.ones((20, 20), dtype=bool))
    assert not (plan.unknown & plan.occupied).any() and plan.unknown.sum() == 380  # a wall is never unknown
    assert Floorplan(occ, 0.1, (0.0, 0.0), unknown=np.zeros((20, 20), dtype=bool)).unknown is None
