"""The simulator's chain for one capture: pattern -> projector drive -> scene render -> camera.
The systems (:mod:`simbench.systems`) build their acquisitions from it.

Seeds: derived from one base seed and each capture's label (:mod:`simbench.seeds`); all are
recorded.
"""

from __future__ import annotations

import dataclasses
import platform
import sys
from collections.abc import Callable
from functools import lru_cache

import numpy as np

from simbench.cache import RenderCache, array_digest, source_digest
from simbench.scene import scene_fingerprint
from simbench.device import SensorModel, apply_to_rig, sensor_to_dict
from simbench.mitsuba_dict import RenderSettings, film_settings, pass_settings
from simbench.optics import distort_image, distorted_projector_drive, lateral_colour_image
from simbench.subsurface import get_medium, subsurface_image
from simbench.photometry import (
    channel_weights,
    electrons_per_radiance_s,
    exposure_s,
    white_balance_gains,
)
from simbench.projector import defocus_pattern, emitted_pattern, video_bitplane_weights
from simbench.render import render_radiance
from simbench.rig import rig_to_dict
from simbench.scene import OBJECT_KIND_TABLE, SceneSpec, with_subsurface
from simbench.seeds import RngLike, child_seed
from simbench.sensor import SimpleCamera, emva_camera, simple_camera
from simbench.spectral import crosstalk_matrix, material_crosstalk
from simbench.truth import GroundTruth, ground_truth, projector_distance

__all__ = [
    "cached_radiance",
    "cached_ground_truth",
    "cached_arrays",
    "physical_scene",
    "exposure_phase",
    "projector_drive_for",
    "ProjectorDrive",
    "DriveImage",
    "render_channels",
    "with_translucency",
    "opaque",
    "record",
    "white_board",
    "REFERENCE_ALBEDO",
    "versions",
]


REFERENCE_ALBEDO = 0.8  # assumption: a matte white board as the reference plane


# distribution names of what provenance records (read from the installed metadata: no import,
# so nothing another package put into sys.modules, such as colour-science's stand-in for a
# missing SciPy, can break or fool the lookup)
VERSIONED_DISTRIBUTIONS = {
    "simbench": "simbench",
    "mitsuba": "mitsuba",
    "drjit": "drjit",
    "numpy": "numpy",
    # OpenCV (remaps, filters); simbench's own C loops (simbench/_lens.c, compiled at
    # install: the C compiler is recorded too)
    "opencv": "opencv-python-headless",
    "colour": "colour-science",
    "scipy": "scipy",
}


def versions() -> dict:
    """Versions of the installed packages that affect results, and of Python."""
    from importlib import metadata

    out = {}
    for key, dist in VERSIONED_DISTRIBUTIONS.items():
        try:
            out[key] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            out[key] = "not installed"
    out["python"] = platform.python_version()
    from simbench.native import compiler

    out["c_compiler"] = compiler()
    return out


def _renderer_id() -> dict:
    import mitsuba as mi

    return {"variant": mi.variant(), "mitsuba": mi.__version__}


class DriveImage:
    """An image for the projector known by its SHA-256 before it is built: ``digest`` keys the
    render cache, ``make()`` builds the image only for a render the cache does not hold."""

    def __init__(self, digest: str, make: Callable[[], np.ndarray]) -> None:
        self.digest = digest
        self.make = make


def cached_radiance(
    scene: SceneSpec,
    drive: "np.ndarray | DriveImage | None",
    *,
    spp: int,
    seed: int,
    max_depth: int,
    sampler: str = "independent",
    cache: RenderCache | None = None,
) -> np.ndarray:
    """:func:`simbench.render.render_radiance`, looked up in / stored to ``cache``; ``drive``
    may be a :class:`DriveImage`, built only on a miss."""
    kw = {"spp": spp, "seed": seed, "max_depth": max_depth, "sampler": sampler}
    lazy = isinstance(drive, DriveImage)

    def render() -> np.ndarray:
        return render_radiance(scene, drive.make() if lazy else drive, **kw)

    if cache is None:
        return render()
    digest = "off" if drive is None else (drive.digest if lazy else array_digest(drive))
    parts = {
        "scene": scene_fingerprint(scene),
        "drive": digest,
        "spp": int(spp),
        "seed": int(seed),
        "max_depth": int(max_depth),
        "sampler": sampler,
        **pass_settings(spp, pixels=scene.rig.camera.width_px * scene.rig.camera.height_px),
        **film_settings(pixels=scene.rig.camera.width_px * scene.rig.camera.height_px),
        **_renderer_id(),
    }
    return cache.get_or_make("radiance", parts, lambda: {"radiance": render()})["radiance"]


def cached_ground_truth(scene: SceneSpec, *, cache: RenderCache | None = None) -> GroundTruth:
    """:func:`simbench.truth.ground_truth`, looked up in / stored to ``cache``."""
    scene = dataclasses.replace(scene, camera_lens=None)  # the truth is at the pinhole's pixel centres
    if cache is None:
        return ground_truth(scene)

    def make() -> dict:
        gt = ground_truth(scene)
        return {"depth_m": gt.depth_m, "column_px": gt.column_px, "object_id": gt.object_id, "lit": gt.lit}

    arrays = cache.get_or_make("truth", {"scene": scene_fingerprint(scene), **_renderer_id()}, make)
    return GroundTruth(**arrays)


def physical_scene(scene: SceneSpec, sensor: SensorModel) -> SceneSpec:
    """The scene as the sensor model sees it: lens distortion in the rig (as calibration
    records it), the camera's thin lens when its defocus is on, and the ambient light at
    ``sensor.ambient_ratio`` of the projector's white irradiance at Z0 (a constant
    environment of radiance ``L`` gives an unoccluded surface ``pi L``; the projector's
    white gives ``pi * scale / Z0^2`` at Z0 in render units).  Apply once per scene."""
    rig = apply_to_rig(scene.rig, sensor)
    lens = scene.camera_lens
    if sensor.camera_lens.defocus:
        if not sensor.is_physical:
            raise ValueError(
                "camera defocus needs the physical (emva) camera model (its pixel pitch sets the aperture)"
            )
        aperture = sensor.camera_lens.aperture_m(rig.camera.focal_px, sensor.camera.pixel_pitch_um)
        lens = (aperture / 2.0, sensor.camera_lens.focus_m)
    ambient = scene.ambient_rgb
    if sensor.ambient_ratio > 0:
        level = sensor.ambient_ratio * scene.projector_scale / scene.reference_depth_m**2
        ambient = tuple(a + level for a in ambient)
    return dataclasses.replace(scene, rig=rig, camera_lens=lens, ambient_rgb=ambient)


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
    pixel lights) and lens distortion (:mod:`simbench.projector`, :mod:`simbench.optics`)."""
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


@lru_cache(maxsize=1)
def _drive_code_digest() -> str:
    """SHA-256 of the code that builds a projector drive, its C loops included (a changed model
    never reuses the digests an older one cached)."""
    import simbench.native
    import simbench.optics
    import simbench.projector

    modules = (simbench.projector, simbench.optics, sys.modules[__name__])
    return source_digest([*(m.__file__ for m in modules), simbench.native.LENS_SOURCE])


def _mono(drive: np.ndarray, p: int) -> np.ndarray:
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
            self._monos[p] = _mono(self.array(), p)
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
            "code": _drive_code_digest(),
            **_renderer_id(),
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


def cached_arrays(
    kind: str,
    parts: dict,
    make: Callable[[], dict[str, np.ndarray]],
    *,
    cache: RenderCache | None = None,
    wait: bool = True,
) -> dict[str, np.ndarray] | None:
    """``make()``'s arrays, looked up in / stored to ``cache`` under ``kind`` and ``parts``
    plus the renderer's identity (variant, Mitsuba version); ``wait=False``: None when another
    process is making them (:meth:`simbench.cache.RenderCache.get_or_make`)."""
    return make() if cache is None else cache.get_or_make(kind, {**parts, **_renderer_id()}, make, wait=wait)


def _ambient_seed(seed: int) -> int:
    """The ambient render's seed, independent of the projector render's."""
    return int(child_seed(seed, "ambient_render").generate_state(1)[0])


def _primary_scene(scene: SceneSpec, p: int) -> SceneSpec:
    """The scene lit by primary ``p`` alone, with each material's reflectance replaced by the
    camera's view of it (column ``p`` of its crosstalk matrix)."""
    white = np.clip(crosstalk_matrix((1.0, 1.0, 1.0))[:, p], 0.0, 1.0)
    objects = []
    for o in scene.objects:
        if o.material.kind == "metal":
            # its optical constants averaged over primary p's band (simbench.spectral.metal_ior_rgb)
            mat = dataclasses.replace(o.material, metal_primary=p, specular_rgb=tuple(float(x) for x in white))
        else:
            k = np.clip(material_crosstalk(o.material.rgb, o.material.spectrum)[:, p], 0.0, 1.0)
            mat = dataclasses.replace(
                o.material, rgb=tuple(float(x) for x in k), specular_rgb=tuple(float(x) for x in white)
            )
        params = dict(o.params)
        for key in OBJECT_KIND_TABLE[o.kind].colour_keys:  # a target's ink, say
            params[key] = tuple(float(x) for x in np.clip(material_crosstalk(params[key], None)[:, p], 0.0, 1.0))
        objects.append(dataclasses.replace(o, material=mat, params=tuple(sorted(params.items()))))
    return dataclasses.replace(scene, objects=tuple(objects))


def with_translucency(radiance: np.ndarray, scene: SceneSpec, *, cache: RenderCache | None = None) -> np.ndarray:
    """``radiance`` (H, W, 3) rendered of ``scene`` with its surfaces opaque, on its camera's
    ideal pixel grid, with the light its translucent objects reflect redistributed by their
    media (:func:`simbench.subsurface.subsurface_image`, per channel with that band's medium);
    ``radiance`` itself when every object is opaque.  Every system's renders pass through it, so
    that a translucent object is translucent to all of them."""
    media = {i: get_medium(o.material.subsurface) for i, o in enumerate(scene.objects) if o.material.subsurface}
    if not media:
        return radiance
    gt = cached_ground_truth(opaque(scene), cache=cache)  # the geometry is the opaque one's
    return subsurface_image(
        radiance, object_id=gt.object_id, depth_m=gt.depth_m, media=media, focal_px=scene.rig.camera.focal_px
    )


def opaque(scene: SceneSpec) -> SceneSpec:
    """``scene`` with every material's subsurface medium removed (the same object otherwise): what
    a render of it sees (:func:`with_translucency` adds the media after)."""
    if not any(o.material.subsurface for o in scene.objects):
        return scene
    return with_subsurface(scene, None)


def render_channels(
    scene: SceneSpec,
    drive: "np.ndarray | ProjectorDrive",
    sensor: SensorModel,
    *,
    seed: int,
    render: RenderSettings,
) -> np.ndarray:
    """Radiance per camera channel on the camera's recorded pixel grid, rendered with ``seed``
    and ``render``'s settings (through its cache).

    Without crosstalk: one render, channel c lit by primary c.  With crosstalk: one render per
    projector primary p (the drive's channel p in all three channels, materials replaced by
    column p of their crosstalk matrix) summed with the weights of
    :func:`simbench.photometry.channel_weights` - exact for direct light; interreflected light is
    coloured by one bounce's crosstalk only (an approximation, as is the coating's
    specular tint).  The ambient light is rendered apart (light adds linearly; one emitter
    per render keeps the path tracer's noise that of a single light) and, with crosstalk, once per
    primary's materials: light of the projector's white.  Then the translucent objects' subsurface
    scattering (:mod:`simbench.subsurface`, on the ideal pixel grid, per camera channel with that
    band's medium: an approximation where a channel sees several primaries, and it spreads all the
    object's light, a glossy coating's highlight included), the camera lens distortion and
    lateral colour (per camera channel: an approximation where a channel sees several primaries'
    wavelengths, exact for narrow-band light).

    ``scene`` is a :func:`physical_scene`; ``drive`` from :func:`projector_drive_for` (or a
    :class:`ProjectorDrive`, built only for renders the cache does not hold).

    Returns
    -------
    ndarray, shape (H, W, 3), float32, in units of each channel's own primary
    """
    translucent_scene = scene
    # the renders do not depend on what happens under the surface (applied after them)
    scene = opaque(scene)
    ambient = max(scene.ambient_rgb) > 0
    dark = dataclasses.replace(scene, ambient_rgb=(0.0, 0.0, 0.0))
    kw = {"spp": render.spp, "max_depth": render.max_depth, "sampler": render.sampler, "cache": render.cache}
    lazy = isinstance(drive, ProjectorDrive)
    if not sensor.crosstalk:
        q = cached_radiance(dark, drive.image() if lazy else drive, seed=seed, **kw)
        if ambient:
            q = q + cached_radiance(scene, None, seed=_ambient_seed(seed), **kw)
    else:
        weights = channel_weights(sensor, scene.rig)
        q = np.zeros((scene.rig.camera.height_px, scene.rig.camera.width_px, 3), np.float32)
        for p in range(3):
            mono = drive.primary(p) if lazy else _mono(drive, p)
            # the same seed for each primary: the sum has one render's sampling pattern; a
            # primary the drive leaves off (calibration frames) lights nothing
            lit = mono is not None if lazy else mono.any()
            r = cached_radiance(_primary_scene(dark, p), mono, seed=seed, **kw) if lit else np.zeros_like(q)
            if ambient:
                r = r + cached_radiance(_primary_scene(scene, p), None, seed=_ambient_seed(seed), **kw)
            q += r * weights[:, p].astype(np.float32)
    q = with_translucency(q, translucent_scene, cache=render.cache)
    q = distort_image(q, scene.rig.camera)
    return lateral_colour_image(q, scene.rig.camera, shift_px=sensor.camera_lens.lateral_colour_px).astype(
        np.float32, copy=False
    )


def white_board(scene: SceneSpec) -> dict:
    """The white reference board the camera's exposure and white balance are set on."""
    return {
        "reference_depth_m": scene.reference_depth_m,
        "reference_albedo": REFERENCE_ALBEDO,
        "projector_scale": scene.projector_scale,
    }


def record(q: np.ndarray, *, sensor: SensorModel, scene: SceneSpec, rng: RngLike = None) -> np.ndarray:
    """The camera's recorded image from :func:`render_channels`' output: the simple camera,
    or the EMVA 1288 camera with its colour filter array at the sensor's (auto) exposure."""
    cam = sensor.camera
    if isinstance(cam, SimpleCamera):
        return simple_camera(q, camera=cam, rng=rng)
    t, per_radiance, gains = _camera_settings(sensor, scene)
    return emva_camera(q, camera=cam, electrons_per_radiance=per_radiance, exposure_s=t, white_balance=gains, rng=rng)


def _camera_settings(sensor: SensorModel, scene: SceneSpec) -> tuple[float, np.ndarray, np.ndarray]:
    """The physical camera's exposure, electrons per unit radiance over it and white-balance
    gains, all set on the white reference board."""
    board = white_board(scene)
    t = exposure_s(sensor, scene.rig, **board)
    return t, electrons_per_radiance_s(sensor, scene.rig) * t, white_balance_gains(sensor, scene.rig, **board)


def record_channels(
    scene: SceneSpec,
    drive: "np.ndarray | ProjectorDrive",
    sensor: SensorModel,
    *,
    seed: int,
    render: RenderSettings,
    rngs: list,
) -> list[np.ndarray]:
    """``[record(render_channels(...), rng=n) for n in rngs]``: one render of the scene
    recorded once per noise seed, each recording looked up in / stored to ``render.cache``.

    A recording is a pure function of what its renders are made from and of the camera; it is
    cached under those inputs - the scene's render fingerprint, the drive's inputs
    (:meth:`ProjectorDrive.inputs`, or an array's digest), the render seed and settings, the
    renderer, the sensor model, the exposure numbers by value, the noise seed, the versions of
    numpy, OpenCV and colour-science (noise draws, demosaicing, crosstalk data) and the bytes of
    the code between a scene and a recording - so a run whose recordings are cached builds no
    drive, reads no render and draws no noise.  A seed that is not an integer or a SeedSequence
    (a Generator) is recorded afresh.
    """
    q: np.ndarray | None = None

    def recorded(n) -> np.ndarray:
        nonlocal q
        if q is None:
            q = render_channels(scene, drive, sensor, seed=seed, render=render)
        return record(q, sensor=sensor, scene=scene, rng=n)

    cache = render.cache
    if cache is None or cache.root is None:
        return [recorded(n) for n in rngs]
    base = {
        "scene": scene_fingerprint(scene),
        "drive": drive.inputs() if isinstance(drive, ProjectorDrive) else array_digest(drive),
        "render": {"seed": int(seed), "spp": int(render.spp), "sampler": render.sampler, "max_depth": render.max_depth},
        "sensor": sensor_to_dict(sensor),
        "exposure": _recording_settings(sensor, scene),
        "code": _recording_code_digest(),
        **_recording_libraries(),
        **_renderer_id(),
    }
    out = []
    for n in rngs:
        key = _seed_key(n)
        if key is None:
            out.append(recorded(n))
        else:
            out.append(
                cache.get_or_make("recording", {**base, "rng": key}, lambda n=n: {"image": recorded(n)})["image"]
            )
    return out


def _seed_key(rng) -> "int | dict | None":
    """A noise seed as cache-key data: an integer, or a SeedSequence by what its streams are
    drawn from (entropy, spawn key, pool size); None for anything else (a Generator's state
    moves on as it draws)."""
    if isinstance(rng, (int, np.integer)) and not isinstance(rng, bool):
        return int(rng)
    if isinstance(rng, np.random.SeedSequence):
        entropy = rng.entropy
        return {
            "entropy": [int(e) for e in entropy] if isinstance(entropy, (list, tuple, np.ndarray)) else int(entropy),
            "spawn_key": [int(k) for k in rng.spawn_key],
            "pool_size": int(rng.pool_size),
        }
    return None


def _recording_settings(sensor: SensorModel, scene: SceneSpec) -> dict:
    """The numbers :func:`record` sets the camera with (by value: they come from colour data
    and photometry, whatever their source)."""
    if isinstance(sensor.camera, SimpleCamera):
        return {}
    t, per_radiance, gains = _camera_settings(sensor, scene)
    return {
        "exposure_s": float(t),
        "electrons_per_radiance": np.asarray(per_radiance).tolist(),
        "white_balance": np.asarray(gains).tolist(),
    }


@lru_cache(maxsize=1)
def _recording_code_digest() -> str:
    """SHA-256 of the code between a scene and a recording: the renders (scene dicts, render
    calls; also behind RENDER_VERSION, which every key holds), the channel sum and the camera
    (this module, the sensor and photometry models, spectral data handling, the lens model and
    its compiled maps)."""
    import simbench.device
    import simbench.mitsuba_dict
    import simbench.native
    import simbench.optics
    import simbench.photometry
    import simbench.render
    import simbench.sensor
    import simbench.spectral
    import simbench.subsurface

    modules = (
        simbench.sensor,
        simbench.photometry,
        simbench.spectral,
        simbench.device,
        simbench.optics,
        simbench.subsurface,
        simbench.render,
        simbench.mitsuba_dict,
    )
    return source_digest([*(m.__file__ for m in modules), sys.modules[__name__].__file__, simbench.native.LENS_SOURCE])


@lru_cache(maxsize=1)
def _recording_libraries() -> dict:
    """The libraries whose algorithms or data a recording's bits depend on: numpy (the noise
    draws), OpenCV (demosaicing, remapping), colour-science (the crosstalk of the primaries'
    renders; its version read without importing it)."""
    from importlib import metadata

    import cv2

    try:
        colour = metadata.version("colour-science")
    except metadata.PackageNotFoundError:
        colour = "not installed"
    return {"numpy": np.__version__, "opencv": cv2.__version__, "colour-science": colour}
