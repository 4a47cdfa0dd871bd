"""The lab's test kit: what the tests and the benchmarks both use to drive a SITL from outside.

- :mod:`sitl.testing.helpers`: waiting on a condition with a deadline, free ports, a pymavlink ground station and
  peer, a lockstep client, the shipped mission config on an instance's ports.
- :mod:`sitl.testing.mavsdk_client`: a MAVSDK client process (:mod:`sitl.testing.mavsdk_flight`) and its events.
- :mod:`sitl.testing.hostile_configs`: malformed mission configs and a dry run that must refuse each one clearly.

``tests/`` and ``bench/`` import these; nothing in ``sitl`` or ``companion`` does, and the drone never has them.
Paths to ``mission_configs/`` are the source tree's: the kit runs from a checkout.
"""
