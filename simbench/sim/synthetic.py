"""Analytic captures of a plane in numpy (no Mitsuba): for decoder tests and benchmarks.

Each camera pixel is integrated over ``supersample x supersample`` sub-pixel rays (the box
filter of the Mitsuba renders); each ray meets the plane, is projected into the projector and
takes the value of the DMD pixel it lands in (nearest, as a DMD shows constant pixels).
Radiance is ``albedo * drive``: no falloff or shading, which a noise-free decoder test does not
need.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from simbench.rig import Rig, project_to_projector

__all__ = ["plane_hits", "synthetic_plane_capture"]


def plane_hits(rows: np.ndarray, cols: np.ndarray, rig: Rig, *, normal: np.ndarray, point_m: np.ndarray) -> np.ndarray:
    """Points where camera rays through (rows, cols) meet the plane ``normal . (X - point) = 0``.

    Returns
    -------
    ndarray, shape rows.shape + (3,), float64; NaN where the ray misses (parallel or behind)
    """
    cam = rig.camera
    rays = np.stack(
        [(cols - cam.cx_px) / cam.focal_px, (rows - cam.cy_px) / cam.focal_px, np.ones_like(rows, dtype=np.float64)],
        axis=-1,
    )
    n = np.asarray(normal, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.dot(np.asarray(point_m, dtype=np.float64), n) / (rays @ n)
    t = np.where(np.isfinite(t) & (t > 0), t, np.nan)
    return rays * t[..., None]


def synthetic_plane_capture(
    drive: np.ndarray,
    rig: Rig,
    *,
    normal: Sequence[float] = (0.0, 0.0, -1.0),
    point_m: Sequence[float] = (0.0, 0.0, 1.0),
    albedo: float = 0.8,
    supersample: int = 4,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Noise-free capture of a plane lit by the projector, or of a sequence of drives (the plane
    traced once for all its frames: 12 phase-shift frames at 6 x 6 rays took 40 s one by one;
    each image has the bits a capture of its drive alone gets).

    Parameters
    ----------
    drive : ndarray, shape (Hp, Wp, 3) or (N, Hp, Wp, 3), float32
        Projector output per channel (of each frame).
    rig : Rig
    normal, point_m : 3-vectors
        The plane.
    albedo : float
    supersample : int
        Sub-pixel rays per pixel side.

    Returns
    -------
    image : ndarray, shape (H, W, 3) or (N, H, W, 3), float32 (radiance)
    column_px : ndarray, shape (H, W), float64; true projector column at pixel centres
    depth_m : ndarray, shape (H, W), float32; true z-depth at pixel centres
    """
    h, w = rig.camera.size_hw
    hp, wp = rig.projector.size_hw
    drive = np.asarray(drive)
    drives = drive[None] if drive.ndim == 3 else drive
    if drives.ndim != 4 or drives.shape[1:] != (hp, wp, 3):
        raise ValueError(f"drive shape {drive.shape} does not match the projector {(hp, wp, 3)}")
    imgs = np.zeros((len(drives), h, w, 3), np.float64)
    offs = (np.arange(supersample) + 0.5) / supersample - 0.5
    rr, cc = np.meshgrid(np.arange(h, dtype=np.float64), np.arange(w, dtype=np.float64), indexing="ij")
    for dy in offs:
        for dx in offs:
            pts = plane_hits(rr + dy, cc + dx, rig, normal=normal, point_m=point_m)
            u, v, _ = project_to_projector(pts, rig)
            iu = np.floor(u + 0.5)
            iv = np.floor(v + 0.5)
            inside = np.isfinite(u) & (iu >= 0) & (iu < wp) & (iv >= 0) & (iv < hp)
            iu = np.where(inside, iu, 0).astype(np.intp)
            iv = np.where(inside, iv, 0).astype(np.intp)
            for img, frame in zip(imgs, drives):
                img += np.where(inside[..., None], frame[iv, iu], 0.0)
    imgs *= albedo / supersample**2
    centre = plane_hits(rr, cc, rig, normal=normal, point_m=point_m)
    u, _, _ = project_to_projector(centre, rig)
    images = imgs.astype(np.float32)
    return images[0] if drive.ndim == 3 else images, u, centre[..., 2].astype(np.float32)
