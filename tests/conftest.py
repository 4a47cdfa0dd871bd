"""Shared fixtures: small configs, a real ONNX model built in the test session, seeded scenes."""

from __future__ import annotations

from pathlib import Path

import pytest

from companion.perception.blob_model import build_blob_density_model, save_model
from companion.perception.config import PerceptionConfig
from companion.perception.density import OnnxDensityModel

REPO_ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="session")
def blob_model_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The blob-contrast density model (640x480, stride 4), built here from its fixed kernels."""
    return save_model(build_blob_density_model(), tmp_path_factory.mktemp("models") / "blob.onnx")


@pytest.fixture(scope="session")
def blob_model(blob_model_path: Path) -> OnnxDensityModel:
    """A loaded onnxruntime session of the blob model, one CPU thread."""
    return OnnxDensityModel(blob_model_path, ["CPUExecutionProvider"], intra_op_threads=1)


@pytest.fixture
def config(blob_model_path: Path) -> PerceptionConfig:
    """Default perception config pointing at the test-built model."""
    return PerceptionConfig.model_validate({"model": {"path": str(blob_model_path)}})
