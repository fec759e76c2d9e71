"""Calibrating the rig as a lab does (issue: calibration in the loop): a printed target at
seeded poses, rendered through the sensor model, solved with OpenCV.

* :mod:`~simbench.calibration.target` - the printed checkerboard (TOML files);
* :mod:`~simbench.calibration.poses` - where the target is held;
* :mod:`~simbench.calibration.procedure` - render, detect, decode, solve;
* :mod:`~simbench.calibration.report` - the rig file, the Markdown report and its figure.
"""

from simbench.calibration.poses import Pose, calibration_poses
from simbench.calibration.procedure import (
    CalibrationResult,
    CalibrationView,
    calibrate_rig,
    check_calibration,
    rig_errors,
    true_rig,
)
from simbench.calibration.target import CalibrationTarget, get_target, load_target

__all__ = [
    "check_calibration",
    "CalibrationTarget",
    "get_target",
    "load_target",
    "Pose",
    "calibration_poses",
    "CalibrationResult",
    "CalibrationView",
    "calibrate_rig",
    "rig_errors",
    "true_rig",
]
