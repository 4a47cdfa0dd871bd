"""SLZ Lander's software-in-the-loop harness: the emulated PX4-style autopilot on real MAVLink, the dynamics, the
seeded world and its camera, and the mission and campaign runners that fly the companion against them."""
