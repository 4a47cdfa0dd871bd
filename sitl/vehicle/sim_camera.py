"""The vehicle's camera in the SITL: the seeded world rendered at the vehicle's true pose, weather applied,
streamed with its sequence number and capture time (simulated clock)."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from companion.cache import KeyedCache
from companion.camera.frames import encode_frame
from companion.geometry import PinholeCamera, Pose, T_body_camera_from_mount
from companion.perception.lens import LensDistortion
from sitl.config import SitlConfig
from sitl.dynamics.base import VehicleState
from sitl.render.camera import Light, WorldRenderer
from sitl.render.sensor import image_velocity_px_s, optics, readout
from sitl.vehicle.frame_server import FrameServer
from sitl.world.crowd import Crowd
from sitl.world.park import Park
from sitl.world.scenario import WeatherKind
from sitl.world.weather import WeatherSchedule, apply_weather

PARKS: KeyedCache[Park] = KeyedCache("parks", capacity=2)
"""The parks of the last scenes this process flew (see the scene caches in :mod:`sitl.render.camera`)."""


def _park(config: SitlConfig) -> Park:
    scenario = config.scenario
    park = Park(
        config.seed,
        roi_side_m=scenario.roi_side_m,
        ground=scenario.ground,
        ground_site=scenario.ground_site,
        clear_ne_m=scenario.clear_ne_m,
    )
    park.ground_bgr.setflags(write=False)  # shared by the missions of one scene: nobody may paint on it
    return park


def scene_light(config: SitlConfig) -> Light:
    """The sun and ambient light of a mission's scene: drawn from its seed within the scenario's ranges."""
    scenario = config.scenario
    rng = np.random.default_rng([config.seed, 8])
    return Light.from_angles(
        float(rng.uniform(scenario.sun_elevation_deg.low, scenario.sun_elevation_deg.high)),
        float(rng.uniform(scenario.sun_azimuth_deg.low, scenario.sun_azimuth_deg.high)),
        float(rng.uniform(scenario.ambient.low, scenario.ambient.high)),
    )


class SimCamera:
    """World + renderer + frame server for one SITL vehicle (see the module docstring)."""

    def __init__(self, config: SitlConfig) -> None:
        cam = config.camera
        scenario = config.scenario
        self.light = scene_light(config)
        park_key = (config.seed, scenario.roi_side_m, scenario.ground, scenario.ground_site, str(scenario.clear_ne_m))
        self.park = PARKS.get(park_key, lambda: _park(config))
        self.crowd = Crowd(scenario, config.seed)
        self.weather = WeatherSchedule(scenario, config.seed)
        self.intrinsics = PinholeCamera.from_hfov(cam.width_px, cam.height_px, cam.hfov_deg)
        self.T_body_camera = T_body_camera_from_mount(tilt_deg=cam.tilt_deg)
        self.renderer = WorldRenderer(self.park, self.crowd, self.intrinsics, self.T_body_camera, self.light)
        self.lens = LensDistortion.from_coefficients(self.intrinsics, cam.distortion)
        self.sensor = cam.sensor
        self.server = FrameServer(config.bind_address, config.frame_port)
        self.period_s = 1.0 / cam.rate_hz
        self.seed = config.seed
        self.seq = 0

    def fileno(self) -> int:
        """For select()."""
        return self.server.fileno()

    def capture(self, t_s: float, state: VehicleState) -> bool:
        """Render and send the frame at ``t_s``; False if it was dropped (no client, or the last one unsent).

        A frame for nobody (no client connected) is counted as dropped without being drawn: after a campaign's
        companion has let go, the SITL runs on at full speed and would draw every frame it owes to no one. Every
        frame's content depends on its instant and sequence number only, so skipping one changes no other."""
        if not self.server.connected:
            self.server.poll()  # a client connecting now gets this frame (a connected one is polled by the send)
        if not self.server.connected:
            self.server.stats.dropped += 1
            self.seq += 1
            return False
        sent = self.server.send(encode_frame(self.seq, t_s, self.draw(t_s, state)))
        self.seq += 1
        return sent

    def draw(self, t_s: float, state: VehicleState) -> npt.NDArray[np.uint8]:
        """The frame at ``t_s`` from ``state``, shape (H, W, 3) BGR uint8: rendered, weathered, then through the
        lens when one is configured."""
        n, e, d = (float(v) for v in state.position_ned_m)
        pose = Pose.from_ned_quaternion(n, e, d, state.quaternion_wxyz)
        weather = self.weather.state_at(t_s)
        view = self.renderer.render(pose, t_s, with_mask=False, with_depth=weather.kind is WeatherKind.FOG)
        image = apply_weather(view.image_bgr, weather, self.seed * 1_000_003 + self.seq, view.depth_m)
        sensor = self.sensor
        if sensor.enabled:
            image = optics(image, sensor, self.seed, self._image_velocity_px_s(pose, state), self.intrinsics.fx_px)
        if self.lens is not None:
            image = self.lens.distort(image)
        return readout(image, sensor, self.seed, self.seq, t_s) if sensor.enabled else image

    def _image_velocity_px_s(self, pose: Pose, state: VehicleState) -> tuple[float, float]:
        """How fast the picture moves during the exposure (px/s), from the vehicle's true velocity and rates."""
        T_world_camera = pose.T_world_body @ self.T_body_camera
        R_world_camera = T_world_camera[:3, :3]
        altitude_m = max(-float(T_world_camera[2, 3]), 0.5)
        depth_m = altitude_m / max(float(R_world_camera[2, 2]), 0.1)  # along the optical axis to the ground
        return image_velocity_px_s(
            state.velocity_ned_mps,
            state.rates_frd_radps,
            R_world_camera.T,
            self.T_body_camera[:3, :3].T,
            self.intrinsics.fx_px,
            depth_m,
        )

    def skip(self) -> None:
        """A frame the lockstep client does not want: not drawn, counted, its sequence number passed (the frames
        after it are the frames they would have been)."""
        self.server.stats.not_wanted += 1
        self.seq += 1

    def people_at(self, t_s: float) -> dict[str, Any]:
        """Ground truth at simulated time ``t_s`` (the crowd walks there first, as a frame would)."""
        self.crowd.advance_to(t_s)
        return self.people()

    def people(self) -> dict[str, Any]:
        """Ground truth: every person's head-plane position, body radius, whether they walk and whether they would
        step away from a warning, now, and how many reactions to warnings there were so far."""
        return {
            "t_s": self.crowd.t_s,
            "positions_ne_m": self.crowd.positions_ne_m.tolist(),
            "radii_m": self.crowd.radii_m.tolist(),
            "moving": self.crowd.moving.tolist(),
            "reactive": self.crowd.reaction.reactive.tolist(),
            "reactions": self.crowd.reaction.reactions,
        }

    def close(self) -> None:
        """Stop serving frames."""
        self.server.close()
        self.renderer.close()
