"""The projector drive: what Mitsuba's ideal projector shows so that a scene is lit as by the
modelled projector (transfer curve, bit-plane timing, black level, DMD layout, defocus, lens
dispersion and distortion), built lazily and known by its digest before it is built.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from simbench.cache import RenderCache, array_digest
from simbench.sim.scene import scene_fingerprint
from simbench.sim.sensor import SensorModel, sensor_to_dict
from simbench.optics import distorted_projector_drive, lateral_colour_image
from simbench.sim.keys import cached_arrays, renderer_id, sim_code_digest
from simbench.sim.photometry import (
    exposure_s,
    white_board,
)
from simbench.sim.projector import defocus_pattern, emitted_pattern, video_bitplane_weights
from simbench.rig import rig_to_dict
from simbench.sim.scene import SceneSpec
from simbench.seeds import child_seed
from simbench.sim.truth import projector_distance

__all__ = ["DriveImage", "ProjectorDrive", "projector_drive_for", "exposure_phase", "PROJECTOR_DEPTH_STRIDE"]


class DriveImage:
    """An image for the projector known by its SHA-256 before it is built: ``digest`` keys the
    render cache, ``make()`` builds the image only for a render the cache does not hold."""

    def __init__(self, digest: str, make: Callable[[], np.ndarray]) -> None:
        self.digest = digest
        self.make = make


PROJECTOR_DEPTH_STRIDE = 4  # projector pixels per depth sample for the defocus map


def exposure_phase(render_seed: int) -> float:
    """Where in the projector's frame a free-running camera's exposure starts, in [0, 1) of a
    frame (projector ``timing = "video"``): drawn from the capture's render seed, since the
    light the camera collects - and so the render - depends on it."""
    return float(np.random.default_rng(child_seed(render_seed, "dlp_exposure_phase")).random())


def projector_drive_for(
    scene: SceneSpec, pattern: np.ndarray, sensor: SensorModel, *, cache: RenderCache | None = None, phase: float = 0.0
) -> np.ndarray:
    """What Mitsuba's ideal projector must show so that the scene is lit as by the modelled
    one: transfer curve, bit-plane timing (video mode: the exposure, from ``phase`` of a frame
    on, :func:`exposure_phase`), black level, DMD layout, defocus (by the depth each projector
    pixel lights) and lens distortion (:mod:`simbench.sim.projector`, :mod:`simbench.optics`)."""
    return ProjectorDrive(scene, pattern, sensor, cache=cache, phase=phase).array()


def _bitplane_weights(scene: SceneSpec, sensor: SensorModel, phase: float) -> np.ndarray | None:
    prj = sensor.projector
    if prj.timing != "video":
        return None
    if not sensor.is_physical:
        raise ValueError("the projector's video-mode timing needs the physical (emva) camera's exposure time")
    return video_bitplane_weights(
        exposure_s=exposure_s(sensor, scene.rig, **white_board(scene)), frame_rate_hz=prj.frame_rate_hz, phase=phase
    )


def _build_drive(
    scene: SceneSpec, pattern: np.ndarray, sensor: SensorModel, *, cache: RenderCache | None, weights: np.ndarray | None
) -> np.ndarray:
    prj = sensor.projector
    drive = emitted_pattern(
        pattern,
        transfer=prj.transfer,
        gamma=prj.gamma,
        contrast_ratio=prj.contrast_ratio,
        layout=prj.dmd,
        bitplane_weights=weights,
    )
    intr = scene.rig.projector
    if prj.lens.defocus:
        parts = {
            "scene": scene_fingerprint(dataclasses.replace(scene, camera_lens=None, ambient_rgb=(0.0, 0.0, 0.0))),
            "stride": PROJECTOR_DEPTH_STRIDE,
        }
        dist = cached_arrays(
            "projector_depth",
            parts,
            lambda: {"z": projector_distance(scene, stride=PROJECTOR_DEPTH_STRIDE)},
            cache=cache,
        )["z"]
        drive = defocus_pattern(
            drive,
            dist,
            aperture_m=prj.lens.aperture_m(intr.focal_px, prj.pixel_pitch_um),
            focal_px=intr.focal_px,
            focus_m=prj.lens.focus_m,
        )
    # the lens disperses what the DMD shows, then distorts it (simbench.optics)
    drive = lateral_colour_image(drive, intr, shift_px=prj.lens.lateral_colour_px)
    if intr.has_distortion:
        drive = distorted_projector_drive(drive, intr)
    return np.ascontiguousarray(drive, dtype=np.float32)


def mono_drive(drive: np.ndarray, p: int) -> np.ndarray:
    """Primary ``p``'s channel of the drive in all three channels (a crosstalk render's drive)."""
    return np.ascontiguousarray(np.repeat(drive[..., p : p + 1], 3, axis=2))


class ProjectorDrive:
    """:func:`projector_drive_for`'s drive, built on first use.  The render cache keys on the
    drive's digest (and on those of the single-primary drives a crosstalk render uses); these
    digests are kept in ``cache`` under a key of the drive's inputs - pattern bytes, projector
    model, exposure phase, rig, the scene's geometry when defocus depends on it, and the code
    that builds drives - so a run whose renders are all cached never builds a drive (building
    one, with its depth-dependent defocus, took a third of a warm quick run).

    ``pattern`` is an array (hashed here) or a :class:`DriveImage`: its digest known, for a
    caller that keeps the pattern's digest (hashing a projector frame per drive was ~6 ms; a
    phase-shift sequence makes 25 drives per acquisition), and the pattern made only if the
    drive is built."""

    def __init__(
        self,
        scene: SceneSpec,
        pattern: "np.ndarray | DriveImage",
        sensor: SensorModel,
        *,
        cache: RenderCache | None = None,
        phase: float = 0.0,
    ) -> None:
        self._scene, self._pattern, self._sensor, self._cache = scene, pattern, sensor, cache
        self._weights = _bitplane_weights(scene, sensor, phase)
        self._array: np.ndarray | None = None
        self._digests: dict[str, str] | None = None
        self._monos: dict[int, np.ndarray] = {}  # the single-primary drives hashed, for their renders

    def array(self) -> np.ndarray:
        if self._array is None:
            pattern = self._pattern.make() if isinstance(self._pattern, DriveImage) else self._pattern
            self._array = _build_drive(self._scene, pattern, self._sensor, cache=self._cache, weights=self._weights)
        return self._array

    def _compute_digests(self) -> dict[str, str]:
        a = self.array()
        out = {"rgb": array_digest(a)}
        for p in range(3):
            m = self._primary_drive(p)
            out[f"mono{p}"] = array_digest(m) if m.any() else ""  # "" = the primary lights nothing
        return out

    def _primary_drive(self, p: int) -> np.ndarray:
        if p not in self._monos:
            self._monos[p] = mono_drive(self.array(), p)
        return self._monos[p]

    def inputs(self) -> dict:
        """Everything the drive is made from (pattern bytes, projector model, exposure phase,
        rig, the scene's geometry when defocus depends on it, the code that builds drives):
        a key for what depends on the drive, known without building it."""
        prj = self._sensor.projector
        scene = self._scene
        return {
            "pattern": self._pattern.digest if isinstance(self._pattern, DriveImage) else array_digest(self._pattern),
            "projector": sensor_to_dict(self._sensor)["projector"],
            "bitplane_weights": None if self._weights is None else self._weights.tolist(),
            "rig": rig_to_dict(scene.rig),
            "geometry": scene_fingerprint(dataclasses.replace(scene, camera_lens=None, ambient_rgb=(0.0, 0.0, 0.0)))
            if prj.lens.defocus
            else None,
            "stride": PROJECTOR_DEPTH_STRIDE,
            "code": sim_code_digest(),
            **renderer_id(),
        }

    def digests(self) -> dict[str, str]:
        if self._digests is None:
            if self._cache is None or self._cache.root is None:
                self._digests = self._compute_digests()
            else:
                arrays = self._cache.get_or_make(
                    "drive_digests",
                    self.inputs(),
                    lambda: {k: np.frombuffer(v.encode(), np.uint8) for k, v in self._compute_digests().items()},
                )
                self._digests = {k: bytes(np.asarray(v, np.uint8)).decode() for k, v in arrays.items()}
        return self._digests

    def image(self) -> DriveImage:
        """The whole drive, for the render cache."""
        return DriveImage(self.digests()["rgb"], self.array)

    def primary(self, p: int) -> DriveImage | None:
        """Primary ``p`` alone in all three channels, or None where the drive leaves it off."""
        digest = self.digests()[f"mono{p}"]
        return DriveImage(digest, lambda: self._primary_drive(p)) if digest else None
