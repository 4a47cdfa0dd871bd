"""A PX4-style autopilot on the MAVLink wire: modes, commands, parameters, telemetry, failsafes, control."""
