"""SLZ Lander companion: the program that runs next to the flight controller.

Packages show the architecture: :mod:`companion.perception` turns camera frames and poses into tracked
safe landing zones; later packages add the camera, vehicle link and guidance.
"""

__version__ = "0.1.0"
