"""Moving scenes: objects in rigid motion at constant velocity, the scene posed at an instant,
and the time slices that integrate a camera exposure.

A scene object may move (scene keys, validated in :mod:`simbench.sim.scene`):

- ``velocity_m_s = [vx, vy, vz]``: a translation velocity in the camera frame (OpenCV axes:
  x right, y down, z forward), m/s;
- ``angular_velocity_deg_s = w`` with ``rotation_axis = [ax, ay, az]`` (default: y, vertical)
  through ``rotation_centre_m = [x, y, z]`` (default: the object's own position): a rotation
  at ``w`` deg/s about that axis (right-handed).

A point ``x`` of the object at time 0 (the instant the scene file describes) is at
``c + R(w t) (x - c) + v t`` at time ``t``.  :func:`simbench.sim.timeline.scene_at` poses a whole
scene at an instant (a static scene of static objects); its render is the radiance then.

Motion blur is physics: the camera integrates radiance over its exposure window.  Mitsuba 3.9.1
(the pinned release; the newest on PyPI) has no animated transforms in its Python module, so the
exposure is integrated by rendering ``n`` time slices at the centres of ``n`` equal sub-windows
(the midpoint rule: a box filter in time) and averaging them, the sample budget split across the
slices (:func:`simbench.sim.timeline.slice_spp`, independent sampling), so a moving capture costs about
what a static one costs.  ``n`` is
chosen so that no point of a moving object travels more than :data:`MAX_SLICE_MOTION_PX` camera
pixels within one slice (:func:`simbench.sim.timeline.slice_count`); tests/test_motion.py checks that the blur is then
converged (twice the slices change the image by no more than render noise) and that a moving
edge's profile is the box-filtered step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from simbench import validate

__all__ = [
    "Motion",
    "MAX_SPEED_M_S",
    "MAX_ANGULAR_DEG_S",
    "MAX_SLICE_MOTION_PX",
    "MAX_SLICES",
    "slice_times",
]

# Validation bounds (assumptions): 50 m/s is a car at 180 km/h, far beyond what a structured-light
# sensor at 1 m could image; 36000 deg/s is 100 turns a second.
MAX_SPEED_M_S = 50.0
MAX_ANGULAR_DEG_S = 36000.0
# a point may move at most this far across the image within one time slice; 0.25 px keeps the
# slices' staircase well under the pixel's own box filter (converged: tests/test_motion.py)
MAX_SLICE_MOTION_PX = 0.25
# a capture never takes more slices than this (each a render of at least one sample per pixel)
MAX_SLICES = 256


@dataclass(frozen=True)
class Motion:
    """Rigid motion at constant velocity (module docstring).  ``centre_m`` None = the object's
    own position (its kind's position key)."""

    velocity_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    angular_velocity_deg_s: float = 0.0
    axis: tuple[float, float, float] = (0.0, 1.0, 0.0)
    centre_m: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        v = validate.numbers(self.velocity_m_s, "velocity_m_s", 3, lo=-MAX_SPEED_M_S, hi=MAX_SPEED_M_S)
        w = validate.number(
            self.angular_velocity_deg_s, "angular_velocity_deg_s", lo=-MAX_ANGULAR_DEG_S, hi=MAX_ANGULAR_DEG_S
        )
        axis = validate.numbers(self.axis, "rotation_axis", 3, lo=-1e3, hi=1e3)
        norm = math.sqrt(sum(a * a for a in axis))
        if norm < 1e-9:
            raise ValueError(f"rotation_axis must not be zero, got {list(axis)}")
        object.__setattr__(self, "velocity_m_s", v)
        object.__setattr__(self, "angular_velocity_deg_s", w)
        object.__setattr__(self, "axis", tuple(a / norm for a in axis))
        if self.centre_m is not None:
            object.__setattr__(
                self, "centre_m", validate.numbers(self.centre_m, "rotation_centre_m", 3, lo=-100.0, hi=100.0)
            )

    @property
    def is_static(self) -> bool:
        return not any(self.velocity_m_s) and self.angular_velocity_deg_s == 0.0

    def rotation(self, t_s: float) -> np.ndarray:
        """The rotation the object has turned through by time ``t_s`` (Rodrigues' formula)."""
        a = np.radians(self.angular_velocity_deg_s * t_s)
        k = np.asarray(self.axis, np.float64)
        kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
        return np.eye(3) + math.sin(a) * kx + (1.0 - math.cos(a)) * (kx @ kx)

    def apply(self, points_m: np.ndarray, t_s: float, *, centre_m: np.ndarray) -> np.ndarray:
        """Where the points ``points_m`` (N, 3) of time 0 are at time ``t_s``."""
        c = np.asarray(self.centre_m if self.centre_m is not None else centre_m, np.float64)
        p = np.asarray(points_m, np.float64)
        return c + (p - c) @ self.rotation(t_s).T + np.asarray(self.velocity_m_s) * t_s

    def to_dict(self) -> dict:
        out = {"velocity_m_s": list(self.velocity_m_s), "angular_velocity_deg_s": self.angular_velocity_deg_s}
        if self.angular_velocity_deg_s:
            out["rotation_axis"] = list(self.axis)
            if self.centre_m is not None:
                out["rotation_centre_m"] = list(self.centre_m)
        return out


def slice_times(window_s: tuple[float, float], n: int) -> np.ndarray:
    """The centres of ``n`` equal sub-windows of ``window_s`` (the midpoint rule)."""
    t0, t1 = window_s
    return t0 + (np.arange(n) + 0.5) * (t1 - t0) / n
