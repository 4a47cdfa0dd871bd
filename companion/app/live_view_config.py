"""``live_view``: the flight served to Foxglove while it flies (:mod:`companion.app.live_view`)."""

from __future__ import annotations

from pydantic import Field

from companion.config import StrictModel


class LiveViewConfig(StrictModel):
    """``live_view``: the flight served to Foxglove while it flies (off by default)."""

    enabled: bool = Field(default=False, description="Serve the flight on Foxglove's WebSocket protocol.")
    host: str = Field(
        default="127.0.0.1",
        description="Address to listen on: 127.0.0.1 for this computer only, 0.0.0.0 for the vehicle's network "
        "(anyone on it can watch: the view sends, it takes no command).",
    )
    port: int = Field(default=8765, ge=1, le=65535, description="TCP port (Foxglove's default 8765).")
    camera_rate_hz: float = Field(default=2.0, ge=0.0, le=30.0, description="Camera frames sent per second (0: none).")
    jpeg_quality: int = Field(default=70, ge=10, le=95, description="JPEG quality of the frames sent.")
    backlog_messages: int = Field(
        default=256, ge=16, le=100_000, description="Messages queued per client; a slow client loses the oldest."
    )
