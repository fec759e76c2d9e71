"""Lens effects between the ideal pinhole renders and the devices: Brown-Conrady distortion,
thin-lens defocus and lateral chromatic aberration.

Distortion (OpenCV's model, coefficients ``(k1, k2, p1, p2, k3)`` on normalised coordinates)::

    r^2 = x^2 + y^2
    x_d = x (1 + k1 r^2 + k2 r^4 + k3 r^6) + 2 p1 x y + p2 (r^2 + 2 x^2)
    y_d = y (1 + k1 r^2 + k2 r^4 + k3 r^6) + p1 (r^2 + 2 y^2) + 2 p2 x y

* Camera: a ray with normalised direction ``(x, y)`` is recorded at pixel ``K (x_d, y_d)``.
  Mitsuba renders the ideal pinhole image, so the recorded image at pixel ``p`` is the ideal
  image at ``K D^-1(K^-1 p)`` (:func:`distort_image`) - for a barrel lens beyond the ideal
  image's ends, so a capture renders the field the lens reaches (:func:`lens_field`,
  :func:`camera_lens_image`); a decoder undoes it by sampling the
  recorded image at ``K D(x)`` for every ideal pixel (:func:`undistort_image`).
* Projector (an inverse camera): the DMD pixel that lights the ray ``(x, y)`` is ``K D(x, y)``.
  Mitsuba's projector is an ideal pinhole, so its texture at ideal pixel ``q`` is the DMD
  image at ``K D(K^-1 q)`` (:func:`distorted_projector_drive`).

Lateral colour (transverse chromatic aberration): a lens's magnification depends on the
wavelength, so each colour channel's image is scaled about the principal point by its own
factor ``1 + m_c`` - to first order, the radial term of the aberration, growing linearly with
the distance from the axis.  It is given as ``shift_px``, each channel's radial displacement at
the farthest image corner (``m_c = shift_c / r_corner``; positive outward): datasheets quote it
so, in micrometres at full field.  Camera: the recorded channel ``c`` at pixel ``p`` comes from
``c0 + (p - c0) / (1 + m_c)`` of the image without it (:func:`lateral_colour_image`, after the
distortion).  Projector: channel ``c`` of the DMD image is projected magnified by ``1 + m_c``,
so before the distortion the drive is resampled the same way.  Longitudinal colour (a focus
shift per wavelength) is not modelled: a symmetric blur biases no phase, and for the paper's
lenses the blur it adds is too small to lower the fringe's contrast measurably
(docs/sensor-model.md: a 5 um focus shift blurs the camera's image by sigma ~0.06 px and the projector's
by ~0.12 DMD px, a contrast loss below 1e-3 at the 21-px period).

Defocus of a thin lens of aperture diameter ``A`` focused at distance ``s``: a point at
distance ``z`` is spread over a blur circle of diameter ``A f |1/z - 1/s|`` in pixels of a
device with focal length ``f`` px (first order in ``F/z``, the focal length over the distance).
A uniform disc of diameter ``c`` has a per-axis standard deviation ``c / 4``; we blur with the
Gaussian of that standard deviation (:func:`blur_sigma_px`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

from simbench import native

if TYPE_CHECKING:
    from simbench.rig import Intrinsics

__all__ = [
    "distort_normalized",
    "undistort_normalized",
    "distort_image",
    "undistort_image",
    "distorted_projector_drive",
    "lateral_colour_magnification",
    "lateral_colour_image",
    "lens_field",
    "camera_lens_image",
    "undistort_projector_columns",
    "blur_circle_px",
    "blur_sigma_px",
    "depth_varying_blur",
]


def _coeffs(distortion) -> tuple[float, float, float, float, float]:
    d = tuple(float(x) for x in distortion)
    if len(d) != 5:
        raise ValueError(f"distortion must be (k1, k2, p1, p2, k3), got {distortion!r}")
    return d


def distort_normalized(x: np.ndarray, y: np.ndarray, distortion: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """Brown-Conrady forward model on normalised coordinates (module docstring).

    References
    ----------
    .. [1] D. C. Brown, "Decentering distortion of lenses", Photogrammetric Engineering 32(3),
       444-462, 1966.
    """
    k1, k2, p1, p2, k3 = _coeffs(distortion)
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return xd, yd


# fixed-point steps of the inverse lens model (converged to 1e-9 within measurement lenses' images)
UNDISTORT_ITERATIONS = 30


def undistort_normalized(
    xd: np.ndarray, yd: np.ndarray, distortion: Sequence[float], *, iterations: int = UNDISTORT_ITERATIONS
) -> tuple[np.ndarray, np.ndarray]:
    """Invert :func:`distort_normalized` by fixed-point iteration (OpenCV's method); converges
    for the moderate distortion of measurement lenses (tested to 1e-9 within the image)."""
    k1, k2, p1, p2, k3 = _coeffs(distortion)
    xd = np.asarray(xd, dtype=np.float64)
    yd = np.asarray(yd, dtype=np.float64)
    x, y = xd.copy(), yd.copy()
    for _ in range(iterations):
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        dx = 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        dy = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
        x = (xd - dx) / radial
        y = (yd - dy) / radial
    return x, y


_BROWN = {
    "brown_maps": (
        None,
        [native.I64, native.I64, native.F64, native.F64, native.F64, native.P, native.I64, native.I64] + [native.P] * 3,
    )
}


def _maps(intr, *, inverse: bool) -> tuple[np.ndarray, np.ndarray]:
    """The remap grids of :func:`distort_normalized` (``inverse`` False) or
    :func:`undistort_normalized` (True) on the camera's pixels, computed in C (simbench/_lens.c:
    the same float64 operations in the same order, so the same bits as those functions;
    tests/test_optics.py), ~20x faster than numpy (the inverse's 30 fixed-point steps cost
    ~0.5 s per camera in numpy)."""
    h, w = intr.size_hw
    d = np.asarray(_coeffs(intr.distortion), np.float64)
    mx, my = np.empty((h, w), np.float32), np.empty((h, w), np.float32)
    scratch = np.empty(3 * w, np.float64)
    native.bind(_BROWN).brown_maps(
        h,
        w,
        float(intr.focal_px),
        float(intr.cx_px),
        float(intr.cy_px),
        d.ctypes.data,
        int(inverse),
        UNDISTORT_ITERATIONS,
        scratch.ctypes.data,
        native.ptr(mx, "map_x", np.float32, writable=True),
        native.ptr(my, "map_y", np.float32, writable=True),
    )
    for m in (mx, my):
        m.setflags(write=False)
    return mx, my


_BLUR = {
    "blur_sigma_max": (native.F64, [native.I64, native.P]),
    "blur_levels": (None, [native.I64, native.I64, native.P, native.F64, native.F64] + [native.P] * 7),
    "blur_level_add": (None, [native.I64] * 7 + [native.P] * 4),
}


# The remap maps depend on the intrinsics alone (a frozen, hashable dataclass): computed once per
# device and reused, read-only (issue 16: rebuilding the map was most of an undistortion's time)
@lru_cache(maxsize=8)
def _distort_maps(intr) -> tuple[np.ndarray, np.ndarray]:
    """Where the recorded pixel's light comes from in the ideal image: K D^-1(K^-1 p)."""
    return _maps(intr, inverse=True)


@lru_cache(maxsize=8)
def _undistort_maps(intr) -> tuple[np.ndarray, np.ndarray]:
    """Where the ideal pixel is recorded: K D(K^-1 q)."""
    return _maps(intr, inverse=False)


def _remap(img: np.ndarray, mx: np.ndarray, my: np.ndarray, interpolation: int) -> np.ndarray:
    import cv2

    src = np.asarray(img)
    dtype = src.dtype
    work = src.astype(np.float32) if dtype not in (np.float32, np.uint8, np.uint16) else src
    out = cv2.remap(work, mx, my, interpolation, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    if out.ndim == 2 and src.ndim == 3:
        out = out[..., None]
    return out.astype(dtype, copy=False)


def distort_image(img: np.ndarray, intr: Intrinsics) -> np.ndarray:
    """What a camera with ``intr.distortion`` records, from the ideal pinhole image ``img``.

    Parameters
    ----------
    img : ndarray, shape (H, W) or (H, W, C)
        Image on the ideal pinhole grid of ``intr``.
    intr : simbench.rig.Intrinsics

    Returns
    -------
    ndarray, same shape and dtype; zero where the recorded pixel sees outside the ideal image
    (a simulated capture renders the wider field instead: :func:`camera_lens_image`).
    """
    import cv2

    if not intr.has_distortion:
        return img
    return _remap(img, *_distort_maps(intr), cv2.INTER_LINEAR)


def undistort_image(img: np.ndarray, intr: Intrinsics, *, interpolation: str = "linear") -> np.ndarray:
    """The ideal pinhole image from a recorded image (OpenCV's undistortion map), zero where
    the ideal pixel falls outside the recorded image.

    References
    ----------
    .. [1] D. C. Brown, "Decentering distortion of lenses", Photogrammetric Engineering 32(3),
       444-462, 1966.
    """
    import cv2

    if not intr.has_distortion:
        return img
    flag = {"linear": cv2.INTER_LINEAR, "nearest": cv2.INTER_NEAREST}[interpolation]
    return _remap(img, *_undistort_maps(intr), flag)


def distorted_projector_drive(drive: np.ndarray, intr: Intrinsics) -> np.ndarray:
    """The ideal-pinhole texture that makes Mitsuba's projector emit like a projector whose lens
    has ``intr.distortion`` while its DMD shows ``drive``: texture(q) = drive(K D(K^-1 q)).

    Bilinear sampling: the texture's pixels are not the DMD's, and nearest-neighbour sampling
    would move each DMD pixel edge by up to half a pixel (a column bias the decoder sees);
    interpolating keeps every edge where the lens puts it, softened over one texel.
    """
    return undistort_image(drive, intr, interpolation="linear")


def lateral_colour_magnification(intr: Intrinsics, shift_px: Sequence[float]) -> np.ndarray:
    """Each channel's relative magnification ``m_c`` from its radial displacement ``shift_px`` at
    the image corner farthest from the principal point (module docstring).

    Returns
    -------
    ndarray, shape (3,), float64
    """
    h, w = intr.size_hw
    corners = np.array([[0.0, 0.0], [w - 1.0, 0.0], [0.0, h - 1.0], [w - 1.0, h - 1.0]])
    r = float(np.max(np.hypot(corners[:, 0] - intr.cx_px, corners[:, 1] - intr.cy_px)))
    shift = np.asarray(shift_px, dtype=np.float64)
    if shift.shape != (3,) or not np.all(np.isfinite(shift)):
        raise ValueError(f"shift_px must be 3 finite numbers (R, G, B), got {shift_px!r}")
    return shift / r


@lru_cache(maxsize=16)
def _magnify_maps(size_hw: tuple[int, int], cx: float, cy: float, m: float) -> tuple[np.ndarray, np.ndarray]:
    h, w = size_hw
    x = cx + (np.arange(w, dtype=np.float64) - cx) / (1.0 + m)
    y = cy + (np.arange(h, dtype=np.float64) - cy) / (1.0 + m)
    mx = np.ascontiguousarray(np.broadcast_to(x.astype(np.float32), (h, w)))
    my = np.ascontiguousarray(np.broadcast_to(y.astype(np.float32)[:, None], (h, w)))
    for a in (mx, my):
        a.setflags(write=False)
    return mx, my


def lateral_colour_image(img: np.ndarray, intr: Intrinsics, *, shift_px: Sequence[float]) -> np.ndarray:
    """``img`` with channel ``c`` scaled about the principal point by ``1 + m_c`` (module
    docstring; :func:`lateral_colour_magnification`): ``out_c(p) = img_c(c0 + (p - c0) / (1 + m_c))``,
    bilinear, zero where the source falls outside the image.  For the camera, what it records
    from the image without lateral colour; for the projector, the drive its lens projects as the
    undispersed one would.

    Parameters
    ----------
    img : ndarray, shape (H, W, 3), on ``intr``'s pixel grid
    intr : simbench.rig.Intrinsics
    shift_px : 3 floats, each channel's radial displacement (px) at the farthest corner

    Returns
    -------
    ndarray, same shape and dtype (``img`` itself where every shift is 0)
    """
    mags = lateral_colour_magnification(intr, shift_px)
    if not np.any(mags):
        return img
    src = np.asarray(img)
    if src.ndim != 3 or src.shape[2] != 3 or src.shape[:2] != tuple(intr.size_hw):
        raise ValueError(f"image of shape {src.shape} is not (H, W, 3) on the {intr.size_hw} grid")
    return _magnify(src, float(intr.cx_px), float(intr.cy_px), mags)


def _magnify(src: np.ndarray, cx: float, cy: float, mags: np.ndarray) -> np.ndarray:
    """:func:`lateral_colour_image` on ``src``'s grid with principal point ``(cx, cy)`` and the
    channels' magnifications ``mags``."""
    import cv2

    out = np.empty_like(src)
    for c, m in enumerate(mags):
        if m == 0.0:
            out[..., c] = src[..., c]
            continue
        mx, my = _magnify_maps(tuple(src.shape[:2]), cx, cy, float(m))
        plane = np.ascontiguousarray(src[..., c], dtype=np.float32)
        moved = cv2.remap(plane, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        out[..., c] = moved.astype(src.dtype, copy=False)
    return out


def _padded(intr: Intrinsics, mx: int, my: int) -> Intrinsics:
    """``intr``'s ideal pinhole grown by ``mx`` columns at each side and ``my`` rows at the top and
    bottom (same rays for the same pixels: the principal point moves with the grid)."""
    if mx == 0 and my == 0:
        return intr
    return dataclasses.replace(
        intr,
        width_px=intr.width_px + 2 * mx,
        height_px=intr.height_px + 2 * my,
        cx_px=intr.cx_px + mx,
        cy_px=intr.cy_px + my,
    )


def _lateral_margin_px(shift_px: Sequence[float]) -> int:
    """Pixels beyond the recorded image that lateral colour reads from: a channel shifted inward
    by ``s`` px at the corner samples up to ``s`` px outside (one more for bilinear weights)."""
    s = max(abs(float(x)) for x in shift_px)
    return 0 if s == 0.0 else int(np.ceil(s)) + 1


@lru_cache(maxsize=8)
def _lens_geometry(intr: Intrinsics, lateral_px: int) -> tuple[Intrinsics, tuple[np.ndarray, np.ndarray] | None]:
    """The ideal field of :func:`lens_field` and the remap grids that distort it onto the recorded
    grid grown by ``lateral_px`` at every side (None without distortion: the field is that grid)."""
    ext = _padded(intr, lateral_px, lateral_px)
    if not intr.has_distortion:
        return ext.undistorted, None
    mx, my = _distort_maps(ext)
    h, w = intr.size_hw
    # the field's margin m: the ideal image's coordinate of a map value v is v + m - lateral_px;
    # m covers the lowest and highest v with a pixel to spare (bilinear reads the next one too);
    # the same margin at both sides, so a centred principal point (a thin lens) stays centred
    margins = []
    for grid, n in ((mx, w), (my, h)):
        lo, hi = float(grid.min()), float(grid.max())
        margins.append(max(0, int(np.ceil(max(lateral_px - lo, hi - lateral_px - (n - 1)))) + 1))
    field = _padded(intr.undistorted, *margins)
    dx, dy = np.float32(margins[0] - lateral_px), np.float32(margins[1] - lateral_px)
    maps = (mx + dx, my + dy)
    for m in maps:
        m.setflags(write=False)
    return field, maps


def lens_field(intr: Intrinsics, *, lateral_colour_px: Sequence[float] = (0.0, 0.0, 0.0)) -> Intrinsics:
    """The ideal pinhole field that a camera with ``intr`` (its distortion) and this lateral colour
    records: ``intr``'s grid grown, by the same margin at opposite sides, until every recorded
    pixel's light comes from inside it - a barrel lens's image ends look beyond the pinhole
    image of the same size, and a real lens shows the scene there, not black.  Render this
    field, then :func:`camera_lens_image`.  ``intr`` itself for an ideal lens.

    Returns
    -------
    simbench.rig.Intrinsics, no distortion, the same focal length
    """
    if not intr.has_distortion and _lateral_margin_px(lateral_colour_px) == 0:
        return intr
    return _lens_geometry(intr, _lateral_margin_px(lateral_colour_px))[0]


def camera_lens_image(
    ideal: np.ndarray, intr: Intrinsics, *, lateral_colour_px: Sequence[float] = (0.0, 0.0, 0.0)
) -> np.ndarray:
    """What the camera records through its lens: :func:`distort_image` then
    :func:`lateral_colour_image`, from an image of the whole field they read
    (:func:`lens_field`), so that every recorded pixel sees the scene.

    Parameters
    ----------
    ideal : ndarray, shape (H', W', C), float32, on ``lens_field(intr, lateral_colour_px=...)``'s grid
    intr : simbench.rig.Intrinsics, the camera (its distortion)
    lateral_colour_px : 3 floats, as for :func:`lateral_colour_image` (relative to ``intr``'s grid)

    Returns
    -------
    ndarray, shape (H, W, C) on ``intr``'s grid; ``ideal`` itself for an ideal lens
    """
    import cv2

    lateral_px = _lateral_margin_px(lateral_colour_px)
    field = lens_field(intr, lateral_colour_px=lateral_colour_px)
    src = np.asarray(ideal)
    if src.ndim != 3 or src.shape[:2] != tuple(field.size_hw):
        raise ValueError(
            f"image of shape {src.shape} is not (H, W, C) on the lens's field {field.size_hw} "
            f"(simbench.optics.lens_field of the {intr.size_hw} camera)"
        )
    if field is intr:
        return ideal
    maps = _lens_geometry(intr, lateral_px)[1]
    out = src if maps is None else _remap(src, *maps, cv2.INTER_LINEAR)
    mags = lateral_colour_magnification(intr, lateral_colour_px)
    if np.any(mags):
        out = _magnify(out, float(intr.cx_px) + lateral_px, float(intr.cy_px) + lateral_px, mags)
    h, w = intr.size_hw
    return np.ascontiguousarray(out[lateral_px : lateral_px + h, lateral_px : lateral_px + w])


def undistort_projector_columns(
    column_px: np.ndarray, row_norm_y: np.ndarray, intr: Intrinsics, *, iterations: int = 8
) -> np.ndarray:
    """Ideal-pinhole projector columns from decoded DMD columns.

    In a rectified rig (parallel axes, baseline along x) a camera pixel with normalised
    ``y`` sees points whose projector normalised ``y`` is the same, so the DMD column ``u_d``
    fixes the ideal ``x`` through ``fx * D_x(x, y) + cx = u_d``, solved here by Newton's method.

    Parameters
    ----------
    column_px : ndarray, shape (H, W), DMD columns (NaN = unknown)
    row_norm_y : ndarray, broadcastable to (H, W), normalised y of each camera pixel
    intr : simbench.rig.Intrinsics (the projector)
    """
    col = np.asarray(column_px, dtype=np.float64)
    if not intr.has_distortion:
        return col
    k1, k2, p1, p2, k3 = _coeffs(intr.distortion)
    y = np.broadcast_to(np.asarray(row_norm_y, dtype=np.float64), col.shape)
    target = (col - intr.cx_px) / intr.focal_px
    x = np.where(np.isfinite(target), target, 0.0)
    for _ in range(iterations):
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        dradial = 2.0 * x * (k1 + r2 * (2.0 * k2 + 3.0 * r2 * k3))
        f = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) - target
        fp = radial + x * dradial + 2.0 * p1 * y + 6.0 * p2 * x
        x = x - f / fp
    return np.where(np.isfinite(col), x * intr.focal_px + intr.cx_px, np.nan)


def blur_circle_px(distance_m: np.ndarray, *, aperture_m: float, focal_px: float, focus_m: float) -> np.ndarray:
    """Blur-circle diameter in pixels of a thin lens (module docstring); NaN distance -> NaN."""
    if not aperture_m >= 0 or not focal_px > 0 or not focus_m > 0:
        raise ValueError(f"need aperture_m >= 0, focal_px > 0, focus_m > 0; got {aperture_m}, {focal_px}, {focus_m}")
    z = np.asarray(distance_m, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        return aperture_m * focal_px * np.abs(1.0 / z - 1.0 / focus_m)


def blur_sigma_px(distance_m: np.ndarray, *, aperture_m: float, focal_px: float, focus_m: float) -> np.ndarray:
    """Standard deviation (px) of the Gaussian standing in for the blur circle: diameter / 4."""
    return blur_circle_px(distance_m, aperture_m=aperture_m, focal_px=focal_px, focus_m=focus_m) / 4.0


def depth_varying_blur(img: np.ndarray, sigma_px: np.ndarray, *, step_px: float = 0.25) -> np.ndarray:
    """Blur ``img`` with a Gaussian whose standard deviation varies per pixel.

    The image is blurred at levels ``0, step, 2 step, ...`` up to the largest sigma and each
    pixel interpolates linearly between the two levels around its own sigma (a layered
    approximation of a spatially varying point-spread function; exact where sigma is constant).

    Parameters
    ----------
    img : ndarray, shape (H, W) or (H, W, C), float32
    sigma_px : ndarray, shape (H, W), float; NaN is treated as 0 (in focus)
    step_px : float
        Spacing of the blur levels.
    """
    import cv2

    src = np.ascontiguousarray(img, dtype=np.float32)
    sig = np.ascontiguousarray(sigma_px, dtype=np.float64)
    if sig.shape != src.shape[:2]:
        raise ValueError(f"sigma map shape {sig.shape} differs from the image's {src.shape[:2]}")
    if not step_px > 0:
        raise ValueError(f"step_px must be > 0, got {step_px}")
    lib = native.bind(_BLUR)
    h, w = sig.shape
    # sigma's NaN and +inf count as 0 (np.nan_to_num); in C, in numpy's float64 operations
    smax = lib.blur_sigma_max(sig.size, native.ptr(sig, "sigma", np.float64, (h, w)))
    if smax <= 0.0:
        return src.copy()
    levels = np.arange(0.0, smax + step_px, step_px)
    # each pixel between levels lo and lo + 1 at frac (pos = clip(sigma / step, 0, top)), the
    # pixels per level, and each row's and column's lowest and highest lo: one pass in C
    lo = np.empty((h, w), np.int32)
    frac = np.empty((h, w), np.float32)
    used = np.empty(len(levels) + 1, np.int64)
    row_lo, row_hi, col_lo, col_hi = (np.empty(n, np.int32) for n in (h, h, w, w))
    lib.blur_levels(
        h,
        w,
        native.ptr(sig, "sigma", np.float64, (h, w)),
        float(step_px),
        float(len(levels) - 1),
        native.ptr(lo, "lo", np.int32, (h, w), writable=True),
        native.ptr(frac, "frac", np.float32, (h, w), writable=True),
        native.ptr(used, "used", np.int64, (len(levels) + 1,), writable=True),
        *(native.ptr(a, "extent", np.int32, a.shape, writable=True) for a in (row_lo, row_hi, col_lo, col_hi)),
    )
    # the rows and columns where a pixel interpolates from level k lie where the row's (column's)
    # lowest level <= k and highest >= k - 1: each level's sum is taken over that box only (the
    # zero weights outside it would add exact zeros; a board whose blur grows across the image
    # puts each level in a narrow strip)
    c = 1 if src.ndim == 2 else src.shape[2]
    out = np.zeros_like(src)
    for k, s in enumerate(levels):
        if used[k] == 0 and (k == 0 or used[k - 1] == 0):
            continue  # no pixel interpolates from this level
        rows = np.flatnonzero((row_lo <= k) & (row_hi >= k - 1))
        cols = np.flatnonzero((col_lo <= k) & (col_hi >= k - 1))
        cur = (
            src
            if s == 0.0
            else cv2.GaussianBlur(src, (0, 0), sigmaX=float(s), sigmaY=float(s), borderType=cv2.BORDER_REPLICATE)
        )
        cur = np.ascontiguousarray(cur, dtype=np.float32).reshape(h, w, c)  # cv2 drops a single channel
        # each pixel's weight and the sum in C: one pass instead of numpy's eight (~0.15 s a
        # projector drive), with the bits of its float32 where / multiply / add
        lib.blur_level_add(
            w,
            c,
            int(rows[0]),
            int(rows[-1]) + 1,
            int(cols[0]),
            int(cols[-1]) + 1,
            k,
            native.ptr(lo, "lo", np.int32, (h, w)),
            native.ptr(frac, "frac", np.float32, (h, w)),
            native.ptr(cur, "level", np.float32, (h, w, c)),
            native.ptr(out, "out", np.float32, out.shape, writable=True),
        )
    return out
