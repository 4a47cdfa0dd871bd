"""``slz replay``: re-run the pipeline and the landing logic on a recorded flight and check that they decide the same.

A replayable log is one recorded with every processed frame saved losslessly (``recorder.frame_every: 1``,
``frame_format: png``). The replay takes the config from the log's header, feeds each frame with the pose it was paired
with to a fresh pipeline, and each decision's recorded stimulus (:mod:`companion.guidance.stimulus`: the vehicle state,
and the frame's result, the silence, the mode...) to a fresh state machine's one entry point, in the logged order. Every
recomputed track list, target and decision is compared with the logged one after the same JSON encoding: a replay on the
machine that flew reproduces the flight exactly, so any difference is a change of behaviour (a regression, or a
different model). Optionally it writes the annotated camera video.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from companion.app.landing_loop import landing_guidance
from companion.app.mission import MissionConfig, with_fallback_sites, with_fence_ne_m
from companion.errors import SlzError
from companion.flightlog.flight_log import FlightHeader, FlightLog, FlightLogError, RecordKind
from companion.flightlog.recorder import plain
from companion.geometry import GeometryError, Pose
from companion.guidance.landing import Decision, LandingGuidance, LandingPhase
from companion.guidance.stimulus import Denied, stimulus_of_record
from companion.guidance.vehicle_state import VehicleState
from companion.guidance.vocabulary import DecisionSource
from companion.perception.errors import PerceptionError
from companion.perception.pipeline import FrameResult, SlzPipeline
from companion.perception.visualize import draw_camera_overlay

logger = logging.getLogger(__name__)

MAX_LISTED = 20


class ReplayError(SlzError):
    """The log cannot be replayed (which file, what is missing)."""


@dataclass
class ReplayReport:
    """What a replay found: counts and the first differences (``MAX_LISTED`` at most)."""

    frames: int = 0
    decisions: int = 0
    frame_mismatches: int = 0
    decision_mismatches: int = 0
    differences: list[str] = field(default_factory=list)

    @property
    def identical(self) -> bool:
        """Every frame result and decision matched."""
        return self.frame_mismatches == 0 and self.decision_mismatches == 0

    def note(self, what: str) -> None:
        """Keep a difference (the first ``MAX_LISTED``)."""
        if len(self.differences) < MAX_LISTED:
            self.differences.append(what)


def _json(value: Any) -> Any:
    """``value`` as the recorder wrote it (so floats compare exactly after the round trip)."""
    return json.loads(json.dumps(plain(value), separators=(",", ":")))


class VideoWriter:
    """The annotated camera view (occupancy, zones, target, phase) as an MP4 file."""

    def __init__(self, path: Path, rate_hz: float) -> None:
        self.path = path
        self.rate_hz = rate_hz
        self._writer: cv2.VideoWriter | None = None

    def add(self, image_bgr: np.ndarray, caption: str) -> None:
        """Append one frame with a caption along its top edge."""
        if self._writer is None:
            h, w = image_bgr.shape[:2]
            self.path.parent.mkdir(parents=True, exist_ok=True)
            fourcc = cv2.VideoWriter_fourcc(*"mp4v")  # type: ignore[attr-defined]
            self._writer = cv2.VideoWriter(str(self.path), fourcc, self.rate_hz, (w, h))
            if not self._writer.isOpened():
                raise ReplayError(f"cannot write video {self.path}")
        out = image_bgr.copy()
        cv2.rectangle(out, (0, 0), (out.shape[1], 22), (0, 0, 0), -1)
        cv2.putText(out, caption, (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
        self._writer.write(out)

    def close(self) -> None:
        """Finish the file."""
        if self._writer is not None:
            self._writer.release()
            self._writer = None


def config_from_header(raw: object) -> MissionConfig:
    """The mission config a flight was flown with, from its log header (a full dump of the config).

    A log written before frames were shrunk at low altitude has no ``perception.model.min_gsd_m_per_px``: its flight
    ran the model on whole frames, so the replay does too (0, off), instead of taking today's default.
    """
    fence = raw.get("geofence") if isinstance(raw, dict) else None
    if isinstance(raw, dict) and isinstance(fence, dict) and fence.get("polygon_latlon_deg") is not None:
        # A fence given in latitude and longitude: the header dumps the unused polygon_ne_m beside it (its default);
        # the flight's projection of it is in the log's fence record.
        raw = {**raw, "geofence": {k: v for k, v in fence.items() if k != "polygon_ne_m"}}
    config = MissionConfig.model_validate(raw)
    perception = raw.get("perception") if isinstance(raw, dict) else None
    model = perception.get("model") if isinstance(perception, dict) else None
    if isinstance(model, dict) and "min_gsd_m_per_px" not in model:
        unshrunk = config.perception.model.model_copy(update={"min_gsd_m_per_px": 0.0})
        config = config.model_copy(update={"perception": config.perception.model_copy(update={"model": unshrunk})})
    return config


def flight_config(flight: FlightLog, header: FlightHeader) -> MissionConfig:
    """The config the flight ran with: its header's (:func:`config_from_header`), with a fence given in latitude and
    longitude as the flight projected it (its ``fence`` record) and the fallback sites it used, the autopilot's rally
    points among them (its ``fallback_sites`` record)."""
    config = config_from_header(header.config)
    fence = flight.first(RecordKind.FENCE)
    if fence is not None:
        config = with_fence_ne_m(config, [(float(n), float(e)) for n, e in fence["polygon_ne_m"]])
    sites = flight.first(RecordKind.FALLBACK_SITES)
    if sites is not None:
        config = with_fallback_sites(config, list(sites["sites"]))
    return config


def replay(log_dir: Path, video_path: Path | None = None, video_rate_hz: float = 10.0) -> ReplayReport:
    """Replay the flight in ``log_dir`` (its ``flight.jsonl`` and ``frames/``); see the module docstring.

    Raises
    ------
    ReplayError
        No header, or a processed frame that was not saved losslessly.
    """
    try:
        flight = FlightLog.read(log_dir)
    except FlightLogError as exc:
        raise ReplayError(str(exc)) from None
    header = flight.header
    if header is None:
        raise ReplayError(f"{log_dir / 'flight.jsonl'}: no header record (config)")
    config = flight_config(flight, header)
    frame_paths = {int(r["seq"]): log_dir / str(r["path"]) for r in flight.of(RecordKind.FRAME)}
    pipeline = SlzPipeline.from_config(config.perception, fence_ne_m=config.geofence.polygon_ne_m)

    def new_guidance() -> LandingGuidance:
        return landing_guidance(config, pipeline.policy)

    guidance = new_guidance()
    report = ReplayReport()
    results: dict[int, FrameResult] = {}
    video = VideoWriter(video_path, video_rate_hz) if video_path is not None else None
    phase = "idle"
    try:
        for kind, record in flight.tagged(RecordKind.FRAME_RESULT, RecordKind.DECISION):
            if kind is RecordKind.FRAME_RESULT:
                seq = int(record["seq"])
                path = frame_paths.get(seq)
                if path is None or path.suffix != ".png":
                    raise ReplayError(
                        f"frame {seq} was not saved losslessly: record with recorder.frame_every 1 and "
                        "frame_format png to replay"
                    )
                raw = cv2.imread(str(path), cv2.IMREAD_COLOR)
                if raw is None:
                    raise ReplayError(f"cannot read {path}")
                image = np.asarray(raw, dtype=np.uint8)
                pose = Pose(np.asarray(record["T_world_body"], dtype=np.float64))
                try:
                    result = pipeline.process(image, pose, float(record["t_s"]))
                except (PerceptionError, GeometryError) as exc:
                    report.frame_mismatches += 1
                    report.note(f"frame {seq}: the pipeline failed in replay: {exc}")
                    continue
                results[seq] = result
                report.frames += 1
                for name in ("tracks", "target"):
                    if _json(getattr(result, name)) != record[name]:
                        report.frame_mismatches += 1
                        report.note(f"frame {seq} (t = {record['t_s']:.2f} s): {name} differ")
                        break
                if video is not None:
                    altitude = -float(pose.position_ned_m[2])
                    caption = f"t {record['t_s']:6.1f} s  alt {altitude:5.1f} m  {phase}"
                    shown = image if pipeline.lens is None else pipeline.lens.undistort(image)  # the pinhole view
                    video.add(draw_camera_overlay(shown, result, pipeline.projector), caption)
            else:
                if record.get("source") == DecisionSource.START and guidance.phase is not LandingPhase.IDLE:
                    guidance = new_guidance()  # a dry run that decides again after its decisions ended
                decision = _decide(guidance, record, results)
                report.decisions += 1
                phase = f"{record['decision']['phase']}: {record['decision']['reason']}"[:70]
                # Only what the log holds: a log from before decisions carried their event has no such fields.
                logged = record["decision"]
                if decision is None or {k: v for k, v in _json(decision).items() if k in logged} != logged:
                    report.decision_mismatches += 1
                    got = "nothing" if decision is None else f"{decision.phase.value} ({decision.reason})"
                    want = f"{record['decision']['phase']} ({record['decision']['reason']})"
                    report.note(f"decision at t = {record['t_s']:.2f} s ({record['source']}): {got}, logged {want}")
    finally:
        if video is not None:
            video.close()
    return report


def _decide(guidance: LandingGuidance, record: dict[str, Any], results: dict[int, FrameResult]) -> Decision | None:
    """The state machine's decision on the stimulus the record names (:func:`stimulus_of_record`: schema 3's
    ``stimulus``, or an older log's ``source`` and ``inputs``), as the flight handed it over."""
    state = VehicleState(**record["state"])
    try:
        stimulus = stimulus_of_record(record, state, results)
    except (KeyError, ValueError) as exc:
        raise ReplayError(f"decision at t = {record['t_s']} s names no stimulus to replay: {exc!r}") from None
    if stimulus is None:  # its frame has no result
        return None
    decided = guidance.on(stimulus)
    if isinstance(decided, Denied):
        raise ReplayError(f"the ground station's command at t = {state.t_s} s is denied now: {decided.reason}")
    return decided
