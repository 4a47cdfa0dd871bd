"""The harness that starts and drives SITL vehicles: SITL and companion processes (started, checked ready, stopped),
free instances leased from one allocator, the lockstep client, one mission flown end to end and scored, warm
workers that keep both processes between missions, hostile input, and the demo. Campaigns (:mod:`sitl.campaign`)
build on it; the simulated vehicle (``sitl.vehicle.process`` and its parts) never imports it."""
