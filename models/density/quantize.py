"""Lower-precision copies of an exported density model, for boards with INT8 or FP16 kernels (a Jetson's TensorRT).

- ``--precision int8`` (default): onnxruntime static quantization calibrated on training frames (never held-out
  ones): QDQ format, per-channel signed INT8 weights, unsigned INT8 activations, MinMax calibration.
- ``--precision fp16``: weights and arithmetic in float16 (onnxruntime's converter); the input and output stay
  float32, so the contract is unchanged.

The contract and training metadata are carried over, plus ``slz.quantization``.

Run::

    .venv/bin/python -m models.density.quantize --model models/density/slz_lite.onnx \
        --out models/density/slz_lite_int8.onnx --calibration data/synth/train --frames 64
    .venv/bin/python -m models.density.quantize --precision fp16 --model models/density/slz_lite.onnx \
        --out runs/slz_lite_fp16.onnx
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt
import onnx
from onnxruntime.quantization import (
    CalibrationDataReader,
    CalibrationMethod,
    QuantFormat,
    QuantType,
    quantize_static,
)
from onnxruntime.quantization.shape_inference import quant_pre_process

from models.data.images import frame_paths, read_bgr
from models.density.onnx_files import QUANTIZATION_KEY, read_metadata, set_metadata, stamp_any_size
from models.density.preprocess import INPUT_HEIGHT_PX, INPUT_WIDTH_PX, to_input


class FrameReader(CalibrationDataReader):
    """Feeds normalised frames (1, 3, 480, 640) to the calibrator."""

    def __init__(self, paths: list[Path], input_name: str = "image") -> None:
        self.paths, self.input_name, self.index = paths, input_name, 0

    def get_next(self) -> dict[str, npt.NDArray[np.float32]] | None:
        if self.index >= len(self.paths):
            return None
        image = read_bgr(self.paths[self.index])
        self.index += 1
        image = np.asarray(cv2.resize(image, (INPUT_WIDTH_PX, INPUT_HEIGHT_PX), interpolation=cv2.INTER_AREA), np.uint8)
        return {self.input_name: to_input(image)[None]}


def calibration_frames(folder: Path, count: int) -> list[Path]:
    """``count`` frames spread evenly over a split folder (``NNNNNN.png`` or ``.jpg``)."""
    frames = frame_paths(folder)
    step = max(1, len(frames) // count)
    return frames[::step][:count]


def quantize(model: Path, out: Path, frames: list[Path]) -> None:
    """Write the INT8 model."""
    metadata = read_metadata(model)
    with tempfile.TemporaryDirectory() as tmp:
        prepared = Path(tmp) / "prepared.onnx"
        quant_pre_process(str(model), str(prepared), skip_symbolic_shape=True)
        quantize_static(
            str(prepared),
            str(out),
            FrameReader(frames),
            quant_format=QuantFormat.QDQ,
            per_channel=True,
            activation_type=QuantType.QUInt8,
            weight_type=QuantType.QInt8,
            calibrate_method=CalibrationMethod.MinMax,
        )
    summary = {
        "format": "QDQ",
        "weights": "int8 per channel",
        "activations": "uint8",
        "calibration_frames": len(frames),
    }
    set_metadata(out, {**metadata, QUANTIZATION_KEY: json.dumps(summary)})
    stamp_any_size(out)  # measured again on the quantized graph


def to_float16(model: Path, out: Path) -> None:
    """Write the FP16 model: float16 weights and arithmetic, float32 input and output."""
    from onnxruntime.transformers.float16 import convert_float_to_float16

    metadata = read_metadata(model)
    half = convert_float_to_float16(onnx.load(str(model)), keep_io_types=True)
    onnx.save(half, str(out))
    summary = {"format": "float16", "weights": "float16", "activations": "float16", "io": "float32"}
    set_metadata(out, {**metadata, QUANTIZATION_KEY: json.dumps(summary)})
    stamp_any_size(out)


def main() -> int:
    parser = argparse.ArgumentParser(description="INT8 or FP16 copies of an SLZ density model.")
    parser.add_argument("--model", type=Path, required=True)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--precision", choices=["int8", "fp16"], default="int8")
    parser.add_argument("--calibration", type=Path, default=Path("data/synth/train"))
    parser.add_argument("--frames", type=int, default=64)
    args = parser.parse_args()
    if args.precision == "fp16":
        to_float16(args.model, args.out)
        sys.stdout.write(f"{args.out}: {args.out.stat().st_size} bytes, float16\n")
        return 0
    frames = calibration_frames(args.calibration, args.frames)
    quantize(args.model, args.out, frames)
    sys.stdout.write(f"{args.out}: {args.out.stat().st_size} bytes, calibrated on {len(frames)} frames\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
