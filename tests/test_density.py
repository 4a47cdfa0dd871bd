"""The onnxruntime density runner on real ONNX graphs built here, and its errors."""

from __future__ import annotations

import json
import logging
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import onnx
import pytest
from onnx import TensorProto, helper, numpy_helper

from companion.perception.density import (
    CONTRACT_METADATA_KEY,
    ChannelOrder,
    DensityModelContract,
    InputEncoder,
    OnnxDensityModel,
    TensorLayout,
    downscaled_size,
    input_scale,
    predict_downscaled,
)
from companion.perception.errors import PerceptionError
from models.blob_detector.graph import build_blob_density_model, save_model
from models.density.onnx_files import stamp_any_size
from models.density.receptive_field import input_extent_px

pytestmark = pytest.mark.integration


def pool_model(
    path: Path,
    input_shape: list[int | str],
    output_shape: list[int | str],
    stride: int,
    contract: Mapping[str, object] | None,
    layout: str = "nchw",
) -> Path:
    """A graph that averages the input's channels and pools at ``stride``: density = mean brightness."""
    nodes = []
    source = "frame"
    if layout == "nhwc":
        nodes.append(helper.make_node("Transpose", ["frame"], ["nchw"], perm=[0, 3, 1, 2]))
        source = "nchw"
    nodes += [
        helper.make_node("ReduceMean", [source], ["gray"], axes=[1], keepdims=1),
        helper.make_node("AveragePool", ["gray"], ["density"], kernel_shape=[stride, stride], strides=[stride, stride]),
    ]
    graph = helper.make_graph(
        nodes,
        "pool",
        [helper.make_tensor_value_info("frame", TensorProto.FLOAT, input_shape)],
        [helper.make_tensor_value_info("density", TensorProto.FLOAT, output_shape)],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    if contract is not None:
        helper.set_model_props(model, {CONTRACT_METADATA_KEY: json.dumps(contract)})
    onnx.save(model, str(path))
    return path


CONTRACT = {"input_width_px": 64, "input_height_px": 48, "output_stride": 8}


def test_blob_model_finds_a_bright_blob_in_the_right_cell(blob_model: OnnxDensityModel) -> None:
    frame = np.full((480, 640, 3), 90, dtype=np.uint8)
    frame[200:208, 400:408] = 250  # an 8 px bright square centred at (u, v) = (403.5, 203.5)
    density = blob_model.predict(frame)
    assert density.values.shape == (120, 160)
    assert density.stride_x == density.stride_y == 4.0
    row, col = np.unravel_index(int(np.argmax(density.values)), density.values.shape)
    assert abs(row - 203.5 / 4) <= 1.5
    assert abs(col - 403.5 / 4) <= 1.5
    assert density.values.max() > 0.1
    quiet = density.values.copy()
    quiet[row - 5 : row + 6, col - 5 : col + 6] = 0
    assert quiet.max() == 0.0  # uniform ground gives nothing, image borders included


def test_frames_of_another_size_are_resized_and_strides_follow(blob_model: OnnxDensityModel) -> None:
    density = blob_model.predict(np.zeros((240, 320, 3), dtype=np.uint8))
    assert density.values.shape == (120, 160)
    assert density.stride_x == pytest.approx(2.0)


def test_contract_from_metadata_and_nhwc_bgr_normalization(tmp_path: Path) -> None:
    contract = {
        **CONTRACT,
        "layout": "nhwc",
        "channel_order": "bgr",
        "scale": 1.0,
        "mean": [10, 20, 30],
        "std": [2, 2, 2],
    }
    path = pool_model(tmp_path / "m.onnx", [1, 48, 64, 3], [1, 1, 6, 8], 8, contract, layout="nhwc")
    model = OnnxDensityModel(path)
    assert model.contract.layout is TensorLayout.NHWC
    frame = np.zeros((48, 64, 3), dtype=np.uint8)
    frame[..., 0], frame[..., 1], frame[..., 2] = 50, 60, 70  # B, G, R
    # ((50-10) + (60-20) + (70-30)) / 2 / 3 = 20 in every cell.
    np.testing.assert_allclose(model.predict(frame).values, 20.0, rtol=1e-6)


def reference_tensor(frame_bgr: np.ndarray, c: DensityModelContract) -> np.ndarray:
    """The contract's input, written out as arithmetic over the whole frame."""
    image = frame_bgr[:, :, ::-1] if c.channel_order is ChannelOrder.RGB else frame_bgr
    x = image.astype(np.float32) * np.float32(c.scale)
    x = (x - np.asarray(c.mean, dtype=np.float32)) / np.asarray(c.std, dtype=np.float32)
    return np.ascontiguousarray(x.transpose(2, 0, 1)[None] if c.layout is TensorLayout.NCHW else x[None])


@pytest.mark.parametrize("layout", ["nchw", "nhwc"])
@pytest.mark.parametrize("order", ["rgb", "bgr"])
@pytest.mark.parametrize(
    ("scale", "mean", "std"), [(1 / 255, (0.45, 0.45, 0.45), (0.25, 0.25, 0.25)), (1.0, (10, 20, 30), (2, 3, 4))]
)
def test_the_input_tensor_is_the_contracts_arithmetic_to_the_bit(
    layout: str, order: str, scale: float, mean: tuple[float, ...], std: tuple[float, ...]
) -> None:
    c = DensityModelContract.model_validate(
        {**CONTRACT, "layout": layout, "channel_order": order, "scale": scale, "mean": mean, "std": std}
    )
    rng = np.random.default_rng(7)
    frame = rng.integers(0, 256, (48, 64, 3), dtype=np.uint8)
    frame[0, :3] = [[0, 0, 0], [255, 255, 255], [0, 128, 255]]  # both ends of the byte range
    encoder = InputEncoder(c)
    encoder.encode(255 - frame)  # the buffer holds another frame's tensor first: every value is written anew
    tensor = encoder.encode(frame)
    expected = reference_tensor(frame, c)
    assert tensor.dtype == np.float32
    assert tensor.flags.c_contiguous
    assert tensor.shape == expected.shape
    assert np.array_equal(tensor.view(np.uint32), expected.view(np.uint32))  # the same bits, not only close


def test_the_shipped_models_input_is_the_contracts_arithmetic_to_the_bit() -> None:
    model = OnnxDensityModel(Path(__file__).resolve().parents[1] / "models" / "density" / "slz_lite.onnx")
    c = model.contract
    frame = np.random.default_rng(3).integers(0, 256, (c.input_height_px, c.input_width_px, 3), dtype=np.uint8)
    expected = reference_tensor(frame, c)
    assert np.array_equal(InputEncoder(c).encode(frame).view(np.uint32), expected.view(np.uint32))


def test_contract_from_a_sidecar_file(tmp_path: Path) -> None:
    path = pool_model(tmp_path / "side.onnx", [1, 3, 48, 64], [1, 1, 6, 8], 8, contract=None)
    (tmp_path / "side.json").write_text(json.dumps(CONTRACT))
    assert OnnxDensityModel(path).contract.output_stride == 8


def test_symbolic_dimensions_are_checked_by_the_dry_run(tmp_path: Path) -> None:
    path = pool_model(tmp_path / "dyn.onnx", [1, 3, "h", "w"], [1, 1, "oh", "ow"], 8, CONTRACT)
    assert OnnxDensityModel(path).predict(np.zeros((48, 64, 3), np.uint8)).values.shape == (6, 8)
    wrong = pool_model(tmp_path / "dyn4.onnx", [1, 3, "h", "w"], [1, 1, "oh", "ow"], 4, CONTRACT)
    with pytest.raises(
        PerceptionError,
        match=r"dry run failed: model output has shape \[1, 1, 12, 16\], expected a \(6, 8\) density map",
    ):
        OnnxDensityModel(wrong)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(PerceptionError, match="model file not found") as info:
        OnnxDensityModel(tmp_path / "nope.onnx")
    assert info.value.where == "density.load"


def test_corrupt_file(tmp_path: Path) -> None:
    path = tmp_path / "corrupt.onnx"
    path.write_bytes(b"\x08\x07 this is not a protobuf")
    with pytest.raises(PerceptionError, match="cannot load ONNX model"):
        OnnxDensityModel(path)


def test_missing_contract(tmp_path: Path) -> None:
    path = pool_model(tmp_path / "m.onnx", [1, 3, 48, 64], [1, 1, 6, 8], 8, contract=None)
    with pytest.raises(PerceptionError, match="no input contract"):
        OnnxDensityModel(path)


def test_invalid_contract_names_the_field(tmp_path: Path) -> None:
    path = pool_model(tmp_path / "m.onnx", [1, 3, 48, 64], [1, 1, 6, 8], 8, {**CONTRACT, "output_stride": 0})
    with pytest.raises(PerceptionError, match=r"contract\.output_stride"):
        OnnxDensityModel(path)


def test_input_shape_that_does_not_fit_the_contract(tmp_path: Path) -> None:
    path = pool_model(tmp_path / "m.onnx", [1, 3, 96, 128], [1, 1, 12, 16], 8, CONTRACT)
    with pytest.raises(
        PerceptionError, match=r"input 'frame' has shape \[1, 3, 96, 128\], contract says \[1, 3, 48, 64\]"
    ):
        OnnxDensityModel(path)


def test_output_shape_that_does_not_fit_the_stride(tmp_path: Path) -> None:
    path = pool_model(tmp_path / "m.onnx", [1, 3, 48, 64], [1, 1, 12, 16], 4, CONTRACT)
    with pytest.raises(PerceptionError, match=r"output 'density' has shape \[1, 1, 12, 16\]"):
        OnnxDensityModel(path)


def test_unavailable_providers_are_skipped_and_none_left_is_an_error(
    blob_model_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level(logging.WARNING):
        model = OnnxDensityModel(blob_model_path, ["NoSuchExecutionProvider", "CPUExecutionProvider"])
    assert model.providers == ["CPUExecutionProvider"]
    assert "NoSuchExecutionProvider" in caplog.text
    with pytest.raises(PerceptionError, match="none of the providers"):
        OnnxDensityModel(blob_model_path, ["NoSuchExecutionProvider"])


@pytest.mark.parametrize(
    "frame",
    [
        np.zeros((480, 640), np.uint8),
        np.zeros((480, 640, 4), np.uint8),
        np.zeros((480, 640, 3), np.float32),
        np.zeros((4, 4, 3), np.uint8),
        "not an image",
    ],
)
def test_bad_frames_are_rejected(blob_model: OnnxDensityModel, frame: object) -> None:
    with pytest.raises(PerceptionError, match=r"density\.predict"):
        blob_model.predict(frame)  # type: ignore[arg-type]


def test_contract_validation() -> None:
    with pytest.raises(ValueError, match="not divisible"):
        DensityModelContract(input_width_px=100, input_height_px=48, output_stride=8)


def test_blob_model_is_deterministic(tmp_path: Path) -> None:
    a = save_model(build_blob_density_model(), tmp_path / "a.onnx").read_bytes()
    b = save_model(build_blob_density_model(), tmp_path / "b.onnx").read_bytes()
    assert a == b


def test_shipped_placeholder_model_is_the_builders_output(tmp_path: Path) -> None:
    shipped = Path(__file__).resolve().parent.parent / "models" / "blob_detector" / "blob_detector.onnx"
    rebuilt = save_model(build_blob_density_model(), tmp_path / "rebuilt.onnx")
    # The same graph and weights, not the same bytes: the kernels are computed with numpy, whose SIMD paths may differ
    # in the last place on another CPU (issue 65).
    a, b = onnx.load(str(shipped)), onnx.load(str(rebuilt))
    assert [(n.op_type, list(n.input), list(n.output)) for n in a.graph.node] == [
        (n.op_type, list(n.input), list(n.output)) for n in b.graph.node
    ], "run models/blob_detector/build.py"
    weights_a = {t.name: numpy_helper.to_array(t) for t in a.graph.initializer}
    weights_b = {t.name: numpy_helper.to_array(t) for t in b.graph.initializer}
    assert weights_a.keys() == weights_b.keys(), "run models/blob_detector/build.py"
    for name, value in weights_a.items():
        np.testing.assert_allclose(value, weights_b[name], rtol=1e-5, atol=1e-7, err_msg=name)


@pytest.mark.parametrize("scale", [0.25, 0.5, 0.73])
def test_a_shrunk_frame_maps_its_blob_to_the_same_place_with_coarser_cells(
    blob_model: OnnxDensityModel, scale: float
) -> None:
    frame = np.full((480, 640, 3), 90, dtype=np.uint8)
    frame[192:224, 384:416] = 250  # a 32 px bright square centred at (u, v) = (399.5, 207.5)
    density = predict_downscaled(blob_model, frame, scale)
    small_w, small_h = downscaled_size(640, 480, scale)
    assert small_w % 16 == 0
    assert small_h % 16 == 0
    assert density.values.shape == (small_h // 4, small_w // 4)
    assert (density.frame_width_px, density.frame_height_px) == (640, 480)
    assert density.stride_x == pytest.approx(640 * 4 / small_w)
    rows, cols = np.mgrid[: density.values.shape[0], : density.values.shape[1]]
    mass = density.values.astype(np.float64)
    assert mass.sum() > 0.0
    u = float(((cols + 0.5) * mass).sum() / mass.sum()) * density.stride_x  # centre of the response, frame px
    v = float(((rows + 0.5) * mass).sum() / mass.sum()) * density.stride_y
    assert abs(u - 399.5) <= density.stride_x
    assert abs(v - 207.5) <= density.stride_y
    np.testing.assert_array_equal(predict_downscaled(blob_model, frame, 1.0).values, blob_model.predict(frame).values)


def test_input_scale_follows_the_ground_sampling_distance() -> None:
    assert input_scale(0.09, 0.045) == 1.0  # coarser than the limit: as it is
    assert input_scale(0.015, 0.045) == pytest.approx(1 / 3)
    assert input_scale(0.001, 0.0) == 1.0  # off
    with pytest.raises(PerceptionError, match="ground sampling distance"):
        input_scale(float("nan"), 0.045)


@pytest.mark.parametrize("scale", [0.0, -0.5, 1.5, float("nan")])
def test_a_scale_outside_0_1_is_refused(blob_model: OnnxDensityModel, scale: float) -> None:
    with pytest.raises(PerceptionError, match="scale must be in"):
        predict_downscaled(blob_model, np.zeros((480, 640, 3), np.uint8), scale)


def save_stride2_graph(
    path: Path, name: str, nodes: list[onnx.NodeProto], inits: list[onnx.TensorProto], stamp: bool = True
) -> Path:
    """Save a graph from a 64x48 ``frame`` to a 32x24 ``density`` (stride 2) with its contract, stamped to run at any
    size as the export stamps it (``stamp``; :func:`stamp_any_size`)."""
    graph = helper.make_graph(
        nodes,
        name,
        [helper.make_tensor_value_info("frame", TensorProto.FLOAT, [1, 3, 48, 64])],
        [helper.make_tensor_value_info("density", TensorProto.FLOAT, [1, 1, 24, 32])],
        initializer=inits,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    contract = {"input_width_px": 64, "input_height_px": 48, "output_stride": 2}
    helper.set_model_props(model, {CONTRACT_METADATA_KEY: json.dumps(contract)})
    onnx.save(model, str(path))
    if stamp:
        stamp_any_size(path)
    return path


def extent_of(path: Path) -> tuple[int, int] | None:
    """:func:`input_extent_px` of the graph saved at ``path``."""
    return input_extent_px(onnx.load(str(path)).graph)


def assert_cropped_as_padded(model: OnnxDensityModel, frame: np.ndarray) -> None:
    """Shrunk frames run cropped (``model``) give the maps of the whole padded frame, to the bit."""
    padded = OnnxDensityModel(model.path, crop_shrunk_frames=False)
    for scale in (0.3, 0.5, 0.75):
        np.testing.assert_array_equal(
            predict_downscaled(model, frame, scale).values, predict_downscaled(padded, frame, scale).values
        )


def conv_model(path: Path, spatial_addend: bool = False, stamp: bool = True) -> Path:
    """A small fully convolutional graph: 3x3 stride 2, ReLU, 3x3 dilated 2, 1x1 (stride 2 overall); with
    ``spatial_addend`` an addend of the contract's spatial size after the first convolution (which only that size
    can take)."""
    rng = np.random.default_rng(5)
    inits = [
        onnx.numpy_helper.from_array(rng.normal(size=(4, 3, 3, 3)).astype(np.float32), "w1"),
        onnx.numpy_helper.from_array(rng.normal(size=(4, 4, 3, 3)).astype(np.float32), "w2"),
        onnx.numpy_helper.from_array(rng.normal(size=(1, 4, 1, 1)).astype(np.float32), "w3"),
    ]
    nodes = [helper.make_node("Conv", ["frame", "w1"], ["c1"], kernel_shape=[3, 3], strides=[2, 2], pads=[1] * 4)]
    if spatial_addend:
        inits.append(onnx.numpy_helper.from_array(np.ones((1, 1, 24, 32), np.float32), "plane"))
        nodes.append(helper.make_node("Add", ["c1", "plane"], ["c1p"]))
    nodes += [
        helper.make_node("Relu", ["c1p" if spatial_addend else "c1"], ["r1"]),
        helper.make_node("Conv", ["r1", "w2"], ["c2"], kernel_shape=[3, 3], dilations=[2, 2], pads=[2] * 4),
        helper.make_node("Conv", ["c2", "w3"], ["c3"]),
        helper.make_node("Abs", ["c3"], ["density"]),
    ]
    return save_stride2_graph(path, "conv", nodes, inits, stamp)


def test_the_context_a_cell_reads_is_followed_through_the_graph(tmp_path: Path) -> None:
    # Output cell i reads inputs 2i - 1 ... 2i + 1 through the first convolution, then its 3x3 dilated-2 window over
    # that (stride 2) adds 2 * 2 on each side: 2i + 5 at the right. 5 - 2 + 1 = 4 px past the last kept cell: 16.
    path = conv_model(tmp_path / "conv.onnx")
    assert extent_of(path) == (2, 5)
    model = OnnxDensityModel(path)
    assert model.context_px == 16
    frame = np.random.default_rng(3).integers(0, 256, (48, 64, 3), dtype=np.uint8)
    assert model.predict_any_size(frame[:32, :48]).shape == (16, 24)  # any multiple of the stride, as it is
    assert_cropped_as_padded(model, frame)


def test_a_model_without_the_stamp_runs_on_its_contract_size_and_says_how_to_stamp_it(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    # The drone does not analyse graphs (no onnx package there): the context comes from the export's stamp only.
    path = conv_model(tmp_path / "conv.onnx", stamp=False)
    with caplog.at_level(logging.INFO, logger="companion.perception.density"):
        model = OnnxDensityModel(path)
    assert model.context_px is None
    assert "python -m models.density.onnx_files" in caplog.text
    small_w, small_h = downscaled_size(64, 48, 0.5)
    shrunk = predict_downscaled(model, np.zeros((48, 64, 3), np.uint8), 0.5)
    assert shrunk.values.shape == (small_h // 2, small_w // 2)
    assert stamp_any_size(path) == 16
    assert OnnxDensityModel(path).context_px == 16


def focus_model(path: Path, upsample: str = "scales", coordinates: str = "asymmetric") -> Path:
    """A graph shaped like YOLOX's early stages under our head: the channels flipped (RGB -> BGR), a space-to-depth
    stem (every other row and column, from rows 0 and 1), a 3x3 at stride 2, a 3x3 stride-2 stage upsampled back
    by 2 (``upsample``: by constant ``scales``, or to fixed ``sizes``) and concatenated, a 1x1 head."""
    rng = np.random.default_rng(7)
    ints = {
        "ch_start": [-1], "ch_end": [-(2**63) + 1], "ch_axis": [1], "ch_step": [-1],
        "even": [0], "odd": [1], "end": [2**63 - 1], "rows": [2], "cols": [3], "two": [2],
    }  # fmt: skip
    inits = [onnx.numpy_helper.from_array(np.array(v, np.int64), k) for k, v in ints.items()]
    inits += [
        onnx.numpy_helper.from_array(rng.normal(size=(4, 6, 3, 3)).astype(np.float32), "w1"),
        onnx.numpy_helper.from_array(rng.normal(size=(4, 4, 3, 3)).astype(np.float32), "w2"),
        onnx.numpy_helper.from_array(rng.normal(size=(1, 8, 1, 1)).astype(np.float32), "w3"),
        onnx.numpy_helper.from_array(np.array([1, 1, 2, 2], np.float32), "scales"),
        onnx.numpy_helper.from_array(np.array([1, 4, 24, 32], np.int64), "sizes"),
    ]
    resize_inputs = ["s4", "", "scales"] if upsample == "scales" else ["s4", "", "", "sizes"]
    nodes = [
        helper.make_node("Slice", ["frame", "ch_start", "ch_end", "ch_axis", "ch_step"], ["bgr"]),
        helper.make_node("Slice", ["bgr", "even", "end", "rows", "two"], ["r0"]),
        helper.make_node("Slice", ["r0", "even", "end", "cols", "two"], ["r0c0"]),
        helper.make_node("Slice", ["bgr", "odd", "end", "rows", "two"], ["r1"]),
        helper.make_node("Slice", ["r1", "even", "end", "cols", "two"], ["r1c0"]),
        helper.make_node("Concat", ["r0c0", "r1c0"], ["focus"], axis=1),
        helper.make_node("Conv", ["focus", "w1"], ["s2"], kernel_shape=[3, 3], pads=[1] * 4),
        helper.make_node("Conv", ["s2", "w2"], ["s4"], kernel_shape=[3, 3], strides=[2, 2], pads=[1] * 4),
        helper.make_node(
            "Resize", resize_inputs, ["up"], mode="nearest", coordinate_transformation_mode=coordinates,
            nearest_mode="floor",
        ),
        helper.make_node("Concat", ["s2", "up"], ["both"], axis=1),
        helper.make_node("Conv", ["both", "w3"], ["c3"]),
        helper.make_node("Abs", ["c3"], ["density"]),
    ]  # fmt: skip
    return save_stride2_graph(path, "focus", nodes, inits)


def test_a_space_to_depth_stem_and_an_upsampled_stage_are_followed(tmp_path: Path) -> None:
    # Rows: the stem's odd rows start one pixel down (stride 2, extent 1); the 3x3 adds 1 cell of 2 px (3); the
    # stride-2 3x3 over that another 2 px (5, stride 4); nearest upsampling by 2 (floor, asymmetric) reads the same
    # pixels at stride 2. Columns reach 4. So (2, 5): 4 px past the last kept cell, a context of 16.
    path = focus_model(tmp_path / "focus.onnx")
    assert extent_of(path) == (2, 5)
    model = OnnxDensityModel(path)
    assert model.context_px == 16
    assert_cropped_as_padded(model, np.random.default_rng(4).integers(0, 256, (48, 64, 3), dtype=np.uint8))
    # Another rounding of the upsampling may read one coarse cell further: a cell of 4 px more.
    rounded = focus_model(tmp_path / "half_pixel.onnx", coordinates="half_pixel")
    assert extent_of(rounded) == (2, 9)
    # Upsampled to fixed sizes, the graph runs at the contract's size only.
    fixed = focus_model(tmp_path / "sizes.onnx", upsample="sizes")
    assert extent_of(fixed) is None
    assert OnnxDensityModel(fixed).context_px is None


def test_graphs_whose_context_is_unbounded_here_run_on_the_contract_size(
    tmp_path: Path, blob_model: OnnxDensityModel
) -> None:
    assert blob_model.context_px is None  # edge padding and a resize on the image's path
    pool_path = pool_model(tmp_path / "pool.onnx", [1, 3, 48, 64], [1, 1, 6, 8], 8, CONTRACT)
    assert stamp_any_size(pool_path) is None  # a mean over the channels (ReduceMean) is not followed
    pooled = OnnxDensityModel(pool_path)
    assert pooled.context_px is None
    with pytest.raises(PerceptionError, match=r"density.predict_any_size: .* runs on 64x48 only"):
        pooled.predict_any_size(np.zeros((16, 16, 3), np.uint8))
    # An addend of the contract's size: the graph reads as convolutional, but only that size runs; the check at
    # load finds it and the model pads shrunk frames as before.
    addend = OnnxDensityModel(conv_model(tmp_path / "addend.onnx", spatial_addend=True))
    assert addend.context_px is None
    small_w, small_h = downscaled_size(64, 48, 0.5)
    assert predict_downscaled(addend, np.zeros((48, 64, 3), np.uint8), 0.5).values.shape == (small_h // 2, small_w // 2)


def test_a_frame_run_as_it_is_must_be_whole_cells(tmp_path: Path) -> None:
    model = OnnxDensityModel(conv_model(tmp_path / "conv.onnx"))
    with pytest.raises(PerceptionError, match="not a multiple of the output stride 2"):
        model.predict_any_size(np.zeros((17, 32, 3), np.uint8))
