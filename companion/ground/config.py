"""The ground station's command channel in the mission config (``ground_station:``)."""

from __future__ import annotations

from pydantic import Field, field_validator

from companion.config import StrictModel, host_port
from companion.ground.mavlink_frames import key_from_hex


class GroundStationConfig(StrictModel):
    """Landing commands from a ground station (:mod:`companion.ground.command_channel`); off unless a URL is given."""

    command_url: str | None = Field(
        default=None,
        description="udpin://HOST:PORT the companion's command channel listens on (MAVLink 2, component 191, "
        "MAV_COMP_ID_ONBOARD_COMPUTER): a ground station, MAVProxy or mavlink-router sends COMMAND_LONG there. "
        "None: no command channel.",
    )
    signing_key_hex: str | None = Field(
        default=None,
        description="MAVLink 2 signing key, 64 hex digits (MAVProxy's `signing setup PASSPHRASE` uses SHA-256 of the "
        "passphrase). Set: every command must be signed with it (unsigned, badly signed or replayed ones are "
        "refused) and the replies are signed. None: commands are taken unsigned.",
    )
    stale_signature_s: float = Field(
        default=60.0,
        gt=0.0,
        le=3600.0,
        description="A signed stream seen for the first time is refused when its timestamp is older than this "
        "(MAVLink's replay rule: one minute).",
    )

    @field_validator("command_url")
    @classmethod
    def _udpin(cls, url: str | None) -> str | None:
        if url is not None:
            host_port(url, "udpin")
        return url

    @field_validator("signing_key_hex")
    @classmethod
    def _key(cls, text: str | None) -> str | None:
        if text is not None:
            key_from_hex(text)  # ValueError names what is wrong
        return text

    @property
    def signing_key(self) -> bytes | None:
        """The signing key's bytes (None: unsigned)."""
        return None if self.signing_key_hex is None else key_from_hex(self.signing_key_hex)
