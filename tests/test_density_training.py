"""Training path of the density models (needs the `training` extra: PyTorch). Skipped where torch is absent.

A few steps on a tiny generated set, export to ONNX, onnxruntime parity within 1e-4, the companion loads it; the
Bayesian Loss behaves as its definition says; augmentation keeps labels on the heads.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

torch = pytest.importorskip("torch")

from companion.perception.density import OnnxDensityModel, predict_downscaled  # noqa: E402
from models.data.generate import Split, generate  # noqa: E402
from models.data.real_ground import composite  # noqa: E402
from models.density import dataset as dataset_module  # noqa: E402
from models.density.architectures import Architecture, build, parameter_count  # noqa: E402
from models.density.dataset import CrowdCrops, load_frames, turn_and_flip  # noqa: E402
from models.density.export import Calibrated, calibrate, export, load_checkpoint, parity  # noqa: E402
from models.density.losses import LossKind, bayesian_loss, mse_loss, point_density_target  # noqa: E402
from models.density.onnx_files import CONTRACT_KEY, read_metadata  # noqa: E402
from models.density.quantize import calibration_frames, quantize, to_float16  # noqa: E402
from models.density.train import train  # noqa: E402
from sitl.world.ground import RealGround  # noqa: E402

pytestmark = pytest.mark.integration


@pytest.mark.unit
def test_paper_network_has_the_papers_size_and_ours_is_smaller() -> None:
    ccnn, lite = build(Architecture.CCNN), build(Architecture.LITE)
    n_conv = sum(isinstance(m, torch.nn.Conv2d) for m in ccnn.modules())
    assert n_conv == 9
    assert 65_000 <= parameter_count(ccnn) <= 75_000
    assert parameter_count(lite) < parameter_count(ccnn)
    x = torch.zeros(1, 3, 64, 96)
    for net in (ccnn, lite):
        out = net.eval()(x)
        assert out.shape == (1, 1, 16, 24)
        assert bool((out >= 0).all())


@pytest.mark.unit
def test_bayesian_loss_is_zero_for_one_person_per_head_and_counts_misses() -> None:
    stride, h, w = 4, 16, 16
    heads = torch.tensor([[10.0, 10.0], [42.0, 30.0]])
    perfect = torch.zeros(1, 1, h, w)
    perfect[0, 0, 2, 2] = 1.0  # cell centre (10, 10)
    perfect[0, 0, 7, 10] = 1.0  # cell centre (42, 30)
    empty = torch.zeros(1, 1, h, w, requires_grad=True)
    assert float(bayesian_loss(perfect, [heads], stride, sigma_px=2.0)) < 0.02
    missed = bayesian_loss(empty, [heads], stride, sigma_px=2.0)
    assert float(missed.detach()) == pytest.approx(2.0, abs=1e-6)  # two heads, expected count zero each
    missed.backward()  # type: ignore[no-untyped-call]
    assert empty.grad is not None
    assert float(empty.grad.abs().sum()) > 0.0
    # Density far from any head is background: the loss sees it (no people in the image: |sum|).
    stray = torch.zeros(1, 1, h, w)
    stray[0, 0, 15, 0] = 0.7
    assert float(bayesian_loss(stray, [torch.zeros(0, 2)], stride)) == pytest.approx(0.7, abs=1e-6)
    with_bg = bayesian_loss(perfect + stray, [heads], stride, sigma_px=2.0, background_px=16.0)
    assert float(with_bg) > 0.6


@pytest.mark.unit
def test_mse_target_sums_to_the_count() -> None:
    heads = torch.tensor([[20.0, 20.0], [40.0, 44.0], [8.0, 50.0]])
    target = point_density_target([heads], 16, 16, 4, sigma_px=4.0)
    assert float(target.sum()) == pytest.approx(3.0, abs=1e-4)
    assert float(mse_loss(target, [heads], 4)) == pytest.approx(0.0, abs=1e-9)


@pytest.mark.unit
@pytest.mark.parametrize("quarter_turns", [0, 1, 2, 3])
@pytest.mark.parametrize("mirror", [False, True])
def test_turns_and_flips_keep_the_label_on_the_head(quarter_turns: int, mirror: bool) -> None:
    image = np.zeros((24, 24, 3), np.uint8)
    image[5, 17] = 255  # pixel centre (17.5, 5.5)
    out, heads = turn_and_flip(image, np.array([[17.5, 5.5]], np.float32), quarter_turns, mirror)
    row, col = np.argwhere(out[:, :, 0] == 255)[0]
    assert (heads[0, 0], heads[0, 1]) == pytest.approx((col + 0.5, row + 0.5), abs=1e-6)


@pytest.fixture(scope="module")
def tiny_set(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("synth")
    generate(root, Split.TRAIN, frames=6)
    return root


def heads_of_twin_crops(a: CrowdCrops, b: CrowdCrops, count: int) -> int:
    """Check that two datasets built alike give the same 128 px samples, every head inside its crop; the heads seen."""
    total = 0
    for i in range(count):
        (xa, pa), (xb, pb) = a[i], b[i]
        assert xa.shape == (3, 128, 128)
        assert torch.equal(xa, xb)
        assert torch.equal(pa, pb)
        assert bool(((pa >= 0) & (pa <= 128)).all())
        total += len(pa)
    return total


def test_crops_are_deterministic_and_keep_heads_inside(tiny_set: Path) -> None:
    frames = load_frames(tiny_set / "train")
    assert heads_of_twin_crops(CrowdCrops(frames, 128, 8, seed=3), CrowdCrops(frames, 128, 8, seed=3), 8) > 0


def test_composites_finer_than_the_real_ground_are_made_at_its_gsd_and_enlarged_whole(
    tiny_set: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    frames = load_frames(tiny_set / "train")
    rng = np.random.default_rng(0)
    ground = [RealGround("flat", rng.integers(90, 110, size=(400, 400, 3), dtype=np.uint8), 0.045)]
    made_px: list[int] = []
    real_composite = composite

    def spy(
        people: np.ndarray, mask: np.ndarray, background: np.ndarray, g: np.random.Generator, gsd: float, **kw: Any
    ) -> Any:
        made_px.append(people.shape[0])
        assert gsd >= 0.045 - 1e-9  # never finer than the stored ground: no softer ground than people
        return real_composite(people, mask, background, g, gsd, **kw)

    monkeypatch.setattr(dataset_module, "composite", spy)

    def crops() -> CrowdCrops:
        return CrowdCrops(
            frames,
            128,
            12,
            seed=5,
            distractors=False,
            real_ground=ground,
            composite_fraction=1.0,
            real_gsd_m_per_px=(0.015, 0.03),
        )

    assert heads_of_twin_crops(crops(), crops(), 12) > 0
    # Made on 128 * (0.015 .. 0.03) / 0.045 = 43 .. 85 px at the stored GSD, then enlarged to 128.
    assert made_px
    assert all(40 <= px <= 88 for px in made_px), made_px
    with pytest.raises(ValueError, match="real_gsd_m_per_px"):
        CrowdCrops(frames, 128, 4, seed=0, real_ground=ground, composite_fraction=1.0, real_gsd_m_per_px=(0.1, 0.05))


def tiny_train(arch: Architecture, loss: LossKind, data: Path, out: Path, steps: int, **options: Any) -> dict[str, Any]:
    """A few steps of :func:`train` on the tiny set (2-frame batches of 96 px crops, CPU, one validation frame)."""
    small: dict[str, Any] = {"batch": 2, "crop_px": 96, "workers": 0, "val_frames": 1, "device_name": "cpu"}
    return train(arch, loss, data, out, steps=steps, **(small | options))


def test_train_export_and_onnxruntime_parity(tiny_set: Path, tmp_path: Path) -> None:
    log = tiny_train(Architecture.LITE, LossKind.BAYESIAN, tiny_set, tmp_path / "run", 6, validate_every=3)
    assert [h["step"] for h in log["history"]] == [3, 6]
    assert all(np.isfinite(h["loss"]) for h in log["history"])
    saved = json.loads((tmp_path / "run" / "training.json").read_text())
    assert saved["architecture"] == "lite"
    model, _ = load_checkpoint(tmp_path / "run" / "model.pt")
    onnx_path = tmp_path / "lite.onnx"
    export(model, log, onnx_path, "slz-lite-test", "0")
    frames = [f.image_bgr for f in load_frames(tiny_set / "train")[:2]]
    assert parity(model, onnx_path, frames) <= 1e-4
    assert CONTRACT_KEY in read_metadata(onnx_path)
    runner = OnnxDensityModel(onnx_path)
    assert runner.contract.name == "slz-lite-test"
    density = runner.predict(frames[0])
    assert density.values.shape == (120, 160)
    assert bool(np.isfinite(density.values).all())
    # Floor and scale fitted on training frames: never worse than uncalibrated, and exported with parity.
    labelled = load_frames(tiny_set / "train")
    pairs = [(f.image_bgr, len(f.heads_px)) for f in labelled]
    floor, scale, mae = calibrate(model, pairs)
    _, _, mae_raw = calibrate(model, pairs, floors=(0.0,))
    assert mae <= mae_raw + 1e-9
    assert floor >= 0.0
    assert scale > 0.0
    calibrated = Calibrated(model, floor, scale).eval()
    calibrated_path = tmp_path / "calibrated.onnx"
    export(calibrated, log, calibrated_path, "slz-lite-test", "0")
    assert parity(calibrated, calibrated_path, frames) <= 1e-4
    # INT8: same contract, same output shape, loads in the companion.
    int8_path = tmp_path / "lite_int8.onnx"
    quantize(onnx_path, int8_path, calibration_frames(tiny_set / "train", 3))
    int8 = OnnxDensityModel(int8_path)
    assert int8.contract == runner.contract
    assert int8.predict(frames[0]).values.shape == (120, 160)
    # FP16: same contract, float32 in and out, the float32 model's map within half precision.
    fp16_path = tmp_path / "lite_fp16.onnx"
    to_float16(onnx_path, fp16_path)
    fp16 = OnnxDensityModel(fp16_path)
    assert fp16.contract == runner.contract
    half = fp16.predict(frames[0]).values
    assert half.dtype == np.float32
    assert float(np.abs(half - density.values).max()) <= 1e-2 * max(1.0, float(np.abs(density.values).max()))


PRETRAINED = Path(__file__).resolve().parents[2] / "shared" / "pretrained"
needs_pretrained = pytest.mark.skipif(
    not (PRETRAINED / "yolox_nano_coco_416.onnx").is_file(), reason="../shared/pretrained is not here"
)


NODES_TO_DARK4 = 130


@needs_pretrained
@pytest.mark.unit
@pytest.mark.parametrize(("context", "nodes"), [(False, 84), (True, NODES_TO_DARK4)])
def test_the_pretrained_stages_compute_what_onnxruntime_computes_on_the_original_graph(
    context: bool, nodes: int
) -> None:
    import onnx
    import onnxruntime as ort

    from models.density.preprocess import MEAN, STD, to_input
    from models.density.pretrained import YOLOX_NANO as STRIDE8
    from models.density.pretrained import YOLOX_NANO_CONTEXT, OnnxStages, PretrainedStages

    YOLOX_NANO = YOLOX_NANO_CONTEXT if context else STRIDE8  # the spec under test

    graph = onnx.load(str(PRETRAINED / YOLOX_NANO.file))
    for name in YOLOX_NANO.outputs:  # the stage outputs, exposed
        graph.graph.output.append(onnx.helper.make_tensor_value_info(name, onnx.TensorProto.FLOAT, None))
    session = ort.InferenceSession(graph.SerializeToString(), providers=["CPUExecutionProvider"])
    image_bgr = np.random.default_rng(3).integers(0, 256, (416, 416, 3), dtype=np.uint8)
    pixels = image_bgr.transpose(2, 0, 1)[None].astype(np.float32)  # YOLOX: BGR, 0-255
    expected = session.run(list(YOLOX_NANO.outputs), {"images": pixels})
    stages = OnnxStages(PRETRAINED / YOLOX_NANO.file, YOLOX_NANO.outputs)
    assert len(stages.nodes) == nodes  # of the graph's 369: the stem, dark2 and dark3 (and dark4)
    with torch.no_grad():
        got = stages(torch.from_numpy(pixels))
        # The same from the density network's own input (normalised RGB): the wrapper undoes the normalisation.
        wrapped = PretrainedStages(YOLOX_NANO, MEAN, STD, PRETRAINED)(torch.from_numpy(to_input(image_bgr))[None])
    for want, mine, theirs, channels, stride in zip(
        expected, got, wrapped, YOLOX_NANO.channels, YOLOX_NANO.strides, strict=True
    ):
        assert want.shape == (1, channels, 416 // stride, 416 // stride)
        assert float(np.abs(want - mine.numpy()).max()) < 1e-4
        assert float(np.abs(want - theirs.numpy()).max()) < 1e-3  # float round trip of the normalisation
    # A weight is a parameter: fine-tuning moves the pretrained layers.
    assert all(p.requires_grad for p in stages.parameters())
    assert sum(p.numel() for p in stages.parameters()) > 20_000


@needs_pretrained
def test_a_pretrained_network_trains_on_two_sites_exports_and_names_them(tiny_set: Path, tmp_path: Path) -> None:
    from sitl.world.ground import GROUND_ROOT

    sites = (GROUND_ROOT / "caliterra", GROUND_ROOT / "garfield")
    options: dict[str, Any] = {"real_ground_dirs": sites, "real_negative_fraction": 0.3, "composite_fraction": 0.3}
    log = tiny_train(
        Architecture.YOLOX_LITE,
        LossKind.MSE,
        tiny_set,
        tmp_path / "run",
        4,
        validate_every=4,
        backbone_lr_scale=0.0,
        **options,
    )
    assert log["real_ground_sites"] == ["caliterra", "garfield"]
    assert log["real_ground"] is None  # several sites: named in real_ground_sites
    assert {name.split("_")[0] for name in log["real_ground_frames"]} == {"IMG", "garfield"}
    model, _ = load_checkpoint(tmp_path / "run" / "model.pt")
    start = build(Architecture.YOLOX_LITE).state_dict()
    frozen = [k for k in start if k.startswith("backbone.")]
    assert frozen
    assert all(torch.equal(start[k], model.state_dict()[k]) for k in frozen)  # scale 0: frozen
    onnx_path = tmp_path / "yolox.onnx"
    export(model, log, onnx_path, "slz-yolox-test", "0")
    frames = [f.image_bgr for f in load_frames(tiny_set / "train")[:2]]
    assert parity(model, onnx_path, frames) <= 1e-4
    exported = OnnxDensityModel(onnx_path)
    assert exported.predict(frames[0]).values.shape == (120, 160)
    # The coarse stage is upsampled by a factor, not to a size: the graph runs at any size and a shrunk frame is
    # run cropped, to the same map as the whole padded frame.
    assert exported.context_px is not None
    whole = OnnxDensityModel(onnx_path, crop_shrunk_frames=False)
    frame = np.ascontiguousarray(cv2.resize(frames[0], (640, 480)), dtype=np.uint8)
    for scale in (0.4, 0.7):
        np.testing.assert_array_equal(
            predict_downscaled(exported, frame, scale).values, predict_downscaled(whole, frame, scale).values
        )
    from models.eval.real import training_sites

    assert training_sites(onnx_path) == {"caliterra", "garfield"}


@needs_pretrained
def test_frozen_stages_keep_the_first_pretrained_stages_and_train_the_rest(tiny_set: Path, tmp_path: Path) -> None:
    log = tiny_train(
        Architecture.YOLOX_LITE, LossKind.MSE, tiny_set, tmp_path / "run", 4, validate_every=4, frozen_stages=1
    )
    assert (log["frozen_stages"], log["backbone_lr_scale"]) == (1, 1.0)
    from models.density.architectures import YoloxLite

    model, _ = load_checkpoint(tmp_path / "run" / "last.pt")
    start = YoloxLite()
    stage_of = start.backbone.stages.stage_of
    assert set(stage_of.values()) == {0, 1}  # the stem and stride 4; stride 8
    before, after = start.state_dict(), model.state_dict()
    for name, stage in stage_of.items():
        key = f"backbone.stages.weights.{name}"
        assert torch.equal(before[key], after[key]) == (stage == 0), (name, stage)
