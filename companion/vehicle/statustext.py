"""STATUSTEXT's chunking rule (MAVLink 2), one definition for the companion and the SITL.

A text that fits 50 characters goes out whole with ``id`` 0. A longer one goes out in chunks of 50 sharing a
non-zero ``id``, with ``chunk_seq`` 0, 1..., the last chunk shorter than 50 (an empty one when the text fills its
chunks), so a reader knows where it ends. At most :data:`STATUSTEXT_MAX_CHARS` characters; non-ASCII becomes ``?``.
"""

from __future__ import annotations

from typing import Any

STATUSTEXT_CHUNK_CHARS = 50
STATUSTEXT_MAX_CHARS = 200  # four chunks


def statustext_chunks(text: str, severity: int, text_id: int) -> list[dict[str, Any]]:
    """The STATUSTEXT fields (``severity``, ``text``, ``id``, ``chunk_seq``) of each message carrying ``text``."""
    data = text.encode("ascii", "replace").decode("ascii")[:STATUSTEXT_MAX_CHARS]
    if len(data) <= STATUSTEXT_CHUNK_CHARS:
        return [{"severity": severity, "text": data, "id": 0, "chunk_seq": 0}]
    chunks = [data[i : i + STATUSTEXT_CHUNK_CHARS] for i in range(0, len(data), STATUSTEXT_CHUNK_CHARS)]
    if len(chunks[-1]) == STATUSTEXT_CHUNK_CHARS:
        chunks.append("")
    return [{"severity": severity, "text": c, "id": text_id, "chunk_seq": i} for i, c in enumerate(chunks)]
