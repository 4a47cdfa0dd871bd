"""The input contract of the density models we train (written into the exported ONNX metadata).

No torch here: training, export, quantization calibration and evaluation all normalise frames the same way.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

INPUT_WIDTH_PX = 640
INPUT_HEIGHT_PX = 480
OUTPUT_STRIDE = 4
SCALE = 1.0 / 255.0
MEAN = (0.45, 0.45, 0.45)
STD = (0.25, 0.25, 0.25)


def contract(name: str, version: str) -> dict[str, object]:
    """The ``slz.contract`` metadata (companion.perception.density.DensityModelContract) of a model we export."""
    return {
        "name": name,
        "version": version,
        "input_width_px": INPUT_WIDTH_PX,
        "input_height_px": INPUT_HEIGHT_PX,
        "channel_order": "rgb",
        "layout": "nchw",
        "scale": SCALE,
        "mean": list(MEAN),
        "std": list(STD),
        "output_stride": OUTPUT_STRIDE,
    }


def to_input(image_bgr: npt.NDArray[np.uint8]) -> npt.NDArray[np.float32]:
    """BGR uint8 image of shape (H, W, 3) -> normalised RGB float32 tensor of shape (3, H, W)."""
    rgb = image_bgr[:, :, ::-1].astype(np.float32) * np.float32(SCALE)
    x = (rgb - np.asarray(MEAN, np.float32)) / np.asarray(STD, np.float32)
    return np.ascontiguousarray(x.transpose(2, 0, 1))
