"""Tiny pretrained-network stand-ins and RGB sessions for the backbone tests and
benchmarks/bench_backbones.py.

The models are the real architectures (Depth Anything on a DINOv2 backbone, SegFormer)
built from their config classes at toy sizes with seeded random weights, saved to a folder
the way the hub ships them (config.json, model.safetensors, preprocessor_config.json) and
loaded back by path: nothing is downloaded.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from zfloc_stream.frames import CameraFrame
from zfloc_stream.io.session import SessionWriter

# a shuffled subset of ADE20K names, in the hub's spelling
ADE_LIKE = ["wall", "floor", "ceiling", "bed ", "windowpane;window", "cabinet", "person", "door;double;door", "table", "rug;carpet;carpeting", "chair", "column, pillar"]

# ImageNet statistics, as in the hub configs of both default models
_MEAN, _STD = [0.485, 0.456, 0.406], [0.229, 0.224, 0.225]


def _randomize(model, seed: int, scale: float = 0.2):
    import torch

    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for p in model.parameters():
            p.copy_(torch.randn(p.shape, generator=g) * scale)
    return model.eval()


def save_depth_model(folder: Path, seed: int = 0, kind: str = "metric", max_depth: int = 20) -> Path:
    from transformers import DepthAnythingConfig, DepthAnythingForDepthEstimation, Dinov2Config

    backbone = Dinov2Config(hidden_size=32, num_hidden_layers=2, num_attention_heads=2, intermediate_size=64, patch_size=14,
                            image_size=56, out_features=["stage1", "stage2"], reshape_hidden_states=False)
    config = DepthAnythingConfig(backbone_config=backbone, reassemble_hidden_size=32, neck_hidden_sizes=[16, 32],
                                 reassemble_factors=[4, 2], fusion_hidden_size=16, head_hidden_size=8,
                                 depth_estimation_type=kind, max_depth=max_depth)
    _randomize(DepthAnythingForDepthEstimation(config), seed).save_pretrained(folder)
    _write_preprocessor(folder, {"image_processor_type": "DPTImageProcessor", "do_resize": True, "size": {"height": 56, "width": 56},
                                 "keep_aspect_ratio": True, "ensure_multiple_of": 14, "resample": 3, "do_rescale": True,
                                 "rescale_factor": 1 / 255, "do_normalize": True, "image_mean": _MEAN, "image_std": _STD, "do_pad": False})
    return folder


def save_segmentation_model(folder: Path, names=ADE_LIKE, seed: int = 1, permutation=None) -> Path:
    """SegFormer with classes `names`. permutation: class i of the saved model is class
    permutation[i] of the unpermuted one (same weights, classifier rows reordered)."""
    import torch
    from transformers import SegformerConfig, SegformerForSemanticSegmentation

    n = len(names)
    order = list(range(n)) if permutation is None else list(permutation)
    config = SegformerConfig(num_channels=3, num_encoder_blocks=2, depths=[1, 1], sr_ratios=[2, 1], hidden_sizes=[8, 16],
                             num_attention_heads=[1, 2], mlp_ratios=[2, 2], decoder_hidden_size=16, num_labels=n,
                             id2label={i: names[order[i]] for i in range(n)}, label2id={names[order[i]]: i for i in range(n)})
    model = _randomize(SegformerForSemanticSegmentation(config), seed)
    cls = model.decode_head.classifier
    # centre the classifier on the features of a few images: a random network's features
    # share a large mean, which would make one class win everywhere
    seen = []
    hook = cls.register_forward_hook(lambda _m, inp, _out: seen.append(inp[0]))
    x = torch.from_numpy(np.stack(random_images(4, shape=(64, 64), seed=99))).permute(0, 3, 1, 2).float() / 255
    with torch.no_grad():
        model(pixel_values=x)
        hook.remove()
        feats = seen[0]
        cls.bias.copy_(-(cls.weight[:, :, 0, 0] @ feats.mean(dim=(0, 2, 3))))
        gain = 5.0 / float(cls(feats).std())  # logits spread ~5 across pixels and classes
        cls.weight.mul_(gain)
        cls.bias.mul_(gain)
        cls.weight.copy_(cls.weight[order])
        cls.bias.copy_(cls.bias[order])
    model.save_pretrained(folder)
    _write_preprocessor(folder, {"image_processor_type": "SegformerImageProcessor", "do_resize": True, "size": {"height": 64, "width": 64},
                                 "resample": 2, "do_rescale": True, "rescale_factor": 1 / 255, "do_normalize": True,
                                 "image_mean": _MEAN, "image_std": _STD, "do_reduce_labels": True})
    return folder


def _write_preprocessor(folder: Path, cfg: dict) -> None:
    (Path(folder) / "preprocessor_config.json").write_text(json.dumps(cfg, indent=2))


def random_images(n: int, shape=(48, 64), seed: int = 0) -> list[np.ndarray]:
    """Images of a few random colour blocks plus noise (pure noise averages out in a
    random network: every pixel would look alike)."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        blocks = rng.integers(0, 256, (4, 4, 3)).astype(float)
        im = np.kron(blocks, np.ones((-(-shape[0] // 4), -(-shape[1] // 4), 1)))[: shape[0], : shape[1]]
        out.append(np.clip(im + rng.normal(0, 10, im.shape), 0, 255).astype(np.uint8))
    return out


# label code -> colour of a simulated RGB frame (walls light, floor wood, ceiling white)
_PALETTE = np.array([[0, 0, 0], [200, 190, 170], [120, 80, 40], [245, 245, 245], [60, 90, 160]], dtype=float)


def rgb_frames(scene: str = "rooms", n: int = 8, seed: int = 0, shape=(60, 80)) -> tuple[list[CameraFrame], object, list[CameraFrame]]:
    """RGB-only camera frames of a simulated walk (colours from the simulator's labels,
    shaded by its depth), the scene's floorplan, and the simulator's own frames (depth
    and labels: what perfect networks would give)."""
    from zfloc_stream.sim import SimSettings, build_scene, simulate

    sc = build_scene(scene, seed=seed)
    sim = simulate(sc, SimSettings(height=shape[0], width=shape[1]), seed=seed, n_frames=n)
    frames, sim_frames = [], list(sim)
    for f in sim_frames:
        shade = 1.0 / (1.0 + 0.1 * np.nan_to_num(f.depth))[..., None]
        rgb = np.clip(_PALETTE[f.labels] * (0.5 + 0.5 * shade), 0, 255).astype(np.uint8)
        frames.append(CameraFrame(None, None, f.K, f.T_odom_cam, f.timestamp, f.ground_truth, rgb=rgb))
    return frames, sc.floorplan, sim_frames


def write_rgb_session(path: Path, frames, floorplan, settings) -> Path:
    with SessionWriter(path, settings, floorplan) as log:
        for i, f in enumerate(frames):
            log.write_frame(i, f)
    return path
