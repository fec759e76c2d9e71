"""Where a lab holds the calibration target: N seeded poses covering the working volume.

The poses follow Zhang's recommendations for plane-based calibration [1]_: the board must not
be parallel from view to view (parallel planes add no constraint on the intrinsics), and the
focal length is best determined by boards tilted by a sizeable angle (his Sec. 6.3: the error
falls as the tilt grows towards 45 deg, beyond which corners are hard to detect).  So every
pose tilts the board by 20-40 deg (uniform) about an axis in its plane whose direction steps
around the circle from pose to pose (stratified, with jitter), rolls it by up to 15 deg about
its normal, and puts it at a depth drawn uniformly over the working volume (assumption:
0.85-1.35 m, the depths of the paper's experiments, Fig. 9: 0.9-1.4 m, with the near end
where the board still fits the camera's view); its position across the view is drawn
uniformly among those where the whole printed board lies inside both the camera's and the
projector's image with a margin, as it must for the corners to be found and decoded.

References
----------
.. [1] Z. Zhang, "A flexible new technique for camera calibration", IEEE Transactions on
   Pattern Analysis and Machine Intelligence 22(11), 1330-1334, 2000.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from simbench import validate
from simbench.calibration.target import CalibrationTarget
from simbench.rig import Intrinsics, Rig, angles_xyz_deg
from simbench.seeds import RngLike

__all__ = ["Pose", "calibration_poses", "DEPTH_RANGE_M", "TILT_RANGE_DEG", "ROLL_DEG", "VIEW_MARGIN"]

DEPTH_RANGE_M = (0.85, 1.35)  # assumption, argued in the module docstring
TILT_RANGE_DEG = (20.0, 40.0)  # Zhang 2000, Sec. 6.3
ROLL_DEG = 15.0  # assumption: a board held by hand is never square to the image
VIEW_MARGIN = 0.03  # the board stays this fraction of the image size inside each border
_TRIES = 2000


@dataclass(frozen=True)
class Pose:
    """A target pose in the camera frame: ``center_m`` and ``rotation_deg`` as a scene object
    takes them (``R = Rz @ Ry @ Rx`` maps board axes to camera axes)."""

    center_m: tuple[float, float, float]
    rotation_deg: tuple[float, float, float]

    @property
    def rotation(self) -> np.ndarray:
        from simbench.rig import rotation_xyz_deg

        return rotation_xyz_deg(self.rotation_deg)

    @property
    def tilt_deg(self) -> float:
        """Angle between the board's normal and the camera's optical axis."""
        return math.degrees(math.acos(float(np.clip(self.rotation[2, 2], -1.0, 1.0))))


def _axis_angle(axis: np.ndarray, angle_rad: float) -> np.ndarray:
    """Rodrigues' rotation about a unit axis."""
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle_rad) * k + (1 - math.cos(angle_rad)) * (k @ k)


def _inside(points_m: np.ndarray, intr: Intrinsics) -> bool:
    """All points in front of a pinhole and inside its image with the margin."""
    z = points_m[:, 2]
    if np.any(z <= 0.05):
        return False
    u = intr.focal_px * points_m[:, 0] / z + intr.cx_px
    v = intr.focal_px * points_m[:, 1] / z + intr.cy_px
    mu, mv = VIEW_MARGIN * intr.width_px, VIEW_MARGIN * intr.height_px
    return bool(
        np.all((u >= mu - 0.5) & (u <= intr.width_px - 0.5 - mu) & (v >= mv - 0.5) & (v <= intr.height_px - 0.5 - mv))
    )


def calibration_poses(target: CalibrationTarget, rig: Rig, *, count: int, rng: RngLike) -> list[Pose]:
    """``count`` target poses (module docstring) for ``rig``, deterministic for a seed.

    Raises ``ValueError`` when a pose cannot be found (a target too large for the views).
    """
    count = validate.integer(count, "poses", lo=3, hi=200)
    rng = np.random.default_rng(rng)
    sx, sy = target.size_m
    outline = np.array([[-sx / 2, -sy / 2, 0], [sx / 2, -sy / 2, 0], [sx / 2, sy / 2, 0], [-sx / 2, sy / 2, 0]])
    r_p, t_p = rig.rotation, np.asarray(rig.position_m)
    poses = []
    for k in range(count):
        for _ in range(_TRIES):
            azimuth = 2.0 * math.pi * (k + rng.uniform(-0.5, 0.5)) / count
            tilt = math.radians(rng.uniform(*TILT_RANGE_DEG))
            roll = math.radians(rng.uniform(-ROLL_DEG, ROLL_DEG))
            z = rng.uniform(*DEPTH_RANGE_M)
            # the visible half-extent of the camera's view at z bounds the centre's position
            x = rng.uniform(-0.5, 0.5) * z * rig.camera.width_px / rig.camera.focal_px
            y = rng.uniform(-0.5, 0.5) * z * rig.camera.height_px / rig.camera.focal_px
            axis = np.array([math.cos(azimuth), math.sin(azimuth), 0.0])
            rot = _axis_angle(axis, tilt) @ _axis_angle(np.array([0.0, 0.0, 1.0]), roll)
            corners = outline @ rot.T + np.array([x, y, z])
            in_projector = (corners - t_p) @ r_p  # X_proj = R^T (X_cam - t)
            if _inside(corners, rig.camera) and _inside(in_projector, rig.projector):
                poses.append(Pose(center_m=(float(x), float(y), float(z)), rotation_deg=angles_xyz_deg(rot)))
                break
        else:
            raise ValueError(
                f"no pose {k} found in {_TRIES} draws: the {target.size_m[0]:.3f} x {target.size_m[1]:.3f} m target "
                f"does not fit the camera's and projector's views at {DEPTH_RANGE_M[0]}-{DEPTH_RANGE_M[1]} m"
            )
    return poses
