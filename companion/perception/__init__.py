"""The Safe Landing Zone perception pipeline (paper, section "SLZ algorithm").

Stages, each its own module and small interface: :mod:`~companion.perception.density` (ONNX density model),
:mod:`~companion.perception.occupancy`, :mod:`~companion.perception.projection` (head plane, world NED),
:mod:`~companion.perception.zones`, :mod:`~companion.perception.tracking`,
:mod:`~companion.perception.selection`; :mod:`~companion.perception.pipeline` runs them in order.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from companion.geometry import PinholeCamera, Pose
    from companion.perception.config import PerceptionConfig, SelectionPolicyName, load_perception_config
    from companion.perception.errors import PerceptionError
    from companion.perception.pipeline import FrameResult, SlzPipeline, camera_from_config

# Loaded on first use: the SITL imports the geometry module only, without the pipeline's scipy and onnxruntime.
_EXPORTS = {
    "FrameResult": "pipeline",
    "PerceptionConfig": "config",
    "PerceptionError": "errors",
    "PinholeCamera": "geometry",
    "Pose": "geometry",
    "SelectionPolicyName": "config",
    "SlzPipeline": "pipeline",
    "camera_from_config": "pipeline",
    "load_perception_config": "config",
}

__all__ = [
    "FrameResult",
    "PerceptionConfig",
    "PerceptionError",
    "PinholeCamera",
    "Pose",
    "SelectionPolicyName",
    "SlzPipeline",
    "camera_from_config",
    "load_perception_config",
]


def __getattr__(name: str) -> Any:
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
