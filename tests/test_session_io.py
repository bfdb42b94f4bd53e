"""SessionWriter + read_session: round trips, Foxglove compatibility, files of other tools."""

import dataclasses

import numpy as np
import pytest
from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
from mcap.reader import make_reader
from mcap.writer import Writer
from mcap_protobuf.decoder import DecoderFactory
from mcap_protobuf.schema import build_file_descriptor_set
from benchmarks.inputs.session_frames import camera_frames, laser_frames
from session_helpers import fake_estimate, write_fake_session

from benchmarks.shared_data import SHARED_DATA

from zfloc_stream.settings.loading import Settings, load_settings
from zfloc_stream.errors import SessionLogError
from zfloc_stream.frames import CameraFrame
from zfloc_stream.geometry.pose_interpolation import interpolate_pose
from zfloc_stream.io.session import SessionWriter, read_session
from zfloc_stream.io.session import schemas as S

INTEL = SHARED_DATA / "sessions" / "intel-camera-30"


def test_camera_round_trip_is_exact(tmp_path):
    frames = camera_frames(12, seed=3)
    settings = load_settings(overrides=["seed=7", "logging.chunk_max_frames=4"])
    logged = write_fake_session(tmp_path / "s.mcap", frames, settings)
    session = read_session(tmp_path / "s.mcap")
    assert session.settings == settings and session.info["source"] == "test"
    records = list(session.records())
    assert [r.index for r in records] == list(range(12)) and session.problems == []
    for rec, orig, lf in zip(records, frames, logged, strict=True):
        f = rec.frame
        assert isinstance(f, CameraFrame)
        assert np.array_equal(f.depth, orig.depth, equal_nan=True) and np.array_equal(f.labels, orig.labels)
        assert np.array_equal(f.K, orig.K)
        # what write_frame handed back is bit-identical to what a reader rebuilds
        assert np.array_equal(f.T_odom_cam, lf.T_odom_cam) and f.timestamp == lf.timestamp
        assert np.array_equal(f.ground_truth, lf.ground_truth)
        assert np.abs(f.T_odom_cam - orig.T_odom_cam).max() < 1e-12 and abs(f.timestamp - orig.timestamp) < 1e-9
        assert np.abs(f.ground_truth - orig.ground_truth).max() < 1e-12
        est, want = rec.outputs.estimate, fake_estimate(rec.index, lf.timestamp)
        assert est.status == want.status and est.frame == rec.index
        assert (rec.outputs.pose is None) == (want.pose is None)
        assert len(rec.outputs.hypotheses.poses) == len(want.alternatives)
    assert [f.timestamp for f in session.frames(3, 5)] == [logged[3].timestamp, logged[4].timestamp]


def test_laser_round_trip(tmp_path):
    frames = laser_frames(6, seed=2)
    logged = write_fake_session(tmp_path / "l.mcap", frames, estimates=False)
    got = list(read_session(tmp_path / "l.mcap").frames())
    assert len(got) == 6
    for f, orig, lf in zip(got, frames, logged, strict=True):
        assert np.array_equal(f.ranges, orig.ranges)
        assert (f.range_min, f.range_max, f.angle_min) == (orig.range_min, orig.range_max, orig.angle_min)
        assert f.angle_increment == lf.angle_increment and abs(f.angle_increment - orig.angle_increment) < 1e-15
        assert np.array_equal(f.T_odom_sensor, lf.T_odom_sensor) and np.allclose(f.ground_truth, orig.ground_truth)


def test_foxglove_schemas_read_by_the_generic_decoder(tmp_path):
    write_fake_session(tmp_path / "s.mcap", camera_frames(3), estimates=True)
    with SessionWriter(tmp_path / "l.mcap", Settings()) as log:
        log.write_frame(0, laser_frames(1)[0])
    seen = {}
    for name in ("s.mcap", "l.mcap"):
        with open(tmp_path / name, "rb") as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            for schema, channel, _msg in reader.iter_messages():
                seen[channel.topic] = (schema.name, schema.encoding, channel.message_encoding)
            f.seek(0)
            for _schema, channel, _msg, decoded in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages(
                topics=[S.TOPIC_DEPTH, S.TOPIC_POSE, S.TOPIC_SCAN]
            ):
                assert type(decoded).DESCRIPTOR.full_name.startswith("foxglove.")
    assert seen[S.TOPIC_DEPTH] == ("foxglove.RawImage", "protobuf", "protobuf")
    assert seen[S.TOPIC_LABELS][0] == "foxglove.RawImage"
    assert seen[S.TOPIC_CALIBRATION][0] == "foxglove.CameraCalibration"
    assert seen[S.TOPIC_ODOMETRY][0] == seen[S.TOPIC_GROUND_TRUTH][0] == seen[S.TOPIC_POSE][0] == "foxglove.PoseInFrame"
    assert seen[S.TOPIC_HYPOTHESES][0] == "foxglove.PosesInFrame"
    assert seen[S.TOPIC_SCAN][0] == "foxglove.LaserScan"
    assert seen[S.TOPIC_STATUS] == (S.STATUS_SCHEMA_NAME, "jsonschema", "json")


def test_bev_grid_is_published_at_the_configured_rate(tmp_path):
    grid = S.BevGrid(np.pad(np.ones((3, 4), np.float32), 2), np.array([1.0, -2.0]), 0.1)
    settings = load_settings(overrides=["logging.bev_every_n_frames=2"])
    with SessionWriter(tmp_path / "b.mcap", settings) as log:
        for i, frame in enumerate(camera_frames(5)):
            f = log.write_frame(i, frame)
            log.write_estimate(fake_estimate(i, f.timestamp), bev=grid)
    recs = list(read_session(tmp_path / "b.mcap").records())
    assert [r.outputs.bev is not None for r in recs] == [True, False, True, False, True]
    g = recs[2].outputs.bev_grid  # cropped to the observed cells
    assert g.values.shape == (3, 4) and np.allclose(g.origin, [1.2, -1.8]) and g.resolution == 0.1


def test_settings_and_floorplan_travel_inside(tmp_path):
    from zfloc_stream.plans.floorplan import Floorplan

    occ = np.zeros((40, 60), bool)
    occ[[0, -1], :] = occ[:, [0, -1]] = True
    occ[10:30, 30] = True
    plan = Floorplan.from_occupancy(occ, 0.05, (-1.25, 3.0), name="box")
    settings = load_settings(overrides=["estimator.ransac.iterations=123"])
    write_fake_session(tmp_path / "s.mcap", camera_frames(2), settings, floorplan=plan)
    session = read_session(tmp_path / "s.mcap")
    assert session.settings.estimator.ransac.iterations == 123
    assert sorted(session.floorplan_files) == ["floorplan.png", "floorplan.yaml"]
    back = session.floorplan
    assert np.array_equal(back.occupied, plan.occupied) and back.resolution == plan.resolution
    # the floorplan was built with the defaults, not the run's settings: rebuilt the same way
    assert np.array_equal(back.origin, plan.origin) and back.settings == plan.settings == session.floorplan_settings
    assert session.load_floorplan(settings).settings == settings
    # and it is drawn for Foxglove once, as a Grid in the map frame (REP 105; logs before it said `floorplan`)
    with open(tmp_path / "s.mcap", "rb") as f:
        grids = [d for _s, _c, _m, d in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages(topics=[S.TOPIC_FLOORPLAN])]
    assert len(grids) == 1 and grids[0].frame_id == "map" and grids[0].column_count == 60
    assert np.array_equal(np.frombuffer(grids[0].data, np.uint8).reshape(40, 60) == 100, occ)


def test_intel_camera_session_from_another_tool():
    session = read_session(INTEL / "session.mcap")
    assert session.settings is None and session.floorplan is None
    gt = np.loadtxt(INTEL / "gt.csv", delimiter=",", skiprows=1)
    frames = list(session.frames())
    assert len(frames) == 30 == len(gt) and session.problems == []
    for f, truth in zip(frames, gt, strict=True):
        assert f.depth.shape == (120, 160) and f.labels is not None and set(np.unique(f.labels)) <= {0, 1, 2, 3}
        assert np.allclose(f.K, [[80, 0, 80], [0, 80, 60], [0, 0, 1]])
        assert np.allclose(f.ground_truth, truth, atol=1e-9)  # heading = optical axis
        assert abs(f.T_odom_cam[2, 3] - 1.3) < 1e-9  # camera 1.3 m above the floor, odom z up
        assert abs(f.T_odom_cam[:3, 1] @ [0, 0, -1]) > np.cos(np.radians(10))  # image y ~ down
        assert np.nanmax(f.depth) < 40
    assert np.all(np.diff([f.timestamp for f in frames]) > 0)


def _foreign_file(path, frames, drop_odometry_of=(), calibration_once=True):
    """A file the way another tool might write it: calibration published once, topics
    interleaved in another order, no zfloc metadata, gt without heading_axis metadata."""
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        ids = {}
        for topic, cls in ((S.TOPIC_ODOMETRY, PoseInFrame), (S.TOPIC_GROUND_TRUTH, PoseInFrame)):
            sid = w.register_schema("foxglove.PoseInFrame", "protobuf", build_file_descriptor_set(cls).SerializeToString())
            ids[topic] = w.register_channel(topic, "protobuf", sid)
        from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
        from foxglove_schemas_protobuf.RawImage_pb2 import RawImage

        for topic, cls in ((S.TOPIC_CALIBRATION, CameraCalibration), (S.TOPIC_DEPTH, RawImage)):
            sid = w.register_schema(cls.DESCRIPTOR.full_name, "protobuf", build_file_descriptor_set(cls).SerializeToString())
            ids[topic] = w.register_channel(topic, "protobuf", sid)
        for i, fr in enumerate(frames):
            ns = S.seconds_to_ns(fr.timestamp)
            msgs = []
            if i not in drop_odometry_of:
                msgs.append((S.TOPIC_ODOMETRY, S.pose_to_msg(fr.T_odom_cam, ns, "odom")))
            msgs.append((S.TOPIC_GROUND_TRUTH, S.PoseInFrame(timestamp=S.to_stamp(ns), frame_id="floorplan",
                                                             pose=S.planar_pose_to_pose(fr.ground_truth, "z"))))
            msgs.append((S.TOPIC_DEPTH, S.depth_to_msg(fr.depth, ns)))
            if i == 0 or not calibration_once:
                msgs.append((S.TOPIC_CALIBRATION, S.calibration_to_msg(fr.K, fr.depth.shape[1], fr.depth.shape[0], ns)))
            for topic, m in msgs:  # log time = recording time, later than the header stamp
                w.add_message(ids[topic], log_time=ns + 5_000_000, data=m.SerializeToString(), publish_time=ns)
        w.finish()


def test_foreign_file_grouping_and_dropped_frames(tmp_path):
    frames = camera_frames(6, seed=5, labels=False)
    _foreign_file(tmp_path / "f.mcap", frames, drop_odometry_of=(2, 5))
    session = read_session(tmp_path / "f.mcap")
    got = list(session.records())
    # frame 2 has no odometry of its own stamp: its pose is interpolated between frames 1 and 3
    # (odometry at its own rate); frame 5 lies after the last odometry message: dropped, with why
    assert [r.index for r in got] == [0, 1, 2, 3, 4]
    assert [r.frame.timestamp for r in got] == pytest.approx([frames[i].timestamp for i in range(5)])
    assert all(np.array_equal(r.frame.K, frames[0].K) and r.frame.labels is None for r in got)
    assert np.allclose(got[3].frame.ground_truth, frames[3].ground_truth)
    expected = interpolate_pose(frames[1].T_odom_cam, frames[3].T_odom_cam, 0.5)
    np.testing.assert_allclose(got[2].frame.T_odom_cam, expected, atol=1e-9)
    assert len(session.problems) == 1 and "no /odometry pose" in session.problems[0] and "outside" in session.problems[0]


def test_foreign_file_with_repeated_timestamps_keeps_every_frame_in_order(tmp_path):
    """A log printed with few digits gives several frames one stamp: the n-th message of
    each topic at that stamp makes the n-th frame (belgioioso-camera-50 is all one stamp)."""
    frames = [dataclasses.replace(f, timestamp=7.0) for f in camera_frames(4, seed=6, labels=False)]
    _foreign_file(tmp_path / "same.mcap", frames, drop_odometry_of=())
    session = read_session(tmp_path / "same.mcap")
    got = list(session.records())
    assert len(got) == 4
    for r, f in zip(got, frames):
        np.testing.assert_allclose(r.frame.T_odom_cam, f.T_odom_cam, atol=1e-9)
        np.testing.assert_allclose(r.frame.ground_truth, f.ground_truth)
    assert len(session.problems) == 1 and "repeated timestamps" in session.problems[0]


def test_errors_name_the_file_and_fault(tmp_path):
    with pytest.raises(SessionLogError, match="not found"):
        read_session(tmp_path / "missing.mcap")
    (tmp_path / "text.mcap").write_text("hello, not an mcap file")
    with pytest.raises(SessionLogError, match=r"text\.mcap: not an MCAP file"):
        read_session(tmp_path / "text.mcap")
    with pytest.raises(SessionLogError, match="not a file"):
        read_session(tmp_path)
    write_fake_session(tmp_path / "s.mcap", camera_frames(3))
    data = (tmp_path / "s.mcap").read_bytes()
    (tmp_path / "cut.mcap").write_bytes(data[: len(data) // 2])
    with pytest.raises(SessionLogError, match=r"cut\.mcap: file is truncated.*salvage"):
        read_session(tmp_path / "cut.mcap")
    with open(tmp_path / "nodepth.mcap", "wb") as f:  # valid MCAP, no input topics
        w = Writer(f)
        w.start()
        w.finish()
    with pytest.raises(SessionLogError, match=r"nodepth\.mcap: no input frames"):
        read_session(tmp_path / "nodepth.mcap")


def test_writer_keeps_repeated_and_backward_times_in_order_and_refuses_bad_paths(tmp_path):
    frames = camera_frames(3)
    with SessionWriter(tmp_path / "s.mcap", Settings()) as log:
        log.write_frame(0, frames[1])
        with pytest.warns(UserWarning, match="kept in arrival order"):
            log.write_frame(1, frames[1])  # repeated stamp (a Carmen log printed with 6 digits)
        log.write_frame(2, frames[0])  # backwards: kept, warned once only
        with pytest.raises(SessionLogError, match="cannot log a"):
            log.write_frame(3, "frame")
    with pytest.raises(SessionLogError, match="cannot create"):
        SessionWriter(tmp_path / "no" / "dir" / "s.mcap", Settings())
    assert len(list(read_session(tmp_path / "s.mcap").frames())) == 3  # every frame kept, closed cleanly


def test_unknown_truth_is_not_logged_and_bad_truth_is_refused(tmp_path):
    import dataclasses

    a, b = camera_frames(2)
    with SessionWriter(tmp_path / "s.mcap", Settings()) as log:
        assert log.write_frame(0, dataclasses.replace(a, ground_truth=np.full(3, np.nan))).ground_truth is None
        with pytest.raises(SessionLogError, match=r"frame 1: ground_truth must be \(x, y, theta\)"):
            log.write_frame(1, dataclasses.replace(b, ground_truth=np.zeros(2)))
    frames = list(read_session(tmp_path / "s.mcap").frames())
    assert len(frames) == 1 and frames[0].ground_truth is None


def test_background_and_inline_writing_give_the_same_bytes(tmp_path):
    frames = camera_frames(7, seed=4)
    for mode in ("true", "false"):
        settings = load_settings(overrides=[f"logging.background={mode}", "logging.chunk_max_frames=2"])
        write_fake_session(tmp_path / f"{mode}.mcap", frames, settings)
    def records(name):  # every chunk and message, in file order (the settings YAML differs)
        from mcap.records import Chunk, Message
        from mcap.stream_reader import StreamReader

        with open(tmp_path / name, "rb") as f:
            return [(r.data, getattr(r, "log_time", None)) for r in StreamReader(f, emit_chunks=True).records if isinstance(r, Chunk | Message)]

    assert records("true.mcap") == records("false.mcap") and len(records("true.mcap")) >= 4


class _DiskFull:
    """A file whose writes fail like a full disk."""

    def write(self, data):
        raise OSError(28, "No space left on device")

    def flush(self):
        pass

    def tell(self):
        return 0

    def close(self):
        pass


@pytest.mark.parametrize("background", ["true", "false"])
def test_write_failures_become_session_log_errors(tmp_path, background):
    settings = load_settings(overrides=[f"logging.background={background}", "logging.chunk_max_frames=1"])
    log = SessionWriter(tmp_path / "s.mcap", settings)
    log._sink._file = log._file = _DiskFull()  # the disk fills up mid-run
    log._mcap._Writer__stream = log._file
    with pytest.raises(SessionLogError, match=r"s\.mcap: writing the session failed: No space left on device"):
        for i, frame in enumerate(camera_frames(6)):  # the worker's failure surfaces on a later call
            log.write_frame(i, frame)
        log.close()
    log.close()  # closing again is harmless
    with pytest.raises(SessionLogError, match="writing the session failed"):
        SessionWriter("/dev/full", settings)
