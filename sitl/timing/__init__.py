"""The SITL's time: the one simulated clock and the lockstep gate that paces it by the companion's acknowledgements.
Below the autopilot and the vehicle process, which both read them."""
