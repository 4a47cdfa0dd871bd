"""Density model runner: camera frame -> crowd density map, through onnxruntime.

The model's input contract (size, channel order, layout, normalization, output stride) travels with the model:
in the ONNX metadata under the key ``slz.contract`` (a JSON object), or in a sidecar file next to it
(``model.onnx`` -> ``model.json``). It is checked against the graph's declared shapes and with one dry run at
load time, so a mismatched model fails on the ground with a clear message, not in flight.
"""

from __future__ import annotations

import enum
import json
import logging
import math
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import cv2
import numpy as np
import numpy.typing as npt
from pydantic import Field, ValidationError, model_validator

from companion.config import StrictModel, format_validation_error
from companion.perception.config import ModelConfig
from companion.perception.errors import PerceptionError

logger = logging.getLogger(__name__)

CONTRACT_METADATA_KEY = "slz.contract"

U8Image = npt.NDArray[np.uint8]
F32Array = npt.NDArray[np.float32]


class ChannelOrder(str, enum.Enum):
    """Channel order the network expects (frames arrive as OpenCV BGR)."""

    RGB = "rgb"
    BGR = "bgr"


class TensorLayout(str, enum.Enum):
    """Memory layout of the input tensor."""

    NCHW = "nchw"
    NHWC = "nhwc"


class DensityModelContract(StrictModel):
    """What a density model expects and produces.

    The input is ``((pixel * scale) - mean) / std`` per channel, in ``channel_order``, as a float32 tensor of
    shape (1, 3, H, W) or (1, H, W, 3). The output is a density map of shape (1, 1, H/s, W/s) or (1, H/s, W/s)
    whose cells hold people per cell (its sum is the people count), with ``s = output_stride``.
    """

    name: str = "unnamed"
    version: str = "0"
    input_width_px: int = Field(ge=8, le=8192)
    input_height_px: int = Field(ge=8, le=8192)
    channel_order: ChannelOrder = ChannelOrder.RGB
    layout: TensorLayout = TensorLayout.NCHW
    scale: float = Field(default=1.0 / 255.0, gt=0.0)
    mean: tuple[float, float, float] = (0.0, 0.0, 0.0)
    std: tuple[float, float, float] = (1.0, 1.0, 1.0)
    output_stride: int = Field(ge=1, le=64)
    context_px: int | None = Field(default=None, ge=0, le=4096)
    """Input pixels past a density cell's own (right and bottom) that the graph reads, measured from the graph at
    export (``models.density.receptive_field.make_any_size``), whose image sides the export left free: then a
    shrunk frame runs as itself plus this much context. None: not stamped; the model runs on its contract's size."""

    @model_validator(mode="after")
    def _divisible(self) -> DensityModelContract:
        if self.input_width_px % self.output_stride or self.input_height_px % self.output_stride:
            raise ValueError(
                f"input size {self.input_width_px}x{self.input_height_px} is not divisible by "
                f"output_stride {self.output_stride}"
            )
        if any(s <= 0 for s in self.std):
            raise ValueError(f"std must be positive (got {self.std})")
        return self

    @property
    def output_shape_hw(self) -> tuple[int, int]:
        """(rows, cols) of the density map."""
        return self.input_height_px // self.output_stride, self.input_width_px // self.output_stride


@dataclass(frozen=True)
class DensityMap:
    """A density map and how its cells relate to the frame it came from.

    Attributes
    ----------
    values : ndarray, shape (h, w), float32
        People per cell. Non-finite values are kept: downstream stages treat them as occupied.
    frame_width_px, frame_height_px : int
        Size of the camera frame the map was computed from.
    """

    values: F32Array
    frame_width_px: int
    frame_height_px: int

    @property
    def stride_x(self) -> float:
        """Frame pixels per density cell, horizontally."""
        return float(self.frame_width_px / self.values.shape[1])

    @property
    def stride_y(self) -> float:
        """Frame pixels per density cell, vertically."""
        return float(self.frame_height_px / self.values.shape[0])


class DensityModel(Protocol):
    """Anything that turns a BGR frame into a :class:`DensityMap` (ONNX runner, test fakes)."""

    def predict(self, frame_bgr: U8Image) -> DensityMap:
        """Density map for one frame of shape (H, W, 3), uint8, BGR."""
        ...


def check_frame(frame_bgr: Any, where: str) -> U8Image:
    """Validate a camera frame: ndarray (H, W, 3) uint8. Raise :class:`PerceptionError` otherwise."""
    if not isinstance(frame_bgr, np.ndarray):
        raise PerceptionError(where, f"frame must be a numpy array, got {type(frame_bgr).__name__}")
    if frame_bgr.ndim != 3 or frame_bgr.shape[2] != 3 or frame_bgr.dtype != np.uint8:
        raise PerceptionError(
            where, f"frame must have shape (H, W, 3) and dtype uint8, got {frame_bgr.shape} {frame_bgr.dtype}"
        )
    if frame_bgr.shape[0] < 8 or frame_bgr.shape[1] < 8:
        raise PerceptionError(where, f"frame too small: {frame_bgr.shape}")
    return frame_bgr


def _read_contract(path: Path, metadata: dict[str, str]) -> DensityModelContract:
    sidecar = path.with_suffix(".json")
    if CONTRACT_METADATA_KEY in metadata:
        raw_text, source = metadata[CONTRACT_METADATA_KEY], f"{path} metadata '{CONTRACT_METADATA_KEY}'"
    elif sidecar.is_file():
        raw_text, source = sidecar.read_text(encoding="utf-8"), str(sidecar)
    else:
        raise PerceptionError(
            "density.load",
            f"{path} has no input contract: expected ONNX metadata '{CONTRACT_METADATA_KEY}' or a sidecar {sidecar}",
        )
    try:
        raw = json.loads(raw_text)
    except json.JSONDecodeError as exc:
        raise PerceptionError("density.load", f"contract in {source} is not valid JSON: {exc}") from None
    try:
        return DensityModelContract.model_validate(raw)
    except ValidationError as exc:
        problems = "; ".join(format_validation_error(exc, "contract"))
        raise PerceptionError("density.load", f"invalid contract in {source}: {problems}") from None


def _dims_match(declared: list[Any], expected: tuple[int, ...]) -> bool:
    """Declared ONNX dims (ints, or str/None when symbolic) against the expected ones."""
    if len(declared) != len(expected):
        return False
    return all(not isinstance(d, int) or d in (e, -1) for d, e in zip(declared, expected, strict=True))


def execution_provider_options(provider: str, engine_cache_dir: Path | None, fp16: bool) -> dict[str, str]:
    """onnxruntime options for one execution provider.

    TensorRT gets FP16 when allowed and, with ``engine_cache_dir``, a persistent engine and timing cache (the key is
    the model and the board, so a changed model builds a new engine). Other providers get none.
    """
    if provider != "TensorrtExecutionProvider":
        return {}
    options = {"trt_fp16_enable": "True" if fp16 else "False"}
    if engine_cache_dir is not None:
        options |= {
            "trt_engine_cache_enable": "True",
            "trt_engine_cache_path": str(engine_cache_dir),
            "trt_timing_cache_enable": "True",
            "trt_timing_cache_path": str(engine_cache_dir),
        }
    return options


class InputEncoder:
    """A frame as the network's input tensor, as its contract says: channel order, ``pixel * scale``, then
    ``(x - mean) / std`` per channel, in the contract's layout, float32.

    A pixel is a byte, so each channel's 256 possible values are computed once (with the same float32 operations,
    so the tensor is the same to the bit) and every frame is a table lookup written straight into the tensor's
    layout: about a fifth of the arithmetic's time at 640 x 480, with no float temporaries of the frame's size.

    Parameters
    ----------
    contract : DensityModelContract
        The model's input contract.
    """

    def __init__(self, contract: DensityModelContract) -> None:
        self.contract = contract
        values = np.arange(256, dtype=np.uint8).astype(np.float32) * np.float32(contract.scale)
        normalize = contract.mean != (0.0, 0.0, 0.0) or contract.std != (1.0, 1.0, 1.0)
        self._tables = [  # shape (1, 256): cv2.LUT's; np.take reads it flattened
            ((values - np.float32(m)) / np.float32(s) if normalize else values).reshape(1, 256)
            for m, s in zip(contract.mean, contract.std, strict=True)
        ]
        # Input channel k of the tensor reads this channel of the BGR frame.
        self._source_channel = (2, 1, 0) if contract.channel_order is ChannelOrder.RGB else (0, 1, 2)
        # One tensor per thread, written anew by each call: a fresh 3.7 MB array per frame costs more in page faults
        # than the lookup itself.
        self._buffer = threading.local()

    def encode(self, frame_bgr: U8Image) -> F32Array:
        """The tensor of one frame, shape (1, 3, H, W) (NCHW) or (1, H, W, 3) (NHWC), C-contiguous float32.

        The array is this thread's buffer: valid until the thread's next call (the model runs on it at once).

        Parameters
        ----------
        frame_bgr : ndarray, shape (H, W, 3), uint8
            The frame at the model's input size, BGR.
        """
        h, w = frame_bgr.shape[:2]
        nchw = self.contract.layout is TensorLayout.NCHW
        shape = (1, 3, h, w) if nchw else (1, h, w, 3)
        tensor: F32Array | None = getattr(self._buffer, "tensor", None)
        if tensor is None or tensor.shape != shape:
            tensor = np.empty(shape, np.float32)
            self._buffer.tensor = tensor
        for k, table in enumerate(self._tables):
            if nchw:  # a contiguous plane: OpenCV's lookup writes it (the same values, a third of np.take's time)
                cv2.LUT(cv2.extractChannel(frame_bgr, self._source_channel[k]), table, dst=tensor[0, k])
            else:
                np.take(table, frame_bgr[:, :, self._source_channel[k]], out=tensor[0, :, :, k])
        return tensor


class OnnxDensityModel:
    """Runs an ONNX density model with onnxruntime.

    Parameters
    ----------
    path : str or Path
        The ``.onnx`` file.
    providers : list of str
        Execution providers in order of preference. Those not available in this onnxruntime build are skipped
        (and logged); if none is left, loading fails.
    intra_op_threads : int
        Threads for one inference (0: onnxruntime's default).
    engine_cache_dir : Path, optional
        TensorRT engine and timing cache (see :func:`execution_provider_options`).
    fp16 : bool
        TensorRT: allow FP16.
    crop_shrunk_frames : bool
        On the CPU provider alone, run a fully convolutional graph on any input size, so that a shrunk frame costs
        its own pixels (:func:`predict_downscaled`): read from the contract's ``context_px``, which the export
        measured from the graph and stamped (every shipped model; ``models.density.onnx_files`` stamps another).
        A model without the stamp runs on its contract's size.

    Raises
    ------
    PerceptionError
        Missing or corrupt file, no usable provider, missing or invalid contract, or graph shapes that do not
        fit the contract.
    """

    def __init__(
        self,
        path: str | Path,
        providers: list[str] | None = None,
        intra_op_threads: int = 1,
        engine_cache_dir: Path | None = None,
        fp16: bool = True,
        crop_shrunk_frames: bool = True,
    ) -> None:
        import onnxruntime as ort

        self.path = Path(path)
        if not self.path.is_file():
            raise PerceptionError("density.load", f"model file not found: {self.path}")
        wanted = providers or ["CPUExecutionProvider"]
        available = ort.get_available_providers()
        chosen = [p for p in wanted if p in available]
        skipped = [p for p in wanted if p not in available]
        if skipped:
            logger.warning("execution providers not available here, skipped: %s", ", ".join(skipped))
        if not chosen:
            raise PerceptionError(
                "density.load", f"none of the providers {wanted} is available (available: {available})"
            )
        if engine_cache_dir is not None and "TensorrtExecutionProvider" in chosen:
            try:
                engine_cache_dir.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise PerceptionError(
                    "density.load", f"cannot create the TensorRT engine cache {engine_cache_dir}: {exc}"
                ) from None
        provider_options = [execution_provider_options(p, engine_cache_dir, fp16) for p in chosen]
        options = ort.SessionOptions()
        options.intra_op_num_threads = intra_op_threads
        options.inter_op_num_threads = 1
        options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        options.log_severity_level = 3
        self._session_args = (options, chosen, provider_options)
        self._session = self._open(str(self.path))
        metadata = dict(self._session.get_modelmeta().custom_metadata_map)
        self.contract = _read_contract(self.path, metadata)
        # Any input size (see predict_downscaled): on the CPU only, where a shape costs nothing to change; a TensorRT
        # engine, or CUDA's tuned kernels, would be built again for every new shape.
        self.context_px: int | None = None
        """Input pixels past a density cell's own (right and bottom) that the network reads: a shrunk frame runs as
        itself plus this much context (:func:`predict_downscaled`). None: the model runs on its contract's size."""
        if crop_shrunk_frames and chosen == ["CPUExecutionProvider"]:
            if self.contract.context_px is not None and self._sides_free():
                self.context_px = self.contract.context_px  # measured and stamped at export
            else:
                logger.info(
                    "%s carries no any-size stamp: shrunk frames are padded to the model's size "
                    "(python -m models.density.onnx_files stamps it)",
                    self.path,
                )
        self.providers: list[str] = list(self._session.get_providers())
        logger.info("density model %s on %s", self.path, ", ".join(self.providers))
        if self.providers[0] != wanted[0]:
            logger.warning(
                "density model falls back to %s: %s is the first choice (see deploy/README.md)",
                self.providers[0],
                wanted[0],
            )
        self._encoder = InputEncoder(self.contract)
        self._check_graph()
        if self.context_px is not None and not self._any_size_agrees():
            logger.warning("%s: a shrunk frame run as itself differs from the padded one; padding as before", path)
            self.context_px = None

    @classmethod
    def from_config(cls, config: ModelConfig) -> OnnxDensityModel:
        """The model as ``perception.model`` configures it (``slz fly``, ``slz doctor``)."""
        return cls(
            config.path,
            config.providers,
            config.intra_op_threads,
            config.engine_cache_dir,
            config.fp16,
            config.crop_shrunk_frames,
        )

    def _open(self, model: str | bytes) -> Any:
        """An onnxruntime session of the model (a path or the bytes of a graph), with this runner's options."""
        import onnxruntime as ort

        options, providers, provider_options = self._session_args
        try:
            return ort.InferenceSession(
                model, sess_options=options, providers=providers, provider_options=provider_options
            )
        except Exception as exc:  # onnxruntime raises several unrelated types for a bad file
            raise PerceptionError("density.load", f"cannot load ONNX model {self.path}: {exc}") from None

    def _sides_free(self) -> bool:
        """Whether the graph's image sides are symbolic (the input's last two dims, as stamped at export)."""
        return all(not isinstance(d, int) for d in self._session.get_inputs()[0].shape[-2:])

    def _any_size_agrees(self) -> bool:
        """Whether this model, on this machine, maps a shrunk frame run with its context exactly as the whole padded
        frame (:func:`predict_downscaled`'s two paths, on a fixed pattern at two scales). Checked once at load."""
        c = self.contract
        rows, cols = np.mgrid[0 : c.input_height_px, 0 : c.input_width_px]
        pattern = np.stack([(rows * 7 + cols * 3) % 256, (rows * cols) % 251, (rows * 5 + cols * 11) % 241], axis=2)
        frame = np.ascontiguousarray(pattern, dtype=np.uint8)
        try:
            for scale in (0.3, 0.7):
                cropped = predict_downscaled(self, frame, scale)
                context, self.context_px = self.context_px, None
                try:
                    padded = predict_downscaled(self, frame, scale)
                finally:
                    self.context_px = context
                if not np.array_equal(cropped.values, padded.values, equal_nan=True):
                    return False
        except PerceptionError:
            return False
        return True

    def _check_graph(self) -> None:
        c = self.contract
        inputs = self._session.get_inputs()
        outputs = self._session.get_outputs()
        if len(inputs) != 1 or len(outputs) < 1:
            raise PerceptionError(
                "density.load", f"expected 1 input and >= 1 output, got {len(inputs)} and {len(outputs)}"
            )
        self._input_name: str = inputs[0].name
        if c.layout is TensorLayout.NCHW:
            expected_in: tuple[int, ...] = (1, 3, c.input_height_px, c.input_width_px)
        else:
            expected_in = (1, c.input_height_px, c.input_width_px, 3)
        if not _dims_match(list(inputs[0].shape), expected_in):
            raise PerceptionError(
                "density.load",
                f"input '{self._input_name}' has shape {inputs[0].shape}, contract says {list(expected_in)}",
            )
        h, w = c.output_shape_hw
        declared_out = list(outputs[0].shape)
        if not (_dims_match(declared_out, (1, 1, h, w)) or _dims_match(declared_out, (1, h, w))):
            raise PerceptionError(
                "density.load",
                f"output '{outputs[0].name}' has shape {declared_out}, contract says [1, 1, {h}, {w}] "
                f"(input {c.input_width_px}x{c.input_height_px} / stride {c.output_stride})",
            )
        try:
            self._run(np.zeros((c.input_height_px, c.input_width_px, 3), dtype=np.uint8))
        except PerceptionError as exc:
            raise PerceptionError("density.load", f"dry run failed: {exc.what}") from None

    def _run(self, frame_bgr: U8Image, any_size: bool = False) -> F32Array:
        """The map of a frame at the contract's size (resized to it), or, with ``any_size``, of a frame whose sides
        are multiples of the output stride, as it is (only where :attr:`context_px` is set)."""
        c = self.contract
        if any_size:
            h, w = frame_bgr.shape[0] // c.output_stride, frame_bgr.shape[1] // c.output_stride
            expected = (h, w)
        else:
            expected = c.output_shape_hw
            if frame_bgr.shape[1] != c.input_width_px or frame_bgr.shape[0] != c.input_height_px:
                frame_bgr = np.asarray(
                    cv2.resize(frame_bgr, (c.input_width_px, c.input_height_px), interpolation=cv2.INTER_AREA),
                    np.uint8,
                )
        tensor = self._encoder.encode(frame_bgr)
        try:
            out = np.asarray(self._session.run(None, {self._input_name: tensor})[0], np.float32)
        except Exception as exc:  # onnxruntime's own error types
            raise PerceptionError("density.predict", f"onnxruntime failed on a {tensor.shape} input: {exc}") from None
        if out.ndim < 2 or out.shape[-2:] != expected or out.size != out.shape[-2] * out.shape[-1]:
            raise PerceptionError(
                "density.predict",
                f"model output has shape {list(out.shape)}, expected a {expected} density map",
            )
        return out.reshape(expected)

    def predict_any_size(self, frame_bgr: U8Image) -> F32Array:
        """People per cell of a frame of any size whose sides are multiples of the output stride, run as it is (no
        resize to the contract's size): shape (H / stride, W / stride). Only where :attr:`context_px` is set.

        Raises
        ------
        PerceptionError
            The model runs on its contract's size only, or a side is not a multiple of the stride.
        """
        c = self.contract
        if self.context_px is None:
            raise PerceptionError(
                "density.predict_any_size", f"{self.path} runs on {c.input_width_px}x{c.input_height_px} only"
            )
        h, w = frame_bgr.shape[:2]
        if h % c.output_stride or w % c.output_stride:
            raise PerceptionError(
                "density.predict_any_size", f"frame {w}x{h} is not a multiple of the output stride {c.output_stride}"
            )
        return self._run(frame_bgr, any_size=True)

    def predict(self, frame_bgr: U8Image) -> DensityMap:
        """Density map of one frame.

        Parameters
        ----------
        frame_bgr : ndarray, shape (H, W, 3), uint8
            The camera frame, BGR. Resized to the contract's input size if it differs.

        Returns
        -------
        DensityMap
            People per cell, shape (input_height / stride, input_width / stride), with its relation to the frame.
        """
        frame_bgr = check_frame(frame_bgr, "density.predict")
        values = self._run(frame_bgr)
        return DensityMap(values, frame_width_px=frame_bgr.shape[1], frame_height_px=frame_bgr.shape[0])


def downscaled_size(width_px: int, height_px: int, scale: float) -> tuple[int, int]:
    """(width, height) of a frame shrunk by ``scale`` in :func:`predict_downscaled`: rounded to multiples of 16 px
    (whole cells of any stride dividing 16, so the map's stride is exact), at least 16, at most the frame."""
    return (
        min(width_px, max(16, 16 * round(width_px * scale / 16))),
        min(height_px, max(16, 16 * round(height_px * scale / 16))),
    )


def predict_downscaled(model: DensityModel, frame_bgr: U8Image, scale: float) -> DensityMap:
    """Density of a frame shrunk by ``scale`` (0 < scale <= 1), as the model would see it from farther away.

    A network trained on people a few pixels wide reads texture magnified by a low altitude (grass, gravel,
    snowflakes) as heads. Shrinking the frame shows it the ground at the scale it was trained on. The shrunk frame is
    padded back to the frame's size with its edge pixels, the model runs once, and the cells over the padding are cut
    off: the map keeps the frame's size with coarser cells (``stride`` divided by ``scale``), each still holding
    people per cell, so the occupancy threshold means what it meant at the trained scale.

    A model that runs on any size (:attr:`OnnxDensityModel.context_px`, a fully convolutional graph on the CPU) gets
    the shrunk frame padded only by the edge pixels its kept cells read: the same values as with the whole padded
    frame (every kept cell reads the same pixels; ``tests/test_density.py`` and ``tests/test_density_model.py``
    compare them to the bit) for the shrunk frame's share of the work (at 8 m, about a third of the time).

    Parameters
    ----------
    model : DensityModel
        Any density model (its input size is the frame's).
    frame_bgr : ndarray, shape (H, W, 3), uint8
        The camera frame.
    scale : float
        Shrink factor, (0, 1]; 1 runs the model on the frame as it is.

    Returns
    -------
    DensityMap
        Shape (h' / s, w' / s) for the shrunk size (h', w'), rounded to multiples of 16 px, and the model's stride
        s (a divisor of 16), over the whole frame (``frame_width_px`` W, ``frame_height_px`` H).
    """
    frame_bgr = check_frame(frame_bgr, "density.predict_downscaled")
    if not (math.isfinite(scale) and 0.0 < scale <= 1.0):
        raise PerceptionError("density.predict_downscaled", f"scale must be in (0, 1], got {scale}")
    if scale == 1.0:
        return model.predict(frame_bgr)
    h, w = frame_bgr.shape[:2]
    small_w, small_h = downscaled_size(w, h, scale)
    small = cv2.resize(frame_bgr, (small_w, small_h), interpolation=cv2.INTER_AREA)
    context = _context_px(model, w, h)
    if context is not None:
        # Only the shrunk frame and the edge pixels its cells read: the same map, a fraction of the work.
        pad_w, pad_h = min(w, small_w + context), min(h, small_h + context)
        padded = np.asarray(
            cv2.copyMakeBorder(small, 0, pad_h - small_h, 0, pad_w - small_w, cv2.BORDER_REPLICATE), np.uint8
        )
        assert isinstance(model, OnnxDensityModel)
        full = DensityMap(model.predict_any_size(padded), frame_width_px=pad_w, frame_height_px=pad_h)
    else:
        padded = np.asarray(cv2.copyMakeBorder(small, 0, h - small_h, 0, w - small_w, cv2.BORDER_REPLICATE), np.uint8)
        full = model.predict(padded)
    rows = min(full.values.shape[0], math.ceil(small_h / full.stride_y))
    cols = min(full.values.shape[1], math.ceil(small_w / full.stride_x))
    values = np.ascontiguousarray(full.values[:rows, :cols])
    return DensityMap(values, frame_width_px=w, frame_height_px=h)


def _context_px(model: DensityModel, width_px: int, height_px: int) -> int | None:
    """The context a shrunk frame of this size runs with (:attr:`OnnxDensityModel.context_px`), or None where the
    model runs on the whole padded frame: any other model, or a frame of another size than its contract's (its
    ``predict`` resizes the frame, which the shrinking then includes)."""
    if not isinstance(model, OnnxDensityModel) or model.context_px is None:
        return None
    c = model.contract
    if (width_px, height_px) != (c.input_width_px, c.input_height_px):
        return None
    return model.context_px


def input_scale(gsd_m_per_px: float, min_gsd_m_per_px: float) -> float:
    """How much to shrink a frame whose finest ground sampling distance is ``gsd_m_per_px`` (metres per pixel on
    the head plane) so that it is no finer than ``min_gsd_m_per_px``: ``min(1, gsd / min_gsd)``; 1 when
    ``min_gsd_m_per_px`` is 0 (off)."""
    if min_gsd_m_per_px <= 0.0:
        return 1.0
    if not (math.isfinite(gsd_m_per_px) and gsd_m_per_px > 0.0):
        raise PerceptionError("density.input_scale", f"ground sampling distance must be > 0, got {gsd_m_per_px}")
    return min(1.0, gsd_m_per_px / min_gsd_m_per_px)
