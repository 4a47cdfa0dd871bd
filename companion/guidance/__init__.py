"""Guidance: where the vehicle may go (geofence) and what it does next (the landing state machine)."""
