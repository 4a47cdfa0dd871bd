"""A classical, untrained density model as an ONNX graph: multi-scale blob contrast.

It stands in for the trained crowd-density CNN (see ``models/``) wherever a real ONNX model is needed before
one exists, and builds the small graphs the tests use. Graph: an average-pooling pyramid -> three columns
(small, medium, large blobs, as MCNN's three heads), each a difference-of-Gaussians per colour channel with edge
padding -> absolute value (dark hair, bright clothes and colour contrast alike) -> mean over channels -> weighted
sum at the output stride -> ``relu(gain * (x - bias))``.

It responds to any small, high-contrast blob, people or not: useful for tests and demos on synthetic scenes,
not for flying over real ones. Building it needs the ``onnx`` package (the ``dev`` extra); running it needs only
onnxruntime.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from companion.perception.density import CONTRACT_METADATA_KEY, DensityModelContract


def _gaussian(size: int, sigma: float) -> npt.NDArray[np.float64]:
    ax = np.arange(size) - (size - 1) / 2.0
    g = np.exp(-(ax[:, None] ** 2 + ax[None, :] ** 2) / (2.0 * sigma**2))
    return np.asarray(g / g.sum(), dtype=np.float64)


def dog_kernel(sigma_px: float, ratio: float = 2.0) -> npt.NDArray[np.float32]:
    """Zero-sum difference-of-Gaussians kernel, shape (1, 1, k, k), k odd."""
    size = int(2 * np.ceil(3 * ratio * sigma_px) + 1)
    kernel = _gaussian(size, sigma_px) - _gaussian(size, ratio * sigma_px)
    return kernel[None, None].astype(np.float32)


def build_blob_density_model(
    width_px: int = 640,
    height_px: int = 480,
    stride: int = 4,
    levels: tuple[int, ...] = (1, 2, 4),
    sigma_px: float = 1.0,
    column_weights: tuple[float, ...] = (1.0, 1.0, 1.0),
    bias: float = 0.04,
    gain: float = 0.5,
    name: str = "blob-detector",
    opset: int = 17,
) -> Any:
    """Build the blob-contrast density model.

    Parameters
    ----------
    width_px, height_px : int
        Fixed input size (the contract's), divisible by ``stride`` and by every level.
    stride : int
        Output stride: the density map is (height / stride, width / stride). A power of two.
    levels : tuple of int
        Pyramid level (downsampling factor, a power of two) of each column: small, medium, large blobs.
    sigma_px : float
        Inner Gaussian sigma of every column's DoG, in pixels of its own level.
    column_weights : tuple of float
        Weight of each column's absolute response.
    bias, gain : float
        Output ``relu(gain * (response - bias))``: ``bias`` is the contrast below which nothing is reported.
    name : str
        Model name in the contract.
    opset : int
        ONNX opset (>= 17).

    Returns
    -------
    onnx.ModelProto
        With the input contract in its metadata (``slz.contract``), RGB, NCHW, scale 1/255.
    """
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    if len(column_weights) != len(levels):
        raise ValueError(f"one weight per level: {len(column_weights)} weights, {len(levels)} levels")
    contract = DensityModelContract(
        name=name,
        version="1",
        input_width_px=width_px,
        input_height_px=height_px,
        output_stride=stride,
    )
    kernel = dog_kernel(sigma_px)
    pad = kernel.shape[-1] // 2
    inits = [
        numpy_helper.from_array(np.repeat(kernel, 3, axis=0), "w_dog"),  # one DoG per colour channel
        numpy_helper.from_array(np.full((1, 3, 1, 1), 1.0 / 3.0, dtype=np.float32), "w_channels"),
        numpy_helper.from_array(np.array([0, 0, pad, pad, 0, 0, pad, pad], dtype=np.int64), "pads"),
        numpy_helper.from_array(np.array(bias, dtype=np.float32), "bias"),
        numpy_helper.from_array(np.array(gain, dtype=np.float32), "gain"),
    ]
    nodes = [helper.make_node("Identity", ["frame"], ["level1"])]
    made = {1}
    for level in sorted(set(levels) - made):
        previous = max(m for m in made if level % m == 0)
        factor = level // previous
        nodes.append(
            helper.make_node(
                "AveragePool",
                [f"level{previous}"],
                [f"level{level}"],
                kernel_shape=[factor] * 2,
                strides=[factor] * 2,
            )
        )
        made.add(level)
    columns = []
    for i, (level, weight) in enumerate(zip(levels, column_weights, strict=True)):
        inits.append(numpy_helper.from_array(np.array(weight, dtype=np.float32), f"w_col{i}"))
        nodes += [
            helper.make_node("Pad", [f"level{level}", "pads"], [f"padded{i}"], mode="edge"),
            helper.make_node("Conv", [f"padded{i}", "w_dog"], [f"dog{i}"], group=3),
            helper.make_node("Abs", [f"dog{i}"], [f"abs{i}"]),
            helper.make_node("Conv", [f"abs{i}", "w_channels"], [f"contrast{i}"]),
            helper.make_node("Mul", [f"contrast{i}", f"w_col{i}"], [f"col{i}"]),
        ]
        if level < stride:
            f = stride // level
            nodes.append(helper.make_node("MaxPool", [f"col{i}"], [f"out{i}"], kernel_shape=[f] * 2, strides=[f] * 2))
        elif level > stride:
            up = float(level // stride)
            inits.append(numpy_helper.from_array(np.array([1.0, 1.0, up, up], dtype=np.float32), f"scales{i}"))
            nodes.append(helper.make_node("Resize", [f"col{i}", "", f"scales{i}"], [f"out{i}"], mode="linear"))
        else:
            nodes.append(helper.make_node("Identity", [f"col{i}"], [f"out{i}"]))
        columns.append(f"out{i}")
    nodes += [
        helper.make_node("Sum", columns, ["response"]),
        helper.make_node("Sub", ["response", "bias"], ["shifted"]),
        helper.make_node("Mul", ["shifted", "gain"], ["scaled"]),
        helper.make_node("Relu", ["scaled"], ["density"]),
    ]
    graph = helper.make_graph(
        nodes,
        name,
        [helper.make_tensor_value_info("frame", TensorProto.FLOAT, [1, 3, height_px, width_px])],
        [helper.make_tensor_value_info("density", TensorProto.FLOAT, [1, 1, height_px // stride, width_px // stride])],
        initializer=inits,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", opset)], producer_name="slz-lander")
    model.ir_version = 8
    helper.set_model_props(model, {CONTRACT_METADATA_KEY: contract.model_dump_json(exclude_none=True)})
    onnx.checker.check_model(model, full_check=True)
    return model


def save_model(model: Any, path: str | Path) -> Path:
    """Write an ONNX model and return its path; the contract stays in the file's metadata."""
    import onnx

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    onnx.save(model, str(path))
    return path
