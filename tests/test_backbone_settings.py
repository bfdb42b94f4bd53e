"""Boundary tests of the backbones.* settings no other test names: backbones.seg_model,
backbones.half_on_gpu and the class lists backbones.floor_classes / ceiling_classes /
unknown_classes. Models are tiny real architectures built from their config classes
(backbone_helpers): nothing is downloaded. The torch-free checks run everywhere; the
network ones are skipped without the [torch] extra."""

import numpy as np
import pytest

from benchmarks.inputs.random_backbones import random_images, save_segmentation_model

from zfloc_stream.backbones import Perception, class_codes
from zfloc_stream.backbones.perception import needs_backbones
from zfloc_stream.frames import CEILING, FLOOR, OTHER, UNKNOWN, WALL, CameraFrame
from zfloc_stream.settings.loading import load_settings

NAMES = {0: "wall", 1: "Tiles; Parquet", 2: "vault", 3: "void", 4: "floor", 5: "ceiling"}


def backbones(*overrides: str):
    return load_settings(overrides=list(overrides)).backbones


# --- the class lists (no torch needed) ------------------------------------------------------
def test_floor_classes_name_the_floor():
    """backbones.floor_classes: a class one of whose names ('parquet') is listed is floor;
    unlisted it is 'other'. The default list has no 'parquet'."""
    assert class_codes(NAMES, backbones())[1] == OTHER
    assert class_codes(NAMES, backbones("backbones.floor_classes=[parquet]"))[1] == FLOOR
    assert class_codes(NAMES, backbones("backbones.floor_classes=[parquet]"))[4] == OTHER  # the list replaces the default
    assert class_codes(NAMES, backbones("backbones.floor_classes=[]"))[4] == OTHER


def test_ceiling_classes_name_the_ceiling_after_the_floor():
    """backbones.ceiling_classes: 'vault' listed is ceiling, unlisted 'other'; a class named
    in both lists is floor (floor is matched first)."""
    assert class_codes(NAMES, backbones())[[2, 5]].tolist() == [OTHER, CEILING]
    assert class_codes(NAMES, backbones("backbones.ceiling_classes=[vault]"))[[2, 5]].tolist() == [CEILING, OTHER]
    both = backbones("backbones.ceiling_classes=[tiles]", "backbones.floor_classes=[tiles]")
    assert class_codes(NAMES, both)[1] == FLOOR


def test_unknown_classes_name_what_the_segmenter_cannot_tell():
    """backbones.unknown_classes: 'void' (in the default list) is unknown; with an empty list
    it is 'other'; a wall name listed as unknown stays wall (wall is matched first)."""
    assert class_codes(NAMES, backbones())[3] == UNKNOWN
    assert class_codes(NAMES, backbones("backbones.unknown_classes=[]"))[3] == OTHER
    assert class_codes(NAMES, backbones("backbones.unknown_classes=[wall, void]"))[[0, 3]].tolist() == [WALL, UNKNOWN]


# --- backbones.seg_model -------------------------------------------------------------------
def test_seg_model_decides_whether_a_frame_with_depth_needs_a_network():
    """backbones.seg_model: an RGB frame with depth but no labels needs the segmenter only
    when one is named (empty: it is used as it is); a frame with labels never does."""
    depth = np.full((6, 8), 2.0, dtype=np.float32)
    K = np.array([[4.0, 0, 4], [0, 4.0, 3], [0, 0, 1]])
    rgb = np.zeros((6, 8, 3), dtype=np.uint8)
    unlabelled = CameraFrame(depth, None, K, np.eye(4), 0.0, rgb=rgb)
    labelled = CameraFrame(depth, np.full((6, 8), WALL, dtype=np.uint8), K, np.eye(4), 0.0, rgb=rgb)
    assert not needs_backbones(unlabelled, backbones())
    assert needs_backbones(unlabelled, backbones("backbones.seg_model=some/segmenter"))
    assert not needs_backbones(labelled, backbones("backbones.seg_model=some/segmenter"))
    assert Perception.from_settings(backbones()) is None


# --- with the networks ([torch] extra) --------------------------------------------------------
@pytest.fixture(scope="module")
def seg_dir(tmp_path_factory):
    pytest.importorskip("torch")
    pytest.importorskip("transformers")
    return save_segmentation_model(tmp_path_factory.mktemp("seg"))


@pytest.fixture(autouse=True)
def _offline(monkeypatch):
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")  # nothing may be fetched


def test_seg_model_loads_the_named_segmenter_only(seg_dir):
    """backbones.seg_model names a local folder: Perception has that segmenter and no depth
    network; its labels replace none of a frame's depth."""
    perception = Perception.from_settings(backbones(f"backbones.seg_model={seg_dir}", "backbones.device=cpu"))
    assert perception is not None and perception.depth is None and perception.segmentation is not None
    assert perception.segmentation.name == str(seg_dir)


def test_floor_classes_reach_the_segmenters_pixels(seg_dir):
    """backbones.floor_classes through the network: with an empty floor list the floor
    classes are 'other', so their probability adds to other's: every pixel the default lists
    label floor becomes 'other', and every 'other' pixel stays so."""
    from zfloc_stream.backbones.hf import HfSegmentationBackbone

    images = random_images(3, shape=(40, 56), seed=5)
    plain = HfSegmentationBackbone(str(seg_dir), backbones("backbones.device=cpu")).predict(images)
    floorless = HfSegmentationBackbone(str(seg_dir), backbones("backbones.device=cpu", "backbones.floor_classes=[]")).predict(images)
    before = np.concatenate([p.ravel() for p in plain])
    after = np.concatenate([p.ravel() for p in floorless])
    assert (before == FLOOR).any() and not (after == FLOOR).any()
    assert (after[before == FLOOR] == OTHER).all() and (after[before == OTHER] == OTHER).all()


def test_half_on_gpu_is_ignored_on_the_cpu(seg_dir):
    """backbones.half_on_gpu: float16 weights only on a CUDA device; on the CPU the network
    runs float32 either way and labels every pixel the same."""
    import torch

    from zfloc_stream.backbones.hf import HfSegmentationBackbone

    images = random_images(2, shape=(40, 56), seed=6)
    half = HfSegmentationBackbone(str(seg_dir), backbones("backbones.device=cpu", "backbones.half_on_gpu=true"))
    full = HfSegmentationBackbone(str(seg_dir), backbones("backbones.device=cpu", "backbones.half_on_gpu=false"))
    assert half.dtype == full.dtype == torch.float32
    assert next(half.model.parameters()).dtype == torch.float32
    for a, b in zip(half.predict(images), full.predict(images), strict=True):
        np.testing.assert_array_equal(a, b)


def test_half_on_gpu_halves_the_network_on_a_gpu(seg_dir):
    """backbones.half_on_gpu on a CUDA device: true runs float16, false float32."""
    import torch

    if not torch.cuda.is_available():
        pytest.skip("no CUDA GPU")
    from zfloc_stream.backbones.hf import HfSegmentationBackbone

    half = HfSegmentationBackbone(str(seg_dir), backbones("backbones.device=cuda", "backbones.half_on_gpu=true"))
    full = HfSegmentationBackbone(str(seg_dir), backbones("backbones.device=cuda", "backbones.half_on_gpu=false"))
    assert half.dtype == torch.float16 and next(half.model.parameters()).dtype == torch.float16
    assert full.dtype == torch.float32
    images = random_images(2, shape=(40, 56), seed=6)
    assert [p.shape for p in half.predict(images)] == [(40, 56)] * 2
