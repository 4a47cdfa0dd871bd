"""Shared fixtures: small configs, a real ONNX model built in the test session, seeded scenes."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from companion.perception.config import PerceptionConfig
from companion.perception.density import OnnxDensityModel
from models.blob_detector.graph import build_blob_density_model, save_model
from sitl.harness.instances import InstanceLease, lease_instance, leased_instance

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


@pytest.fixture
def instances() -> Iterator[Callable[[], int]]:
    """Lease free SITL instances (``sitl.harness.instances``) for this test: call it once per SITL; all are given back
    after the test. Tests never pick instance numbers, so they pass beside another test run, a campaign or a demo."""
    leases: list[InstanceLease] = []

    def take() -> int:
        leases.append(lease_instance())
        return leases[-1].instance

    yield take
    for lease in leases:
        lease.release()


@pytest.fixture
def instance(instances: Callable[[], int]) -> int:
    """One leased SITL instance for this test."""
    return instances()


@pytest.fixture(scope="module")
def module_instance() -> Iterator[int]:
    """One leased SITL instance for a module's shared SITL."""
    with leased_instance() as lease:
        yield lease.instance
