"""Published numbers the testbed uses, each with its source.

Numbers here come from a paper, a data sheet or a standard and are used as they were published:
the paper's tables (the targets of the reproduction), its rig and pattern, the competitors'
device numbers and the real devices' measured noise the simulated competitors are checked
against.  Assumptions (numbers we chose and argue for) stay beside the code that uses them,
marked "assumption"; sensor presets cite their data sheets in ``simbench/presets/*.toml``.

References
----------
.. [Li2017] F. Li, B. Zhang, G. Shi, Y. Niu, R. Li, L. Yang, X. Xie, "Single-Shot Dense Depth
   Sensing with Color Sequence Coded Fringe Pattern", Sensors 17(11), 2558, 2017.
.. [Khoshelham2012] K. Khoshelham, S. Oude Elberink, "Accuracy and Resolution of Kinect Depth
   Data for Indoor Mapping Applications", Sensors 12(2), 1437-1454, 2012.
.. [Nguyen2012] C. V. Nguyen, S. Izadi, D. Lovell, "Modeling Kinect Sensor Noise for Improved 3D
   Reconstruction and Tracking", 3DIMPVT 2012, 524-530.
.. [Chiabrando2009] F. Chiabrando, R. Chiabrando, D. Piatti, F. Rinaudo, "Sensors for 3D
   Imaging: Metric Evaluation and Calibration of a CCD/CMOS Time-of-Flight Camera", Sensors
   9(12), 10080-10096, 2009.
.. [Sarbolandi2015] H. Sarbolandi, D. Lefloch, A. Kolb, "Kinect Range Sensing: Structured-Light
   versus Time-of-Flight Kinect", Computer Vision and Image Understanding 139, 1-20, 2015.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "PAPER_TABLE1",
    "PAPER_TABLE3",
    "PAPER_COMPETITORS",
    "PAPER_PERIOD_PX",
    "PAPER_DEBRUIJN_ORDER",
    "PAPER_CAMERA",
    "PAPER_PROJECTOR",
    "PAPER_BASELINE_M",
    "KINECT_FOCAL_PX",
    "KINECT_BASELINE_M",
    "KINECT_FPS",
    "MT9M001_ROW_TIME_S",
    "SR4000_SIZE_WH",
    "SR4000_FOV_X_DEG",
    "SR4000_MODULATION_HZ",
    "CHIABRANDO_TOF",
    "nguyen_kinect_sigma_mm",
]

# [Li2017] Table 1 (simulated boards): colour -> (sRGB of the board, mean absolute error in mm)
PAPER_TABLE1 = {
    "white": ((255, 255, 255), 0.42),
    "red": ((255, 0, 0), 0.83),
    "green": ((0, 255, 0), 0.84),
    "blue": ((0, 0, 255), 0.41),
    "yellow": ((255, 255, 0), 0.46),
    "pink": ((255, 0, 255), 0.55),
    "cyan": ((0, 255, 255), 0.56),
}
# [Li2017] Table 3 (the real rig), mm: object -> (proposed method, Kinect, ToF camera)
PAPER_TABLE3 = {"cube": (0.8366, 1.4665, 1.8699), "cuboid": (1.3345, 1.4599, 1.9811)}
# the systems the paper compares its method with (Table 3's columns after its own, Fig. 9's
# curves): registered system name -> (the paper's name for it, its column in PAPER_TABLE3)
PAPER_COMPETITORS = {"kinect": ("Kinect", 1), "tof": ("ToF", 2)}
# [Li2017] Sec. 3-4, Eq. 7-8: fringe period T (projector px) and the De Bruijn window length
PAPER_PERIOD_PX = 21
PAPER_DEBRUIJN_ORDER = 3
# [Li2017] Sec. 6, Table 2: Point Grey Flea3 FL3-U3-13E4C-C and TI DLP LightCrafter 4500,
# (width px, height px, focal length px); baseline 93 mm (Table 2 as printed is garbled:
# simbench.rig's module docstring says what we read from it)
PAPER_CAMERA = (1280, 960, 2312.5320)
PAPER_PROJECTOR = (1824, 1140, 2227.9948)
PAPER_BASELINE_M = 0.093
# frame rates of the paper's devices, for multi-shot sequences: the Flea3 FL3-U3-13E4C-C reads
# out at most 60 frames/s at full resolution (Point Grey Flea3 USB 3.0 data sheet: 1.3 MP, 60 FPS);
# the LightCrafter 4500 shows 8-bit patterns at up to 120 Hz (TI DLPU011, Ch. 4 "Pattern
# Sequences": a 120 Hz input frame, a 2.78 ms slot per colour).  A sequence runs at the slower.
FLEA3_MAX_FPS = 60.0
LIGHTCRAFTER_8BIT_PATTERN_HZ = 120.0

# the Kinect v1: IR camera focal length (the competitor issue's 571 px; [Khoshelham2012]
# calibrate ~580 px) and the projector-camera baseline [Khoshelham2012]
KINECT_FOCAL_PX = 571.0
KINECT_BASELINE_M = 0.075
# the Kinect v1 delivers depth at 30 Hz [Sarbolandi2015]; its IR camera is an Aptina MT9M001
# (1/2-inch 1280 x 1024 CMOS, 5.2 um pixels, 10-bit ADC, electronic rolling shutter, 30 fps
# progressive scan; one row every 1,524 pixel clocks = 31.75 us at the recommended 48 MHz
# master clock: Aptina MT9M001 data sheet, Rev. K 5/11, Table 3 "Frame Timing")
KINECT_FPS = 30.0
MT9M001_ROW_TIME_S = 31.75e-6
# the MESA SR4000: 176 x 144 lock-in pixels, 43.6 deg horizontal field, 30 MHz default
# modulation (data sheet as quoted by [Chiabrando2009])
SR4000_SIZE_WH = (176, 144)
SR4000_FOV_X_DEG = 43.6
SR4000_MODULATION_HZ = 30e6
# [Chiabrando2009]: per-pixel temporal sigma of the SR4000 on a wall at 1.3 m: (depth m, sigma mm)
CHIABRANDO_TOF = (1.3, 4.0)


def nguyen_kinect_sigma_mm(z_m: float | np.ndarray) -> np.ndarray:
    """Kinect v1 axial noise (mm) at depth ``z_m`` (m): ``1.2 + 1.9 (z - 0.4)^2`` [Nguyen2012]."""
    return 1.2 + 1.9 * (np.asarray(z_m, dtype=float) - 0.4) ** 2
