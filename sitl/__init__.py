"""SLZ Lander's software-in-the-loop harness (simulation side: scenes, rendering, later the autopilot)."""
