"""STATUSTEXT's chunking rule (MAVLink 2), one definition for the companion and the SITL.

A text that fits 50 characters goes out whole with ``id`` 0. A longer one goes out in chunks of 50 sharing a
non-zero ``id``, with ``chunk_seq`` 0, 1..., the last chunk shorter than 50 (an empty one when the text fills its
chunks), so a reader knows where it ends. At most :data:`STATUSTEXT_MAX_CHARS` characters; non-ASCII becomes ``?``.
"""

from __future__ import annotations

from companion.vehicle.ground_messages import StatusText

STATUSTEXT_CHUNK_CHARS = 50
STATUSTEXT_MAX_CHARS = 200  # four chunks


def statustext_chunks(text: str, severity: int, text_id: int) -> list[StatusText]:
    """Each STATUSTEXT message carrying ``text``."""
    data = text.encode("ascii", "replace").decode("ascii")[:STATUSTEXT_MAX_CHARS]
    if len(data) <= STATUSTEXT_CHUNK_CHARS:
        return [StatusText(severity, data, 0, 0)]
    chunks = [data[i : i + STATUSTEXT_CHUNK_CHARS] for i in range(0, len(data), STATUSTEXT_CHUNK_CHARS)]
    if len(chunks[-1]) == STATUSTEXT_CHUNK_CHARS:
        chunks.append("")
    return [StatusText(severity, c, text_id, i) for i, c in enumerate(chunks)]
