"""Latency of the shipped density models per 640x480 frame, on one and on two CPU threads.

Run: ``.venv/bin/python -m bench.density [--frames N] [--model NAME=PATH.onnx ...] [--out bench/results/density.json]``
(``--model`` adds a candidate, e.g. a freshly trained network, beside the shipped ones).
Times ``OnnxDensityModel.predict`` (preprocessing included: colour conversion, normalisation, layout) on rendered
frames of the held-out style, after a warm-up, and a low-altitude frame (``predict_downscaled`` at 0.4: cropped where
the model runs at any size, padded to the whole frame where not). Prints median and p95 per variant and thread
count, the model's parameters and file size, and writes them as JSON with the machine's context.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from bench.machine import machine_context, save_report
from companion.perception.density import OnnxDensityModel, predict_downscaled
from models.data.images import read_bgr
from models.density.onnx_files import TRAINING_KEY, read_metadata

REPO_ROOT = Path(__file__).resolve().parent.parent
SHRUNK_SCALE = 0.4
"""A frame shrunk as at about 6 m (``perception.model.min_gsd_m_per_px``): the low-altitude cost, where a model
that runs at any size runs the shrunk frame cropped (``companion.perception.density.predict_downscaled``)."""


VARIANTS = {
    "slz-yolox (default)": "models/density/slz_yolox.onnx",
    "slz-yolox fp16": "models/density/slz_yolox_fp16.onnx",
    "slz-lite (synthetic-only option)": "models/density/slz_lite.onnx",
    "slz-lite int8 (history)": "models/density/slz_lite_int8.onnx",
    "slz-ccnn (paper, history)": "models/density/slz_ccnn.onnx",
    "slz-lite-wide-real (history)": "models/density/slz_lite_wide_real.onnx",
    "yolox-cb (issue 52 candidate, history)": "models/density/candidates/yolox_cb.onnx",
    "blob placeholder": "models/blob_detector/blob_detector.onnx",
}


def frames_for_bench(count: int) -> list[np.ndarray]:
    """Frames of the held-out style rendered by the SITL world (a few scenes, several altitudes)."""
    import tempfile

    from models.data.generate import Split, generate

    with tempfile.TemporaryDirectory() as tmp:
        written = generate(Path(tmp), Split.HELDOUT, frames=min(count, 8), base_seed=500)
        return [read_bgr(Path(tmp) / "heldout" / f"{f.stem}.png") for f in written]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--warmup", type=int, default=10)
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "bench" / "results" / "density.json")
    parser.add_argument("--model", action="append", default=[], help="NAME=PATH.onnx: also time this model")
    args = parser.parse_args()
    variants = dict(VARIANTS)
    for spec in args.model:
        name, _, rel = spec.partition("=")
        if not rel:
            parser.error(f"--model wants NAME=PATH, got {spec!r}")
        variants[name] = rel
    cv2.setNumThreads(1)
    frames = frames_for_bench(8)
    report: dict[str, object] = {"frame": "640x480 BGR", "frames": args.frames, "machine": machine_context()}
    rows = []
    for name, rel in variants.items():
        path = Path(rel) if Path(rel).is_absolute() else REPO_ROOT / rel
        if not path.is_file():
            sys.stdout.write(f"{name}: {rel} not found, skipped\n")
            continue
        training = json.loads(read_metadata(path).get(TRAINING_KEY, "{}"))
        for threads in (1, 2):
            model = OnnxDensityModel(path, intra_op_threads=threads)
            times = []
            for k in range(args.frames + args.warmup):
                start = time.perf_counter()
                model.predict(frames[k % len(frames)])
                if k >= args.warmup:
                    times.append((time.perf_counter() - start) * 1e3)
            shrunk = []  # a low-altitude frame: shrunk to SHRUNK_SCALE, cropped where the model runs at any size
            for k in range(args.frames // 2 + args.warmup):
                start = time.perf_counter()
                predict_downscaled(model, frames[k % len(frames)], SHRUNK_SCALE)
                if k >= args.warmup:
                    shrunk.append((time.perf_counter() - start) * 1e3)
            rows.append(
                {
                    "variant": name,
                    "file": rel,
                    "bytes": path.stat().st_size,
                    "parameters": training.get("parameters"),
                    "threads": threads,
                    "median_ms": float(np.median(times)),
                    "p95_ms": float(np.percentile(times, 95)),
                    "shrunk_scale": SHRUNK_SCALE,
                    "shrunk_cropped": model.context_px is not None,
                    "shrunk_median_ms": float(np.median(shrunk)),
                }
            )
    report["results"] = rows
    machine = report["machine"]
    assert isinstance(machine, dict)
    sys.stdout.write(f"density models, 640x480 frames, {args.frames} runs each, {machine['cpu_model']}\n")
    sys.stdout.write(
        f"{'variant':<30}{'threads':>8}{'median ms':>12}{'p95 ms':>10}{f'x{SHRUNK_SCALE:g} ms':>10}{'cropped':>9}"
        f"{'params':>10}{'bytes':>10}\n"
    )
    for r in rows:
        sys.stdout.write(
            f"{r['variant']:<30}{r['threads']:>8}{r['median_ms']:>12.2f}{r['p95_ms']:>10.2f}"
            f"{r['shrunk_median_ms']:>10.2f}{'yes' if r['shrunk_cropped'] else 'no':>9}"
            f"{r['parameters'] or '-':>10}{r['bytes']:>10}\n"
        )
    save_report(report, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
