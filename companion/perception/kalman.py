"""A linear Kalman filter: the predict and update steps the zone tracker needs, nothing else.

It computes exactly what ``filterpy.kalman.KalmanFilter`` computes (the same products in the same order, Joseph-form
covariance update), so tracks are bit-for-bit those of filterpy (``tests/test_tracking.py`` checks it), without
filterpy's imports (its ``kalman`` package loads ``scipy.stats``, a second of start-up, and it pulls matplotlib onto
the drone).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

F64Array = npt.NDArray[np.float64]


class KalmanFilter:
    """State ``x`` (n,) with covariance ``P`` (n, n), measured as ``z = H x`` (m,) with noise covariance ``R`` (m, m).

    Parameters
    ----------
    x : ndarray, shape (n,)
        Initial state.
    P : ndarray, shape (n, n)
        Initial state covariance.
    H : ndarray, shape (m, n)
        Measurement matrix.
    R : ndarray, shape (m, m)
        Measurement noise covariance.
    """

    def __init__(self, x: F64Array, P: F64Array, H: F64Array, R: F64Array) -> None:
        n, m = x.shape[0], H.shape[0]
        if P.shape != (n, n) or H.shape != (m, n) or R.shape != (m, m):
            raise ValueError(f"shapes do not fit: x {x.shape}, P {P.shape}, H {H.shape}, R {R.shape}")
        self.x = np.array(x, dtype=np.float64)
        self.P = np.array(P, dtype=np.float64)
        self.H = np.array(H, dtype=np.float64)
        self.R = np.array(R, dtype=np.float64)
        self._I = np.eye(n)

    def predict(self, F: F64Array, Q: F64Array) -> None:
        """Propagate: ``x = F x``, ``P = F P F' + Q`` (F, Q: (n, n))."""
        self.x = np.dot(F, self.x)
        self.P = np.dot(np.dot(F, self.P), F.T) + Q

    def update(self, z: F64Array) -> None:
        """Fuse a measurement ``z`` (m,); the covariance in Joseph form, ``(I-KH) P (I-KH)' + K R K'``."""
        y = z - np.dot(self.H, self.x)
        PHT = np.dot(self.P, self.H.T)
        S = np.dot(self.H, PHT) + self.R
        K = np.dot(PHT, np.linalg.inv(S))
        self.x = self.x + np.dot(K, y)
        I_KH = self._I - np.dot(K, self.H)
        self.P = np.dot(np.dot(I_KH, self.P), I_KH.T) + np.dot(np.dot(K, self.R), K.T)
