"""The dynamics interface, the vehicle state it exposes, and the airframe description the mixer needs.

Frames: world NED (m), body FRD. Quaternions are ``[w, x, y, z]`` and rotate body vectors into the world frame.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
import numpy.typing as npt

from companion.errors import SlzError

F64Array = npt.NDArray[np.float64]


class DynamicsError(SlzError):
    """A dynamics backend failed or cannot be created.

    Parameters
    ----------
    backend : str
        Which backend (``"rigid_body"``, ``"jsbsim_f450"``).
    what : str
        What went wrong.
    """

    def __init__(self, backend: str, what: str) -> None:
        super().__init__(f"{backend}: {what}")
        self.backend = backend
        self.what = what


class DynamicsBackend(str, enum.Enum):
    """Available dynamics models."""

    RIGID_BODY = "rigid_body"
    JSBSIM_F450 = "jsbsim_f450"


@dataclass(frozen=True)
class Airframe:
    """What the controller's mixer knows about the vehicle (PX4's CA_ROTOR* and THR_MDL_FAC parameters).

    Attributes
    ----------
    rotor_positions_frd_m : tuple of (x, y) pairs
        Rotor positions in the body FRD frame, metres, in motor-output order.
    rotor_yaw_sign : tuple of float
        +1 where the rotor's drag torque yaws the body clockwise seen from above (positive yaw, NED), else -1.
    thrust_model_factor : float
        Normalized thrust of a rotor is ``(1 - f) * u + f * u**2`` for a command ``u`` in [0, 1] (PX4 THR_MDL_FAC).
    hover_thrust : float
        Collective normalized thrust that holds the vehicle in hover (PX4 MPC_THR_HOVER), in [0, 1].
    mass_kg : float
        Mass (for reference; the controller works in normalized thrust).
    """

    rotor_positions_frd_m: tuple[tuple[float, float], ...]
    rotor_yaw_sign: tuple[float, ...]
    thrust_model_factor: float
    hover_thrust: float
    mass_kg: float


@dataclass
class VehicleState:
    """The true state of the vehicle.

    Attributes
    ----------
    position_ned_m : ndarray, shape (3,)
        Centre of mass in world NED.
    velocity_ned_mps : ndarray, shape (3,)
        Velocity in world NED.
    quaternion_wxyz : ndarray, shape (4,)
        Attitude, body FRD to world NED.
    rates_frd_radps : ndarray, shape (3,)
        Angular rates in the body frame.
    acceleration_ned_mps2 : ndarray, shape (3,)
        Kinematic acceleration in world NED over the last step (gravity included: what moved the vehicle).
    on_ground : bool
        True while a landing leg touches the ground.
    """

    position_ned_m: F64Array = field(default_factory=lambda: np.zeros(3))
    velocity_ned_mps: F64Array = field(default_factory=lambda: np.zeros(3))
    quaternion_wxyz: F64Array = field(default_factory=lambda: np.array([1.0, 0.0, 0.0, 0.0]))
    rates_frd_radps: F64Array = field(default_factory=lambda: np.zeros(3))
    acceleration_ned_mps2: F64Array = field(default_factory=lambda: np.zeros(3))
    on_ground: bool = True


class Dynamics(Protocol):
    """A vehicle model: motor commands in, state out, advanced in fixed steps."""

    @property
    def airframe(self) -> Airframe:
        """The vehicle's geometry and thrust model, for the mixer."""
        ...

    @property
    def min_rate_hz(self) -> float:
        """The lowest step rate at which the model is stable (e.g. JSBSim's ground contact needs 300 Hz)."""
        ...

    def state(self) -> VehicleState:
        """The current true state (a copy)."""
        ...

    def set_motor_commands(self, commands: F64Array) -> None:
        """ESC commands, shape (4,), each in [0, 1] (clipped), in the airframe's motor order."""
        ...

    def set_wind(self, wind_ned_mps: F64Array) -> None:
        """Wind velocity in world NED, m/s."""
        ...

    def step(self, dt_s: float) -> None:
        """Advance the model by ``dt_s`` seconds."""
        ...
