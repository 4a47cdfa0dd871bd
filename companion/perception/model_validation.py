"""What each shipped density model is validated on, by the SHA-256 of its file: the doctor and ``slz fly`` say it
where a user reads (models/density/MODEL_CARD.md has the measurements).

No shipped model is validated on real imagery: each learned people from the SITL's renderer, and on real frames each
marks 9-20 % of person-free ground as occupied. A model not listed here (one you trained or exported yourself) has no
validation record, and the doctor says so.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class ModelValidation:
    """One model's validation record.

    Attributes
    ----------
    name : str
        The shipped file's name.
    real_imagery : bool
        Validated for flight over real ground with real people below.
    summary : str
        What it was validated on, and how it fails elsewhere (one line).
    """

    name: str
    real_imagery: bool
    summary: str


_SYNTHETIC = (
    "validated on the SITL's rendered parks only; on real frames it marks {false_pct} of person-free ground occupied "
    "(models/density/MODEL_CARD.md): do not fly it over real people"
)

SHIPPED: dict[str, ModelValidation] = {
    "c6e61bd4e565f7c643f318bcc88bbc3cda3a98cce52391d8a86fa45318af22b5": ModelValidation(
        "slz_lite.onnx", False, _SYNTHETIC.format(false_pct="9-20 %")
    ),
    "f750b07399bb167be9acd0e84cc74eebfbfd3ce095ff96d3934a3e91e34cb4ab": ModelValidation(
        "slz_lite_int8.onnx", False, _SYNTHETIC.format(false_pct="11-20 %")
    ),
    "71be670efc175b2108179e52b757b002db042f7fbc57ff3f18c097c552e05e4f": ModelValidation(
        "slz_ccnn.onnx", False, _SYNTHETIC.format(false_pct="10-28 %")
    ),
    "093b54deb35460b3d49fff8a70bebe42643217ed2cb2695a682df5c426694421": ModelValidation(
        "slz_lite_wide_real.onnx",
        False,
        "trained with one real site's ground (Caliterra), validated on rendered parks; on a real site it never saw "
        "(issue 52) it marks 25-27 % of person-free ground occupied, and it finds fewer real people "
        "(models/density/MODEL_CARD.md): do not fly it over real people",
    ),
}


def file_sha256(path: Path) -> str:
    """The hex SHA-256 of a file's bytes."""
    digest = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def validation_of(path: Path) -> ModelValidation | None:
    """The validation record of the model file at ``path``; None when it is not a shipped model (or unreadable)."""
    try:
        return SHIPPED.get(file_sha256(path))
    except OSError:
        return None
