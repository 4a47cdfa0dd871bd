"""The SITL vehicle's process: :class:`~sitl.vehicle.process.SitlVehicle` runs the dynamics, the emulated autopilot
and the camera under one simulated clock, on MAVLink and the control channel; its parts (the clock, the lockstep gate,
the frame server and control channel, the truth and trajectory logs, the fault schedule, the run's end) are modules
here, each without the process's I/O loop."""
