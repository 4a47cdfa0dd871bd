"""Metadata of the ONNX files we ship (no PyTorch needed)."""

from __future__ import annotations

import hashlib
from pathlib import Path

import onnx

from companion.errors import SlzError

CONTRACT_KEY = "slz.contract"
"""JSON input contract read by ``companion.perception.density.OnnxDensityModel``."""
TRAINING_KEY = "slz.training"
"""JSON summary of how the weights were trained."""
QUANTIZATION_KEY = "slz.quantization"
"""JSON summary of the INT8 quantization (for the quantized variant)."""


class OnnxGraphError(SlzError):
    """An ONNX graph cannot be read as asked (which file, which tensor or operation): a pretrained backbone
    (``models/density/pretrained.py``)."""


def read_metadata(model_path: Path) -> dict[str, str]:
    """``metadata_props`` of an ONNX file."""
    proto = onnx.load(str(model_path), load_external_data=False)
    return {p.key: p.value for p in proto.metadata_props}


def set_metadata(model_path: Path, entries: dict[str, str]) -> None:
    """Add or replace ``metadata_props`` of an ONNX file in place."""
    proto = onnx.load(str(model_path))
    kept = [p for p in proto.metadata_props if p.key not in entries]
    del proto.metadata_props[:]
    proto.metadata_props.extend(kept)
    for key, value in entries.items():
        proto.metadata_props.add(key=key, value=value)
    onnx.save(proto, str(model_path))


def sha256(path: Path) -> str:
    """Hex SHA-256 of a file (the model hash flight logs record)."""
    return hashlib.sha256(path.read_bytes()).hexdigest()
