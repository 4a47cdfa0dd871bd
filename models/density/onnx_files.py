"""Metadata of the ONNX files we ship (no PyTorch needed)."""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import onnx

from companion.errors import SlzError
from models.density.receptive_field import make_any_size

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


def stamp_any_size(model_path: Path) -> int | None:
    """Measure at export what a board cannot at load (it has onnxruntime, not ``onnx``): free the graph's image
    sides and write the context a density cell reads into the contract (``context_px``), in place.

    Returns
    -------
    int or None
        The context (px); None where the graph's receptive field cannot be bounded: the file is then left with
        fixed sides and a contract without ``context_px`` (the model runs on its contract's size).

    Raises
    ------
    OnnxGraphError
        The file carries no ``slz.contract`` metadata.
    """
    proto = onnx.load(str(model_path))
    props = {p.key: p for p in proto.metadata_props}
    if CONTRACT_KEY not in props:
        raise OnnxGraphError(f"{model_path}: no '{CONTRACT_KEY}' metadata to stamp")
    contract = json.loads(props[CONTRACT_KEY].value)
    context_px = make_any_size(proto)
    if context_px is None:
        contract.pop("context_px", None)
    else:
        contract["context_px"] = context_px
    props[CONTRACT_KEY].value = json.dumps(contract)
    onnx.save(proto, str(model_path))
    return context_px


def sha256(path: Path) -> str:
    """Hex SHA-256 of a file (the model hash flight logs record)."""
    return hashlib.sha256(path.read_bytes()).hexdigest()


def main(argv: list[str] | None = None) -> int:
    """``python -m models.density.onnx_files FILE...``: stamp each model's any-size context (:func:`stamp_any_size`)."""
    paths = [Path(a) for a in (sys.argv[1:] if argv is None else argv)]
    if not paths:
        sys.stderr.write("usage: python -m models.density.onnx_files MODEL.onnx...\n")
        return 2
    for path in paths:
        context_px = stamp_any_size(path)
        sys.stdout.write(
            f"{path}: "
            + ("fixed size (no bounded context)" if context_px is None else f"any size, context {context_px} px")
            + "\n"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
