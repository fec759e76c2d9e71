"""What the projector emits for an 8-bit pattern: transfer curve, black level, the DMD's pixel
layout and defocus.  Each function is pure; :func:`emitted_pattern` chains them in the order
light takes (electronics -> mirrors -> lens).

Transfer: ``linear`` is the LightCrafter 4500's pattern mode (8-bit patterns are shown as
binary bit-planes with exposure times in the ratio of the bit weights, so the emitted light is
proportional to the 8-bit value); ``gamma`` is its video mode (a display gamma such as 2.2).

Timing: a DMD makes grey levels in time, showing each bit-plane of a channel for a time
proportional to its weight, so a camera sees the intended level only if its exposure takes in
whole sequences.  ``triggered`` is the paper's set-up (the LightCrafter 4500 in pattern mode
triggers the camera, which exposes for whole patterns): exact.  ``video`` is a free-running
projector in video mode beside a free-running camera (a lab without a trigger cable): each
frame shows red, green and blue in turn, and the exposure starts at an arbitrary point of the
frame, so the bit-planes its ends cut are collected in part (:func:`video_bitplane_weights`).

Black level: a DMD's "off" mirrors still send some light into the lens; with a full-on /
full-off contrast ratio ``C`` the emitted level is ``1/C + (1 - 1/C) * t(v)``.

DMD layout: the DLP4500 is a 912 x 1140 array of diamond (45-degree) mirrors whose alternate
rows are shifted by half a mirror; the 1824-column pattern lives on half-mirror columns.  In
``diamond`` mode mirror ``i`` of row ``r`` covers pattern columns ``2i + (r mod 2)`` and the
next one and shows their mean, so each row shows pairs of equal columns, alternate rows
offset by one column (the diamond's shape is approximated by its bounding pair of columns).
"""

from __future__ import annotations

import math

import numpy as np

from simbench import native
from simbench.optics import blur_sigma_px, depth_varying_blur

__all__ = [
    "TRANSFERS",
    "TIMINGS",
    "DMD_LAYOUTS",
    "transfer_curve",
    "video_bitplane_weights",
    "dmd_layout",
    "defocus_pattern",
    "emitted_pattern",
]

TRANSFERS = ("linear", "gamma")
TIMINGS = ("triggered", "video")
BITS = 8
DMD_LAYOUTS = ("square", "diamond")


def video_bitplane_weights(*, exposure_s: float, frame_rate_hz: float, phase: float) -> np.ndarray:
    """Share of each bit-plane's light a free-running camera collects from a projector in
    video mode, relative to what an exposure of whole frames would, shape (3, 8), float64.

    Model (assumption: TI's DLPC350 programmer's guide documents video mode's bit-plane
    sequences only as configurable, so this takes the simplest): every frame of
    ``1 / frame_rate_hz`` shows red, green, then blue for a third of the frame each, each colour
    its 8 bit-planes most significant first for times in the ratio 128:64:...:1, without dark
    time.  The exposure ``[t0, t0 + exposure_s)`` starts at ``t0 = phase / frame_rate_hz``.
    Weight (c, b) is the time the exposure overlaps plane b of colour c, over
    ``exposure_s * frame_rate_hz`` times the plane's time per frame: all weights are 1 when the
    exposure is a whole number of frames, whatever the phase, and 1 on average over the phase.
    """
    if not exposure_s > 0 or not frame_rate_hz > 0:
        raise ValueError(f"exposure_s and frame_rate_hz must be > 0, got {exposure_s}, {frame_rate_hz}")
    if not 0.0 <= phase < 1.0:
        raise ValueError(f"phase must be in [0, 1), got {phase}")
    frame = 1.0 / frame_rate_hz
    seg = frame / 3.0
    weights = np.empty((3, BITS))
    t0, t1 = phase * frame, phase * frame + exposure_s
    full = float(2**BITS - 1)
    for c in range(3):
        start = c * seg
        for b in range(BITS - 1, -1, -1):  # most significant first
            dur = seg * (2**b) / full
            got = 0.0
            for k in range(math.floor((t0 - start - dur) / frame), math.ceil((t1 - start) / frame) + 1):
                a = start + k * frame
                got += max(0.0, min(t1, a + dur) - max(t0, a))
            weights[c, b] = got / (exposure_s * frame_rate_hz * dur)
            start += dur
    return weights


def transfer_curve(
    pattern: np.ndarray,
    *,
    transfer: str,
    gamma: float = 2.2,
    contrast_ratio: float = math.inf,
    bitplane_weights: np.ndarray | None = None,
) -> np.ndarray:
    """Relative emitted light per channel for an 8-bit pattern.

    Parameters
    ----------
    pattern : ndarray, shape (H, W, 3), uint8
    transfer : {'linear', 'gamma'}
    gamma : float
        Display gamma of the ``gamma`` transfer.
    contrast_ratio : float
        Full-on / full-off contrast (``inf`` = perfectly black off-state).
    bitplane_weights : ndarray, shape (3, 8), optional
        The share of each bit-plane a camera collects (:func:`video_bitplane_weights`); the
        level shown is the transfer's rounded to 8 bits, each of its set bits weighted.
        None = every plane collected whole (a triggered camera).

    Returns
    -------
    ndarray, shape (H, W, 3), float32 in [0, 1]
    """
    if pattern.dtype != np.uint8:
        raise ValueError(f"the projector takes 8-bit patterns, got {pattern.dtype}")
    if pattern.ndim != 3 or pattern.shape[2] != 3:
        raise ValueError(f"the projector takes (H, W, 3) patterns, got shape {pattern.shape}")
    # a function of each channel's 8-bit code alone: its 256 values per channel, computed by
    # numpy's float32 operations, then looked up per pixel (in C: one pass, not eight)
    table = _transfer_table(transfer, gamma, contrast_ratio, bitplane_weights)
    code = np.ascontiguousarray(pattern)
    out = np.empty(code.shape, np.float32)
    native.bind(_LUT).lut_u8(
        code.shape[0] * code.shape[1],
        3,
        native.ptr(code, "pattern", np.uint8, code.shape),
        native.ptr(table, "table", np.float32, (256, 3)),
        native.ptr(out, "out", np.float32, code.shape, writable=True),
    )
    return out


_LUT = {"lut_u8": (None, [native.I64, native.I64, native.P, native.P, native.P])}
_DMD = {"dmd_diamond": (None, [native.I64, native.I64, native.I64, native.P, native.P])}


def _transfer_table(
    transfer: str, gamma: float, contrast_ratio: float, bitplane_weights: np.ndarray | None
) -> np.ndarray:
    """:func:`transfer_curve` of every 8-bit code, per channel: (256, 3) float32."""
    if transfer not in TRANSFERS:
        raise ValueError(f"unknown projector transfer {transfer!r}; valid: {list(TRANSFERS)}")
    if not gamma > 0:
        raise ValueError(f"gamma must be > 0, got {gamma}")
    if not contrast_ratio >= 1:
        raise ValueError(f"contrast_ratio must be >= 1, got {contrast_ratio}")
    pattern = np.repeat(np.arange(256, dtype=np.uint8)[:, None], 3, axis=1)  # (256, 3): every code
    v = pattern.astype(np.float32) / np.float32(255.0)
    if transfer == "gamma":
        v = v ** np.float32(gamma)
    if bitplane_weights is not None:
        w = np.asarray(bitplane_weights, np.float64)
        if w.shape != (3, BITS):
            raise ValueError(f"bitplane_weights must have shape (3, {BITS}), got {w.shape}")
        codes = np.arange(256)
        shown = codes if transfer == "linear" else np.round((codes / 255.0) ** gamma * 255.0)
        bits = (shown.astype(np.int64)[:, None] >> np.arange(BITS)) & 1  # (256, 8)
        lut = (bits * (2.0 ** np.arange(BITS)) @ w.T / 255.0).astype(np.float32)  # (256, 3)
        v = np.stack([lut[pattern[..., c], c] for c in range(3)], axis=-1)
    black = np.float32(0.0 if math.isinf(contrast_ratio) else 1.0 / contrast_ratio)
    if black > 0:
        v = black + (np.float32(1.0) - black) * v
    return v.astype(np.float32)


def dmd_layout(drive: np.ndarray, *, layout: str) -> np.ndarray:
    """The drive as the DMD's mirrors show it (module docstring).

    Parameters
    ----------
    drive : ndarray, shape (H, W, C), float32, W even for ``diamond``
    layout : {'square', 'diamond'}
    """
    if layout not in DMD_LAYOUTS:
        raise ValueError(f"unknown DMD layout {layout!r}; valid: {list(DMD_LAYOUTS)}")
    if layout == "square":
        return drive
    h, w = drive.shape[:2]
    if w % 2:
        raise ValueError(f"a diamond DMD needs an even number of pattern columns, got {w}")
    src = np.ascontiguousarray(drive, dtype=np.float32)
    c = 1 if src.ndim == 2 else src.shape[2]
    out = np.empty_like(src)
    # even rows: the mean of column pairs (0, 1), (2, 3), ...; odd rows: mirrors start half a
    # mirror to the right, pairs (1, 2), (3, 4), ..., the first and last columns the edge
    # mirrors' visible halves; 0.5 * (a + b) in float32, in C (one pass, not numpy's eight)
    native.bind(_DMD).dmd_diamond(
        h,
        w,
        c,
        native.ptr(src, "drive", np.float32, src.shape),
        native.ptr(out, "out", np.float32, out.shape, writable=True),
    )
    return out


def defocus_pattern(
    drive: np.ndarray, distance_m: np.ndarray, *, aperture_m: float, focal_px: float, focus_m: float
) -> np.ndarray:
    """Defocus of the projector lens: blur the DMD image, at each projector pixel, by the blur
    circle of the surface it lights (thin lens, :mod:`simbench.optics`).

    The blur of light arriving at a surface at distance z from the lens, seen back in DMD
    pixels, is the thin lens's blur circle for an object at z; blurring the pattern by it is
    exact for a surface at constant depth and a good approximation where depth varies slowly
    over the blur (at depth edges it mixes the two sides' blur).

    Parameters
    ----------
    drive : ndarray, shape (H, W, 3), float32
    distance_m : ndarray, shape (H, W); depth along the projector's axis of the surface each
        projector pixel lights (NaN = nothing lit: no blur needed)
    """
    if distance_m.shape != drive.shape[:2]:
        raise ValueError(f"projector depth map shape {distance_m.shape} differs from the pattern's {drive.shape[:2]}")
    sigma = blur_sigma_px(distance_m, aperture_m=aperture_m, focal_px=focal_px, focus_m=focus_m)
    return depth_varying_blur(drive, sigma)


def emitted_pattern(
    pattern: np.ndarray,
    *,
    transfer: str = "linear",
    gamma: float = 2.2,
    contrast_ratio: float = math.inf,
    layout: str = "square",
    bitplane_weights: np.ndarray | None = None,
) -> np.ndarray:
    """Transfer curve (with the bit-plane timing), black level and DMD layout of an 8-bit
    pattern (defocus and distortion need the scene and the lens, see
    :func:`simbench.sim.drive.projector_drive_for`).

    Returns
    -------
    ndarray, shape (H, W, 3), float32 in [0, 1] (above 1 where a video-mode exposure
    collects more than its share of a plane)
    """
    v = transfer_curve(
        pattern, transfer=transfer, gamma=gamma, contrast_ratio=contrast_ratio, bitplane_weights=bitplane_weights
    )
    return dmd_layout(v, layout=layout)
