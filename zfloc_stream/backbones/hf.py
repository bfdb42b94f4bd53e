"""Hugging Face transformers adapters: AutoModelForDepthEstimation and
AutoModelForSemanticSegmentation behind the interfaces of base.py.

    depth = HfDepthBackbone("depth-anything/Depth-Anything-V2-Metric-Indoor-Small-hf", settings.backbones)
    metres = depth.predict([rgb])[0]          # HxW float32, the image's own size

A model is a local folder (config.json + weights + preprocessor_config.json) or a hub id
found in the local Hugging Face cache (fetched only with backbones.download). The device
is chosen automatically (CUDA when present) and a GPU runs in float16. Preprocessing
(resize, rescale, normalise) runs in torch on the model's device from the values of the
model's preprocessor_config.json, so a batch never leaves the GPU and torchvision is not
needed; the network's output is resized back to the input image, whose pixel grid is the
one the camera intrinsics describe.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..settings.loading import BackboneSettings
from ..errors import BackboneError
from .base import choose_device, import_torch
from .labels import class_codes, grouping_matrix

PREPROCESSOR_FILE = "preprocessor_config.json"
# PIL resample codes used by image processors -> torch interpolation modes
_RESAMPLE = {0: "nearest", 2: "bilinear", 3: "bicubic"}
# depth models whose output is relative (inverse) depth, not metres
_RELATIVE_DEPTH_TYPES = {"dpt"}


def resolve_source(spec: str) -> str:
    """A local model folder, or a hub id ('org/name'). Something that can only be a path
    and is not a folder is an error here, before transformers sees it."""
    spec = str(spec).strip()
    if not spec:
        raise BackboneError("model name is empty: give a local folder or a Hugging Face hub id")
    path = Path(spec).expanduser()
    if path.is_dir():
        return str(path)
    if path.exists():
        raise BackboneError(f"model path {spec} is a file: give the model's folder (config.json, weights, {PREPROCESSOR_FILE})")
    if spec.startswith(("/", ".", "~")) or spec.count("/") > 1 or "\\" in spec:
        raise BackboneError(f"model folder not found: {spec}")
    return spec


@dataclass(frozen=True)
class Preprocess:
    """The image processor's resize / rescale / normalise, from its JSON config."""

    height: int | None  # target size; None with shortest_edge
    width: int | None
    shortest_edge: int | None
    keep_aspect_ratio: bool
    multiple: int
    mode: str
    rescale: float | None
    mean: tuple[float, ...] | None
    std: tuple[float, ...] | None

    @classmethod
    def from_config(cls, cfg: dict, model: str) -> Preprocess:
        if cfg.get("do_center_crop") or cfg.get("do_pad"):
            raise BackboneError(f"{model}: its image processor crops or pads, so outputs would not line up with the image")
        size = cfg.get("size") if cfg.get("do_resize", True) else None
        h = w = edge = None
        if isinstance(size, int):
            h = w = size
        elif isinstance(size, dict) and "height" in size and "width" in size:
            h, w = int(size["height"]), int(size["width"])
        elif isinstance(size, dict) and "shortest_edge" in size:
            edge = int(size["shortest_edge"])
        elif size is not None:
            raise BackboneError(f"{model}: image processor size {size!r} is not supported (height/width or shortest_edge)")
        normalize = cfg.get("do_normalize", True)
        return cls(
            height=h,
            width=w,
            shortest_edge=edge,
            keep_aspect_ratio=bool(cfg.get("keep_aspect_ratio", False)),
            multiple=int(cfg.get("ensure_multiple_of") or 1),
            mode=_RESAMPLE.get(int(cfg.get("resample", 2)), "bilinear"),
            rescale=float(cfg.get("rescale_factor", 1 / 255)) if cfg.get("do_rescale", True) else None,
            mean=tuple(cfg.get("image_mean", (0.485, 0.456, 0.406))) if normalize else None,
            std=tuple(cfg.get("image_std", (0.229, 0.224, 0.225))) if normalize else None,
        )

    def output_size(self, h: int, w: int) -> tuple[int, int]:
        """Network input size for an h x w image (DPT's rule for keep_aspect_ratio: the
        scale closer to 1 is used on both axes, sides rounded to the multiple)."""
        if self.shortest_edge is not None:
            s = self.shortest_edge / min(h, w)
            sh = sw = s
        elif self.height is None:
            return h, w
        else:
            sh, sw = self.height / h, self.width / w
            if self.keep_aspect_ratio:
                sh = sw = sw if abs(1 - sw) < abs(1 - sh) else sh
        m = self.multiple
        return max(m, int(round(sh * h / m)) * m), max(m, int(round(sw * w / m)) * m)

    def __call__(self, torch, images: np.ndarray, device, dtype):
        """(B, H, W, 3) uint8 -> (B, 3, h, w) network input on the device."""
        x = torch.from_numpy(np.ascontiguousarray(images)).to(device).permute(0, 3, 1, 2).float()
        size = self.output_size(*images.shape[1:3])
        if size != tuple(images.shape[1:3]):
            antialias = self.mode in ("bilinear", "bicubic")  # as PIL, which filters when shrinking
            x = torch.nn.functional.interpolate(x, size=size, mode=self.mode, antialias=antialias, align_corners=False if antialias else None)
        if self.rescale is not None:
            x = x * self.rescale
        if self.mean is not None:
            x = (x - torch.tensor(self.mean, device=device).view(1, -1, 1, 1)) / torch.tensor(self.std, device=device).view(1, -1, 1, 1)
        return x.to(dtype)


def _first_line(err: Exception) -> str:
    text = str(err).strip()
    return text.splitlines()[0] if text else type(err).__name__


class _HfModel:
    """Loading shared by both adapters: source, weights, preprocessing, device, dtype."""

    auto_class = ""  # transformers class name
    kind = ""  # for messages

    def __init__(self, spec: str, cfg: BackboneSettings):
        source = resolve_source(spec)  # a missing folder is reported with or without torch
        torch, transformers = import_torch()
        self.torch = torch
        self.cfg = cfg
        self.name = str(spec)
        local_only = not cfg.download
        bars = transformers.utils.logging.is_progress_bar_enabled()
        transformers.utils.logging.disable_progress_bar()  # our CLI owns the terminal
        try:
            self.model = getattr(transformers, self.auto_class).from_pretrained(source, local_files_only=local_only)
            with open(transformers.utils.cached_file(source, PREPROCESSOR_FILE, local_files_only=local_only)) as f:
                pre = json.load(f)
        except OSError as err:
            if Path(source).is_dir():
                raise BackboneError(f"{self.kind} model {spec}: {_first_line(err)}") from None
            raise BackboneError(
                f"{self.kind} model '{spec}' is not a local folder and not in the Hugging Face cache: "
                f"fetch it once with `hf download {spec}` (or set backbones.download=true)"
            ) from None
        except (ValueError, KeyError, json.JSONDecodeError) as err:
            raise BackboneError(f"{self.kind} model {spec} cannot be loaded as {self.auto_class}: {_first_line(err)}") from None
        finally:
            if bars:
                transformers.utils.logging.enable_progress_bar()
        if not isinstance(pre, dict):
            raise BackboneError(f"{self.kind} model {spec}: {PREPROCESSOR_FILE} is not a JSON object")
        self.preprocess = Preprocess.from_config(pre, self.name)
        self.device = choose_device(torch, cfg.device)
        self.dtype = torch.float16 if self.device.type == "cuda" and cfg.half_on_gpu else torch.float32
        self.model = self.model.to(device=self.device, dtype=self.dtype).eval()

    def _batches(self, images: list[np.ndarray]):
        """(indices, stacked images) per run of at most batch_size images of one size."""
        images = [_check_rgb(im, self.name) for im in images]
        by_size: dict[tuple[int, int], list[int]] = {}
        for i, im in enumerate(images):
            by_size.setdefault(im.shape[:2], []).append(i)
        n = self.cfg.batch_size
        for indices in by_size.values():
            for k in range(0, len(indices), n):
                chunk = indices[k : k + n]
                yield chunk, np.stack([images[i] for i in chunk])

    def _run(self, batch: np.ndarray):
        x = self.preprocess(self.torch, batch, self.device, self.dtype)
        with self.torch.inference_mode():
            return self.model(pixel_values=x)

    def _resize(self, x, size: tuple[int, int]):
        """(B, C, h, w) -> (B, C, H, W), bilinear, float32."""
        return self.torch.nn.functional.interpolate(x.float(), size=size, mode="bilinear", align_corners=False)


class HfDepthBackbone(_HfModel):
    """RGB -> metric depth (metres, float32, 0 where beyond backbones.max_depth)."""

    auto_class = "AutoModelForDepthEstimation"
    kind = "depth"

    def __init__(self, spec: str, cfg: BackboneSettings):
        super().__init__(spec, cfg)
        config = self.model.config
        if getattr(config, "depth_estimation_type", None) == "relative" or config.model_type in _RELATIVE_DEPTH_TYPES:
            raise BackboneError(f"depth model {spec} predicts relative depth; a metric model is needed (e.g. a Depth-Anything-V2-Metric model)")

    def predict(self, images: list[np.ndarray]) -> list[np.ndarray]:
        out: list[np.ndarray | None] = [None] * len(images)
        for indices, batch in self._batches(images):
            depth = self._run(batch).predicted_depth
            depth = self._resize(depth[:, None], batch.shape[1:3])[:, 0].cpu().numpy()
            for i, d in zip(indices, depth, strict=True):
                d = d.astype(np.float32)
                d[~np.isfinite(d) | (d <= 0) | (d > self.cfg.max_depth)] = 0.0
                out[i] = d
        return out


class HfSegmentationBackbone(_HfModel):
    """RGB -> label codes. Class probabilities are summed per code (wall, floor, ...) at
    the network's resolution, upsampled, then the most probable code wins: cheaper than
    upsampling 150 ADE20K logits and smooth at edges."""

    auto_class = "AutoModelForSemanticSegmentation"
    kind = "segmentation"

    def __init__(self, spec: str, cfg: BackboneSettings):
        super().__init__(spec, cfg)
        config = self.model.config
        self.codes = class_codes(config.id2label, cfg, f"segmentation model {spec}")
        n = int(getattr(config, "num_labels", self.codes.size))
        if self.codes.size != n:
            raise BackboneError(f"segmentation model {spec}: id2label names {self.codes.size} classes but the model has {n}")
        self.grouping = self.torch.from_numpy(grouping_matrix(self.codes)).to(self.device)

    def predict(self, images: list[np.ndarray]) -> list[np.ndarray]:
        out: list[np.ndarray | None] = [None] * len(images)
        for indices, batch in self._batches(images):
            probs = self._run(batch).logits.float().softmax(dim=1)
            grouped = self.torch.einsum("bchw,ck->bkhw", probs, self.grouping)
            labels = self._resize(grouped, batch.shape[1:3]).argmax(dim=1).to(self.torch.uint8).cpu().numpy()
            for i, lab in zip(indices, labels, strict=True):
                out[i] = lab
        return out


def _check_rgb(image, model: str) -> np.ndarray:
    im = np.asarray(image)
    if im.ndim != 3 or im.shape[2] != 3 or im.dtype != np.uint8:
        raise BackboneError(f"{model}: images must be HxWx3 uint8 RGB, got shape {im.shape} {im.dtype}")
    return im
