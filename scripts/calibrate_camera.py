"""Calibrate the companion's camera from photographs of a chessboard: the ``perception.camera`` section to paste.

Print a chessboard (or show one on a flat screen), measure one square, and take 15-30 photographs of it with the
drone's camera at the resolution it flies with: the board filling a good part of the frame, tilted various ways, in
every corner of the image. Then::

    python scripts/calibrate_camera.py photos/*.png --pattern 9x6 --square-m 0.025

``--pattern`` counts the board's *inner* corners (a board of 10 x 7 squares has 9 x 6). The script finds the corners
(sub-pixel), runs OpenCV's ``calibrateCamera`` with five coefficients (k1, k2, p1, p2, k3) and prints the
intrinsics and coefficients as YAML with the RMS reprojection error: under about 0.5 px is a good calibration; a
larger one usually means blurred photographs or a board that is not flat. ``slz`` undistorts each frame with them
(``companion.perception.lens``); the SITL's camera takes the same coefficients to fly a simulated lens.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt
import yaml

from companion.geometry import PinholeCamera

MIN_VIEWS = 6
"""Fewer photographs with the whole board found than this do not constrain five coefficients."""


class CalibrationError(Exception):
    """The photographs do not give a calibration (what was missing)."""


@dataclass(frozen=True)
class Calibration:
    """A camera's intrinsics (pixels) and OpenCV distortion coefficients, with the RMS reprojection error (px)."""

    camera: PinholeCamera
    distortion: list[float]
    rms_px: float
    views: int

    def camera_section(self) -> dict[str, object]:
        """The ``perception.camera`` fields it determines."""
        c = self.camera
        return {
            "width_px": c.width_px,
            "height_px": c.height_px,
            "fx_px": round(c.fx_px, 3),
            "fy_px": round(c.fy_px, 3),
            "cx_px": round(c.cx_px, 3),
            "cy_px": round(c.cy_px, 3),
            "distortion": [round(k, 6) for k in self.distortion],
        }


def find_corners(image_bgr: npt.NDArray[np.uint8], pattern: tuple[int, int]) -> npt.NDArray[np.float32] | None:
    """The board's inner corners in one photograph, sub-pixel, shape (N, 1, 2); None when the whole board is not
    found."""
    grey = cv2.cvtColor(image_bgr, cv2.COLOR_BGR2GRAY)
    found, corners = cv2.findChessboardCorners(grey, pattern, flags=cv2.CALIB_CB_ADAPTIVE_THRESH)
    if not found:
        return None
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-3)
    return np.asarray(cv2.cornerSubPix(grey, corners, (5, 5), (-1, -1), criteria), dtype=np.float32)


def calibrate(images_bgr: Sequence[npt.NDArray[np.uint8]], pattern: tuple[int, int], square_m: float) -> Calibration:
    """Calibrate from chessboard photographs (all of one size, shape (H, W, 3) BGR uint8); see the module docstring.

    Raises
    ------
    CalibrationError
        Photographs of different sizes, or fewer than :data:`MIN_VIEWS` with the whole board found.
    """
    sizes = {image.shape[:2] for image in images_bgr}
    if len(sizes) != 1:
        raise CalibrationError(f"the photographs have {len(sizes)} different sizes; calibrate one resolution at once")
    (height_px, width_px) = sizes.pop()
    board = np.zeros((pattern[0] * pattern[1], 3), np.float32)
    board[:, :2] = np.mgrid[0 : pattern[0], 0 : pattern[1]].T.reshape(-1, 2) * square_m
    image_points = [c for c in (find_corners(image, pattern) for image in images_bgr) if c is not None]
    if len(image_points) < MIN_VIEWS:
        raise CalibrationError(
            f"the whole {pattern[0]}x{pattern[1]} board was found in {len(image_points)} of {len(images_bgr)} "
            f"photographs; at least {MIN_VIEWS} are needed"
        )
    rms, K, coefficients, _, _ = cv2.calibrateCamera(
        [board] * len(image_points), image_points, (width_px, height_px), None, None
    )
    return Calibration(
        PinholeCamera(width_px, height_px, float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])),
        [float(c) for c in np.ravel(coefficients)],
        float(rms),
        len(image_points),
    )


def _pattern(text: str) -> tuple[int, int]:
    try:
        cols, rows = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: give the inner corners as COLSxROWS, e.g. 9x6") from None
    if cols < 3 or rows < 3:
        raise argparse.ArgumentTypeError(f"{text!r}: at least 3x3 inner corners")
    return cols, rows


def main(argv: Sequence[str] | None = None) -> int:
    """Calibrate and print the ``perception.camera`` section (see the module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else None)
    parser.add_argument("images", nargs="+", type=Path, help="photographs of the chessboard")
    parser.add_argument("--pattern", type=_pattern, required=True, help="inner corners, COLSxROWS (e.g. 9x6)")
    parser.add_argument("--square-m", type=float, required=True, help="side of one square, metres")
    parser.add_argument("--out", type=Path, help="also write the YAML here")
    args = parser.parse_args(argv)
    images = []
    for path in args.images:
        image = cv2.imread(str(path), cv2.IMREAD_COLOR)
        if image is None:
            sys.stderr.write(f"calibrate_camera: cannot read {path}\n")
            return 2
        images.append(np.asarray(image, dtype=np.uint8))
    try:
        result = calibrate(images, args.pattern, args.square_m)
    except CalibrationError as exc:
        sys.stderr.write(f"calibrate_camera: {exc}\n")
        return 1
    text = yaml.safe_dump({"perception": {"camera": result.camera_section()}}, sort_keys=False)
    sys.stdout.write(f"# {result.views} views, RMS reprojection error {result.rms_px:.3f} px\n{text}")
    if args.out is not None:
        args.out.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
