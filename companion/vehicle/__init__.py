"""The vehicle side of the companion: telemetry into a time-indexed pose buffer, and the link to the autopilot."""
