"""The calibration procedure of a projector-camera rig, rendered and solved as a lab does it.

At every target pose (:func:`simbench.calibration.poses.calibration_poses`) the projector shows
a white frame, then vertical and horizontal phase-shifting + Gray-code sequences
(:mod:`simbench.decode.temporal`, the multi-shot reference's own patterns); the camera records
each through the sensor model (noise, colour filter array, lenses: the same path as every
capture, :func:`simbench.sim.capture.record`).  Then:

1. the checkerboard's inner corners are found in the white frame
   (``cv2.findChessboardCornersSB``) and the camera is calibrated from them
   (``cv2.calibrateCamera``, Zhang's method [1]_);
2. the projector is calibrated as an inverse camera [2]_: the two sequences give every lit
   camera pixel its projector column and row, and a homography fitted to those of the pixels
   around each corner (on the white squares, where the fringes are bright) carries the corner
   into the projector's image (local homographies, [3]_: exact for a plane seen by two
   pinholes, and lens distortion is smooth over a window);
3. ``cv2.stereoCalibrate`` refines both and finds the projector's pose.

Both devices are pinholes with one focal length (square pixels), a principal point and
Brown-Conrady distortion - the rig file's model; :data:`DISTORTION_MODELS` says which
coefficients a solve fits (radial k1, k2 by default; the Bouguet toolbox the paper used, its
Sec. 6, refs. 32-33, also fits tangential p1, p2 by default).

References
----------
.. [1] Z. Zhang, "A flexible new technique for camera calibration", IEEE Transactions on
   Pattern Analysis and Machine Intelligence 22(11), 1330-1334, 2000.
.. [2] S. Zhang, P. S. Huang, "Novel method for structured light system calibration", Optical
   Engineering 45(8), 083601, 2006.
.. [3] D. Moreno, G. Taubin, "Simple, accurate, and robust projector-camera calibration",
   Second International Conference on 3D Imaging, Modeling, Processing, Visualization and
   Transmission (3DIMPVT), 464-471, 2012.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from simbench.calibration.poses import DEPTH_RANGE_M, Pose, calibration_poses
from simbench.calibration.target import CalibrationTarget
from simbench.decode.temporal import PhaseShiftSpec, decode_phase_shift, grey_frame, phase_shift_frames
from simbench.io import camera_full_scale
from simbench.sim.mitsuba_dict import RenderSettings
from simbench.rig import Intrinsics, Rig, angles_xyz_deg
from simbench.seeds import DEFAULT_SEED, derive_seed, frame_seed

__all__ = [
    "CalibrationView",
    "CalibrationResult",
    "calibrate_rig",
    "check_calibration",
    "observe_pose",
    "find_corners",
    "projector_points",
    "solve_calibration",
    "rig_errors",
    "true_rig",
    "MIN_WINDOW_POINTS",
    "DISTORTION_MODELS",
    "DEFAULT_TARGET",
    "DEFAULT_POSES",
    "CALIBRATION_SPP",
    "CALIBRATION_CORNER_SPP",
    "CALIBRATION_SAMPLER",
    "CALIBRATION_MAX_DEPTH",
    "calibration_frames",
    "corner_spacing_px",
]

log = logging.getLogger(__name__)

# The defaults of a calibration run (simbench calibrate, and experiments with rig =
# "calibrated"): the default target; the sequences at 1 sample per pixel (their sampling noise
# averages out over a local homography's ~1000 pixels), the white frames at 16 (the corner
# detector reads edge-pixel coverage: observe_pose), stratified (multijitter) samples; direct
# light only (one board: nothing to interreflect).
DEFAULT_TARGET = "checkerboard"
CALIBRATION_SPP = 1
CALIBRATION_CORNER_SPP = 16
CALIBRATION_SAMPLER = "multijitter"
CALIBRATION_MAX_DEPTH = 2
# OpenCV's documentation asks for at least 10 views of the target (calibrateCamera tutorial)
DEFAULT_POSES = 10

# the local homography needs this many decoded pixels around a corner (assumption: a 4-point
# homography fitted to >= 50 points averages the phase noise down by > 3x)
MIN_WINDOW_POINTS = 50
# bump when what observe_pose computes from the same renders changes (its cache key); 4: a
# frame's three per-primary renders became one (simbench.sim.capture.grey_scene), and so did
# the ambient light's (grey_ambient_scene), the same frames to float rounding; 5: the corner
# search without Intel IPP (_opencv_without_ipp: corners ~1e-5 px apart)
OBSERVATION_VERSION = 5
# The lens models a solve may fit (OpenCV flags; every model has one focal length: square
# pixels).  "radial" (the default) fits k1, k2; "radial_tangential" also p1, p2, the Bouguet
# toolbox's default (k3 stays 0 in both, as there).  The tangential terms model a decentred
# lens element; they trade off against the principal point: on the default rig and target,
# noise-free, 15 poses, the principal point comes out 1.2-1.6 px off with them and 0.0-0.3 px
# without (measured with simbench calibrate --distortion), so a lab whose lenses are centred -
# machine-vision lenses and DLP projection optics are - fixes them at 0.
DISTORTION_MODELS = {
    "radial": ("CALIB_FIX_ASPECT_RATIO", "CALIB_FIX_K3", "CALIB_ZERO_TANGENT_DIST"),
    "radial_tangential": ("CALIB_FIX_ASPECT_RATIO", "CALIB_FIX_K3"),
}
_CRITERIA_ITERATIONS = 200
_CRITERIA_EPS = 1e-12


@dataclass(frozen=True)
class CalibrationView:
    """What one pose gave: the corners found in the camera image (N, 2) float64 (or None:
    the board was not found), their projector coordinates (N, 2) float64 (NaN where the
    window around a corner had too few decoded pixels), and the pose the target was at."""

    pose: Pose
    camera_px: np.ndarray | None
    projector_px: np.ndarray | None


@dataclass(frozen=True)
class CalibrationResult:
    """The estimated rig and how well it fits.

    ``rms_px`` holds the reprojection RMS (pixels) of the camera alone, the projector alone and
    the joint stereo refinement; ``view_rms_px`` the camera's and the projector's per view
    (NaN for views not used); ``residuals_px`` the reprojection residuals (camera, projector),
    each (M, 2); ``used_views`` which poses entered the stereo solve.
    """

    rig: Rig
    rms_px: dict[str, float]
    view_rms_px: dict[str, list[float]]
    residuals_px: dict[str, np.ndarray]
    views: tuple[CalibrationView, ...]
    used_views: tuple[int, ...]


def _grey_u8(image: np.ndarray) -> np.ndarray:
    img = np.asarray(image)
    if np.issubdtype(img.dtype, np.integer):
        scale = 255.0 / float(np.iinfo(img.dtype).max)
    else:
        scale = 255.0
    return np.clip(np.rint(img.astype(np.float64).mean(axis=-1) * scale), 0, 255).astype(np.uint8)


def find_corners(image_u8: np.ndarray, *, target: CalibrationTarget) -> np.ndarray | None:
    """The target's inner corners in a grey 8-bit image, (N, 2) float64 in OpenCV pixel
    coordinates, row by row as :meth:`CalibrationTarget.object_points`; None if not found."""
    import cv2

    img = np.asarray(image_u8)
    if img.dtype != np.uint8 or img.ndim != 2:
        raise ValueError(f"need a grey uint8 image, got {img.dtype} {img.shape}")
    # contrast stretched to the full range (a board at the far end of the volume fills a third
    # of it); OpenCV's own CALIB_CB_NORMALIZE_IMAGE equalises the dark background's histogram
    # too and then misses boards it finds without it
    with _opencv_without_ipp():
        stretched = cv2.normalize(img, None, 0, 255, cv2.NORM_MINMAX)
        flags = cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY
        found, corners = cv2.findChessboardCornersSB(stretched, target.pattern_size, flags=flags)
        if not found:
            return None
        # the sector-based detector's corners are good to ~0.2 px on our renders; the saddle-point
        # refinement over a window of a fifth of a square brings them to ~0.06 px (measured on the
        # default rig against the projected truth)
        c = corners.reshape(-1, 2)
        spacing = corner_spacing_px(c, target=target)
        win = int(np.clip(0.2 * spacing, 2, 12))
        criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-4)
        refined = cv2.cornerSubPix(img, c.astype(np.float32).reshape(-1, 1, 2).copy(), (win, win), (-1, -1), criteria)
    return refined.reshape(-1, 2).astype(np.float64)


@contextmanager
def _opencv_without_ipp() -> Iterator[None]:
    """OpenCV's own code instead of Intel IPP's, on this thread alone, for the corner search.

    IPP picks its code by the CPU it runs on, and its results are not OpenCV's to the last bit
    (opencv/opencv#29279, #24082).  Measured 2026-11-27: the same quick run gave the calibrated
    rig's errors ~1e-5 of their values apart on an Intel Xeon and on an AMD EPYC, every other
    column the same bytes; on the AMD, ``cv2.cornerSubPix`` moved the corners of 2 of the run's
    10 views by a float32 step (1.5-3e-5 px) with IPP switched off (``OPENCV_IPP=disabled``),
    and nothing else of the quick run changed with it.  IPP's switch is per thread (OpenCV
    keeps it in thread-local data), so OpenCV's own worker threads are held to this one
    meanwhile; the search takes well under a second a view either way."""
    import cv2

    use_ipp, threads = cv2.ipp.useIPP(), cv2.getNumThreads()
    cv2.ipp.setUseIPP(False)
    cv2.setNumThreads(1)
    try:
        yield
    finally:
        cv2.setNumThreads(threads)
        cv2.ipp.setUseIPP(use_ipp)


def corner_spacing_px(corners_px: np.ndarray, *, target: CalibrationTarget) -> float:
    """Median distance between neighbouring corners along the board's rows, pixels."""
    grid = np.asarray(corners_px).reshape(*target.pattern_size[::-1], 2)
    return float(np.median(np.hypot(*np.diff(grid, axis=1).reshape(-1, 2).T)))


def projector_points(
    corners_px: np.ndarray,
    column_px: np.ndarray,
    row_px: np.ndarray,
    modulation: np.ndarray,
    *,
    window_px: float,
    min_modulation: float,
) -> np.ndarray:
    """Projector coordinates of camera points by local homographies (Moreno and Taubin 2012).

    Parameters
    ----------
    corners_px : ndarray, shape (N, 2)
        Camera points (x, y), OpenCV pixel coordinates.
    column_px, row_px : ndarray, shape (H, W)
        Decoded projector column and row of every camera pixel, NaN where undecoded.
    modulation : ndarray, shape (H, W)
        Fringe modulation; a window uses its pixels with at least half its bright pixels'
        modulation (the white squares, not the dark ones or their blurred borders) and at
        least ``min_modulation``.
    window_px : float
        Half size of the square window around each point.

    Returns
    -------
    ndarray, shape (N, 2), float64: projector (x, y), NaN where a window had fewer than
    :data:`MIN_WINDOW_POINTS` usable pixels or the fit failed.

    References
    ----------
    .. [1] D. Moreno, G. Taubin, "Simple, accurate, and robust projector-camera calibration",
       3DIMPVT 2012, 464-471.
    """
    h, w = column_px.shape
    out = np.full((len(corners_px), 2), np.nan)
    r = max(2, int(math.ceil(window_px)))
    for n, (x, y) in enumerate(np.asarray(corners_px, np.float64)):
        x0, x1 = max(0, int(round(x)) - r), min(w, int(round(x)) + r + 1)
        y0, y1 = max(0, int(round(y)) - r), min(h, int(round(y)) + r + 1)
        if x1 - x0 < 3 or y1 - y0 < 3:
            continue
        col, row, mod = (a[y0:y1, x0:x1] for a in (column_px, row_px, modulation))
        ok = np.isfinite(col) & np.isfinite(row) & (mod >= min_modulation)
        if ok.sum() < MIN_WINDOW_POINTS:
            continue
        ok &= mod >= 0.5 * np.percentile(mod[ok], 90)
        if ok.sum() < MIN_WINDOW_POINTS:
            continue
        yy, xx = np.nonzero(ok)
        # centred on the corner: the fit is then well conditioned and maps the corner exactly
        src = np.stack([xx + x0 - x, yy + y0 - y], axis=1).astype(np.float64)
        dst = np.stack([col[ok], row[ok]], axis=1).astype(np.float64)
        hmg = _fit_homography(src, dst)
        if hmg is None:
            continue
        p = hmg @ np.array([0.0, 0.0, 1.0])
        out[n] = p[:2] / p[2]
    return out


def _fit_homography(src: np.ndarray, dst: np.ndarray) -> np.ndarray | None:
    """Least-squares homography (``cv2.findHomography``, method 0), refitted once without the
    points off by more than 3 robust sigmas (a stray Gray-code order error); deterministic."""
    import cv2

    keep = np.ones(len(src), bool)
    hmg = None
    for _ in range(2):
        hmg, _mask = cv2.findHomography(src[keep], dst[keep], 0)
        if hmg is None:
            return None
        proj = cv2.perspectiveTransform(src[None], hmg)[0]
        err = np.hypot(*(proj - dst).T)
        sigma = 1.4826 * np.median(err[keep]) + 1e-9
        new_keep = err <= max(3.0 * sigma, 0.05)
        if new_keep.sum() < MIN_WINDOW_POINTS or np.array_equal(new_keep, keep):
            break
        keep = new_keep
    return hmg


def _pose_scene(target: CalibrationTarget, pose: Pose, rig: Rig, index: int) -> object:
    from simbench.sim.scene import scene_from_dict

    data = {
        "name": f"calibration_pose{index:02d}",
        # the lab sets the exposure on the white paper at the nearest depth of the volume, so
        # that the brightest pose does not saturate (assumption)
        "reference_depth_m": DEPTH_RANGE_M[0],
        "object": [target.scene_object(center_m=pose.center_m, rotation_deg=pose.rotation_deg)],
    }
    return dataclasses.replace(scene_from_dict(data, where="calibration target"), rig=rig)


def _sequences(size_hw: tuple[int, int]) -> tuple[PhaseShiftSpec, PhaseShiftSpec]:
    return PhaseShiftSpec(size_hw=size_hw, axis="columns"), PhaseShiftSpec(size_hw=size_hw, axis="rows")


def observe_pose(
    target: CalibrationTarget,
    pose: Pose,
    rig: Rig,
    *,
    sensor: object,
    index: int,
    seed: int,
    render: RenderSettings,
    corner_spp: int = CALIBRATION_CORNER_SPP,
    frames_u8: Sequence[np.ndarray] | None = None,
    wait: bool = True,
) -> CalibrationView | None:
    """Render and record one pose (the white frame and both sequences), find the corners and
    decode their projector coordinates.  The white frame is rendered with ``corner_spp``
    samples (at least ``render.spp``): the corner detector reads the coverage of the pixels on
    the squares' edges, which a few path-tracing samples make noisy (a real pixel integrates
    its area exactly; measured on the default rig: corner RMS 0.06 px at 16 multijittered
    samples, 0.1-0.2 px at 4-16 independent ones), while the sequences' sampling noise
    averages out over the ~1000 pixels of a local homography.  ``frames_u8``: drives in place of
    :func:`calibration_frames` (None: those, made once per process when a pose is not cached).  ``rig`` is the
    ideal rig (the sensor model adds its lenses, :func:`simbench.sim.capture.physical_scene`);
    the observations are cached in ``render.cache`` by everything that affects them, the
    frames' renders are not (up to 3 x 25 images a pose).  ``wait=False``: None when another
    process sharing the cache is observing the pose (its observation is then read later)."""
    from simbench.sim.scene import scene_fingerprint
    from simbench.sim.sensor import sensor_to_dict
    from simbench.sim.keys import cached_arrays
    from simbench.sim.capture import physical_scene

    scene = physical_scene(_pose_scene(target, pose, rig, index), sensor)
    render_seed = derive_seed(seed, f"calibration/pose{index}/render")
    noise_seed = derive_seed(seed, f"calibration/pose{index}/noise")
    cols, rows = _sequences(rig.projector.size_hw)

    def make() -> dict:
        frames = calibration_frames(rig.projector.size_hw) if frames_u8 is None else frames_u8
        cam, proj = _observe(scene, target, sensor, cols, rows, render, render_seed, noise_seed, corner_spp, frames)
        return {
            "camera_px": np.zeros((0, 2)) if cam is None else cam,
            "projector_px": np.zeros((0, 2)) if proj is None else proj,
        }

    parts = {
        "scene": scene_fingerprint(scene),
        "sensor": sensor_to_dict(sensor),
        "spp": render.spp,
        "corner_spp": corner_spp,
        "sampler": render.sampler,
        "max_depth": render.max_depth,
        "seeds": [render_seed, noise_seed],
        "sequences": [dataclasses.asdict(cols), dataclasses.asdict(rows)],
        "version": OBSERVATION_VERSION,
    }
    arrays = cached_arrays("calibration_view", parts, make, cache=render.cache, wait=wait)
    if arrays is None:
        return None
    found = len(arrays["camera_px"]) > 0
    return CalibrationView(
        pose=pose,
        camera_px=arrays["camera_px"] if found else None,
        projector_px=arrays["projector_px"] if found else None,
    )


@lru_cache(maxsize=2)
def calibration_frames(projector_hw: tuple[int, int]) -> tuple[np.ndarray, ...]:
    """The projector frames of one pose as 8-bit grey drives (Hp, Wp, 3, read-only): white,
    then the column sequence, then the row sequence
    (:func:`simbench.decode.temporal.phase_shift_frames`).  Made once per projector size and
    process (~1.2 s at the paper projector's), and only when a pose is not in the cache."""
    from simbench.pattern import grey_drive

    cols, rows = _sequences(tuple(projector_hw))
    grey = [np.ones((1, *projector_hw), np.float32), phase_shift_frames(cols), phase_shift_frames(rows)]
    frames = grey_drive(np.concatenate(grey))
    frames.setflags(write=False)
    return tuple(frames)


def _observe(scene, target, sensor, cols, rows, render, render_seed, noise_seed, corner_spp, frames):
    from simbench.sim.drive import ProjectorDrive, exposure_phase
    from simbench.sim.capture import record, render_channels

    uncached = dataclasses.replace(render, cache=None)  # 75 renders a pose: too many to keep
    phase = exposure_phase(render_seed)
    # light adds linearly: the ambient light (the same in every frame of a pose) is rendered
    # once per sample count, as render_channels would render it with each frame (same seeds)
    dark = dataclasses.replace(scene, ambient_rgb=(0.0, 0.0, 0.0))
    off = np.zeros_like(frames[0], dtype=np.float32)
    ambient: dict[int, np.ndarray | float] = {}
    grey = []
    for k, frame in enumerate(frames):
        settings = dataclasses.replace(uncached, spp=max(corner_spp, render.spp)) if k == 0 else uncached
        if settings.spp not in ambient:
            lit = max(scene.ambient_rgb) > 0
            ambient[settings.spp] = (
                render_channels(scene, off, sensor, seed=render_seed, render=settings) if lit else 0.0
            )
        # the drive as an array: an uncached render needs no digest of it; the surface's
        # distance from the projector (its defocus), the same for every frame of the pose,
        # comes from the cache (computing it per frame took ~80 ms)
        drive = ProjectorDrive(scene, frame, sensor, cache=render.cache, phase=phase).array()
        q = render_channels(dark, drive, sensor, seed=render_seed, render=settings) + ambient[settings.spp]
        # (a 10- or 12-bit camera's digital numbers at its own full scale, not uint16's)
        rec = record(q, sensor=sensor, scene=scene, rng=frame_seed(noise_seed, k))
        grey.append(camera_full_scale(rec, bits=sensor.camera.bits))
    corners = find_corners(_grey_u8(grey[0]), target=target)
    if corners is None:
        log.warning("%s: the target's corners were not found; the pose is left out", scene.name)
        return None, None
    n_cols = cols.captures
    stack = np.stack([grey_frame(g) for g in grey[1:]])
    c = decode_phase_shift(stack[:n_cols], spec=cols)
    r = decode_phase_shift(stack[n_cols:], spec=rows)
    # the window: half the corner spacing (a square), so a window sees its corner's squares only
    spacing = corner_spacing_px(corners, target=target)
    proj = projector_points(
        corners,
        c.column_px,
        r.column_px,
        np.minimum(c.modulation, r.modulation),
        window_px=0.5 * spacing,
        min_modulation=cols.min_modulation,
    )
    return corners, proj


def _criteria() -> tuple:
    import cv2

    return (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, _CRITERIA_ITERATIONS, _CRITERIA_EPS)


def _flags(model: str) -> int:
    import cv2

    from simbench import validate

    flags = 0
    for name in DISTORTION_MODELS[validate.choice(model, "distortion model", DISTORTION_MODELS)]:
        flags |= getattr(cv2, name)
    return flags


def _calibrate_one(
    obj: list, img: list, size_wh: tuple[int, int], model: str
) -> tuple[float, np.ndarray, np.ndarray, list]:
    """cv2.calibrateCamera with the rig file's model; (rms, K, dist (5,), per-view rms)."""
    import cv2

    k0 = np.eye(3)  # only fx / fy = 1 is used (CALIB_FIX_ASPECT_RATIO without a guess)
    rms, k, dist, rvecs, tvecs = cv2.calibrateCamera(
        obj, img, size_wh, k0, np.zeros(5), flags=_flags(model), criteria=_criteria()
    )
    per_view = []
    for o, i, rv, tv in zip(obj, img, rvecs, tvecs):
        p, _ = cv2.projectPoints(o, rv, tv, k, dist)
        per_view.append(float(np.sqrt(np.mean(np.sum((p.reshape(-1, 2) - i.reshape(-1, 2)) ** 2, axis=1)))))
    return float(rms), k, dist.ravel()[:5], per_view


def _intrinsics(k: np.ndarray, dist: np.ndarray, size_hw: tuple[int, int]) -> Intrinsics:
    h, w = size_hw
    return Intrinsics(w, h, float(k[0, 0]), float(k[0, 2]), float(k[1, 2]), tuple(float(d) for d in dist[:5]))


@contextmanager
def _single_thread_solvers() -> Iterator[None]:
    """OpenCV's solvers and BLAS on one thread, so that the calibration does not depend on the
    machine's core count.  OpenCV's multi-threaded Levenberg-Marquardt sums in a varying order
    (measured: the focal length differs in the 12th digit from run to run); a multi-threaded
    OpenBLAS sums in an order set by its thread count (measured: the calibrated rig's errors
    differ in the 10th digit between 1 and 2 threads).  One thread is bit-reproducible, and the
    solve takes well under a second either way."""
    import cv2
    from threadpoolctl import threadpool_limits

    before = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        with threadpool_limits(1, user_api="blas"):
            yield
    finally:
        cv2.setNumThreads(before)


def solve_calibration(
    views: list[CalibrationView],
    *,
    target: CalibrationTarget,
    camera_hw: tuple[int, int],
    projector_hw: tuple[int, int],
    distortion: str = "radial",
) -> CalibrationResult:
    """Camera, projector and stereo calibration from the views' observations (module
    docstring, steps 1-3) with the lens model ``distortion`` (:data:`DISTORTION_MODELS`).
    Needs >= 3 views with their corners found (Zhang's minimum for a full pinhole); a corner
    enters the projector's and the stereo solve only with its projector coordinates.
    """
    with _single_thread_solvers():
        return _solve(views, target, camera_hw, projector_hw, distortion)


def _solve(views, target, camera_hw, projector_hw, distortion) -> CalibrationResult:
    import cv2

    obj_all = target.object_points()
    found = [k for k, v in enumerate(views) if v.camera_px is not None]
    if len(found) < 3:
        raise ValueError(f"the target was found in {len(found)} of {len(views)} views; calibration needs at least 3")
    cam_obj = [obj_all for _ in found]
    cam_img = [views[k].camera_px.astype(np.float32) for k in found]
    rms_c, k_c, d_c, view_c = _calibrate_one(cam_obj, cam_img, camera_hw[::-1], distortion)

    used, s_obj, s_cam, s_proj = [], [], [], []
    for k in found:
        ok = np.all(np.isfinite(views[k].projector_px), axis=1)
        if ok.sum() >= 6:  # a homography per view needs 4; 6 keep it from being exact
            used.append(k)
            s_obj.append(obj_all[ok])
            s_cam.append(views[k].camera_px[ok].astype(np.float32))
            s_proj.append(views[k].projector_px[ok].astype(np.float32))
    if len(used) < 3:
        raise ValueError(
            f"the projector's coordinates were decoded in {len(used)} views; calibrating it needs at least 3"
        )
    rms_p, k_p, d_p, view_p = _calibrate_one(s_obj, s_proj, projector_hw[::-1], distortion)
    flags = _flags(distortion) | cv2.CALIB_USE_INTRINSIC_GUESS
    rms_s, k_c, d_c, k_p, d_p, r, t, _e, _f = cv2.stereoCalibrate(
        s_obj, s_cam, s_proj, k_c, d_c, k_p, d_p, camera_hw[::-1], flags=flags, criteria=_criteria()
    )
    # OpenCV: X_proj = R X_cam + T; the rig file: X_cam = R_rig X_proj + t
    r_rig = r.T
    t_rig = -r.T @ t.ravel()
    rig = Rig(
        camera=_intrinsics(k_c, d_c.ravel(), camera_hw),
        projector=_intrinsics(k_p, d_p.ravel(), projector_hw),
        position_m=tuple(float(x) for x in t_rig),
        rotation_deg=angles_xyz_deg(r_rig),
        name="calibrated",
    )
    residuals = _stereo_residuals(s_obj, s_cam, s_proj, k_c, d_c, k_p, d_p, r, t)
    view_rms = {"camera": [math.nan] * len(views), "projector": [math.nan] * len(views)}
    for k, v in zip(found, view_c):
        view_rms["camera"][k] = v
    for k, v in zip(used, view_p):
        view_rms["projector"][k] = v
    return CalibrationResult(
        rig=rig,
        rms_px={"camera": rms_c, "projector": rms_p, "stereo": float(rms_s)},
        view_rms_px=view_rms,
        residuals_px=residuals,
        views=tuple(views),
        used_views=tuple(used),
    )


def _stereo_residuals(obj, cam, proj, k_c, d_c, k_p, d_p, r, t) -> dict[str, np.ndarray]:
    """Residuals of the stereo solution: each view's board pose from the camera (solvePnP
    with the refined camera), then projected into both devices."""
    import cv2

    res_c, res_p = [], []
    for o, c, p in zip(obj, cam, proj):
        ok, rv, tv = cv2.solvePnP(o, c, k_c, d_c, flags=cv2.SOLVEPNP_ITERATIVE)
        if not ok:
            continue
        pc, _ = cv2.projectPoints(o, rv, tv, k_c, d_c)
        rot = cv2.Rodrigues(rv)[0]
        rv_p = cv2.Rodrigues(r @ rot)[0]
        tv_p = r @ tv + t.reshape(3, 1)
        pp, _ = cv2.projectPoints(o, rv_p, tv_p, k_p, d_p)
        res_c.append(pc.reshape(-1, 2) - c.reshape(-1, 2))
        res_p.append(pp.reshape(-1, 2) - p.reshape(-1, 2))
    return {"camera": np.concatenate(res_c), "projector": np.concatenate(res_p)}


def true_rig(rig: Rig, sensor: object) -> Rig:
    """The rig the renders realise: ``rig`` with the sensor's lens distortion, the projector's
    principal point on Mitsuba's padding grid - what a perfect calibration would return."""
    from simbench.sim.sensor import apply_to_rig
    from simbench.sim.mitsuba_dict import realised_rig

    return realised_rig(apply_to_rig(rig, sensor))


def rig_errors(estimated: Rig, truth: Rig) -> dict[str, float]:
    """Per-parameter error of an estimated rig: focal lengths in % of the truth, principal
    points and distortion coefficients as differences, baseline and projector position in mm,
    the rotation as the angle of ``R_est R_true^T`` in degrees."""
    out: dict[str, float] = {}
    for dev in ("camera", "projector"):
        e, t = getattr(estimated, dev), getattr(truth, dev)
        out[f"{dev}_focal_pct"] = 100.0 * (e.focal_px - t.focal_px) / t.focal_px
        out[f"{dev}_cx_px"] = e.cx_px - t.cx_px
        out[f"{dev}_cy_px"] = e.cy_px - t.cy_px
        for name, a, b in zip(("k1", "k2", "p1", "p2", "k3"), e.distortion, t.distortion):
            out[f"{dev}_{name}"] = a - b
    out["baseline_mm"] = 1000.0 * (estimated.baseline_m - truth.baseline_m)
    out["position_mm"] = 1000.0 * float(np.linalg.norm(np.subtract(estimated.position_m, truth.position_m)))
    rel = estimated.rotation @ truth.rotation.T
    out["rotation_deg"] = math.degrees(math.acos(float(np.clip((np.trace(rel) - 1.0) / 2.0, -1.0, 1.0))))
    return out


def check_calibration(rig: Rig, *, target: CalibrationTarget, sensor: object | None) -> None:
    """A ValueError, before any render, when :func:`calibrate_rig` cannot calibrate ``rig`` with
    ``target`` through ``sensor``: a rig whose lenses are not the sensor model's, a target that
    looks the same turned by 180 degrees."""
    from simbench.sim.sensor import check_rig_lens

    if sensor is not None:  # (tests observe poses without one)
        check_rig_lens(rig, sensor, where=f"the rig to calibrate ({rig.name})")
    columns, rows = target.squares
    if (columns + rows) % 2 == 0:  # (a printed chart in a scene may have any counts)
        raise ValueError(
            f"calibration target {target.name!r}: squares {[columns, rows]} - give one count even and the other odd: "
            f"with {columns - 1} x {rows - 1} inner corners the board looks the same turned by 180 degrees, and its "
            "corners could be found in either order (OpenCV's rule for calibration checkerboards)"
        )


def calibrate_rig(
    rig: Rig,
    *,
    target: CalibrationTarget,
    sensor: object,
    poses: int = DEFAULT_POSES,
    seed: int = DEFAULT_SEED,
    render: RenderSettings,
    corner_spp: int = CALIBRATION_CORNER_SPP,
    distortion: str = "radial",
    progress: Callable[[int, int], None] | None = None,
) -> CalibrationResult:
    """The whole procedure (module docstring) for ``rig`` seen through ``sensor``: ``poses``
    seeded target poses, each rendered, recorded and observed, then solved.

    Parameters
    ----------
    rig : the ideal rig (a preset or file: the sensor model adds its lenses)
    target : the printed board
    sensor : :class:`simbench.sim.sensor.SensorModel`
    poses : number of target poses (OpenCV's documentation asks for >= 10 views)
    seed : base seed: the poses (``calibration/poses``) and each pose's render and noise
    render : the sequences' spp, the sampler, path depth and the cache of the observations
    corner_spp : samples per pixel of the white frames (:func:`observe_pose`)
    distortion : the lens model fitted (:data:`DISTORTION_MODELS`)
    progress : called with (poses done, poses) after each pose
    """
    check_calibration(rig, target=target, sensor=sensor)
    plan = calibration_poses(target, rig, count=poses, rng=derive_seed(seed, "calibration/poses"))
    views: list[CalibrationView | None] = [None] * len(plan)
    # Processes sharing the cache (reproduce's workers, which all calibrate the run's rig
    # first) share the poses: first those no other process is observing, then the rest, read
    # once their observer has stored them (on one process: every pose in the first pass).
    for wait in (False, True):
        for k, pose in enumerate(plan):
            if views[k] is not None:
                continue
            views[k] = observe_pose(
                target, pose, rig, sensor=sensor, index=k, seed=seed, render=render, corner_spp=corner_spp, wait=wait
            )
            if views[k] is not None and progress is not None:
                progress(sum(v is not None for v in views), len(plan))
    return solve_calibration(
        views,
        target=target,
        camera_hw=rig.camera.size_hw,
        projector_hw=rig.projector.size_hw,
        distortion=distortion,
    )
