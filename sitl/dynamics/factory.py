"""The dynamics backend a SITL config names, made (the backends import :mod:`~sitl.dynamics.base`; only this module
knows them all, so the interface never imports its implementations)."""

from __future__ import annotations

from sitl.dynamics.base import Dynamics, DynamicsBackend, F64Array


def make_dynamics(
    backend: DynamicsBackend, rate_hz: float = 400.0, home_position_ned_m: F64Array | None = None
) -> Dynamics:
    """The named backend stepping at ``rate_hz``, resting on the ground at ``home_position_ned_m`` (the origin)."""
    if backend is DynamicsBackend.RIGID_BODY:
        from sitl.dynamics.rigid_body import RigidBodyQuadrotor

        return RigidBodyQuadrotor(home_position_ned_m=home_position_ned_m)
    from sitl.dynamics.jsbsim_f450 import JsbsimF450

    return JsbsimF450(home_position_ned_m=home_position_ned_m, rate_hz=rate_hz)
