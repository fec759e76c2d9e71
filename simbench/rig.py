"""Camera, projector and their relative pose; projection and triangulation.

Frames and conventions
----------------------
* The world frame *is* the camera frame, OpenCV style: x right, y down, z forward (metres).
* Pixel coordinates are OpenCV's: pixel ``(row, col)`` has its centre at ``(v, u) = (row, col)``;
  a principal point at the image centre is ``((W-1)/2, (H-1)/2)``.
* Pinhole intrinsics with square pixels (one focal length in px, as Mitsuba's sensors have).
* The projector's pose is ``X_cam = R @ X_proj + t``: ``t`` (``position_m``) is the projector's
  optical centre in the camera frame and ``R`` rotates projector axes into camera axes.

The paper's rig (Sec. 6, Table 2)
---------------------------------
Camera Point Grey Flea3 FL3-U3-13E4C-C, 1280x960, f = 2312.5320 px; projector TI LightCrafter 4500,
1824x1140, f = 2227.9948 px; baseline 93 mm; parallel optical axes. Table 2 as printed is
garbled: its "principal points" ([1027.9968, 1014.5375] for a 1280x960 camera, i.e. outside the
image vertically) and its "distortion" entries (3x3 blocks that read like rotation matrices)
cannot be used as printed, so the preset puts both principal points at the image centres and
uses no distortion; this is what the paper's "optical axes are parallel" implies.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from simbench import native, validate
from simbench.io import atomic_write_text, read_toml

__all__ = [
    "Intrinsics",
    "Rig",
    "paper_rig",
    "RIG_PRESETS",
    "get_rig",
    "rig_from_dict",
    "rig_to_dict",
    "load_rig",
    "save_rig",
    "rig_toml",
    "rotation_xyz_deg",
    "angles_xyz_deg",
    "pixel_rays",
    "project_to_projector",
    "triangulate_columns",
    "projector_column_at_depth",
    "scale_camera",
    "check_stripe_baseline",
    "MIN_BASELINE_X_SHARE",
    "rig_differences",
    "rig_from_opencv",
    "OPENCV_SQUARE_PIXEL_SHARE",
    "OPENCV_BASELINE_RANGE_M",
]


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics of a camera or projector (square pixels).

    Attributes
    ----------
    width_px, height_px : int
        Image (or DMD pattern) size.
    focal_px : float
        Focal length in pixels.
    cx_px, cy_px : float
        Principal point, OpenCV coordinates (centre = ``(W-1)/2, (H-1)/2``).
    distortion : tuple of 5 float
        Brown-Conrady coefficients in OpenCV's order ``(k1, k2, p1, p2, k3)`` acting on
        normalised coordinates (all zero = an ideal pinhole).  For a camera they map a ray to
        the pixel where it is recorded; for a projector, a ray to the DMD pixel that lights it
        (see :mod:`simbench.optics`).
    """

    width_px: int
    height_px: int
    focal_px: float
    cx_px: float
    cy_px: float
    distortion: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        v = validate
        w, h = v.image_size(self.width_px, self.height_px, "image")
        f = v.number(self.focal_px, "focal_px", lo=0.0, lo_open=True, hi=1e6)
        # assumption: the principal point lies within one image size of the image (lens-shifted
        # projectors such as 100 %-offset DLP engines put it at the border, never far beyond)
        cx = v.number(self.cx_px, "cx_px", lo=-w, hi=2.0 * w)
        cy = v.number(self.cy_px, "cy_px", lo=-h, hi=2.0 * h)
        d = v.numbers(self.distortion, "distortion (k1, k2, p1, p2, k3)", 5, lo=-10.0, hi=10.0)
        for name, value in (
            ("width_px", w),
            ("height_px", h),
            ("focal_px", f),
            ("cx_px", cx),
            ("cy_px", cy),
            ("distortion", d),
        ):
            object.__setattr__(self, name, value)

    @property
    def has_distortion(self) -> bool:
        return any(x != 0.0 for x in self.distortion)

    @property
    def undistorted(self) -> "Intrinsics":
        """The same intrinsics as an ideal pinhole."""
        return Intrinsics(self.width_px, self.height_px, self.focal_px, self.cx_px, self.cy_px)

    @classmethod
    def centred(cls, width_px: int, height_px: int, focal_px: float) -> "Intrinsics":
        return cls(width_px, height_px, focal_px, (width_px - 1) / 2.0, (height_px - 1) / 2.0)

    @property
    def size_hw(self) -> tuple[int, int]:
        return (int(self.height_px), int(self.width_px))

    @property
    def matrix(self) -> np.ndarray:
        """The 3x3 OpenCV camera matrix K."""
        return np.array([[self.focal_px, 0.0, self.cx_px], [0.0, self.focal_px, self.cy_px], [0.0, 0.0, 1.0]])

    @property
    def fov_x_deg(self) -> float:
        """Horizontal field of view of a centred frustum of this width (Mitsuba's ``fov``)."""
        return math.degrees(2.0 * math.atan(self.width_px / (2.0 * self.focal_px)))


def rotation_xyz_deg(angles_deg: tuple[float, float, float]) -> np.ndarray:
    """Rotation matrix ``Rz @ Ry @ Rx`` from angles (degrees) about the x, y, z axes."""
    ax, ay, az = np.radians(np.asarray(angles_deg, dtype=np.float64))
    cx, sx, cy, sy, cz, sz = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def angles_xyz_deg(rotation: np.ndarray) -> tuple[float, float, float]:
    """The angles (degrees) about x, y, z of a rotation matrix, the inverse of
    :func:`rotation_xyz_deg` (the angle about y in [-90, 90])."""
    r = np.asarray(rotation, dtype=np.float64)
    if r.shape != (3, 3) or not np.allclose(r @ r.T, np.eye(3), atol=1e-6) or np.linalg.det(r) < 0:
        raise ValueError(f"not a rotation matrix: {r.tolist()}")
    ay = math.asin(float(np.clip(-r[2, 0], -1.0, 1.0)))
    ax = math.atan2(r[2, 1], r[2, 2])
    az = math.atan2(r[1, 0], r[0, 0])
    return tuple(math.degrees(a) for a in (ax, ay, az))


@dataclass(frozen=True)
class Rig:
    """A camera and a projector with the projector's pose in the camera frame.

    Attributes
    ----------
    camera, projector : Intrinsics
    position_m : tuple of 3 float
        Projector optical centre in the camera frame (metres).
    rotation_deg : tuple of 3 float
        Projector orientation as angles about x, y, z (degrees), ``R = Rz @ Ry @ Rx``.
    name : str
    """

    camera: Intrinsics
    projector: Intrinsics
    position_m: tuple[float, float, float] = (0.093, 0.0, 0.0)
    rotation_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    name: str = "custom"
    _r: np.ndarray = field(init=False, repr=False, compare=False)
    _rectified: bool = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        # assumption: a projector within 10 m of the camera; angles within one turn
        object.__setattr__(self, "position_m", validate.numbers(self.position_m, "position_m", 3, lo=-10.0, hi=10.0))
        object.__setattr__(
            self, "rotation_deg", validate.numbers(self.rotation_deg, "rotation_deg", 3, lo=-360.0, hi=360.0)
        )
        for name in ("camera", "projector"):
            if not isinstance(getattr(self, name), Intrinsics):
                raise ValueError(f"{name} must be Intrinsics, got {type(getattr(self, name)).__name__}")
        if np.linalg.norm(self.position_m) < 1e-6:
            raise ValueError("projector position_m coincides with the camera: no baseline")
        object.__setattr__(self, "_r", rotation_xyz_deg(self.rotation_deg))
        # once: every decode asks (its triangulation steps), and np.allclose costs ~0.1 ms
        object.__setattr__(
            self,
            "_rectified",
            bool(
                np.allclose(self._r, np.eye(3), atol=1e-9)
                and abs(self.position_m[1]) < 1e-9
                and abs(self.position_m[2]) < 1e-9
                and self.position_m[0] > 0
            ),
        )

    @property
    def rotation(self) -> np.ndarray:
        """R, shape (3, 3): projector axes expressed in the camera frame."""
        return self._r.copy()

    @property
    def baseline_m(self) -> float:
        return float(np.linalg.norm(self.position_m))

    @property
    def is_rectified(self) -> bool:
        """Parallel optical axes, baseline along +x: the geometry of paper Sec. 5.4."""
        return self._rectified


# fx and fy of one device this far apart (relative) are taken as one square pixel's focal length
# (their mean); farther apart, refused (assumption: a calibration's fx, fy of a square-pixel sensor
# agree within its ~0.1-0.3 % uncertainty; a rig has one focal length per device, as Mitsuba's
# sensors and the simulated projector do)
OPENCV_SQUARE_PIXEL_SHARE = 0.005
# the baselines a converted calibration may give (m; assumption: a projector-camera depth rig is
# 1 mm to 10 m across - outside that, T's unit was read wrongly: mm as m is 1000x, m as mm 1/1000x)
OPENCV_BASELINE_RANGE_M = (0.001, 10.0)


def _opencv_intrinsics(matrix, distortion, size_wh, who: str) -> Intrinsics:
    k = np.asarray(matrix, dtype=np.float64)
    if k.shape != (3, 3) or not np.allclose(k[2], (0.0, 0.0, 1.0)) or k[1, 0] != 0.0:
        raise ValueError(f"{who}: a camera matrix must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]], got {k.tolist()}")
    fx, fy = float(k[0, 0]), float(k[1, 1])
    if abs(k[0, 1]) > 1e-9 * fx:
        raise ValueError(f"{who}: skew {k[0, 1]:g} px: a rig's pixels are square and unskewed")
    if not (fx > 0 and fy > 0) or abs(fx - fy) > OPENCV_SQUARE_PIXEL_SHARE * max(fx, fy):
        raise ValueError(
            f"{who}: fx = {fx:g} and fy = {fy:g} px differ by more than {100 * OPENCV_SQUARE_PIXEL_SHARE:g} %: a rig "
            "has square pixels. A projector calibrated on a grid of other proportions than its pattern image (a "
            "DLP4500's native 912-px-wide grid for its 1824-px pattern: fx about half fy) needs its matrix in the "
            "pattern's pixels (there: fx' = 2 fx, cx' = 2 (cx + 0.5) - 0.5); a camera, cv2.CALIB_FIX_ASPECT_RATIO"
        )
    d = np.ravel(np.asarray(distortion if distortion is not None else (), dtype=np.float64))
    if d.size > 5 and np.any(d[5:] != 0.0):
        raise ValueError(
            f"{who}: {d.size} distortion coefficients; a rig takes OpenCV's first five (k1, k2, p1, p2, k3): "
            "calibrate without the rational, thin-prism and tilted models"
        )
    d = np.pad(d[:5], (0, 5 - min(d.size, 5)))
    w, h = (int(v) for v in size_wh)
    return Intrinsics(w, h, 0.5 * (fx + fy), float(k[0, 2]), float(k[1, 2]), tuple(float(x) for x in d))


def rig_from_opencv(
    *,
    camera_matrix: np.ndarray,
    camera_distortion: np.ndarray | None,
    camera_size_wh: tuple[int, int],
    projector_matrix: np.ndarray,
    projector_distortion: np.ndarray | None,
    projector_size_wh: tuple[int, int],
    rotation: np.ndarray,
    translation: np.ndarray,
    translation_unit_m: float,
    name: str = "opencv",
) -> Rig:
    """A rig from a projector-camera stereo calibration in OpenCV's conventions:
    ``cv2.stereoCalibrate`` with the camera as its first device and the projector as its second,
    whose ``R, T`` map a point from the camera's frame into the projector's, ``X_p = R X_c + T``.
    The rig's pose is the inverse: ``position_m = -R^T T * translation_unit_m`` (the projector's
    optical centre in the camera frame) and ``rotation_deg`` the angles of ``R^T`` (projector axes in
    camera axes).

    Parameters
    ----------
    camera_matrix, projector_matrix : ndarray, shape (3, 3)
        OpenCV camera matrices ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``: fx and fy within
        :data:`OPENCV_SQUARE_PIXEL_SHARE` of each other (their mean is taken), no skew.  The
        projector's in the pixels of the pattern image it projects (a DLP4500 calibrated on its
        912-px native grid projects an 1824-px pattern: its first row in the pattern's pixels
        first, ``fx' = 2 fx``, ``cx' = 2 (cx + 0.5) - 0.5``).
    camera_distortion, projector_distortion : array of up to 5 floats, or None
        OpenCV's ``(k1, k2, p1, p2, k3)``; longer vectors only if their extra terms are 0.
    camera_size_wh, projector_size_wh : (width, height) in px
    rotation : ndarray, shape (3, 3) or (3,)
        ``R`` of ``cv2.stereoCalibrate``, or its Rodrigues vector.
    translation : array of 3 floats
        ``T`` of ``cv2.stereoCalibrate``, in the unit of the calibration target's coordinates.
    translation_unit_m : float
        Metres per unit of ``T`` (0.001 for a target measured in mm): no default, since OpenCV's
        ``T`` carries whatever unit the target's square size was given in.  A baseline outside
        :data:`OPENCV_BASELINE_RANGE_M` is refused (a unit read wrongly).
    name : str

    Returns
    -------
    Rig
    """
    import cv2

    r = np.asarray(rotation, dtype=np.float64)
    if r.shape in ((3,), (3, 1), (1, 3)):
        r = cv2.Rodrigues(r.reshape(3, 1))[0]
    if r.shape != (3, 3):
        raise ValueError(f"rotation: a 3x3 matrix or a Rodrigues vector, got shape {r.shape}")
    t = np.ravel(np.asarray(translation, dtype=np.float64))
    if t.shape != (3,):
        raise ValueError(f"translation: 3 numbers, got {t.size}")
    unit = validate.number(translation_unit_m, "translation_unit_m", lo=0.0, lo_open=True, hi=1.0)
    position = -r.T @ t * unit
    baseline = float(np.linalg.norm(position))
    if not OPENCV_BASELINE_RANGE_M[0] <= baseline <= OPENCV_BASELINE_RANGE_M[1]:
        raise ValueError(
            f"the projector would be {baseline:.6g} m from the camera (|T| = {np.linalg.norm(t):g} x "
            f"translation_unit_m {unit:g}): is translation_unit_m the metres per unit of T - the unit of the "
            "calibration target's square size (0.001 for mm)?"
        )
    return Rig(
        camera=_opencv_intrinsics(camera_matrix, camera_distortion, camera_size_wh, "camera"),
        projector=_opencv_intrinsics(projector_matrix, projector_distortion, projector_size_wh, "projector"),
        position_m=tuple(float(x) for x in position),
        rotation_deg=angles_xyz_deg(r.T),
        name=name,
    )


# the least share of the baseline along the camera's x axis the colour-fringe decoders take: its
# vertical stripes code the projector's column, which only the x component turns into depth
# (assumption: a rig under a tenth of its baseline along x decodes nothing a user would want)
MIN_BASELINE_X_SHARE = 0.1


def check_stripe_baseline(rig: Rig) -> None:
    """Refuse a rig whose baseline is not along the camera's x axis, for a decoder of vertical
    stripes (the projector's columns): a baseline along y or z moves no column with depth (a new
    user's audit: a vertical baseline rendered, then failed to decode with hints of a wrong rig or
    an unlit capture)."""
    b = np.asarray(rig.position_m, np.float64)
    norm = float(np.linalg.norm(b))
    if abs(b[0]) < MIN_BASELINE_X_SHARE * norm:
        raise ValueError(
            f"rig {rig.name!r}: the projector sits at {[round(float(v), 4) for v in b]} m, its baseline "
            f"{abs(b[0]) * 1000:.1f} mm along the camera's x axis of {norm * 1000:.1f} mm: the pattern's vertical "
            "stripes code the projector's column, which only a baseline along x turns into depth - place the "
            "projector beside the camera (position_m = [b, 0, 0], b > 0 on its right or < 0 on its left)"
        )


# How far a rig may lie from another and still describe the same device (rig_differences): a
# calibration of a rig, even a poor one, stays well within these (assumption: published
# projector-camera calibrations report focal lengths within ~1 %, principal points within a few
# pixels, baselines within ~1 % and rotations within ~0.5 deg; this repository's 10-pose
# calibration, results/calibration/report.md, within 0.03 %, 0.4 px, 0.3 mm), and a rig beyond
# them decodes to depths off by about as much (depth scales with baseline and focal length)
SAME_RIG_FOCAL_SHARE = 0.05
SAME_RIG_PRINCIPAL_SHARE = 0.05
SAME_RIG_POSITION_SHARE = 0.05
SAME_RIG_ROTATION_DEG = 5.0


def rig_differences(rig: Rig, other: Rig) -> list[str]:
    """What makes ``rig`` another device than ``other`` - not a calibration of it: image sizes
    that differ, a focal length more than :data:`SAME_RIG_FOCAL_SHARE` off, a principal point more
    than :data:`SAME_RIG_PRINCIPAL_SHARE` of the image's size off, a projector position more than
    :data:`SAME_RIG_POSITION_SHARE` of ``other``'s baseline off, or a rotation more than
    :data:`SAME_RIG_ROTATION_DEG` off; each as one phrase (empty: the same device)."""
    out = []
    for dev in ("camera", "projector"):
        a, b = getattr(rig, dev), getattr(other, dev)
        if a.size_hw != b.size_hw:
            out.append(f"{dev} {a.width_px}x{a.height_px} against {b.width_px}x{b.height_px}")
            continue
        if abs(a.focal_px - b.focal_px) > SAME_RIG_FOCAL_SHARE * b.focal_px:
            out.append(f"{dev} focal length {a.focal_px:g} px against {b.focal_px:g}")
        if max(abs(a.cx_px - b.cx_px) / b.width_px, abs(a.cy_px - b.cy_px) / b.height_px) > SAME_RIG_PRINCIPAL_SHARE:
            out.append(f"{dev} principal point ({a.cx_px:g}, {a.cy_px:g}) against ({b.cx_px:g}, {b.cy_px:g})")
    moved = float(np.linalg.norm(np.subtract(rig.position_m, other.position_m)))
    if moved > SAME_RIG_POSITION_SHARE * other.baseline_m:
        out.append(
            f"baseline {1000 * rig.baseline_m:.1f} mm against {1000 * other.baseline_m:.1f} "
            f"(the projector {1000 * moved:.1f} mm apart)"
        )
    turn = float(np.clip((np.trace(rig.rotation @ other.rotation.T) - 1.0) / 2.0, -1.0, 1.0))
    if np.degrees(np.arccos(turn)) > SAME_RIG_ROTATION_DEG:
        out.append(f"projector turned {np.degrees(np.arccos(turn)):.1f} deg from the other's")
    return out


def paper_rig() -> Rig:
    """The rig of paper Sec. 6 (see the module docstring for what Table 2 could not give)."""
    from simbench.literature import PAPER_BASELINE_M, PAPER_CAMERA, PAPER_PROJECTOR

    return Rig(
        camera=Intrinsics.centred(*PAPER_CAMERA),
        projector=Intrinsics.centred(*PAPER_PROJECTOR),
        position_m=(PAPER_BASELINE_M, 0.0, 0.0),
        rotation_deg=(0.0, 0.0, 0.0),
        name="li2017",
    )


RIG_PRESETS = {"paper": paper_rig}


def scale_camera(rig: Rig, factor: float) -> Rig:
    """The rig with the camera's resolution scaled by ``factor`` (same field of view and pose).

    Pixel centres map as ``x' = (x + 0.5) * factor - 0.5``.  Used for quick runs at reduced
    resolution; the projector is unchanged.
    """
    cam = rig.camera
    w, h = cam.width_px * factor, cam.height_px * factor
    # (whole to within float rounding: 0.5125 x 1280 is 655.9999999999999)
    whole = factor > 0 and all(abs(v - round(v)) <= 1e-9 * max(1.0, v) and round(v) >= 1 for v in (w, h))
    if not whole:
        step = math.gcd(cam.width_px, cam.height_px)
        raise ValueError(
            f"camera scale {factor:g} gives a {w:g}x{h:g} image: it must give whole image sizes (camera "
            f"{cam.width_px}x{cam.height_px}: a multiple of 1/{step}, e.g. 0.25 or 0.5)"
        )
    w_px, h_px = int(round(w)), int(round(h))

    def centre(c: float, n: int, n_scaled: int) -> float:
        # a centred principal point stays exactly centred (at 0.5125, 640 x 0.5125 - 0.5 is
        # 327.49999999999994, not the centre 327.5 the thin-lens defocus insists on)
        return (n_scaled - 1) / 2.0 if c == (n - 1) / 2.0 else (c + 0.5) * factor - 0.5

    scaled = Intrinsics(
        w_px,
        h_px,
        cam.focal_px * factor,
        centre(cam.cx_px, cam.width_px, w_px),
        centre(cam.cy_px, cam.height_px, h_px),
        cam.distortion,
    )
    suffix = f"@{factor:g}x" if factor != 1 else ""
    return Rig(scaled, rig.projector, rig.position_m, rig.rotation_deg, rig.name + suffix)


def get_rig(name_or_path: str | Path, *, base_dir: Path | None = None) -> Rig:
    """A rig preset by name (``paper``) or a rig TOML file (relative to ``base_dir``)."""
    key = str(name_or_path)
    if key in RIG_PRESETS:
        return RIG_PRESETS[key]()
    path = Path(key)
    if base_dir is not None and not path.is_absolute():
        path = base_dir / path
    if path.suffix.lower() != ".toml":
        raise ValueError(f"unknown rig {key!r}: give a preset ({', '.join(sorted(RIG_PRESETS))}) or a .toml file")
    return load_rig(path)


_INTR_KEYS = ("width_px", "height_px", "focal_px", "cx_px", "cy_px", "distortion")
_POSE_KEYS = ("position_m", "rotation_deg")


def _check_keys(table: dict, allowed: tuple[str, ...], where: str, *, required=()) -> None:
    unknown = sorted(set(table) - set(allowed))
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {unknown}; valid keys: {list(allowed)}")
    missing = [k for k in required if k not in table]
    if missing:
        raise ValueError(f"{where}: missing key(s) {missing}")


def _intrinsics_from(table: object, where: str) -> Intrinsics:
    if not isinstance(table, dict):
        raise ValueError(f"{where}: expected a table, got {type(table).__name__}")
    _check_keys(table, _INTR_KEYS, where, required=("width_px", "height_px", "focal_px"))
    w, h = table["width_px"], table["height_px"]
    try:
        return Intrinsics(
            width_px=w,
            height_px=h,
            focal_px=table["focal_px"],
            cx_px=table.get("cx_px", (w - 1) / 2.0 if isinstance(w, int) else w),
            cy_px=table.get("cy_px", (h - 1) / 2.0 if isinstance(h, int) else h),
            distortion=table.get("distortion", (0.0,) * 5),
        )
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {exc}") from None


def rig_from_dict(data: dict, *, where: str = "rig") -> Rig:
    """Build a :class:`Rig` from the TOML table layout documented in :func:`save_rig`."""
    # no default pose: a rig file without its baseline would triangulate with some other rig's
    _check_keys(data, ("name", "camera", "projector", "pose"), where, required=("camera", "projector", "pose"))
    pose = data["pose"]
    if not isinstance(pose, dict):
        raise ValueError(f"{where}.pose: expected a table")
    _check_keys(pose, _POSE_KEYS, f"{where}.pose", required=("position_m",))
    camera = _intrinsics_from(data["camera"], f"{where}.camera")
    projector = _intrinsics_from(data["projector"], f"{where}.projector")
    try:
        return Rig(
            camera=camera,
            projector=projector,
            position_m=tuple(pose["position_m"]),
            rotation_deg=tuple(pose.get("rotation_deg", (0.0, 0.0, 0.0))),
            name=str(data.get("name", "custom")),
        )
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {exc}") from None


def rig_to_dict(rig: Rig) -> dict:
    def intr(i: Intrinsics) -> dict:
        # distortion only when present: ideal rigs keep their files (and cache keys) unchanged
        return {
            k: (list(getattr(i, k)) if k == "distortion" else getattr(i, k))
            for k in _INTR_KEYS
            if k != "distortion" or i.has_distortion
        }

    return {
        "name": rig.name,
        "camera": intr(rig.camera),
        "projector": intr(rig.projector),
        "pose": {"position_m": list(rig.position_m), "rotation_deg": list(rig.rotation_deg)},
    }


_RIG_HEADER = """\
# simbench rig file.  Units: pixels and metres; frames: OpenCV (x right, y down, z forward).
# [camera] / [projector]: width_px, height_px, focal_px, cx_px, cy_px (principal point in OpenCV
#   pixel coordinates, where the image centre is ((W-1)/2, (H-1)/2); omitted = centred);
#   optional distortion = [k1, k2, p1, p2, k3] (Brown-Conrady, OpenCV order; omitted = none).
# [pose] (required): the projector in the camera frame: position_m = optical centre (required);
#   rotation_deg = angles about x, y, z in degrees, R = Rz @ Ry @ Rx maps projector axes to camera
#   axes (omitted = none).
"""


def rig_toml(rig: Rig) -> str:
    """The text of a rig TOML file (:func:`save_rig`), with its explanatory header."""
    import tomli_w

    return _RIG_HEADER + tomli_w.dumps(rig_to_dict(rig))


def save_rig(rig: Rig, path: str | Path) -> Path:
    """Write a rig TOML file (atomically) that :func:`load_rig` reads back to an equal rig."""
    return atomic_write_text(Path(path), rig_toml(rig))


def load_rig(path: str | Path) -> Rig:
    """Read a rig TOML file; errors name the file and the offending field."""
    # "FILE: rig.camera: ..." as a sensor file's errors read (not "FILE.camera", a file's name)
    return rig_from_dict(read_toml(path, what="rig"), where=f"{path}: rig")


def pixel_rays(intr: Intrinsics) -> np.ndarray:
    """Ray directions through every pixel centre, normalised to z = 1.

    Returns
    -------
    ndarray, shape (H, W, 3), float64
    """
    h, w = intr.size_hw
    u = (np.arange(w) - intr.cx_px) / intr.focal_px
    v = (np.arange(h) - intr.cy_px) / intr.focal_px
    rays = np.empty((h, w, 3))
    rays[..., 0] = u[None, :]
    rays[..., 1] = v[:, None]
    rays[..., 2] = 1.0
    return rays


def project_to_projector(points_m: np.ndarray, rig: Rig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Project camera-frame points into the projector.

    Parameters
    ----------
    points_m : ndarray, shape (..., 3)

    Returns
    -------
    u_px, v_px, z_m : ndarray, shape (...)
        Projector pixel coordinates (OpenCV; on the DMD, i.e. through the projector's lens
        distortion if it has one) and depth along the projector's axis.
    """
    from simbench.optics import distort_normalized

    p = np.asarray(points_m, dtype=np.float64) - np.asarray(rig.position_m)
    q = p @ rig.rotation  # R^T (X - t), row-vector form
    z = q[..., 2]
    prj = rig.projector
    with np.errstate(divide="ignore", invalid="ignore"):
        x, y = q[..., 0] / z, q[..., 1] / z
    # a point in the projector's focal plane or behind it has no projector pixel (inf would
    # turn into NaN with a warning inside the distortion polynomial)
    behind = ~(z > 0)
    if np.any(behind):
        x, y = np.where(behind, np.nan, x), np.where(behind, np.nan, y)
    if prj.has_distortion:
        x, y = distort_normalized(x, y, prj.distortion)
    return prj.focal_px * x + prj.cx_px, prj.focal_px * y + prj.cy_px, z


# fixed-point steps of triangulate_columns through projector distortion in a non-rectified rig
TRIANGULATION_ITERATIONS = 4
# Newton steps of one projector-column undistortion (simbench.optics.undistort_projector_columns)
COLUMN_NEWTON_STEPS = 8

_TRIANGULATE = {
    "triangulate_columns": (
        None,
        [native.I64, native.P, native.P, native.P, native.I64, native.I64, native.P]
        + [native.I64, native.I64, native.I64, native.P],
    )
}


def triangulation_values(rig: Rig) -> np.ndarray:
    """The rig as the compiled triangulation reads it (float64, 22 numbers): camera focal, cx,
    cy, projector focal, cx, the rotation row-major, the position, the projector's distortion."""
    cam, prj = rig.camera, rig.projector
    values = [cam.focal_px, cam.cx_px, cam.cy_px, prj.focal_px, prj.cx_px, *rig._r.ravel(), *rig.position_m]
    return np.array(values + [float(x) for x in prj.distortion], np.float64)


def triangulation_steps(rig: Rig) -> tuple[bool, int, int]:
    """How the compiled triangulation treats ``rig``'s projector: (undo its lens distortion,
    Newton steps per undistortion, fixed-point steps for the row where the point lands - none
    in a rectified rig, where it is the camera pixel's)."""
    return rig.projector.has_distortion, COLUMN_NEWTON_STEPS, 0 if rig.is_rectified else TRIANGULATION_ITERATIONS


def triangulate_columns(
    column_px: np.ndarray, rig: Rig, *, rows: np.ndarray = None, cols: np.ndarray = None, row0: int = 0
) -> np.ndarray:
    """Depth (camera z, metres) where each camera pixel's ray meets its projector column's plane.

    The plane of projector column u is ``x - a z = 0`` in the projector's frame,
    ``a = (u - cx) / f`` (an ideal pinhole).  A projector with lens distortion shows DMD
    column u_d where the ideal column is u: a decoded DMD column gives the ideal one only together
    with its projector row (:func:`simbench.optics.undistort_projector_columns`).  In a rectified
    rig that row's normalised y is the camera pixel's, exactly; in any other (a calibrated rig is
    never exactly rectified) the row where the point lands comes from the depth so far, a fixed
    point (:data:`TRIANGULATION_ITERATIONS` steps) that gains ~3 orders of magnitude per step for
    a near-rectified rig.  Computed in C (simbench/_ckernels.c) in float64, in the operation
    order of the numpy form kept in tests/numpy_reference.py (same bits, tests/test_rig.py),
    with each iteration stopped once it changes nothing (which changes no bit either).

    Parameters
    ----------
    column_px : ndarray, shape (H, W) or (N,)
        Projector column (OpenCV coordinates) seen by each camera pixel; NaN = unknown.
    rows, cols : ndarray, optional
        Camera pixel coordinates when ``column_px`` is not a full (H, W) image.
    row0 : int
        Image row of ``column_px``'s first row when it is a band of full-width rows (no
        ``rows``/``cols``).

    Returns
    -------
    ndarray, same shape, float64; NaN where the ray is parallel to the plane or behind.
    """
    col = np.ascontiguousarray(column_px, dtype=np.float64)
    out = np.empty(col.shape, np.float64)
    if rows is None:
        if col.ndim != 2:
            raise ValueError(f"column_px: expected an (H, W) image without rows/cols, got shape {col.shape}")
        r_ptr = c_ptr = None
        grid_w = col.shape[1]
    else:
        r64, c64 = (np.ascontiguousarray(np.broadcast_to(a, col.shape), np.float64) for a in (rows, cols))
        r_ptr, c_ptr = r64.ctypes.data, c64.ctypes.data
        grid_w = 1
    distorted, newton_steps, refine_steps = triangulation_steps(rig)
    native.bind(_TRIANGULATE).triangulate_columns(
        col.size,
        col.ctypes.data,
        r_ptr,
        c_ptr,
        int(row0),
        grid_w,
        triangulation_values(rig).ctypes.data,
        int(distorted),
        newton_steps,
        refine_steps,
        out.ctypes.data,
    )
    return out


def projector_column_at_depth(
    depth_m: float | np.ndarray, rig: Rig, *, rows: np.ndarray = None, cols: np.ndarray = None
) -> np.ndarray:
    """Projector column lighting each camera pixel if the surface there were at ``depth_m``.

    ``depth_m`` may be a scalar (a fronto-parallel plane) or an (H, W) map.

    Returns
    -------
    ndarray, shape (H, W) (or (N,) with ``rows``/``cols``), float64
    """
    cam = rig.camera
    if rows is None:
        rays = pixel_rays(cam)
    else:
        rays = np.stack(
            [
                (np.asarray(cols, dtype=np.float64) - cam.cx_px) / cam.focal_px,
                (np.asarray(rows, dtype=np.float64) - cam.cy_px) / cam.focal_px,
                np.ones(np.shape(rows)),
            ],
            axis=-1,
        )
    pts = rays * np.asarray(depth_m, dtype=np.float64)[..., None]
    u, _, _ = project_to_projector(pts, rig)
    return u


def register_depth(depth_m: np.ndarray, *, source: Intrinsics, target: Intrinsics) -> np.ndarray:
    """Resample a depth map from camera ``source`` onto camera ``target``'s pixel grid, for two
    cameras sharing their centre and axes (nearest neighbour: depth is not interpolated across
    edges).  Pixels of ``target`` outside ``source``'s view are NaN.

    Returns
    -------
    ndarray, shape target.size_hw, float32
    """
    d = np.asarray(depth_m, dtype=np.float32)
    if d.shape != source.size_hw:
        raise ValueError(f"depth map shape {d.shape} does not match the source camera {source.size_hw}")
    yy, xx = np.indices(target.size_hw, dtype=np.float64)
    xs = np.rint((xx - target.cx_px) * source.focal_px / target.focal_px + source.cx_px).astype(np.int64)
    ys = np.rint((yy - target.cy_px) * source.focal_px / target.focal_px + source.cy_px).astype(np.int64)
    inside = (xs >= 0) & (xs < source.width_px) & (ys >= 0) & (ys < source.height_px)
    out = np.full(target.size_hw, np.nan, np.float32)
    out[inside] = d[ys[inside], xs[inside]]
    return out
