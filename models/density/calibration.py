"""The count calibration shared by checkpoint selection (``train.py``) and the export (``export.py``).

MSE-trained density maps keep a small positive floor on empty ground. ``scale * relu(density - floor)`` removes it;
the pair that minimises the mean absolute count error over labelled frames is found here (no PyTorch needed).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

FLOORS: tuple[float, ...] = tuple(float(f) for f in np.concatenate([[0.0], np.geomspace(1e-4, 0.05, 24)]))
"""Candidate floors, people per density cell."""


def fit_floor_and_scale(
    maps: Sequence[npt.NDArray[np.float32]], true_counts: Sequence[int], floors: Sequence[float] = FLOORS
) -> tuple[float, float, float]:
    """The (floor, scale) with the lowest count MAE over the frames, and that MAE.

    Parameters
    ----------
    maps : sequence of ndarray, shape (h, w)
        Density maps, people per cell.
    true_counts : sequence of int
        Labelled heads per frame.
    floors : sequence of float
        Candidate floors; for each, the scale is the ratio of true to predicted totals.

    Returns
    -------
    tuple of float
        ``(floor, scale, mae)``; ``(0, 1, inf)`` when every candidate leaves an empty total.
    """
    truth = np.asarray(true_counts, np.float64)
    best = (0.0, 1.0, float("inf"))
    for floor in floors:
        sums = np.array([np.maximum(d - floor, 0.0).sum() for d in maps], np.float64)
        if sums.sum() <= 0:
            continue
        scale = float(truth.sum() / sums.sum())
        mae = float(np.abs(scale * sums - truth).mean())
        if mae < best[2]:
            best = (float(floor), scale, mae)
    return best


def fit_floor_for_threshold(
    maps: Sequence[npt.NDArray[np.float32]],
    true_counts: Sequence[int],
    operating_threshold: float,
    deployed_threshold: float,
    floors: Sequence[float] = FLOORS,
) -> tuple[float, float, float]:
    """The (floor, scale) with the lowest count MAE among those that keep the occupancy of ``operating_threshold``.

    ``scale * relu(density - floor) >= deployed_threshold`` exactly where ``density >= operating_threshold`` when
    ``floor < operating_threshold`` and ``scale = deployed_threshold / (operating_threshold - floor)``: the exported
    model is occupied, at the threshold the perception config deploys, where the raw network is at the threshold
    chosen for it (``models/eval/threshold.py``), and its counts lose the floor.

    Returns
    -------
    tuple of float
        ``(floor, scale, mae)``; floor 0 is always a candidate.
    """
    if not (operating_threshold > 0.0 and deployed_threshold > 0.0):
        raise ValueError(f"thresholds must be positive, got {operating_threshold}, {deployed_threshold}")
    truth = np.asarray(true_counts, np.float64)
    best = (0.0, deployed_threshold / operating_threshold, float("inf"))
    for floor in sorted({0.0, *floors}):
        if floor >= operating_threshold:
            continue
        scale = deployed_threshold / (operating_threshold - floor)
        sums = np.array([np.maximum(d - floor, 0.0).sum() for d in maps], np.float64)
        mae = float(np.abs(scale * sums - truth).mean())
        if mae < best[2]:
            best = (float(floor), scale, mae)
    return best
