"""The Hugging Face adapters on tiny real-architecture models with random weights, saved
and loaded back by path (skipped without the [torch] extra). No accuracy claim: these
check loading, batching, resizing, label mapping and the RGB path through `run`."""

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("transformers")

from benchmarks.inputs.random_backbones import (  # noqa: E402
    ADE_LIKE,
    random_images,
    rgb_frames,
    save_depth_model,
    save_segmentation_model,
    write_rgb_session,
)

from zfloc_stream.backbones.hf import HfDepthBackbone, HfSegmentationBackbone  # noqa: E402
from zfloc_stream.settings.loading import BackboneSettings, Settings  # noqa: E402
from zfloc_stream.errors import BackboneError  # noqa: E402
from zfloc_stream.frames import CEILING, FLOOR, OTHER, WALL  # noqa: E402
from zfloc_stream.io.session import read_session  # noqa: E402
from zfloc_stream.tools.cli import main  # noqa: E402
from zfloc_stream.tools.replay_cli import main as replay_main  # noqa: E402


@pytest.fixture(autouse=True)
def _offline(monkeypatch):
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")  # belt and braces: nothing may be fetched


@pytest.fixture(scope="module")
def depth_dir(tmp_path_factory):
    return save_depth_model(tmp_path_factory.mktemp("depth"))


@pytest.fixture(scope="module")
def seg_dir(tmp_path_factory):
    return save_segmentation_model(tmp_path_factory.mktemp("seg"))


def test_depth_model_loads_by_path_and_outputs_metres_at_image_size(depth_dir):
    cfg = BackboneSettings(device="auto", batch_size=2, max_depth=15.0)
    depth = HfDepthBackbone(str(depth_dir), cfg)
    assert depth.device.type == ("cuda" if torch.cuda.is_available() else "cpu")
    images = random_images(3, shape=(48, 64)) + random_images(1, shape=(30, 40), seed=9)
    out = depth.predict(images)
    assert [d.shape for d in out] == [(48, 64)] * 3 + [(30, 40)]
    assert all(d.dtype == np.float32 for d in out)
    raw = HfDepthBackbone(str(depth_dir), cfg.model_copy(update={"max_depth": 1e6})).predict(images)
    for d, r in zip(out, raw, strict=True):
        assert (r > 0).all() and r.std() > 0.1  # random weights: depth varies with the image
        np.testing.assert_array_equal(d, np.where(r <= 15.0, r, 0.0))  # beyond max_depth: no reading
        assert 0 < (d > 0).mean() < 1
    # a batch of 2 + 1 gives what one frame at a time gives
    single = HfDepthBackbone(str(depth_dir), cfg.model_copy(update={"batch_size": 1}))
    for a, b in zip(out, single.predict(images), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-4)


def test_relative_depth_model_is_refused(tmp_path):
    folder = save_depth_model(tmp_path / "rel", kind="relative")
    with pytest.raises(BackboneError, match="relative depth"):
        HfDepthBackbone(str(folder), BackboneSettings())


def test_wrong_kind_of_model_is_one_clear_error(depth_dir):
    with pytest.raises(BackboneError, match="segmentation model .* cannot be loaded as AutoModelForSemanticSegmentation"):
        HfSegmentationBackbone(str(depth_dir), BackboneSettings())


def test_hub_id_not_in_cache_says_how_to_fetch_it():
    with pytest.raises(BackboneError, match="hf download nobody-here/no-such-model"):
        HfDepthBackbone("nobody-here/no-such-model", BackboneSettings())


def test_segmentation_codes_follow_names_not_indices(tmp_path, seg_dir):
    cfg = BackboneSettings(batch_size=3)
    base = HfSegmentationBackbone(str(seg_dir), cfg)
    expected = {"wall": WALL, "floor": FLOOR, "ceiling": CEILING, "windowpane;window": WALL, "door;double;door": WALL,
                "rug;carpet;carpeting": FLOOR, "column, pillar": WALL, "bed ": OTHER, "chair": OTHER}
    names = base.model.config.id2label
    for i, name in names.items():
        if name in expected:
            assert base.codes[i] == expected[name], name
    # the same network with its classes stored in another order labels every pixel the same
    perm = np.random.default_rng(3).permutation(len(ADE_LIKE))
    shuffled = HfSegmentationBackbone(str(save_segmentation_model(tmp_path / "shuffled", permutation=perm)), cfg)
    assert [shuffled.model.config.id2label[i] for i in range(len(perm))] != [names[i] for i in range(len(perm))]
    images = random_images(4, shape=(50, 70), seed=4)
    a, b = base.predict(images), shuffled.predict(images)
    for la, lb in zip(a, b, strict=True):
        assert la.shape == (50, 70) and la.dtype == np.uint8
        np.testing.assert_array_equal(la, lb)
    assert len(np.unique(np.concatenate([x.ravel() for x in a]))) >= 2  # not one constant code


def test_rgb_session_localized_end_to_end_through_run(tmp_path, depth_dir, seg_dir, capsys):
    frames, floorplan, _ = rgb_frames("rooms", n=6, shape=(60, 80))
    session = write_rgb_session(tmp_path / "phone.mcap", frames, floorplan, Settings())
    out = tmp_path / "out"
    code = main(["run", "--input", str(session), "--depth-model", str(depth_dir), "--seg-model", str(seg_dir),
                 "--set", "backbones.batch_size=4", "--out", str(out), "--no-progress"])
    assert code == 0, capsys.readouterr().err
    rows = (out / "trajectory.csv").read_text().splitlines()
    assert len(rows) == 1 + len(frames)
    logged = read_session(out / "session.mcap")
    assert logged.settings.estimator.scale_mode == "prior"  # network depth: metric up to ~10%
    assert logged.settings.backbones.depth_model == str(depth_dir)
    recs = list(logged.records())
    assert len(recs) == len(frames)
    # the log holds the networks' depth and labels for each frame's own image
    cfg = logged.settings.backbones
    depth = HfDepthBackbone(str(depth_dir), cfg).predict([f.rgb for f in frames])
    labels = HfSegmentationBackbone(str(seg_dir), cfg).predict([f.rgb for f in frames])
    for rec, f, d, lab in zip(recs, frames, depth, labels, strict=True):
        np.testing.assert_array_equal(rec.frame.rgb, f.rgb)
        np.testing.assert_allclose(rec.frame.depth, d, rtol=1e-4, atol=1e-4)
        assert np.mean(rec.frame.labels == lab) > 0.99
    # and it replays bit for bit from the logged depth and labels, without the networks
    code = replay_main([str(out / "session.mcap"), "--check", "--set", "backbones.depth_model=/no/such/model"])
    assert code == 0, capsys.readouterr()
