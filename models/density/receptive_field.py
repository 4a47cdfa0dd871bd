"""How far a density cell reads its input, from a convolutional ONNX graph: measured once at export.

:func:`make_any_size` frees a graph's image sides and returns the context (pixels) a cell reads past its own;
``models.density.onnx_files.stamp_any_size`` writes it into the file's contract (``context_px``), which is all the
drone reads (``companion.perception.density.OnnxDensityModel``): the graph analysis and the ``onnx`` package stay
on the machine that builds the models.
"""

from __future__ import annotations

import math
from typing import Any

import numpy.typing as npt

# Operators that map each spatial position of their input(s) to the same position of their output: they pass an
# output cell's dependence on the input through unchanged (:func:`input_extent_px`).
_POINTWISE_OPS = frozenset(
    {
        "Abs", "Add", "BatchNormalization", "Cast", "Clip", "DequantizeLinear", "Div", "Elu", "Exp", "Identity",
        "LeakyRelu", "Max", "Min", "Mul", "PRelu", "QuantizeLinear", "Relu", "Sigmoid", "Softplus", "Sub", "Sum",
        "Tanh",
    }
)  # fmt: skip
# Windowed operators: (index of the spatial input, index of the weight whose last two dims are the kernel, or None).
_WINDOW_OPS = {
    "Conv": (0, 1),
    "ConvInteger": (0, 1),
    "QLinearConv": (0, 3),
    "MaxPool": (0, None),
    "AveragePool": (0, None),
}


def _constant_values(graph: Any) -> dict[str, npt.NDArray[Any]]:
    """The graph's initializers and ``Constant`` outputs, by tensor name (shapes, slice bounds, resize scales), and
    the ``Cast`` of any of them (a float16 export casts its float constants back to float32 where they feed an
    operator it kept in float32, a resize's scales)."""
    from onnx import helper, numpy_helper

    values = {t.name: numpy_helper.to_array(t) for t in graph.initializer}
    for node in graph.node:
        if node.op_type == "Constant" and node.attribute and node.attribute[0].name == "value":
            values[node.output[0]] = numpy_helper.to_array(node.attribute[0].t)
    casts = [n for n in graph.node if n.op_type == "Cast" and n.attribute]
    changed = True
    while changed:  # a cast of a cast of a constant, in any order in the file
        changed = False
        for node in casts:
            if node.input[0] in values and node.output[0] not in values:
                to = {a.name: a for a in node.attribute}["to"].i
                values[node.output[0]] = values[node.input[0]].astype(helper.tensor_dtype_to_np_dtype(to))
                changed = True
    return values


# How far a tensor on the image's path reads the input: cell (i, j) reads rows up to ``stride_y * i + hi_y`` and
# columns up to ``stride_x * j + hi_x``; ``deepest``, the coarsest stride on any path to it (the alignment a crop
# needs).
_Extent = tuple[int, int, int, int, int]
_MAX_ALIGNMENT_PX = 16  # a shrunk frame's sides are multiples of 16 px (downscaled_size)
_OPEN_END = 2**31  # a slice end at least this large runs to the axis's end, whatever its size


def _slice_extent(node: Any, tracked: _Extent, consts: dict[str, npt.NDArray[Any]]) -> _Extent | None:
    """A ``Slice`` of an image-path tensor: channels pass through; along a spatial axis only an open-ended slice with
    a small start and a positive step (YOLOX's space-to-depth stem) keeps a cell's extent boundable."""
    if len(node.input) < 3 or any(name and name not in consts for name in node.input[1:]):
        return None
    starts, ends = consts[node.input[1]].tolist(), consts[node.input[2]].tolist()
    axes = consts[node.input[3]].tolist() if len(node.input) > 3 and node.input[3] else list(range(len(starts)))
    steps = consts[node.input[4]].tolist() if len(node.input) > 4 and node.input[4] else [1] * len(starts)
    sy, sx, hy, hx, deepest = tracked
    for start, end, axis, step in zip(starts, ends, axes, steps, strict=True):
        if axis in (0, 1, -3, -4):  # batch or channels
            continue
        if not (0 <= start < 16 and end >= _OPEN_END and 1 <= step <= 16):
            return None
        if axis in (2, -2):
            hy, sy = hy + start * sy, sy * step
        else:
            hx, sx = hx + start * sx, sx * step
    return sy, sx, hy, hx, max(deepest, sy, sx)


def _resize_extent(node: Any, tracked: _Extent, consts: dict[str, npt.NDArray[Any]]) -> _Extent | None:
    """An integer upsampling by constant ``scales`` (a feature map brought back to a finer stride): output cell i
    reads input cell floor(i / f), no farther than the same pixels (nearest, ``asymmetric`` and ``floor``), or one
    input cell more (any other nearest rounding, linear). ``sizes`` fix the output's size: None."""
    if len(node.input) < 3 or (len(node.input) > 3 and node.input[3]) or node.input[2] not in consts:
        return None
    attrs = {a.name: a for a in node.attribute}
    mode = attrs["mode"].s if "mode" in attrs else b"nearest"
    if mode not in (b"nearest", b"linear"):
        return None
    scales = consts[node.input[2]].tolist()
    if len(scales) != 4 or scales[:2] != [1.0, 1.0]:
        return None
    sy, sx, hy, hx, deepest = tracked
    factors = []
    for scale, stride in ((scales[2], sy), (scales[3], sx)):
        factor = round(scale)
        if factor < 1 or abs(scale - factor) > 1e-6 or stride % factor:
            return None
        factors.append(factor)
    coordinates = attrs["coordinate_transformation_mode"].s if "coordinate_transformation_mode" in attrs else b""
    rounding = attrs["nearest_mode"].s if "nearest_mode" in attrs else b""
    exact = mode == b"nearest" and coordinates == b"asymmetric" and rounding == b"floor"
    if not exact:
        hy, hx = hy + sy, hx + sx
    return sy // factors[0], sx // factors[1], hy, hx, deepest


def _topological(graph: Any) -> list[Any]:
    """The graph's nodes, each after the nodes whose outputs it reads. ONNX asks for that order, but not every tool
    keeps it (onnxruntime's float16 converter appends the input's and output's casts at the end)."""
    produced = {name for node in graph.node for name in node.output}
    ready = {i.name for i in graph.input} | {t.name for t in graph.initializer}
    pending, ordered = list(graph.node), []
    while pending:
        waiting = []
        for node in pending:
            if all(not name or name in ready or name not in produced for name in node.input):
                ordered.append(node)
                ready.update(node.output)
            else:
                waiting.append(node)
        if len(waiting) == len(pending):  # a cycle: left in the file's order
            return ordered + waiting
        pending = waiting
    return ordered


def input_extent_px(graph: Any) -> tuple[int, int] | None:
    """How far an output cell of a convolutional ONNX graph reads its input: (stride, extent).

    Output cell ``i`` (along either image axis) depends on input pixels ``stride * i + lo`` to ``stride * i + hi``
    only; ``extent`` is the larger of ``hi`` over both axes, so the pixels right of (or below) a cell's own that it
    reads. Followed through every path of the graph from its first input to its first output, over windowed
    operators (Conv, QLinearConv, ConvInteger, pooling: kernel, dilation, stride, explicit pads), pointwise ones,
    concatenation along the channels, open-ended strided slices (a space-to-depth stem) and integer upsampling by
    constant scales (a coarse stage brought back to a finer stride).

    Parameters
    ----------
    graph : onnx.GraphProto
        The graph.

    Returns
    -------
    tuple of int, or None
        None when the graph holds any other operator on the image's path (a resize to fixed sizes, a transpose, a
        flatten...), automatic padding, paths of different strides meeting, different strides along the two axes at
        the output, or a stage coarser than 16 px (a shrunk frame's sides are multiples of 16): then no cell's
        context can be bounded this way.
    """
    initializers = {t.name: list(t.dims) for t in graph.initializer}
    consts: dict[str, npt.NDArray[Any]] | None = None
    extent: dict[str, _Extent] = {graph.input[0].name: (1, 1, 0, 0, 1)}
    for node in _topological(graph):
        tracked = [extent[name] for name in node.input if name in extent]
        if not tracked:
            continue
        attrs = {a.name: a for a in node.attribute}
        out: _Extent | None
        if node.op_type in _POINTWISE_OPS or (node.op_type == "Concat" and attrs["axis"].i == 1):  # channels
            if len({t[:2] for t in tracked}) != 1:
                return None
            out = (
                tracked[0][0],
                tracked[0][1],
                max(t[2] for t in tracked),
                max(t[3] for t in tracked),
                max(t[4] for t in tracked),
            )
        elif node.op_type in ("Slice", "Resize"):
            if len(tracked) != 1 or node.input[0] not in extent:
                return None
            consts = _constant_values(graph) if consts is None else consts
            measure = _slice_extent if node.op_type == "Slice" else _resize_extent
            out = measure(node, tracked[0], consts)
        elif node.op_type in _WINDOW_OPS:
            x_index, w_index = _WINDOW_OPS[node.op_type]
            if len(tracked) != 1 or node.input[x_index] not in extent:
                return None
            if "auto_pad" in attrs and attrs["auto_pad"].s not in (b"", b"NOTSET"):
                return None
            if "ceil_mode" in attrs and attrs["ceil_mode"].i:
                return None
            if "kernel_shape" in attrs:
                kernel = list(attrs["kernel_shape"].ints)
            elif w_index is not None and node.input[w_index] in initializers:
                kernel = initializers[node.input[w_index]][-2:]
            else:
                return None
            if len(kernel) != 2:
                return None
            dilations = list(attrs["dilations"].ints) if "dilations" in attrs else [1, 1]
            strides = list(attrs["strides"].ints) if "strides" in attrs else [1, 1]
            pads = list(attrs["pads"].ints) if "pads" in attrs else [0, 0, 0, 0]
            sy, sx, hy, hx, deepest = tracked[0]
            # Output j reads inputs s*j - pad_begin ... s*j - pad_begin + (k - 1) * d of this operator's input.
            hy += (dilations[0] * (kernel[0] - 1) - pads[0]) * sy
            hx += (dilations[1] * (kernel[1] - 1) - pads[1]) * sx
            sy, sx = sy * strides[0], sx * strides[1]
            out = (sy, sx, hy, hx, max(deepest, sy, sx))
        else:
            return None
        if out is None:
            return None
        for name in node.output:
            extent[name] = out
    result = extent.get(graph.output[0].name)
    if result is None or result[0] != result[1] or result[4] > _MAX_ALIGNMENT_PX:
        return None
    return result[0], max(result[2], result[3])


def make_any_size(model: Any) -> int | None:
    """Free a model's image sides (symbolic) in place, and return the context (pixels) a cell reads past its own,
    rounded up to whole multiples of 16 px; None, the model left as it was, where that cannot be bounded
    (:func:`input_extent_px`).

    Done once at export (``models/density/any_size.py`` stamps the result into the file and its contract's
    ``context_px``), so a board without the ``onnx`` package runs shrunk frames cropped too.

    Parameters
    ----------
    model : onnx.ModelProto
        The model, changed in place when the result is not None.
    """
    found = input_extent_px(model.graph)
    if found is None:
        return None
    stride, hi = found
    values = (model.graph.input[0], model.graph.output[0])
    if any(len(v.type.tensor_type.shape.dim) < 3 for v in values):
        return None
    for value, names in zip(values, (("height", "width"), ("rows", "cols")), strict=True):
        # The image's (1, 3, H, W) and the map's (1, 1, h, w) or (1, h, w): ONNX convolutions are channels-first, so
        # a channels-last input reaches them through a transpose, which input_extent_px refuses.
        for dim, name in zip(value.type.tensor_type.shape.dim[-2:], names, strict=True):
            dim.ClearField("dim_value")
            dim.dim_param = name
    del model.graph.value_info[:]  # the intermediate shapes of the contract's size
    return 16 * math.ceil(max(0, hi - stride + 1) / 16)  # past the last cell's own pixels
