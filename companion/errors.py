"""The root of the errors SLZ Lander raises on purpose."""

from __future__ import annotations


class SlzError(Exception):
    """Every error the project raises on purpose derives from this (one class per subsystem, each carrying what failed
    and where): ``except SlzError`` catches what the project names, a bad config, a lost link, a failed render, and
    lets a programming error through."""
