"""The simulated object stage device (:class:`hardware.stage.ObjectStage` on the sim world)."""

from __future__ import annotations

import numpy as np

from ..errors import SafetyError
from ..stage import ObjectStage, StageState
from .devices import _SimDevice


class SimStage(_SimDevice, ObjectStage):
    """The simulated object stage (``hardware.stage``): moves the surface under the fingers."""

    kind = "stage"
    model = "SimStage (XY + rotary)"

    def __init__(self, world, clock):
        super().__init__(world, clock, world.cfg.stage.rate_hz)
        self.scfg = world.cfg.stage
        world.add_sink(1.0 / self.scfg.rate_hz, self._sample)

    @property
    def axis_m(self) -> np.ndarray:
        return self.world.stage.axis.copy()

    def _sample(self, t: float) -> None:
        if self._producing():
            st = self.world.stage
            xy, theta = st.commanded(t)
            self._push(StageState(self.host_time(t), self.device_time(t), np.r_[xy, theta], st.velocity(t),
                                  st.moving(t)))

    def _check(self, what: str, value: float, limit: float, key: str, unit: str) -> None:
        if not abs(value) <= limit:
            raise SafetyError(f"stage: {what} {value:.4g} {unit} beyond hardware.stage.{key}={limit}")

    def translate(self, dx: float, dy: float, speed: float, asynchronous: bool = False) -> None:
        self._require_connected()
        c = self.scfg
        self._check("speed", speed, c.max_speed_m_s, "max_speed_m_s", "m/s")
        if not speed > 0:
            raise SafetyError(f"stage: speed {speed} m/s must be > 0")
        with self.world.lock:
            end = self.world.stage.commanded(self.world.time)[0] + (dx, dy)
            for axis, v in zip("xy", end):
                self._check(f"{axis} position", v, c.max_travel_m, "max_travel_m", "m from home")
            t_end = self.world.stage_command("translate", (dx, dy), speed)
        if not asynchronous:
            self._wait(t_end)

    def rotate(self, angle: float, speed: float, asynchronous: bool = False) -> None:
        self._require_connected()
        c = self.scfg
        self._check("angular speed", speed, c.max_angular_speed_rad_s, "max_angular_speed_rad_s", "rad/s")
        if not speed > 0:
            raise SafetyError(f"stage: angular speed {speed} rad/s must be > 0")
        with self.world.lock:
            end = self.world.stage.commanded(self.world.time)[1] + angle
            self._check("angle", end, c.max_rotation_rad, "max_rotation_rad", "rad from home")
            t_end = self.world.stage_command("rotate", angle, speed)
        if not asynchronous:
            self._wait(t_end)

    def _wait(self, t_end: float) -> None:
        self.clock.sleep_until(t_end, stop_when=lambda: self.kind in self.world.lost)
        self._require_connected()

    def stop(self) -> None:
        self._require_connected()
        with self.world.lock:
            self.world.stage.stop(self.world.time)

    def is_moving(self) -> bool:
        self._require_connected()
        return self.world.stage.moving(self.world.time)

    def pose(self) -> np.ndarray:
        self._require_connected()
        xy, theta = self.world.stage.commanded(self.world.time)
        return np.r_[xy, theta]

    def read_states(self) -> list[StageState]:
        return self._drain()
