"""The flight recorder: every decision, state change, tracked zone, target, setpoint and failsafe, as JSON lines.

Each record is one line ``{"t_s": <vehicle clock>, "kind": ..., ...}``. The first record (``header``) holds the
config, the model's SHA-256 and the software version. Lines are written and flushed as they come; at every phase
change, failsafe and at close the file is also fsync'd, so a crash of the app loses at most the records since the
last flush and never a phase change. Frames may be saved beside the log, every ``frame_every``-th frame: JPEG to look
at, or PNG (lossless) for ``slz replay``.
"""

from __future__ import annotations

import json
import logging
import math
import os
from collections.abc import Callable
from dataclasses import asdict, is_dataclass
from enum import Enum
from pathlib import Path
from typing import IO, Any

import cv2
import numpy as np
import numpy.typing as npt

from companion.errors import SlzError

logger = logging.getLogger(__name__)

SYNC_KINDS = frozenset({"header", "phase", "failsafe", "supervision", "command", "end", "error"})


class RecorderError(SlzError):
    """The flight log could not be opened or written (which file, what happened)."""


def plain(value: Any) -> Any:
    """JSON-able form of dataclasses, enums, numpy values and paths; NaN and inf become None."""
    if is_dataclass(value) and not isinstance(value, type):
        return {k: plain(v) for k, v in asdict(value).items()}
    if isinstance(value, Enum):
        return value.value
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return plain(value.tolist())
    if isinstance(value, (np.floating, float)):
        f = float(value)
        return f if math.isfinite(f) else None
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, Path):
        return str(value)
    return value


class FlightRecorder:
    """Appends records to ``<directory>/flight.jsonl``.

    Parameters
    ----------
    directory : Path
        Created if missing. The log is ``flight.jsonl``; frames go to ``frames/``.
    frame_every : int
        Save every n-th frame given to :meth:`frame` (0: none).
    lossless : bool
        PNG instead of JPEG.
    """

    def __init__(self, directory: Path, frame_every: int = 0, lossless: bool = False) -> None:
        self.directory = directory
        self.path = directory / "flight.jsonl"
        self.frame_every = frame_every
        self.lossless = lossless
        self._frames_seen = 0
        self.records = 0
        self.listeners: list[Callable[[dict[str, Any]], None]] = []
        """Also given each record once it is written (the live view); they must not raise."""
        try:
            directory.mkdir(parents=True, exist_ok=True)
            self._file: IO[str] | None = self.path.open("a", encoding="utf-8")
        except OSError as exc:
            raise RecorderError(f"cannot open flight log {self.path}: {exc.strerror or exc}") from None

    def write(self, kind: str, t_s: float | None, **fields: Any) -> None:
        """Append one record (flushed; fsync'd for phase changes, failsafes, commands and the end)."""
        if self._file is None:
            raise RecorderError(f"flight log {self.path} is closed")
        record = {"t_s": plain(t_s), "kind": kind, **{k: plain(v) for k, v in fields.items()}}
        try:
            self._file.write(json.dumps(record, separators=(",", ":")) + "\n")
            self._file.flush()
            if kind in SYNC_KINDS:
                os.fsync(self._file.fileno())
        except OSError as exc:
            raise RecorderError(f"cannot write flight log {self.path}: {exc.strerror or exc}") from None
        self.records += 1
        for listener in self.listeners:
            listener(record)

    def frame(self, seq: int, t_s: float, image_bgr: npt.NDArray[np.uint8]) -> Path | None:
        """Save a frame (JPEG, or PNG when lossless) if it is one of every ``frame_every``; returns its path."""
        self._frames_seen += 1
        if self.frame_every <= 0 or (self._frames_seen - 1) % self.frame_every:
            return None
        folder = self.directory / "frames"
        folder.mkdir(exist_ok=True)
        if self.lossless:
            path, params = folder / f"{seq:07d}.png", [cv2.IMWRITE_PNG_COMPRESSION, 1]
        else:
            path, params = folder / f"{seq:07d}.jpg", [cv2.IMWRITE_JPEG_QUALITY, 90]
        if not cv2.imwrite(str(path), image_bgr, params):
            logger.warning("could not write frame %s", path)
            return None
        self.write("frame", t_s, seq=seq, path=str(path.relative_to(self.directory)))
        return path

    def close(self) -> None:
        """Flush, fsync and close (idempotent)."""
        if self._file is None:
            return
        try:
            self._file.flush()
            os.fsync(self._file.fileno())
        finally:
            self._file.close()
            self._file = None


def open_append(path: Path) -> IO[str]:
    """Open a JSON-lines log to append to, first cutting off a torn last line (a kill mid-write) so that the next
    record starts on a line of its own; the torn record is lost, as it was already."""
    if path.is_file():
        with path.open("rb+") as f:
            data = f.read()
            if data and not data.endswith(b"\n"):
                keep = data.rfind(b"\n") + 1
                logger.warning("%s: torn last line (%d bytes) cut off before appending", path, len(data) - keep)
                f.truncate(keep)
    return path.open("a", encoding="utf-8")


def read_log(path: Path) -> list[dict[str, Any]]:
    """All complete records of a JSON-lines log; a torn last line (crash mid-write) is skipped and logged.

    Raises
    ------
    RecorderError
        The file is not UTF-8, or a line other than the last is not a JSON object (named by its line number).
    """
    records: list[dict[str, Any]] = []
    try:
        with path.open(encoding="utf-8") as f:
            lines = f.read().split("\n")
    except UnicodeDecodeError as exc:
        raise RecorderError(f"{path}: not UTF-8 text (byte {exc.start})") from None
    for number, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        try:
            record = json.loads(line)
        except (json.JSONDecodeError, RecursionError):
            if number >= len(lines) - 1:
                logger.warning("%s: last line %d is incomplete (the app stopped mid-write), skipped", path, number)
                continue
            raise RecorderError(f"{path}:{number}: not a JSON record") from None
        if not isinstance(record, dict):
            raise RecorderError(f"{path}:{number}: a {type(record).__name__}, not a JSON object")
        records.append(record)
    return records


def _size_bytes(folder: Path) -> int:
    return sum(p.stat().st_size for p in folder.rglob("*") if p.is_file())


def prune_flights(directory: Path, keep_flights: int = 0, max_total_mb: float = 0.0) -> list[Path]:
    """Rotate the flight logs in ``directory`` before a new flight: delete the oldest flight folders.

    A flight folder is a sub-folder holding a ``flight.jsonl``; anything else in ``directory`` is left alone. Age is
    the log's modification time (the newest record).

    Parameters
    ----------
    directory : Path
        ``recorder.directory``; a missing directory holds no flight.
    keep_flights : int
        Keep at most this many flights (0: no limit on the count).
    max_total_mb : float
        Delete the oldest until the flights take at most this many MiB (0: no limit on the size).

    Returns
    -------
    list of Path
        The deleted folders, oldest first.
    """
    import shutil

    if not directory.is_dir() or (keep_flights <= 0 and max_total_mb <= 0.0):
        return []
    flights = sorted(
        (p for p in directory.iterdir() if p.is_dir() and (p / "flight.jsonl").is_file()),
        key=lambda p: ((p / "flight.jsonl").stat().st_mtime, p.name),
    )
    sizes = {p: _size_bytes(p) for p in flights}
    total = sum(sizes.values())
    deleted: list[Path] = []
    for flight in flights:
        too_many = keep_flights > 0 and len(flights) - len(deleted) > keep_flights
        too_big = max_total_mb > 0.0 and total > max_total_mb * 1024 * 1024
        if not (too_many or too_big):
            break
        shutil.rmtree(flight)
        total -= sizes[flight]
        deleted.append(flight)
        logger.info("flight log rotation: deleted %s (%.1f MiB)", flight, sizes[flight] / 1024 / 1024)
    return deleted
