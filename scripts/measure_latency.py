"""Measure the camera's latency (``camera.latency_s``: exposure to arrival) from a recorded flight.

A camera without capture times (V4L2, RTSP, files) stamps each frame with its arrival on the vehicle clock minus
``camera.latency_s``; the pose paired with it is the autopilot's at that instant. A wrong latency pairs each frame
with the pose of another moment, and every zone lands in the wrong place by the distance the vehicle moved (or turned)
in between. This script finds the latency the frames themselves show:

1. Record a flight (a dry run does) with every frame saved (``recorder.frame_every: 1``) while the pilot yaws the
   hovering vehicle left and right for ten seconds or more, over textured ground, at 10-20 m.
2. ``python scripts/measure_latency.py FLIGHT_DIR``

It measures how far the image turns between consecutive frames (ORB features, a rotation fitted with RANSAC) and how
far the logged poses turn between the frames' logged capture times, and finds the time shift ``d`` that makes the two
agree best (the poses' yaw is interpolated). The latency to configure is the one the flight ran with plus ``d``.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

from companion.flightlog.flight_log import FlightLog, FlightLogError, RecordKind, flight_folder

MIN_PAIRS = 20
"""Frame pairs with a measured rotation needed for an estimate."""
MIN_TURN_DEG = 20.0
"""The yaw the poses must sweep in all (peak to peak) for the rotation to say anything about time."""
SEARCH_S = 0.5
"""Latency corrections searched: within this of the configured latency, both ways."""


class LatencyError(Exception):
    """The flight does not show its camera's latency (what is missing)."""


@dataclass(frozen=True)
class LatencyEstimate:
    """What the frames show: the shift ``correction_s`` to add to ``configured_s``, the fit's residual (deg RMS per
    frame pair) and how many frame pairs it rests on."""

    configured_s: float
    correction_s: float
    residual_deg: float
    pairs: int

    @property
    def latency_s(self) -> float:
        """The latency to configure: exposure to arrival, seconds."""
        return self.configured_s + self.correction_s


def image_turn_deg(before: npt.NDArray[np.uint8], after: npt.NDArray[np.uint8]) -> float | None:
    """How far the picture turned from ``before`` to ``after`` (degrees, positive clockwise on screen, about the image
    centre or anywhere: a similarity fitted to matched ORB features with RANSAC); None without enough matches."""
    orb = cv2.ORB_create(nfeatures=1500)  # type: ignore[attr-defined]  # not in OpenCV 5's stubs
    grey = [cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) for image in (before, after)]
    (kp_a, des_a), (kp_b, des_b) = (orb.detectAndCompute(g, None) for g in grey)
    if des_a is None or des_b is None or len(kp_a) < 20 or len(kp_b) < 20:
        return None
    matches = cv2.BFMatcher(cv2.NORM_HAMMING, crossCheck=True).match(des_a, des_b)
    if len(matches) < 20:
        return None
    src = np.asarray([kp_a[m.queryIdx].pt for m in matches], dtype=np.float32)
    dst = np.asarray([kp_b[m.trainIdx].pt for m in matches], dtype=np.float32)
    M, inliers = cv2.estimateAffinePartial2D(src, dst, method=cv2.RANSAC, ransacReprojThreshold=2.0)
    if M is None or inliers is None or int(inliers.sum()) < 15:
        return None
    return math.degrees(math.atan2(M[1, 0], M[0, 0]))


def yaw_deg(T_world_body: npt.ArrayLike) -> float:
    """The heading of the body's x axis in world NED, degrees."""
    R = np.asarray(T_world_body, dtype=np.float64)
    return math.degrees(math.atan2(R[1, 0], R[0, 0]))


def fit_correction(
    times_s: Sequence[float], yaws_deg: Sequence[float], turns_deg: Sequence[float | None]
) -> tuple[float, float, int]:
    """The shift ``d`` (s) that best explains the picture's turns by the poses' yaw: the turn from frame k - 1 to k
    is the yaw at ``t_k - d`` minus the yaw at ``t_(k-1) - d`` (a nadir camera whose image top is the nose turns the
    picture against the vehicle: clockwise yaw seen from above, anticlockwise picture). Returns (d, RMS residual in
    degrees, pairs used)."""
    t = np.asarray(times_s, dtype=np.float64)
    yaw = np.degrees(np.unwrap(np.radians(np.asarray(yaws_deg, dtype=np.float64))))
    pairs = [(k, float(turn)) for k, turn in enumerate(turns_deg) if turn is not None and k > 0]
    if len(pairs) < MIN_PAIRS:
        raise LatencyError(f"{len(pairs)} frame pairs with a measured turn; at least {MIN_PAIRS} are needed")
    if float(yaw.max() - yaw.min()) < MIN_TURN_DEG:
        raise LatencyError(
            f"the vehicle turned {float(yaw.max() - yaw.min()):.1f} degrees in all: yaw it left and right by "
            f"{MIN_TURN_DEG:g} or more while recording"
        )
    index = np.array([k for k, _ in pairs])
    measured = -np.array([turn for _, turn in pairs])  # the picture turns against the vehicle
    best: tuple[float, float] | None = None
    for d in np.arange(-SEARCH_S, SEARCH_S + 1e-9, 0.002):
        predicted = np.interp(t[index] - d, t, yaw) - np.interp(t[index - 1] - d, t, yaw)
        error = float(np.sqrt(np.mean((predicted - measured) ** 2)))
        if best is None or error < best[1]:
            best = (float(d), error)
    assert best is not None
    return best[0], best[1], len(pairs)


def estimate(flight_dir: Path) -> LatencyEstimate:
    """The camera latency the recorded flight shows (see the module docstring)."""
    flight_dir = flight_folder(flight_dir)
    try:
        log = FlightLog.read(flight_dir)
    except FlightLogError as exc:
        raise LatencyError(str(exc)) from None
    header = log.header
    configured_s = float(header.config["camera"]["latency_s"]) if header else 0.0
    paths = {int(r["seq"]): flight_dir / str(r["path"]) for r in log.of(RecordKind.FRAME)}
    results = sorted((r for r in log.of(RecordKind.FRAME_RESULT) if int(r["seq"]) in paths), key=lambda r: r["t_s"])
    if len(results) < MIN_PAIRS + 1:
        raise LatencyError(
            f"{len(results)} processed frames were saved; record with recorder.frame_every: 1 (every frame)"
        )
    times, yaws, turns = [], [], []
    previous: npt.NDArray[np.uint8] | None = None
    previous_seq = None
    for r in results:
        image = cv2.imread(str(paths[int(r["seq"])]), cv2.IMREAD_COLOR)
        if image is None:
            raise LatencyError(f"cannot read {paths[int(r['seq'])]}")
        frame = np.asarray(image, dtype=np.uint8)
        consecutive = previous is not None and previous_seq is not None and int(r["seq"]) == previous_seq + 1
        turns.append(image_turn_deg(previous, frame) if consecutive and previous is not None else None)
        times.append(float(r["t_s"]))
        yaws.append(yaw_deg(r["T_world_body"]))
        previous, previous_seq = frame, int(r["seq"])
    correction_s, residual_deg, pairs = fit_correction(times, yaws, turns)
    return LatencyEstimate(configured_s, correction_s, residual_deg, pairs)


def main(argv: Sequence[str] | None = None) -> int:
    """Estimate and print the latency (see the module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else None)
    parser.add_argument("flight", type=Path, help="flight folder (flight.jsonl and frames/, every frame saved)")
    args = parser.parse_args(argv)
    try:
        found = estimate(args.flight)
    except LatencyError as exc:
        sys.stderr.write(f"measure_latency: {exc}\n")
        return 1
    sys.stdout.write(
        f"flown with camera.latency_s {found.configured_s:.3f} s; the frames show {found.correction_s:+.3f} s more "
        f"({found.pairs} frame pairs, residual {found.residual_deg:.2f} deg RMS)\n"
        f"camera:\n  latency_s: {max(0.0, found.latency_s):.3f}\n"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
