"""The Safe Landing Zone perception pipeline (paper, section "SLZ algorithm").

Stages, each its own module and small interface: :mod:`~companion.perception.density` (ONNX density model),
:mod:`~companion.perception.occupancy`, :mod:`~companion.perception.projection` (head plane, world NED),
:mod:`~companion.perception.zones`, :mod:`~companion.perception.tracking`,
:mod:`~companion.perception.selection`; :mod:`~companion.perception.pipeline` runs them in order.
"""

from __future__ import annotations

from companion.geometry import PinholeCamera, Pose
from companion.perception.config import PerceptionConfig, SelectionPolicyName, load_perception_config
from companion.perception.errors import PerceptionError
from companion.perception.pipeline import FrameResult, SlzPipeline, camera_from_config

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
