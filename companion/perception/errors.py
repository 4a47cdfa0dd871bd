"""The perception subsystem's exception."""

from __future__ import annotations

from companion.errors import SlzError


class PerceptionError(SlzError):
    """Something in the SLZ perception pipeline failed.

    Parameters
    ----------
    where : str
        The stage or call that failed, e.g. ``"density.load"`` or ``"tracking.update"``.
    what : str
        A human-readable description of what went wrong, with the offending values.
    """

    def __init__(self, where: str, what: str) -> None:
        super().__init__(f"{where}: {what}")
        self.where = where
        self.what = what
