"""What each shipped density model is validated on, by the SHA-256 of its file: the doctor and ``slz fly`` say it
where a user reads (models/density/MODEL_CARD.md has the measurements).

No shipped model is validated for flight over real people: each learned people from the SITL's renderer, and only 134
real people seen from above (SDD) were ever checked. The default, ``slz_yolox.onnx`` (issue 63), also learned real
ground from three sites and is measured on real ground it never read; the synthetic-only models mark 9-25 % of such
ground occupied. Files kept as history (the candidates of issue 52, the models before it) say so. A model not listed
here (one you trained or exported yourself) has no validation record, and the doctor says so.
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

_DEFAULT = (
    "the default: rendered people and the real ground of three sites (Caliterra, Garfield, Boruszyn); its recipe, "
    "each site held out in turn, marks 1-6 % (1-9 % at half scale) of person-free ground occupied on a site it never "
    "read, 14-18 % on NEON's forest; it finds 127 and 129 (half scale) of 134 real people seen from above (SDD); fly a "
    "dry run first (docs/field-dry-run.md)"
)
_HISTORY = "history, not for flight (models/density/MODEL_CARD.md): "

SHIPPED: dict[str, ModelValidation] = {
    "053af37266ec187c70a6007d313d41c57933a639cb89eda29fd3cdc4ab870e6c": ModelValidation(
        "slz_yolox.onnx", False, _DEFAULT
    ),
    "058004c8d7c74335712a9544dc63e34ba3dcd5a12cfc37788d35ec8c6378b639": ModelValidation(
        "slz_yolox_fp16.onnx", False, "FP16 copy of " + _DEFAULT
    ),
    "c6e61bd4e565f7c643f318bcc88bbc3cda3a98cce52391d8a86fa45318af22b5": ModelValidation(
        "slz_lite.onnx",
        False,
        "the synthetic-only model of the first tables (an option, not the default): "
        + _SYNTHETIC.format(false_pct="9-25 %"),
    ),
    "f750b07399bb167be9acd0e84cc74eebfbfd3ce095ff96d3934a3e91e34cb4ab": ModelValidation(
        "slz_lite_int8.onnx", False, _HISTORY + _SYNTHETIC.format(false_pct="10-25 %")
    ),
    "71be670efc175b2108179e52b757b002db042f7fbc57ff3f18c097c552e05e4f": ModelValidation(
        "slz_ccnn.onnx", False, _HISTORY + "the paper's architecture; " + _SYNTHETIC.format(false_pct="8-21 %")
    ),
    "093b54deb35460b3d49fff8a70bebe42643217ed2cb2695a682df5c426694421": ModelValidation(
        "slz_lite_wide_real.onnx",
        False,
        _HISTORY + "trained with one real site's ground (Caliterra), validated on rendered parks; on a real site it "
        "never saw (issue 52) it marks 25-27 % of person-free ground occupied, and it finds fewer real people: do not "
        "fly it over real people",
    ),
    "cf85f8502d08d621476c409ef5cc4b8632fbf6145a95f2400b48ab63f2d98839": ModelValidation(
        "yolox_cb.onnx", False, _HISTORY + "issue 52's candidate held out from Garfield, as flown over it"
    ),
    "3149cbce41eaca4d7ff65241692aef2637bfc8e14a1156192f672e2ff0387f6a": ModelValidation(
        "yolox_gb.onnx", False, _HISTORY + "issue 52's candidate held out from Caliterra, as flown over it"
    ),
    "589edd82c1aa6967320bb9eaceb032b42edcfb94fffec59229d019283cc62a5e": ModelValidation(
        "wide_cb.onnx", False, _HISTORY + "issue 52's from-scratch candidate held out from Garfield, as flown over it"
    ),
    "e24c184800ccf24e48ab390f23916bed270c2d2dcd6c2ad9ba9661014a941655": ModelValidation(
        "wide_gb.onnx", False, _HISTORY + "issue 52's from-scratch candidate held out from Caliterra, as flown over it"
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
