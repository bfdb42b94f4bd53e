"""RGB backbones: frames per second of depth + segmentation at 640x480.

    python -m benchmarks.bench_backbones                       # tiny models, then the real ones if cached
    python -m benchmarks.bench_backbones --frames 32 --batch 1 4 --device cpu
    python -m benchmarks.bench_backbones --depth-model DIR --seg-model DIR

Tiny models are the real architectures (Depth Anything, SegFormer) at toy sizes with
random weights (benchmarks/inputs/random_backbones.py): they measure the adapters' own cost (colour
upload, resize, normalisation, output resize, label grouping). The real defaults
(Depth-Anything-V2-Metric-Indoor-Small, SegFormer-B0 ADE20K) are measured when their
weights are in the local Hugging Face cache or given as folders; nothing is downloaded.
On a machine with CUDA, `--device auto` runs them there in float16. Numbers only: on a
shared machine, torch's worker threads slow down many times over when other processes
hold the cores (best and median of --repeats passes are printed; compare --threads 1).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from zfloc_stream.backbones import Perception, import_torch
from zfloc_stream.settings.loading import BackboneSettings
from zfloc_stream.errors import BackboneError
from zfloc_stream.frames import CameraFrame

from benchmarks.harness import Benchmark
from benchmarks.inputs.random_backbones import random_images, save_depth_model, save_segmentation_model

REAL_DEPTH = "depth-anything/Depth-Anything-V2-Metric-Indoor-Small-hf"
REAL_SEG = "nvidia/segformer-b0-finetuned-ade-512-512"


def rgb_frames(n: int, shape=(480, 640)) -> list[CameraFrame]:
    h, w = shape
    K = np.array([[w / 2, 0, w / 2], [0, w / 2, h / 2], [0, 0, 1.0]])
    return [CameraFrame(None, None, K, np.eye(4), float(i), rgb=im) for i, im in enumerate(random_images(n, shape, seed=1))]


def measure(table, label: str, depth: str, seg: str, frames, batches, device: str, torch, repeats: int) -> None:
    for batch in batches:
        cfg = BackboneSettings(depth_model=depth, seg_model=seg, device=device, batch_size=batch)
        try:
            t0 = time.perf_counter()
            perception = Perception.from_settings(cfg)
            load = time.perf_counter() - t0
        except BackboneError as err:
            print(f"{label}: skipped ({err})")
            return
        dev = (perception.depth or perception.segmentation).device
        parts = {"depth": Perception(perception.depth, None, batch), "seg": Perception(None, perception.segmentation, batch), "both": perception}
        for name, p in parts.items():
            p.complete(frames[:batch])  # warm-up: kernels, allocator
            fps = []
            for _ in range(repeats):  # best and median of several passes: the machine is shared
                if dev.type == "cuda":
                    torch.cuda.synchronize()
                t0 = time.perf_counter()
                for k in range(0, len(frames), batch):
                    p.complete(frames[k : k + batch])
                if dev.type == "cuda":
                    torch.cuda.synchronize()
                fps.append(len(frames) / (time.perf_counter() - t0))
            table.add(models=label, device=dev.type, batch=batch, network=name, best_fps=max(fps), median_fps=float(np.median(fps)), load_s=load)


def main(argv=None) -> int:
    bench = Benchmark("backbones", __doc__, frames=16, repeat=3)
    bench.parser.add_argument("--batch", type=int, nargs="+", default=[1, 4], help="batch sizes (default 1 4)")
    bench.parser.add_argument("--threads", type=int, default=0, help="torch CPU threads (default: torch's choice)")
    bench.parser.add_argument("--device", default="auto", help="auto (CUDA when present), cpu, cuda")
    bench.parser.add_argument("--depth-model", default=REAL_DEPTH, help=f"real depth model, folder or cached hub id (default {REAL_DEPTH})")
    bench.parser.add_argument("--seg-model", default=REAL_SEG, help=f"real segmentation model (default {REAL_SEG})")
    args = bench.parse(argv)  # --frames: 640x480 frames timed per case; --repeat: timed passes (best and median)
    shape = (480, 640)
    if args.quick:  # the tiny models only, 2 frames of 48x64, one pass
        args.frames, args.batch, args.repeat, shape = 2, [1], 1, (48, 64)
    torch, transformers = import_torch()
    if args.threads > 0:
        torch.set_num_threads(args.threads)
    bench.note(f"torch {torch.__version__}, transformers {transformers.__version__}, {torch.get_num_threads()} CPU threads, "
               f"CUDA {'yes' if torch.cuda.is_available() else 'no'}; {args.frames} frames of {shape[1]}x{shape[0]} per case")
    frames = rgb_frames(args.frames, shape)
    table = bench.table(["models", "device", "batch", "network", ("best_fps", "best fps"), ("median_fps", "median fps"), ("load_s", "load s")])
    with tempfile.TemporaryDirectory() as tmp:
        depth = save_depth_model(Path(tmp) / "depth")
        seg = save_segmentation_model(Path(tmp) / "seg")
        measure(table, "tiny", str(depth), str(seg), frames, args.batch, args.device, torch, args.repeat)
    if not args.quick:
        measure(table, "real", args.depth_model, args.seg_model, frames, args.batch, args.device, torch, args.repeat)
    return bench.done()


if __name__ == "__main__":
    raise SystemExit(main())
