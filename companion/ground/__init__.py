"""The ground station's link to the companion: MAVLink 2 frames (signed) and the command channel a pilot's ground
station sends landing commands to."""
