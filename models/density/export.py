"""Export a trained density network to ONNX (opset 17) with its input contract, and check it against PyTorch.

Run::

    .venv/bin/python -m models.density.export --checkpoint runs/train/lite/model.pt --out models/density/slz_lite.onnx \
        --name slz-lite --version 1 --check-frames data/synth/train

The ONNX file carries the ``slz.contract`` metadata that ``companion.perception.density.OnnxDensityModel`` reads, and
``slz.training`` (architecture, parameters, loss, steps, validation MAE). onnxruntime's output must match PyTorch's
within ``--tolerance`` (default 1e-4, absolute, per density cell) on random inputs and on real frames.

``--operating-threshold T`` bakes the network's chosen occupancy threshold into the file: ``scale * relu(density -
floor)`` with ``scale = 0.01 / (T - floor)``, so that the perception config's threshold (0.01 people per cell) is
occupied exactly where the network reaches ``T``, and the floor (fitted on ``--calibrate`` frames, below ``T``)
leaves the counts.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np
import onnx
import onnxruntime as ort
import torch

from models.data.images import frame_paths, read_bgr
from models.density.architectures import Architecture, build
from models.density.calibration import FLOORS, fit_floor_and_scale, fit_floor_for_threshold
from models.density.onnx_files import CONTRACT_KEY, TRAINING_KEY, set_metadata, stamp_any_size
from models.density.preprocess import INPUT_HEIGHT_PX, INPUT_WIDTH_PX, contract, to_input

if TYPE_CHECKING:
    from models.density.dataset import LabelledFrame

OPSET = 17


class Calibrated(torch.nn.Module):
    """``scale * relu(density - floor)``: removes the small positive floor a density network leaves on empty ground
    (it adds up to whole people over a 640x480 frame) and rescales the count. Both fitted on training frames."""

    def __init__(self, model: torch.nn.Module, floor: float, scale: float) -> None:
        super().__init__()
        self.model, self.floor, self.scale = model, floor, scale

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.relu(self.model(x) - self.floor) * self.scale


def calibrate(
    model: torch.nn.Module, frames: list[tuple[np.ndarray, int]], floors: tuple[float, ...] = ()
) -> tuple[float, float, float]:
    """The (floor, scale) that minimise the count MAE over ``frames`` (image, true count), and that MAE.

    For each candidate floor the scale is the ratio of true to predicted totals; the pair with the lowest mean
    absolute count error wins. Fit on training-split frames only.
    """
    maps = density_maps(model, [image for image, _ in frames])
    return fit_floor_and_scale(maps, [k for _, k in frames], floors or FLOORS)


def density_maps(model: torch.nn.Module, images_bgr: list[np.ndarray]) -> list[np.ndarray]:
    """The network's density map (h, w), people per cell, of each (H, W, 3) BGR frame."""
    with torch.no_grad():
        return [model(torch.from_numpy(to_input(image))[None])[0, 0].numpy() for image in images_bgr]


def load_checkpoint(path: Path) -> tuple[torch.nn.Module, dict[str, Any]]:
    """The network in eval mode and its training log."""
    checkpoint = torch.load(path, map_location="cpu", weights_only=True)
    model = build(Architecture(checkpoint["architecture"]))
    model.load_state_dict(checkpoint["state_dict"])
    model.eval()
    return model, dict(checkpoint["log"])


def export(model: torch.nn.Module, log: dict[str, Any], out: Path, name: str, version: str) -> None:
    """Write the ONNX file for input (1, 3, 480, 640) and output (1, 1, 120, 160) (the contract's size); a fully
    convolutional graph's sides are left free, with its context in the contract (:func:`stamp_any_size`)."""
    out.parent.mkdir(parents=True, exist_ok=True)
    dummy = torch.zeros(1, 3, INPUT_HEIGHT_PX, INPUT_WIDTH_PX)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the TorchScript exporter announces its deprecation
        torch.onnx.export(
            model,
            (dummy,),
            str(out),
            input_names=["image"],
            output_names=["density"],
            opset_version=OPSET,
            dynamo=False,
            do_constant_folding=True,
        )
    training = {k: v for k, v in log.items() if k != "history"}
    set_metadata(out, {CONTRACT_KEY: json.dumps(contract(name, version)), TRAINING_KEY: json.dumps(training)})
    stamp_any_size(out)  # the image sides freed and the context measured here, where onnx is installed
    onnx.checker.check_model(str(out))


def parity(model: torch.nn.Module, onnx_path: Path, frames_bgr: list[np.ndarray], seed: int = 0) -> float:
    """Largest absolute difference between PyTorch and onnxruntime outputs over random inputs and the frames."""
    session = ort.InferenceSession(str(onnx_path), providers=["CPUExecutionProvider"])
    rng = np.random.default_rng(seed)
    inputs = [rng.normal(0.0, 1.0, size=(3, INPUT_HEIGHT_PX, INPUT_WIDTH_PX)).astype(np.float32) for _ in range(2)]
    inputs += [to_input(f) for f in frames_bgr]
    worst = 0.0
    with torch.no_grad():
        for x in inputs:
            expected = model(torch.from_numpy(x)[None]).numpy()
            got = session.run(None, {"image": x[None]})[0]
            worst = max(worst, float(np.abs(expected - got).max()))
    return worst


def main() -> int:
    parser = argparse.ArgumentParser(description="Export a trained SLZ density network to ONNX and check parity.")
    parser.add_argument("--checkpoint", type=Path, required=True)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--name", required=True)
    parser.add_argument("--version", default="1")
    parser.add_argument("--check-frames", type=Path, default=None, help="folder of frames (*.png/*.jpg) for parity")
    parser.add_argument("--tolerance", type=float, default=1e-4)
    parser.add_argument(
        "--calibrate", type=Path, default=None, help="training split folder: fit floor and scale on its last frames"
    )
    parser.add_argument("--calibrate-frames", type=int, default=40)
    parser.add_argument(
        "--operating-threshold",
        type=float,
        default=None,
        help="the raw network's occupancy threshold (models/eval/threshold.py): exported so that the perception "
        "config's threshold (--deployed-threshold) is occupied exactly where this one is; the floor, below it, is "
        "fitted on --calibrate frames",
    )
    parser.add_argument("--deployed-threshold", type=float, default=0.01)
    args = parser.parse_args()
    model, log = load_checkpoint(args.checkpoint)
    labelled: list[LabelledFrame] = []
    if args.calibrate is not None:
        from models.density.dataset import load_frames

        labelled = load_frames(args.calibrate, last=args.calibrate_frames)
    if args.operating_threshold is not None:
        floor, scale, mae = 0.0, args.deployed_threshold / args.operating_threshold, math.nan
        if args.calibrate is not None:  # else no floor fitted: the count error is unknown (null in the metadata)
            maps = density_maps(model, [f.image_bgr for f in labelled])
            floor, scale, mae = fit_floor_for_threshold(
                maps, [len(f.heads_px) for f in labelled], args.operating_threshold, args.deployed_threshold
            )
        model = Calibrated(model, floor, scale).eval()
        log = {
            **log,
            "calibration": {
                "floor": floor,
                "scale": scale,
                "frames": len(labelled),
                "count_mae": None if math.isnan(mae) else mae,
                "operating_threshold": args.operating_threshold,
                "deployed_threshold": args.deployed_threshold,
            },
        }
        sys.stdout.write(
            f"occupied at {args.deployed_threshold:g} where the network reaches {args.operating_threshold:g}: "
            f"floor {floor:.5f}, scale {scale:.3f}, count MAE {mae:.2f} on {len(labelled)} training frames\n"
        )
    elif args.calibrate is not None:
        floor, scale, mae = calibrate(model, [(f.image_bgr, len(f.heads_px)) for f in labelled])
        model = Calibrated(model, floor, scale).eval()
        log = {**log, "calibration": {"floor": floor, "scale": scale, "frames": len(labelled), "count_mae": mae}}
        sys.stdout.write(
            f"calibrated on {len(labelled)} training frames: floor {floor:.5f}, scale {scale:.3f}, "
            f"count MAE {mae:.2f}\n"
        )
    export(model, log, args.out, args.name, args.version)
    frames: list[np.ndarray] = []
    if args.check_frames is not None:
        for path in frame_paths(args.check_frames)[:4]:  # the first four frames, never their masks
            image = read_bgr(path)
            frames.append(cv2.resize(image, (INPUT_WIDTH_PX, INPUT_HEIGHT_PX), interpolation=cv2.INTER_AREA))
    worst = parity(model, args.out, frames)
    ok = worst <= args.tolerance
    sys.stdout.write(
        f"{args.out}: {args.out.stat().st_size} bytes, opset {OPSET}; onnxruntime vs PyTorch max |diff| {worst:.2e} "
        f"over {2 + len(frames)} inputs: {'ok' if ok else 'FAILED'} (tolerance {args.tolerance:g})\n"
    )
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
