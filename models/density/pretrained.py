"""Early layers of a network trained on real photographs, as a trainable PyTorch module (training only).

Issue 52: features learned on real photographs are the usual way through a synthetic-to-real gap. The pretrained
networks in ``../shared/pretrained`` (Apache-2.0; ``../shared/SOURCES.md``) come as ONNX graphs. This module reads
the part of a graph that feeds the tensors asked for and runs it with torch operations whose convolution weights are
``nn.Parameter`` s: a small interpreter of our own for the operations these backbones use (Conv, Sigmoid, Mul, Add,
Concat, Slice, Relu, Clip, MaxPool), so no converter package is needed. Batch norms are already folded into the
convolutions of an exported graph, so fine-tuning moves the folded weights (use a low learning rate, or freeze).

:data:`YOLOX_NANO` names what the density network takes from YOLOX-nano (COCO, 0.91 M parameters): its stride-4 and
stride-8 stages (``dark2``, 32 channels; ``dark3``, 64 channels), 84 of its 369 nodes and 0.10 M of its parameters.
YOLOX takes BGR in 0-255 without normalisation; :class:`PretrainedStages` takes the density network's own input (RGB,
``(x / 255 - mean) / std``, ``models.density.preprocess``) and undoes that first, so the exported density model keeps
the companion's input contract.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import onnx
import torch
from onnx import numpy_helper
from torch import nn
from torch.nn import functional as F  # noqa: N812

from models.density.onnx_files import OnnxGraphError

PRETRAINED_DIR = Path(__file__).resolve().parents[3] / "shared" / "pretrained"


@dataclass(frozen=True)
class BackboneSpec:
    """Which pretrained graph, which of its tensors, and what input it expects."""

    file: str
    outputs: tuple[str, ...]
    channels: tuple[int, ...]
    strides: tuple[int, ...]
    input_bgr: bool
    input_scale: float  # the graph's input = pixel (0-255) * input_scale
    licence: str


YOLOX_NANO = BackboneSpec(
    file="yolox_nano_coco_416.onnx",
    outputs=("721", "781"),  # dark2 (stride 4, 32 ch) and dark3 (stride 8, 64 ch): the SiLU outputs of their stages
    channels=(32, 64),
    strides=(4, 8),
    input_bgr=True,
    input_scale=1.0,
    licence="Apache-2.0 (Megvii-BaseDetection/YOLOX; COCO train2017 weights)",
)


YOLOX_NANO_CONTEXT = BackboneSpec(
    file="yolox_nano_coco_416.onnx",
    outputs=("721", "781", "841"),  # dark2, dark3 and dark4 (stride 16, 128 ch): 130 of the graph's 369 nodes
    channels=(32, 64, 128),
    strides=(4, 8, 16),
    input_bgr=True,
    input_scale=1.0,
    licence="Apache-2.0 (Megvii-BaseDetection/YOLOX; COCO train2017 weights)",
)
"""YOLOX-nano up to its stride-16 stage: the context around a person (a path, a lawn, a roof) that stride 8 lacks."""


def _attributes(node: onnx.NodeProto) -> dict[str, object]:
    return {a.name: onnx.helper.get_attribute_value(a) for a in node.attribute}


def _ints(attributes: dict[str, object], key: str, default: list[int]) -> list[int]:
    """An integer-list attribute of a node (its default where absent)."""
    value = attributes.get(key, default)
    assert isinstance(value, list | tuple)
    return [int(v) for v in value]


def _int(attributes: dict[str, object], key: str, default: int) -> int:
    """An integer attribute of a node (its default where absent)."""
    value = attributes.get(key, default)
    assert isinstance(value, int)
    return value


class OnnxStages(nn.Module):
    """The nodes of an ONNX graph that feed ``outputs``, run with torch; convolution weights trainable.

    Parameters
    ----------
    path : Path
        The ONNX file.
    outputs : tuple of str
        Names of the tensors to return, in this order.
    """

    SUPPORTED = frozenset({"Conv", "Sigmoid", "Mul", "Add", "Concat", "Slice", "Relu", "Clip", "MaxPool"})

    def __init__(self, path: Path, outputs: tuple[str, ...]) -> None:
        super().__init__()
        if not path.is_file():
            raise OnnxGraphError(f"{path}: no such pretrained graph (../shared/pretrained, see ../shared/SOURCES.md)")
        graph = onnx.load(str(path)).graph
        constants = {t.name: numpy_helper.to_array(t) for t in graph.initializer}
        producer = {out: node for node in graph.node for out in node.output}
        needed: list[onnx.NodeProto] = []
        seen: set[str] = set()

        def visit(tensor: str) -> None:  # depth-first: every node after the nodes it reads
            node = producer.get(tensor)
            if node is None or node.name in seen:
                return
            seen.add(node.name)
            for source in node.input:
                visit(source)
            needed.append(node)

        first_needed: list[int] = []  # per output: where its nodes (those no earlier output needs) begin
        for name in outputs:
            if name not in producer:
                raise OnnxGraphError(f"{path}: no tensor named {name!r}")
            first_needed.append(len(needed))
            visit(name)
        self.inputs = [i.name for i in graph.input]
        self.outputs = outputs
        self.nodes: list[tuple[str, list[str], str, dict[str, object]]] = []
        self.weights = nn.ParameterDict()
        self.constants: dict[str, np.ndarray] = {}
        self.stage_of: dict[str, int] = {}
        """Each weight's stage: the index of the first output whose nodes include its convolution."""
        for k, node in enumerate(needed):
            if node.op_type not in self.SUPPORTED:
                raise OnnxGraphError(f"{path}: node {node.name} is a {node.op_type}, which is not supported")
            attributes = _attributes(node)
            if node.op_type == "Conv":
                for role, name in zip(("weight", "bias"), node.input[1:], strict=False):
                    self.weights[f"{node.name}_{role}"] = nn.Parameter(torch.from_numpy(constants[name].copy()))
                    self.stage_of[f"{node.name}_{role}"] = sum(1 for start in first_needed if start <= k) - 1
            else:
                for name in node.input:
                    if name in constants:
                        self.constants[name] = constants[name]
            self.nodes.append((node.op_type, list(node.input), node.output[0], attributes | {"name": node.name}))

    def stage_parameters(self, stages: int) -> list[nn.Parameter]:
        """The weights of the first ``stages`` stages (those that compute the first ``stages`` outputs)."""
        return [w for key, w in self.weights.items() if self.stage_of[key] < stages]

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        """The graph's input (N, C, H, W) -> the ``outputs`` tensors."""
        values: dict[str, torch.Tensor] = {self.inputs[0]: x}
        for op, inputs, output, attributes in self.nodes:
            values[output] = self._run(op, inputs, attributes, values)
        return [values[name] for name in self.outputs]

    def _run(
        self, op: str, inputs: list[str], attributes: dict[str, object], values: dict[str, torch.Tensor]
    ) -> torch.Tensor:
        name = str(attributes["name"])
        if op == "Conv":
            pads = _ints(attributes, "pads", [0, 0, 0, 0])
            if pads[:2] != pads[2:]:
                raise OnnxGraphError(f"node {name}: asymmetric padding {pads}")
            bias = self.weights.get(f"{name}_bias")
            return F.conv2d(
                values[inputs[0]],
                self.weights[f"{name}_weight"],
                bias,
                stride=tuple(_ints(attributes, "strides", [1, 1])),
                padding=tuple(pads[:2]),
                dilation=tuple(_ints(attributes, "dilations", [1, 1])),
                groups=_int(attributes, "group", 1),
            )
        if op == "Sigmoid":
            return torch.sigmoid(values[inputs[0]])
        if op == "Relu":
            return torch.relu(values[inputs[0]])
        if op == "Clip":
            low, high = (float(self.constants[i]) for i in inputs[1:3])
            return torch.clamp(values[inputs[0]], low, high)
        if op == "Mul":
            return values[inputs[0]] * values[inputs[1]]
        if op == "Add":
            return values[inputs[0]] + values[inputs[1]]
        if op == "Concat":
            return torch.cat([values[i] for i in inputs], dim=_int(attributes, "axis", 0))
        if op == "MaxPool":
            kernel = tuple(_ints(attributes, "kernel_shape", []))
            pads = _ints(attributes, "pads", [0, 0, 0, 0])
            stride = tuple(_ints(attributes, "strides", [1, 1]))
            return F.max_pool2d(values[inputs[0]], kernel, stride=stride, padding=tuple(pads[:2]))
        # Slice: starts, ends, axes, steps from constants (YOLOX's Focus stem: every other row and column)
        tensor = values[inputs[0]]
        starts, ends = self.constants[inputs[1]], self.constants[inputs[2]]
        axes = self.constants[inputs[3]] if len(inputs) > 3 else np.arange(len(starts))
        steps = self.constants[inputs[4]] if len(inputs) > 4 else np.ones(len(starts), np.int64)
        index: list[slice] = [slice(None)] * tensor.dim()
        for start, end, axis, step in zip(starts, ends, axes, steps, strict=True):
            stop = None if int(end) >= 2**62 else int(end)
            index[int(axis)] = slice(int(start), stop, int(step))
        return tensor[tuple(index)]


class PretrainedStages(nn.Module):
    """A pretrained backbone's stages on the density network's own input.

    Parameters
    ----------
    spec : BackboneSpec
        The graph and the tensors taken from it.
    mean, std : tuple of float
        The density network's input normalisation (RGB, after scaling pixels to 0-1), undone here.
    root : Path
        Where the pretrained graphs lie.
    """

    def __init__(
        self,
        spec: BackboneSpec,
        mean: tuple[float, float, float],
        std: tuple[float, float, float],
        root: Path = PRETRAINED_DIR,
    ) -> None:
        super().__init__()
        self.spec = spec
        self.stages = OnnxStages(root / spec.file, spec.outputs)
        self.mean: torch.Tensor
        self.std: torch.Tensor
        self.register_buffer("mean", torch.tensor(mean, dtype=torch.float32).view(1, 3, 1, 1))
        self.register_buffer("std", torch.tensor(std, dtype=torch.float32).view(1, 3, 1, 1))

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        """Normalised RGB (N, 3, H, W), H and W multiples of 8 -> the spec's tensors (N, C_k, H / s_k, W / s_k)."""
        pixels = (x * self.std + self.mean) * (255.0 * self.spec.input_scale)
        if self.spec.input_bgr:
            pixels = pixels.flip(1)
        return list(self.stages(pixels))
