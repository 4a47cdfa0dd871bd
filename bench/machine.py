"""The machine context printed with every benchmark: CPU model, cores, library versions."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from sitl.campaign.provenance import machine


def machine_context() -> dict[str, object]:
    """What the numbers were measured on."""
    import cv2
    import numpy as np
    import onnxruntime

    return {
        **machine(),
        "numpy": np.__version__,
        "opencv": cv2.__version__,
        "onnxruntime": onnxruntime.__version__,
    }


def save_report(report: dict[str, Any], path: Path) -> None:
    """Write a benchmark's JSON report and say where."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    sys.stdout.write(f"wrote {path}\n")
