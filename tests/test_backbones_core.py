"""RGB frames and the backbone plumbing without torch: label mapping by class names, the
preprocessing sizes, model paths, the missing-extra error, RGB topics in sessions, and
Perception batching with stand-in networks."""

import subprocess
import sys

import cv2
import numpy as np
import pytest
from benchmarks.inputs.random_backbones import rgb_frames, write_rgb_session
from mcap.writer import Writer
from mcap_protobuf.schema import build_file_descriptor_set

from zfloc_stream.backbones import INSTALL_HINT, Perception, class_codes, import_torch
from zfloc_stream.backbones.hf import Preprocess, resolve_source
from zfloc_stream.settings.loading import BackboneSettings, Settings
from zfloc_stream.errors import BackboneError, FrameError
from zfloc_stream.frames import CEILING, FLOOR, OTHER, UNKNOWN, WALL, CameraFrame
from zfloc_stream.stream.localizer import Localizer
from zfloc_stream.io.session import SessionWriter, read_session
from zfloc_stream.io.session import schemas as S
from zfloc_stream.tools.cli import main

ADE = {0: "wall", 1: "building, edifice", 3: "floor, flooring", 5: "ceiling", 8: "windowpane;window", 14: "door;double;door",
       28: "rug;carpet;carpeting", 42: "column, pillar", 19: "chair", 2: "sky", 4: "Unlabeled"}


def test_class_codes_from_names():
    codes = class_codes(ADE, BackboneSettings())
    assert codes.size == 43
    assert codes[[0, 8, 14, 42]].tolist() == [WALL] * 4
    assert codes[[3, 28]].tolist() == [FLOOR, FLOOR]
    assert codes[5] == CEILING
    assert codes[4] == UNKNOWN
    assert codes[[1, 2, 19]].tolist() == [OTHER] * 3
    assert codes[10] == OTHER  # an index the model does not name


def test_class_codes_do_not_depend_on_class_order():
    cfg = BackboneSettings()
    names = list(ADE.values())
    perm = np.random.default_rng(0).permutation(len(names))
    a = class_codes({i: n for i, n in enumerate(names)}, cfg)
    b = class_codes({i: names[p] for i, p in enumerate(perm)}, cfg)
    assert [b[i] for i in range(len(names))] == [a[p] for p in perm]
    by_name_a = {n: a[i] for i, n in enumerate(names)}
    assert all(by_name_a[names[p]] == b[i] for i, p in enumerate(perm))


def test_class_codes_need_a_wall_class_and_follow_settings():
    with pytest.raises(BackboneError, match="no class is named like a wall.*backbones.wall_classes"):
        class_codes({0: "cat", 1: "dog"}, BackboneSettings())
    codes = class_codes({0: "cat", 1: "dog"}, BackboneSettings(wall_classes=["dog"]))
    assert codes.tolist() == [OTHER, WALL]


def test_preprocess_sizes_follow_the_processor_rules():
    dpt = Preprocess.from_config({"size": {"height": 518, "width": 518}, "keep_aspect_ratio": True, "ensure_multiple_of": 14, "resample": 3}, "m")
    assert dpt.output_size(480, 640) == (518, 686)  # the scale closer to 1 on both axes, multiples of 14
    assert dpt.mode == "bicubic"
    seg = Preprocess.from_config({"size": {"height": 512, "width": 512}}, "m")
    assert seg.output_size(480, 640) == (512, 512)
    assert Preprocess.from_config({"size": 224}, "m").output_size(10, 20) == (224, 224)
    assert Preprocess.from_config({"size": {"shortest_edge": 240}}, "m").output_size(480, 640) == (240, 320)
    with pytest.raises(BackboneError, match="crops or pads"):
        Preprocess.from_config({"size": 224, "do_center_crop": True}, "m")


def test_model_sources(tmp_path):
    assert resolve_source("depth-anything/Depth-Anything-V2-Metric-Indoor-Small-hf") == "depth-anything/Depth-Anything-V2-Metric-Indoor-Small-hf"
    assert resolve_source(str(tmp_path)) == str(tmp_path)
    for missing in (str(tmp_path / "nope"), "./models/depth", "a/b/c"):
        with pytest.raises(BackboneError, match="model folder not found"):
            resolve_source(missing)
    (tmp_path / "f.bin").write_bytes(b"x")
    with pytest.raises(BackboneError, match="is a file"):
        resolve_source(str(tmp_path / "f.bin"))


class _NoTorch:
    """A meta-path finder that makes `import torch` / `import transformers` fail, as on
    an install without the [torch] extra."""

    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in ("torch", "transformers"):
            raise ImportError(f"No module named '{name}'")
        return None


@pytest.fixture
def no_torch(monkeypatch):
    for name in list(sys.modules):
        if name.split(".")[0] in ("torch", "transformers"):
            monkeypatch.delitem(sys.modules, name)
    monkeypatch.setattr(sys, "meta_path", [_NoTorch(), *sys.meta_path])


def test_missing_extra_says_exactly_what_to_install(no_torch):
    with pytest.raises(BackboneError) as err:
        import_torch()
    assert INSTALL_HINT in str(err.value) and "torch==2.13.0" in str(err.value) and "transformers" in str(err.value)
    with pytest.raises(BackboneError, match="pip install torch==2.13.0"):
        Perception.from_settings(BackboneSettings(depth_model="org/depth"))


def test_package_imports_without_torch():
    code = ("import sys\n"
            "class F:\n"
            "    def find_spec(self, name, path=None, target=None):\n"
            "        if name.split('.')[0] in ('torch', 'transformers'): raise ImportError(name)\n"
            "sys.meta_path.insert(0, F())\n"
            "import zfloc_stream, zfloc_stream.backbones, zfloc_stream.stream.localizer, zfloc_stream.tools.cli, zfloc_stream.io.session\n"
            "print('ok')")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and proc.stdout.strip() == "ok", proc.stderr


def _cli_failure(capsys, *args) -> str:
    assert main([*args, "--no-progress"]) == 2
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


@pytest.fixture(scope="module")
def rgb_session(tmp_path_factory):
    frames, plan, _ = rgb_frames("rooms", n=4, shape=(30, 40))
    return write_rgb_session(tmp_path_factory.mktemp("rgb") / "phone.mcap", frames, plan, Settings()), frames


def test_cli_missing_model_folder_is_one_line_exit_2(tmp_path, rgb_session, capsys):
    line = _cli_failure(capsys, "run", "--input", str(rgb_session[0]), "--depth-model", str(tmp_path / "no-model"), "--out", str(tmp_path / "o"))
    assert line == f"zfloc-stream: error: model folder not found: {tmp_path / 'no-model'}"


def test_cli_missing_extra_is_one_line_exit_2(tmp_path, rgb_session, capsys, no_torch):
    line = _cli_failure(capsys, "run", "--input", str(rgb_session[0]), "--depth-model", "org/depth", "--out", str(tmp_path / "o"))
    assert INSTALL_HINT in line


def test_cli_rgb_session_without_depth_model_is_refused(tmp_path, rgb_session, capsys):
    line = _cli_failure(capsys, "run", "--input", str(rgb_session[0]), "--out", str(tmp_path / "o"))
    assert "--depth-model" in line


def test_rgb_frames_validated():
    K = np.array([[20.0, 0, 20], [0, 20, 15], [0, 0, 1]])
    rgb = np.zeros((30, 40, 3), np.uint8)
    f = CameraFrame(None, None, K, np.eye(4), 1.0, rgb=rgb)
    assert f.shape == (30, 40) and f.depth is None
    with pytest.raises(FrameError, match="needs depth or an RGB image"):
        CameraFrame(None, None, K, np.eye(4), 1.0)
    with pytest.raises(FrameError, match="uint8"):
        CameraFrame(None, None, K, np.eye(4), 1.0, rgb=rgb.astype(float))
    with pytest.raises(FrameError, match="HxWx3"):
        CameraFrame(None, None, K, np.eye(4), 1.0, rgb=rgb[..., 0])
    with pytest.raises(FrameError, match="rgb image is 40x30 but depth is 20x10"):
        CameraFrame(np.ones((10, 20), np.float32), None, K, np.eye(4), 1.0, rgb=rgb)
    with pytest.raises(FrameError, match="labels shape"):
        CameraFrame(None, np.zeros((3, 3), np.uint8), K, np.eye(4), 1.0, rgb=rgb)


def test_rgb_session_round_trip(rgb_session):
    path, frames = rgb_session
    session = read_session(path)
    got = list(session.frames())
    assert len(got) == len(frames)
    for a, b in zip(got, frames, strict=True):
        assert a.depth is None and a.labels is None
        np.testing.assert_array_equal(a.rgb, b.rgb)
        np.testing.assert_array_equal(a.K, b.K)


def _foreign_rgb_file(path, frames, encode):
    """/camera/image from another tool: `encode(rgb, ns) -> message` (RawImage or CompressedImage)."""
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        ids = {}
        sample = encode(frames[0].rgb, 0)
        for topic, cls in ((S.TOPIC_ODOMETRY, S.PoseInFrame), (S.TOPIC_CALIBRATION, S.CameraCalibration), (S.TOPIC_IMAGE, type(sample))):
            sid = w.register_schema(cls.DESCRIPTOR.full_name, "protobuf", build_file_descriptor_set(cls).SerializeToString())
            ids[topic] = w.register_channel(topic, "protobuf", sid)
        for fr in frames:
            ns = S.seconds_to_ns(fr.timestamp)
            h, wd = fr.shape
            for topic, m in ((S.TOPIC_CALIBRATION, S.calibration_to_msg(fr.K, wd, h, ns)), (S.TOPIC_IMAGE, encode(fr.rgb, ns)),
                             (S.TOPIC_ODOMETRY, S.pose_to_msg(fr.T_odom_cam, ns, "odom"))):
                w.add_message(ids[topic], log_time=ns, data=m.SerializeToString(), publish_time=ns)
        w.finish()


def _compressed(fmt):
    def encode(rgb, ns):
        ok, data = cv2.imencode("." + fmt, np.ascontiguousarray(rgb[:, :, ::-1]))
        assert ok
        return S.CompressedImage(timestamp=S.to_stamp(ns), frame_id="camera", format=fmt, data=data.tobytes())

    return encode


def _bgr8(rgb, ns):
    h, w = rgb.shape[:2]
    padded = np.zeros((h, 3 * w + 4), np.uint8)  # rows padded: step > 3 * width
    padded[:, : 3 * w] = rgb[:, :, ::-1].reshape(h, -1)
    return S.RawImage(timestamp=S.to_stamp(ns), frame_id="camera", width=w, height=h, encoding="bgr8", step=3 * w + 4, data=padded.tobytes())


# jpeg: lossy at sharp colour edges, but a swapped channel order would be off by ~100 on average
@pytest.mark.parametrize("encode,max_diff,mean_diff", [(_compressed("png"), 0, 0), (_compressed("jpeg"), 90, 5), (_bgr8, 0, 0)], ids=["png", "jpeg", "bgr8"])
def test_foreign_colour_images_read_as_rgb(tmp_path, rgb_session, encode, max_diff, mean_diff):
    frames = rgb_session[1]
    _foreign_rgb_file(tmp_path / "f.mcap", frames, encode)
    got = list(read_session(tmp_path / "f.mcap").frames())
    assert len(got) == len(frames)
    for a, b in zip(got, frames, strict=True):
        diff = np.abs(a.rgb.astype(int) - b.rgb.astype(int))
        assert diff.max() <= max_diff and diff.mean() <= mean_diff


def test_unsupported_colour_encoding_is_a_clear_error():
    msg = S.RawImage(width=2, height=2, encoding="mono8", step=2, data=bytes(4))
    with pytest.raises(Exception, match="colour image encoding 'mono8' is not supported"):
        S.image_from_msg(msg)
    with pytest.raises(Exception, match="format 'gif'"):
        S.image_from_msg(S.CompressedImage(format="gif", data=b"GIF89a"))


class _FakeDepth:
    """A stand-in network: depth = 1 + mean colour / 100, recording its batch sizes."""

    name = "fake-depth"

    def __init__(self):
        self.calls = []

    def predict(self, images):
        self.calls.append(len(images))
        return [np.full(im.shape[:2], 1.0 + im.mean() / 100, np.float32) for im in images]


class _FakeSegmentation:
    name = "fake-seg"

    def __init__(self):
        self.calls = []

    def predict(self, images):
        self.calls.append(len(images))
        return [np.full(im.shape[:2], WALL, np.uint8) for im in images]


def _frames_mixed():
    K = np.array([[20.0, 0, 20], [0, 20, 15], [0, 0, 1]])
    rng = np.random.default_rng(0)
    out = []
    for i in range(7):
        rgb = rng.integers(0, 256, (30, 40, 3), dtype=np.uint8)
        depth = np.full((30, 40), 2.5, np.float32) if i == 3 else None  # frame 3: a depth camera
        out.append(CameraFrame(depth, None, K, np.eye(4), float(i), rgb=rgb))
    return out


def test_perception_batches_in_order_and_depth_camera_wins():
    depth, seg = _FakeDepth(), _FakeSegmentation()
    perception = Perception(depth, seg, batch_size=2)
    frames = _frames_mixed()
    out = list(perception.stream(iter(frames)))
    assert [f.timestamp for f in out] == [f.timestamp for f in frames]
    assert seg.calls == [2, 2, 2, 1]  # frames 0-1, 2-3, 4-5, 6: the depth-camera frame 3 needs labels only
    assert depth.calls == [2, 1, 2, 1]  # ... and no network depth
    np.testing.assert_array_equal(out[3].depth, frames[3].depth)  # the depth camera's depth is kept
    for f, o in zip(frames, out, strict=True):
        np.testing.assert_array_equal(o.labels, WALL)
        if f.depth is None:
            assert o.depth[0, 0] == pytest.approx(1.0 + f.rgb.mean() / 100)
    # without a segmenter the depth-camera frame needs nothing: it flushes the batch before it
    depth = _FakeDepth()
    out = list(Perception(depth, None, batch_size=2).stream(iter(frames)))
    assert depth.calls == [2, 1, 2, 1] and out[3] is frames[3]
    assert [f.timestamp for f in out] == [f.timestamp for f in frames]


def test_localizer_runs_backbones_on_rgb_frames_and_skips_without_them():
    from zfloc_stream.sim import build_scene

    plan = build_scene("rooms", seed=0).floorplan
    frames = _frames_mixed()
    est = Localizer(plan, Settings()).push(frames[0])
    assert est.skipped is not None and "--depth-model" in est.skipped
    depth = _FakeDepth()
    loc = Localizer(plan, Settings(), perception=Perception(depth, None))
    est = loc.push(frames[0])
    assert est.skipped is None and depth.calls == [1] and "backbones" in est.timings


class _Oracle:
    """Perfect networks: the simulator's depth (or labels) of the frame whose image this is."""

    def __init__(self, sim_frames, rgb_frames, attribute):
        self.name = f"oracle-{attribute}"
        self.truth = {f.rgb.tobytes(): getattr(s, attribute) for f, s in zip(rgb_frames, sim_frames, strict=True)}

    def predict(self, images):
        return [self.truth[im.tobytes()] for im in images]


def test_rgb_session_localizes_through_run_with_perfect_networks(tmp_path):
    """The RGB path itself (MCAP colour images -> batched networks -> depth/labels on the
    camera's pixel grid -> metric-prior localization) loses nothing: with networks that
    return the simulator's depth and labels, an RGB session localizes like a depth one."""
    from zfloc_stream.io.datasets import detect_source
    from zfloc_stream.tools.session_runner import run_session

    frames, plan, sim_frames = rgb_frames("apartment", n=40, shape=(120, 160))
    path = write_rgb_session(tmp_path / "phone.mcap", frames, plan, Settings())
    sequence = detect_source(path)
    assert sequence.needs_depth_network and sequence.settings_overrides == {"estimator": {"scale_mode": "prior"}}
    logged = list(sequence.frames())  # as read back from the file
    perception = Perception(_Oracle(sim_frames, logged, "depth"), _Oracle(sim_frames, logged, "labels"), batch_size=4)
    settings = Settings.model_validate({"estimator": {"scale_mode": "prior"}})
    outcome = run_session(sequence.floorplan, sequence.frames(), settings, tmp_path / "out", progress=False, perception=perception)
    assert all(e.skipped is None for e in outcome.estimates)
    errors = outcome.final_errors()
    assert outcome.estimates[-1].status in ("tracking", "ambiguous")
    assert errors.max() < 1.0, errors
