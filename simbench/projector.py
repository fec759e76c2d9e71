"""What the projector emits for an 8-bit pattern: transfer curve, black level, the DMD's pixel
layout and defocus.  Each function is pure; :func:`emitted_pattern` chains them in the order
light takes (electronics -> mirrors -> lens).

Transfer: ``linear`` is the LightCrafter 4500's pattern mode (8-bit patterns are shown as
binary bit-planes with exposure times in the ratio of the bit weights, so the emitted light is
proportional to the 8-bit value); ``gamma`` is its video mode (a display gamma such as 2.2).

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

from simbench.optics import blur_sigma_px, depth_varying_blur

__all__ = ["TRANSFERS", "DMD_LAYOUTS", "transfer_curve", "dmd_layout", "defocus_pattern", "emitted_pattern"]

TRANSFERS = ("linear", "gamma")
DMD_LAYOUTS = ("square", "diamond")


def transfer_curve(pattern: np.ndarray, *, transfer: str, gamma: float = 2.2, contrast_ratio: float = math.inf) -> np.ndarray:
    """Relative emitted light per channel for an 8-bit pattern.

    Parameters
    ----------
    pattern : ndarray, shape (H, W, 3), uint8
    transfer : {'linear', 'gamma'}
    gamma : float
        Display gamma of the ``gamma`` transfer.
    contrast_ratio : float
        Full-on / full-off contrast (``inf`` = perfectly black off-state).

    Returns
    -------
    ndarray, shape (H, W, 3), float32 in [0, 1]
    """
    if pattern.dtype != np.uint8:
        raise ValueError(f"the projector takes 8-bit patterns, got {pattern.dtype}")
    if transfer not in TRANSFERS:
        raise ValueError(f"unknown projector transfer {transfer!r}; valid: {list(TRANSFERS)}")
    if not gamma > 0:
        raise ValueError(f"gamma must be > 0, got {gamma}")
    if not contrast_ratio >= 1:
        raise ValueError(f"contrast_ratio must be >= 1, got {contrast_ratio}")
    v = pattern.astype(np.float32) / np.float32(255.0)
    if transfer == "gamma":
        v = v ** np.float32(gamma)
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
    out = np.empty_like(drive)
    even = drive[0::2]
    pair = 0.5 * (even[:, 0::2] + even[:, 1::2])
    out[0::2, 0::2] = pair
    out[0::2, 1::2] = pair
    odd = drive[1::2]
    # odd rows: mirrors start half a mirror to the right; the first column is the edge mirror's
    # visible half
    pair = 0.5 * (odd[:, 1:-1:2] + odd[:, 2::2])
    out[1::2, 1:-1:2] = pair
    out[1::2, 2::2] = pair
    out[1::2, 0] = odd[:, 0]
    out[1::2, -1] = odd[:, -1]
    return out


def defocus_pattern(drive: np.ndarray, distance_m: np.ndarray, *, aperture_m: float, focal_px: float, focus_m: float) -> np.ndarray:
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
) -> np.ndarray:
    """Transfer curve, black level and DMD layout of an 8-bit pattern (defocus and distortion
    need the scene and the lens, see :func:`simbench.simulate.projector_drive_for`).

    Returns
    -------
    ndarray, shape (H, W, 3), float32 in [0, 1]
    """
    return dmd_layout(transfer_curve(pattern, transfer=transfer, gamma=gamma, contrast_ratio=contrast_ratio), layout=layout)
