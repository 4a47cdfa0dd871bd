"""Build the shipped placeholder density model, ``models/blob_detector/blob_detector.onnx``.

Run: ``.venv/bin/python models/blob_detector/build.py``. Deterministic: the same file every time (fixed kernels,
no training). See ``models/README.md`` for what it is and is not.
"""

from __future__ import annotations

import hashlib
import sys
from pathlib import Path

from models.blob_detector.graph import build_blob_density_model, save_model


def main() -> int:
    path = save_model(build_blob_density_model(), Path(__file__).with_name("blob_detector.onnx"))
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    sys.stdout.write(f"wrote {path} ({path.stat().st_size} bytes, sha256 {digest[:16]})\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
