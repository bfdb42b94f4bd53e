"""Camera frames completed by the backbones: network depth where a frame has none (a depth
camera's depth always wins), network labels where it has none and a segmenter is named.

    perception = Perception.from_settings(settings.backbones)   # None when no model is named
    for frame in perception.stream(frames):                    # batched, order kept
        localizer.push(frame)
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator

from ..settings.loading import BackboneSettings
from ..errors import FrameError
from ..frames import CameraFrame
from .base import DepthBackbone, SegmentationBackbone


def needs_backbones(frame, cfg: BackboneSettings) -> bool:
    """True for a camera frame with RGB and no depth, or with RGB, no labels and a
    segmenter named in the settings."""
    if not isinstance(frame, CameraFrame) or frame.rgb is None:
        return False
    return frame.depth is None or (frame.labels is None and bool(cfg.seg_model))


class Perception:
    def __init__(self, depth: DepthBackbone | None = None, segmentation: SegmentationBackbone | None = None, batch_size: int = 1):
        self.depth = depth
        self.segmentation = segmentation
        self.batch_size = max(1, int(batch_size))

    @classmethod
    def from_settings(cls, cfg: BackboneSettings) -> Perception | None:
        """Load the Hugging Face models named in the settings (None when none is)."""
        if not (cfg.depth_model or cfg.seg_model):
            return None
        from .hf import HfDepthBackbone, HfSegmentationBackbone

        depth = HfDepthBackbone(cfg.depth_model, cfg) if cfg.depth_model else None
        segmentation = HfSegmentationBackbone(cfg.seg_model, cfg) if cfg.seg_model else None
        return cls(depth, segmentation, cfg.batch_size)

    def wants(self, frame) -> bool:
        if not isinstance(frame, CameraFrame) or frame.rgb is None:
            return False
        return (frame.depth is None and self.depth is not None) or (frame.labels is None and self.segmentation is not None)

    def complete(self, frames: list) -> list:
        """The frames with network depth / labels filled in (one batched call per network).
        A frame whose network depth has no valid pixel raises FrameError for that frame
        only: it is returned as it was (the localizer skips it, saying why)."""
        todo = [i for i, f in enumerate(frames) if self.wants(f)]
        need_depth = [i for i in todo if frames[i].depth is None and self.depth is not None]
        need_labels = [i for i in todo if frames[i].labels is None and self.segmentation is not None]
        depths = dict(zip(need_depth, self.depth.predict([frames[i].rgb for i in need_depth]) if need_depth else [], strict=True))
        labels = dict(zip(need_labels, self.segmentation.predict([frames[i].rgb for i in need_labels]) if need_labels else [], strict=True))
        out = list(frames)
        for i in todo:
            f = frames[i]
            try:
                out[i] = CameraFrame(depths.get(i, f.depth), labels.get(i, f.labels), f.K, f.T_odom_cam, f.timestamp, f.ground_truth, rgb=f.rgb)
            except FrameError:
                out[i] = f
        return out

    def stream(self, frames: Iterable) -> Iterator:
        """Frames in order; those that need a network are run in batches of batch_size
        (a frame that needs nothing flushes the batch before it)."""
        batch: list = []
        for frame in frames:
            if self.wants(frame):
                batch.append(frame)
                if len(batch) >= self.batch_size:
                    yield from self.complete(batch)
                    batch = []
                continue
            if batch:
                yield from self.complete(batch)
                batch = []
            yield frame
        if batch:
            yield from self.complete(batch)
