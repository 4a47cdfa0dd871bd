"""The shipped density models: they load, they find people where the ground truth says, and not on empty ground.

Real onnxruntime on the real shipped files, on frames rendered by the SITL world in the held-out style (people,
ground and weather the training never saw).
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from companion.geometry import PinholeCamera, Pose, T_body_camera_from_mount
from companion.perception.config import OccupancyConfig, PerceptionConfig, load_perception_config
from companion.perception.density import OnnxDensityModel, predict_downscaled
from models.data.generate import Split, generate
from models.density.onnx_files import CONTRACT_KEY, TRAINING_KEY, read_metadata
from models.eval.evaluate import evaluate_model
from models.eval.metrics import detect_heads
from sitl.render.camera import Light, WorldRenderer
from sitl.world.crowd import Crowd
from sitl.world.park import Park
from sitl.world.scenario import ScenarioConfig, Style

pytestmark = pytest.mark.integration

REPO_ROOT = Path(__file__).resolve().parent.parent
SHIPPED = {
    "slz_yolox": REPO_ROOT / "models/density/slz_yolox.onnx",
    "slz_yolox_fp16": REPO_ROOT / "models/density/slz_yolox_fp16.onnx",
    "slz_lite": REPO_ROOT / "models/density/slz_lite.onnx",
    "slz_lite_int8": REPO_ROOT / "models/density/slz_lite_int8.onnx",
    "slz_ccnn": REPO_ROOT / "models/density/slz_ccnn.onnx",
}


def test_the_default_config_flies_the_model_trained_on_every_real_site() -> None:
    config = load_perception_config(REPO_ROOT / "mission_configs/perception.yaml")
    assert (REPO_ROOT / config.model.path).resolve() == SHIPPED["slz_yolox"].resolve()
    assert PerceptionConfig().model.path.resolve() == SHIPPED["slz_yolox"].resolve()  # the installation's default
    metadata = read_metadata(SHIPPED["slz_yolox"])
    training = json.loads(metadata[TRAINING_KEY])
    assert training["architecture"] == "yolox-lite"
    assert set(training["real_ground_sites"]) == {"caliterra", "garfield", "boruszyn"}  # NEON held out
    assert json.loads(metadata[CONTRACT_KEY])["output_stride"] == 4
    assert json.loads(read_metadata(SHIPPED["slz_yolox_fp16"])[TRAINING_KEY]) == training  # the same model in FP16


def test_the_fp16_copy_gives_the_fp32_maps_within_a_small_part_of_the_threshold(heldout_frames: Path) -> None:
    fp32, fp16 = OnnxDensityModel(SHIPPED["slz_yolox"]), OnnxDensityModel(SHIPPED["slz_yolox_fp16"])
    threshold = OccupancyConfig().density_threshold
    for path in sorted(heldout_frames.glob("*[0-9].png")):
        frame = np.asarray(cv2.imread(str(path)), np.uint8)
        a, b = fp32.predict(frame).values, fp16.predict(frame).values
        assert float(np.abs(a - b).max()) < 0.5 * threshold, path.name  # measured: 0.0009 people per cell at most
        assert float(((a >= threshold) != (b >= threshold)).mean()) < 0.002, path.name  # cells that change side


@pytest.fixture(scope="module")
def heldout_frames(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("heldout")
    generate(root, Split.HELDOUT, frames=4, base_seed=4242)
    return root / "heldout"


# Floors for 4 held-out frames (snow, fog, dust; 10-27 m; 271 visible heads). Measured when the models were
# built: head recall within 8 px 0.31 (lite), 0.35 (int8), 0.11 (CCNN); person pixels called free 0.04 %, 0 %, 0.8 %;
# issue 63's default 0.45 (FP32 and FP16), no person pixel called free.
RECALL_8PX_FLOOR = {
    "slz_yolox": 0.35,
    "slz_yolox_fp16": 0.35,
    "slz_lite": 0.25,
    "slz_lite_int8": 0.25,
    "slz_ccnn": 0.08,
}
MISS_RATE_CEILING = 0.03


@pytest.mark.parametrize("name", list(SHIPPED))
def test_people_are_found_where_the_ground_truth_says(name: str, heldout_frames: Path) -> None:
    scores = evaluate_model(
        OnnxDensityModel(SHIPPED[name]), heldout_frames, REPO_ROOT / "mission_configs/perception.yaml"
    )
    heads = sum(s.true_count for s in scores)
    assert heads > 50
    recall_8px = sum(s.matched["8px"] for s in scores) / heads
    miss_rate = sum(s.missed_person_px for s in scores) / sum(s.person_px for s in scores)
    assert recall_8px >= RECALL_8PX_FLOOR[name], f"{name}: head recall within 8 px {recall_8px:.2f}"
    assert miss_rate <= MISS_RATE_CEILING, f"{name}: {100 * miss_rate:.1f} % of person pixels called free"


def _empty_park_frame(seed: int, altitude_m: float) -> np.ndarray:
    scenario = ScenarioConfig(people_min=0, people_max=0, style=Style.HELDOUT)
    camera = PinholeCamera.from_hfov(640, 480, 90.0)
    renderer = WorldRenderer(
        Park(seed, style=Style.HELDOUT),
        Crowd(scenario, seed),
        camera,
        T_body_camera_from_mount(),
        Light.from_angles(50.0, 120.0, 0.5),
    )
    try:
        view = renderer.render(
            Pose.from_ned_euler(3.0, -2.0, -altitude_m, 0.0, 0.0, 0.7), 0.0, with_mask=False, with_depth=False
        )
    finally:
        renderer.close()
    return view.image_bgr


@pytest.mark.parametrize("name", list(SHIPPED))
def test_no_people_are_seen_on_an_empty_park(name: str) -> None:
    """Measured when built: 0.8-1.3 % of cells occupied (lite), 1.2-2.3 % (CCNN), 0-2 "heads" detected, on an empty
    park with benches, bins, bushes and blobs."""
    model = OnnxDensityModel(SHIPPED[name])
    for seed, altitude_m in ((11, 10.0), (12, 25.0)):
        density = model.predict(_empty_park_frame(seed, altitude_m))
        occupied = float((density.values >= OccupancyConfig().density_threshold).mean())
        assert occupied < 0.04, f"{name} at {altitude_m} m: {100 * occupied:.1f} % of an empty park occupied"
        heads = len(detect_heads(density))
        assert heads <= 4, f"{name} at {altitude_m} m detects {heads} heads on an empty park"


def _park_frame_with_people(seed: int, altitude_m: float) -> np.ndarray:
    scenario = ScenarioConfig(people_min=100, people_max=100)
    renderer = WorldRenderer(
        Park(seed),
        Crowd(scenario, seed),
        PinholeCamera.from_hfov(640, 480, 90.0),
        T_body_camera_from_mount(),
        Light.from_angles(40.0, 200.0, 0.45),
    )
    try:
        pose = Pose.from_ned_euler(1.0, 2.0, -altitude_m, 0.05, -0.03, 0.3)
        return renderer.render(pose, 0.0, with_mask=False, with_depth=False).image_bgr
    finally:
        renderer.close()


@pytest.mark.parametrize("name", [*SHIPPED, "slz_lite_wide_real"])
def test_a_shrunk_frame_run_with_its_context_is_the_padded_frames_map_to_the_bit(name: str) -> None:
    """The campaign machine's CPU path (``crop_shrunk_frames``): a frame shrunk for min_gsd_m_per_px runs as itself
    plus the context its cells read, and every kept cell equals the whole padded frame's, bit for bit, at every
    scale a descent passes through."""
    path = REPO_ROOT / "models/density" / f"{name}.onnx"
    cropped, padded = OnnxDensityModel(path), OnnxDensityModel(path, crop_shrunk_frames=False)
    assert cropped.context_px is not None
    assert cropped.context_px % 16 == 0
    assert padded.context_px is None
    for frame in (_park_frame_with_people(21, 12.0), _park_frame_with_people(22, 5.0)):
        for scale in np.linspace(0.12, 1.0, 12):
            a = predict_downscaled(cropped, frame, float(scale)).values
            b = predict_downscaled(padded, frame, float(scale)).values
            assert a.shape == b.shape
            assert np.array_equal(a, b), f"{name} at scale {scale:.2f}: max difference {np.abs(a - b).max()}"


_WITHOUT_ONNX = """
import json, sys
sys.modules["onnx"] = None  # as installed from requirements/drone.lock: onnxruntime, not the onnx package
import cv2
import numpy as np
from companion.geometry import Pose
from companion.perception.config import load_perception_config
from companion.perception.pipeline import SlzPipeline

config = load_perception_config("mission_configs/perception.yaml")
pipeline = SlzPipeline.from_config(config)
model = pipeline.density_model
shapes = []
run_any_size = model.predict_any_size
model.predict_any_size = lambda frame: (shapes.append(list(frame.shape)), run_any_size(frame))[1]
pose = Pose.from_ned_euler(0.0, 0.0, -8.0, 0.0, 0.0, 0.0)
frame = np.random.default_rng(5).integers(0, 256, (config.camera.height_px, config.camera.width_px, 3), np.uint8)
pipeline.process(frame, pose, 0.0)
print(json.dumps({
    "onnx_importable": sys.modules.get("onnx") is not None,
    "context_px": model.context_px,
    "stamped_px": model.contract.context_px,
    "scale": pipeline.input_scale(pose),
    "frame": list(frame.shape),
    "shapes": shapes,
}))
"""


def test_on_the_drones_lock_alone_the_density_stage_at_8_m_runs_the_cropped_input() -> None:
    """The drone's lock installs onnxruntime, not ``onnx``: the shipped default carries its any-size stamp (measured
    at export), so at 8 m the shrunk frame runs as itself plus its context, not padded to the whole frame."""
    lock = (REPO_ROOT / "requirements/drone.lock").read_text(encoding="utf-8")
    assert re.search(r"^onnx==", lock, re.MULTILINE) is None, "the drone's lock installs onnx: the test means nothing"
    done = subprocess.run(
        [sys.executable, "-c", _WITHOUT_ONNX], cwd=REPO_ROOT, capture_output=True, text=True, timeout=120, check=False
    )
    assert done.returncode == 0, done.stderr[-3000:]
    seen = json.loads(done.stdout.strip().splitlines()[-1])
    assert seen["onnx_importable"] is False
    assert seen["stamped_px"] is not None
    assert seen["context_px"] == seen["stamped_px"]
    assert seen["scale"] < 0.9, f"at 8 m the frame should be shrunk, scale {seen['scale']}"
    assert len(seen["shapes"]) == 1, "the density stage did not run the any-size path"
    height_px, width_px = seen["shapes"][0][:2]
    assert height_px < seen["frame"][0], seen
    assert width_px < seen["frame"][1], seen


@pytest.mark.parametrize("name", [*SHIPPED, "slz_lite_wide_real", "candidates/wide_cb", "candidates/wide_gb"])
def test_every_shipped_model_is_stamped_to_run_at_any_size(name: str) -> None:
    """Each shipped model's contract carries the context its graph reads (``models.density.onnx_files``), measured
    again here from the graph: the stamp is what the graph says."""
    import onnx

    from models.density.receptive_field import make_any_size

    path = REPO_ROOT / "models/density" / f"{name}.onnx"
    stamped = json.loads(read_metadata(path)[CONTRACT_KEY])["context_px"]
    assert stamped == make_any_size(onnx.load(str(path)))
    assert OnnxDensityModel(path).context_px == stamped
