"""Vehicle dynamics behind one small interface (:class:`~sitl.dynamics.base.Dynamics`).

Backends: :mod:`~sitl.dynamics.rigid_body` (numpy 6-DOF quadrotor, the default) and
:mod:`~sitl.dynamics.jsbsim_f450` (JSBSim's F450 model; optional, needs the ``jsbsim`` package).
"""

from sitl.dynamics.base import Airframe, Dynamics, DynamicsError, VehicleState
from sitl.dynamics.factory import make_dynamics

__all__ = ["Airframe", "Dynamics", "DynamicsError", "VehicleState", "make_dynamics"]
