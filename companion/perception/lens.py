"""Lens distortion in OpenCV's model: the pipeline undistorts each frame, the SITL distorts what it renders.

A real camera's lens bends straight lines; the pinhole model every stage after it uses (projection onto the head
plane, footprints, zones) does not. With ``perception.camera.distortion`` set to the camera's coefficients (from a
calibration: ``scripts/calibrate_camera.py``, docs/perception.md), :meth:`LensDistortion.undistort` resamples each
frame onto the pinhole image of the same intrinsics ``K`` first, and everything downstream stays exact. The SITL's
camera (``sitl.camera.distortion``) does the opposite with :meth:`LensDistortion.distort`, so a simulated lens can be
flown and the undistortion tested end to end.

Coefficients are OpenCV's, in its order: ``(k1, k2, p1, p2[, k3[, k4, k5, k6[, s1, s2, s3, s4[, tx, ty]]]])``, so a
``cv2.calibrateCamera`` result is used as it is. All zero (or none) is no lens: frames pass untouched, bit for bit.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np
import numpy.typing as npt

from companion.geometry import PinholeCamera
from companion.perception.errors import PerceptionError

U8Image = npt.NDArray[np.uint8]
COEFFICIENT_COUNTS = (0, 4, 5, 8, 12, 14)
"""How many coefficients OpenCV's model takes (0: none)."""


class LensDistortion:
    """OpenCV's distortion model for one camera: its maps computed once, applied to each frame.

    Parameters
    ----------
    camera : PinholeCamera
        The intrinsics ``K`` and the image size (the undistorted image keeps both).
    coefficients : sequence of float
        OpenCV's distortion coefficients (see the module docstring), 4, 5, 8, 12 or 14 of them.
    """

    def __init__(self, camera: PinholeCamera, coefficients: Sequence[float]) -> None:
        if len(coefficients) not in COEFFICIENT_COUNTS[1:]:
            raise PerceptionError(
                "lens", f"{len(coefficients)} distortion coefficients: OpenCV's model takes 4, 5, 8, 12 or 14"
            )
        self.camera = camera
        self.coefficients = np.asarray(coefficients, np.float64)
        if not np.all(np.isfinite(self.coefficients)):
            raise PerceptionError("lens", "distortion coefficients must be finite numbers")
        K = camera.K
        size = (camera.width_px, camera.height_px)
        # Undistort: for each pixel of the pinhole image, where it lies in the distorted frame.
        self._undistort_maps = cv2.initUndistortRectifyMap(K, self.coefficients, None, K, size, cv2.CV_32FC1)
        # Distort: for each pixel of the distorted frame, where its ray lies in the pinhole image.
        u, v = np.meshgrid(np.arange(camera.width_px, dtype=np.float64), np.arange(camera.height_px, dtype=np.float64))
        pixels = np.stack([u.ravel(), v.ravel()], axis=1).reshape(-1, 1, 2)
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-6)
        pinhole = cv2.undistortPoints(pixels, K, self.coefficients, R=None, P=K, criteria=criteria)
        pinhole = pinhole.reshape(camera.height_px, camera.width_px, 2)
        self._distort_maps = (
            np.ascontiguousarray(pinhole[..., 0], dtype=np.float32),
            np.ascontiguousarray(pinhole[..., 1], dtype=np.float32),
        )

    @classmethod
    def from_coefficients(cls, camera: PinholeCamera, coefficients: Sequence[float]) -> LensDistortion | None:
        """The lens for ``coefficients``; None when there is none (no coefficients, or all zero)."""
        if len(coefficients) not in COEFFICIENT_COUNTS:
            raise PerceptionError(
                "lens", f"{len(coefficients)} distortion coefficients: OpenCV's model takes 4, 5, 8, 12 or 14"
            )
        if not any(coefficients):
            return None
        return cls(camera, coefficients)

    def _check(self, image: U8Image, where: str) -> None:
        if image.shape[:2] != (self.camera.height_px, self.camera.width_px):
            raise PerceptionError(
                where,
                f"frame is {image.shape[1]}x{image.shape[0]}, the lens was calibrated at "
                f"{self.camera.width_px}x{self.camera.height_px}",
            )

    def undistort(self, image: U8Image) -> U8Image:
        """The pinhole image (same ``K`` and size) of a frame the lens distorted; shape (H, W[, C]), uint8.
        Pixels whose ray falls outside the frame are black."""
        self._check(image, "lens.undistort")
        out = cv2.remap(image, *self._undistort_maps, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
        return np.asarray(out, dtype=np.uint8)

    def distort(self, image: U8Image) -> U8Image:
        """What the lens makes of a pinhole image (same ``K`` and size); shape (H, W[, C]), uint8."""
        self._check(image, "lens.distort")
        out = cv2.remap(image, *self._distort_maps, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        return np.asarray(out, dtype=np.uint8)
