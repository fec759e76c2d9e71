"""The simulator's chain for one capture: pattern -> projector drive -> scene render -> camera.
The systems (:mod:`simbench.systems`) build their acquisitions from it;
the drive is :mod:`simbench.sim.drive`'s, the cache keys :mod:`simbench.sim.keys`'.

Seeds: derived from one base seed and each capture's label (:mod:`simbench.seeds`); all are
recorded.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from simbench.cache import RenderCache, array_digest
from simbench.sim.scene import scene_fingerprint
from simbench.sim.sensor import SensorModel, apply_to_rig, sensor_to_dict
from simbench.sim.drive import DriveImage, ProjectorDrive, mono_drive
from simbench.sim.keys import recording_libraries, renderer_id, seed_key, sim_code_digest
from simbench.sim.mitsuba_dict import RenderSettings, ambient_spp, film_settings, pass_settings
from simbench.optics import camera_lens_image, lens_field
from simbench.sim.subsurface import get_medium, subsurface_image
from simbench.sim.photometry import (
    channel_weights,
    electrons_per_radiance_s,
    exposure_s,
    white_balance_gains,
    white_board,
)
from simbench.sim.render import render_radiance
from simbench.sim.scene import OBJECT_KIND_TABLE, SceneSpec, with_subsurface
from simbench.seeds import RngLike, child_seed, slice_seed
from simbench.sim.motion import slice_times
from simbench.sim.timeline import is_moving, scene_at, slice_count, slice_spp
from simbench.sim.camera import SimpleCamera, emva_camera, simple_camera
from simbench.sim.spectral import crosstalk_matrix, material_crosstalk
from simbench.sim.truth import GroundTruth, ground_truth

__all__ = [
    "cached_radiance",
    "one_pass_response",
    "single_bounce",
    "grey_scene",
    "grey_ambient_scene",
    "uniform_ambient",
    "fills_view",
    "cached_ground_truth",
    "physical_scene",
    "render_channels",
    "with_translucency",
    "opaque",
    "record",
    "record_channels",
]


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
    """:func:`simbench.sim.render.render_radiance`, looked up in / stored to ``cache``; ``drive``
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
        **renderer_id(),
    }
    return cache.get_or_make("radiance", parts, lambda: {"radiance": render()})["radiance"]


def cached_ground_truth(scene: SceneSpec, *, cache: RenderCache | None = None) -> GroundTruth:
    """:func:`simbench.sim.truth.ground_truth`, looked up in / stored to ``cache``."""
    scene = dataclasses.replace(scene, camera_lens=None)  # the truth is at the pinhole's pixel centres
    if cache is None:
        return ground_truth(scene)

    def make() -> dict:
        gt = ground_truth(scene)
        return {"depth_m": gt.depth_m, "column_px": gt.column_px, "object_id": gt.object_id, "lit": gt.lit}

    arrays = cache.get_or_make("truth", {"scene": scene_fingerprint(scene), **renderer_id()}, make)
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
        cam = rig.camera
        centre = ((cam.width_px - 1) / 2.0, (cam.height_px - 1) / 2.0)
        if (cam.cx_px, cam.cy_px) != centre:  # (a new user's audit: refused later, naming the render's padded field)
            raise ValueError(
                f"rig {scene.rig.name!r}: the camera's principal point ({cam.cx_px:g}, {cam.cy_px:g}) is off its image "
                f"centre ({centre[0]:g}, {centre[1]:g}), and the sensor model's camera defocus is Mitsuba's thin lens, "
                "which has no principal-point offset: centre it in the rig file, or switch the defocus off "
                "([camera.lens] defocus = false in a sensor TOML; the 'minimal' and 'ideal' presets have none)"
            )
        aperture = sensor.camera_lens.aperture_m(cam.focal_px, sensor.camera.pixel_pitch_um)
        lens = (aperture / 2.0, sensor.camera_lens.focus_m)
    ambient = scene.ambient_rgb
    if sensor.ambient_ratio > 0:
        level = sensor.ambient_ratio * scene.projector_scale / scene.reference_depth_m**2
        ambient = tuple(a + level for a in ambient)
    return dataclasses.replace(scene, rig=rig, camera_lens=lens, ambient_rgb=ambient)


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
            # its optical constants averaged over primary p's band (simbench.sim.spectral.metal_ior_rgb)
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


# object kinds that are convex when flat: no point of one sees another point of it, so all the
# projector's light reaches the camera in one bounce (a plane counts while it has no bow or waviness)
_CONVEX_KINDS = ("plane", "box", "sphere")


def one_pass_response(scene: SceneSpec) -> np.ndarray | None:
    """The 3x3 camera response ``k[c, p]`` (camera channel c seen from projector primary p) of
    the scene's one material when a crosstalk capture's projector light factors per pixel, else
    None - the condition under which :func:`render_channels` renders the three primaries in one
    pass.

    With crosstalk, primary p's render has the drive's channel p in every channel and each
    material's reflectance replaced by column p of its crosstalk matrix, so its channel c is
    ``k[c, p] S_p``, ``S_p`` the light of primary p on a white surface - exactly so when every
    path the camera sees bounces once, off one material with no specular lobe: a single diffuse
    object that cannot light itself (a flat plane, a box, a sphere), nothing else in the scene.
    Then one render with the drive's three channels as they are and a white material gives the
    three ``S_p`` at once (the same seed draws the same paths: the diffuse lobe is sampled the same
    whatever its albedo, and the projector is a delta light), and the capture is ``k * weights``
    applied per pixel - the per-primary renders' sum to float rounding.  Interreflection between
    materials, a glossy or metallic lobe, a printed chart's inks or a mesh (perhaps concave) keep
    the per-primary renders."""
    if not _lit_once(scene):
        return None
    (o,) = scene.objects
    return np.clip(material_crosstalk(o.material.rgb, o.material.spectrum), 0.0, 1.0)


def _lit_once(scene: SceneSpec) -> bool:
    """One diffuse object that cannot light itself and nothing else (:func:`one_pass_response`)."""
    if len(scene.objects) != 1:
        return False
    o = scene.objects[0]
    if o.kind not in _CONVEX_KINDS or o.material.kind != "diffuse" or OBJECT_KIND_TABLE[o.kind].colour_keys:
        return False
    # a bowed or wavy board is concave somewhere: it may light itself
    return not (o.kind == "plane" and any(float(o.get(k, 0.0) or 0.0) != 0.0 for k in ("bow_m_per_m", "waviness_m")))


# how far beyond the image's edge (camera pixels) a plane must reach to count as filling the
# view: a border pixel's footprint (half a pixel) and a thin lens's spread, with room to spare
_FILL_MARGIN_PX = 4.0


def fills_view(scene: SceneSpec) -> bool:
    """Whether the scene's one object is a plane that covers the camera's whole view (every
    pixel's footprint, :data:`_FILL_MARGIN_PX` beyond the image), so that no camera ray sees the
    ambient environment itself - the condition, beside :func:`one_pass_response`, for rendering
    the ambient light in one pass too: a pixel that sees the environment directly gets each
    channel's own ambient, mixed by the weights alone, not by the material's response."""
    from simbench.sim.timeline import _extent_points

    if len(scene.objects) != 1 or scene.objects[0].kind != "plane":
        return False
    corners = np.unique(_extent_points(scene.objects[0]), axis=0)  # the flat box's 4 corners, each twice
    if corners.shape[0] != 4 or not (corners[:, 2] > 0).all():
        return False
    cam = scene.rig.camera
    uv = corners[:, :2] / corners[:, 2:] * cam.focal_px + (cam.cx_px, cam.cy_px)
    centre = uv.mean(axis=0)
    quad = uv[np.argsort(np.arctan2(uv[:, 1] - centre[1], uv[:, 0] - centre[0]))]  # convex: ordered by angle
    m = _FILL_MARGIN_PX + 0.5
    u1, v1 = cam.width_px - 1 + m, cam.height_px - 1 + m
    image = np.array([[-m, -m], [u1, -m], [u1, v1], [-m, v1]])
    # each image corner on the same side of every edge of the convex quad: inside it
    edges = np.roll(quad, -1, axis=0) - quad
    rel = image[:, None, :] - quad[None, :, :]
    cross = edges[None, :, 0] * rel[..., 1] - edges[None, :, 1] * rel[..., 0]
    return bool(((cross > 0).all(axis=1) | (cross < 0).all(axis=1)).all())


def uniform_ambient(scene: SceneSpec, *, max_depth: int) -> np.ndarray | None:
    """The ambient light the camera sees where the scene is one diffuse plane that fills the view
    (:func:`one_pass_response`, :func:`fills_view`) and the render's paths reach a light after a
    bounce (``max_depth`` -1 or >= 2, Mitsuba's convention): ``rho_c L_c`` in every pixel, shape
    (3,) float32 (the material's reflectance as rendered, its ``rgb`` - a measured spectrum's
    linear sRGB too -, times the constant environment's radiance per channel), else None.

    A Lambertian surface that sees nothing but a constant environment over its hemisphere
    reflects ``rho / pi * integral(L cos theta d omega) = rho L`` at every point, whatever its
    distance or tilt, and where the plane fills the view every camera ray meets it: the path
    tracer's ambient render of such a scene is that constant plus its sampling noise (white plane,
    36 spp multijitter: mean 0.0200000 for L = 0.02, 1.0 % noise per pixel), so the constant
    replaces the render (one render fewer per capture; the captures change by that noise alone,
    ``tests/test_physics_renders.py``)."""
    if max(scene.ambient_rgb) <= 0 or 0 <= max_depth < 2 or not fills_view(scene) or not _lit_once(scene):
        return None
    (o,) = scene.objects
    return (np.asarray(o.material.rgb, np.float64) * np.asarray(scene.ambient_rgb, np.float64)).astype(np.float32)


def single_bounce(scene: SceneSpec, *, max_depth: int) -> bool:
    """Whether every path of a render of ``scene`` that reaches the projector bounces once, off
    a Lambertian surface: every material diffuse (printed inks included) and either the
    renderer stops there (``max_depth`` 0-2, Mitsuba's convention: 2 is direct light) or the
    scene is one convex object (:func:`one_pass_response`'s geometry, a printed target
    included) that cannot light itself.  The condition, beside a grey drive, for
    :func:`grey_scene`'s one render."""
    if not scene.objects or any(o.material.kind != "diffuse" for o in scene.objects):
        return False
    if 0 <= max_depth <= 2:
        return True
    if len(scene.objects) != 1:
        return False
    o = scene.objects[0]
    flat = o.kind in ("plane", "target") and not any(
        float(o.get(k, 0.0) or 0.0) != 0.0 for k in ("bow_m_per_m", "waviness_m")
    )
    return o.kind in ("box", "sphere") or flat


def _recorded_reflectances(scene: SceneSpec, weights: np.ndarray) -> tuple[list[np.ndarray], list[dict]]:
    """Each object's material reflectance and inks as camera channel c records them under equal
    light of the projector's three primaries, ``sum_p weights[c, p] k[c, p]`` (``k`` the
    crosstalk matrix, clipped as :func:`_primary_scene` clips it)."""
    weights = np.asarray(weights, np.float64)

    def mixed(rgb, spectrum) -> np.ndarray:
        return (weights * np.clip(material_crosstalk(rgb, spectrum), 0.0, 1.0)).sum(axis=1)

    mats = [mixed(o.material.rgb, o.material.spectrum) for o in scene.objects]
    inks = [{key: mixed(o.get(key), None) for key in OBJECT_KIND_TABLE[o.kind].colour_keys} for o in scene.objects]
    return mats, inks


def _with_reflectances(scene: SceneSpec, mats: list[np.ndarray], inks: list[dict], divisor) -> SceneSpec:
    objects = []
    for o, m, ink in zip(scene.objects, mats, inks):
        mat = dataclasses.replace(o.material, rgb=tuple(float(x) for x in m / divisor), spectrum=None)
        params = dict(o.params)
        params.update({key: tuple(float(x) for x in v / divisor) for key, v in ink.items()})
        objects.append(dataclasses.replace(o, material=mat, params=tuple(sorted(params.items()))))
    return dataclasses.replace(scene, objects=tuple(objects))


def grey_scene(scene: SceneSpec, weights: np.ndarray) -> tuple[SceneSpec, float]:
    """``scene`` with each reflectance (materials' and inks') replaced by what camera channel c
    records of it under light of equal drive in the projector's three primaries,
    ``sum_p weights[c, p] k[c, p]`` (``k`` its crosstalk matrix, clipped as
    :func:`_primary_scene` clips it), divided by ``scale`` (returned; >= 1) so that no
    reflectance exceeds 1.

    Where every path bounces once off a Lambertian surface (:func:`single_bounce`), a path's
    contribution to channel c of primary p's render is ``drive * k[c, p] * G`` with G the same
    for every primary (the same seed draws the same paths: the diffuse lobe is sampled the same
    whatever its albedo, and the projector is a delta light), so the weighted sum of the three
    per-primary renders of a grey drive is ``scale`` times one render of this scene - to float
    rounding (2e-7 of the brightest pixel, ``tests/test_physics_renders.py``)."""
    mats, inks = _recorded_reflectances(scene, weights)
    scale = max(1.0, *(float(m.max()) for m in mats), *(float(v.max()) for d in inks for v in d.values()))
    return _with_reflectances(scene, mats, inks, scale), scale


def grey_ambient_scene(scene: SceneSpec, weights: np.ndarray) -> SceneSpec:
    """``scene`` whose ambient render is the three per-primary ambient renders' weighted sum,
    where every path bounces once off a Lambertian surface (:func:`single_bounce`): the
    environment's channel c times ``sum_p weights[c, p]`` (what a pixel that sees the
    environment itself records of the primaries' ambient renders), each reflectance
    :func:`grey_scene`'s divided by that sum (<= 1: a weighted mean of reflectances), so that a
    path off a surface carries ``L_c sum_p weights[c, p] k[c, p]``, as the sum does (the constant
    environment is sampled the same whatever its radiance)."""
    total = np.asarray(weights, np.float64).sum(axis=1)  # [c]
    mats, inks = _recorded_reflectances(scene, weights)
    out = _with_reflectances(scene, mats, inks, total)
    return dataclasses.replace(out, ambient_rgb=tuple(float(a * t) for a, t in zip(scene.ambient_rgb, total)))


def _grey_drive(drive: "np.ndarray | ProjectorDrive") -> "np.ndarray | DriveImage | None":
    """The drive of primary 0 alone in all three channels when the drive shows the same image in
    its three primaries (a phase-shift or calibration frame, the same after the projector
    model), else None (also when it shows nothing)."""
    if isinstance(drive, ProjectorDrive):
        digests = {drive.digests()[f"mono{p}"] for p in range(3)}
        return drive.primary(0) if len(digests) == 1 and "" not in digests else None
    grey = np.array_equal(drive[..., 0], drive[..., 1]) and np.array_equal(drive[..., 1], drive[..., 2])
    return drive if grey and drive.any() else None


def _white_scene(scene: SceneSpec) -> SceneSpec:
    """``scene`` (one diffuse object: :func:`one_pass_response`) with a white material."""
    (o,) = scene.objects
    mat = dataclasses.replace(o.material, rgb=(1.0, 1.0, 1.0), spectrum=None)
    return dataclasses.replace(scene, objects=(dataclasses.replace(o, material=mat),))


def with_translucency(radiance: np.ndarray, scene: SceneSpec, *, cache: RenderCache | None = None) -> np.ndarray:
    """``radiance`` (H, W, 3) rendered of ``scene`` with its surfaces opaque, on its camera's
    ideal pixel grid, with the light its translucent objects reflect redistributed by their
    media (:func:`simbench.sim.subsurface.subsurface_image`, per channel with that band's medium);
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
    window_s: tuple[float, float] | None = None,
) -> np.ndarray:
    """Radiance per camera channel on the camera's recorded pixel grid, rendered with ``seed``
    and ``render``'s settings (through its cache).

    Without crosstalk: one render, channel c lit by primary c.  With crosstalk: one render per
    projector primary p (the drive's channel p in all three channels, materials replaced by
    column p of their crosstalk matrix) summed with the weights of
    :func:`simbench.sim.photometry.channel_weights` - exact for direct light; interreflected light is
    coloured by one bounce's crosstalk only (an approximation, as is the coating's
    specular tint).  Where that sum factors per pixel (one diffuse convex object:
    :func:`one_pass_response`), the three primaries are one render of the drive as it is on a
    white material, each pixel's channels then mixed by the material's response and the weights
    - the same capture to float rounding, a third of the renders; so too where the drive shows
    the same image in the three primaries (phase-shift and calibration frames) and every path
    bounces once off Lambertian surfaces (:func:`single_bounce`: direct light, or a printed target
    alone), one render of the reflectances each channel records (:func:`grey_scene`; their ambient
    light likewise, :func:`grey_ambient_scene`).  The ambient light is rendered apart (light
    adds linearly; one emitter per render keeps the path tracer's noise that of a single light),
    at a quarter of the samples (:func:`simbench.sim.mitsuba_dict.ambient_spp`), and, with
    crosstalk, once per primary's materials: light of the projector's white.  Then the
    translucent objects' subsurface
    scattering (:mod:`simbench.sim.subsurface`, on the ideal pixel grid, per camera channel with that
    band's medium: an approximation where a channel sees several primaries, and it spreads all the
    object's light, a glossy coating's highlight included), the camera lens distortion and
    lateral colour (per camera channel: an approximation where a channel sees several primaries'
    wavelengths, exact for narrow-band light).  The renders cover the field the lens records
    (:func:`simbench.optics.lens_field`: a few pixels wider than the camera's image for a barrel
    lens), so the recorded image has the scene up to its ends.

    ``scene`` is a :func:`physical_scene`; ``drive`` from :func:`projector_drive_for` (or a
    :class:`ProjectorDrive`, built only for renders the cache does not hold).

    A moving scene (:mod:`simbench.sim.motion`) is integrated over the exposure ``window_s``
    (start, end) in seconds: the mean of :func:`simbench.sim.timeline.slice_count` renders at the
    slices' centre instants, each with its own seed (:func:`simbench.seeds.slice_seed`),
    :func:`simbench.sim.timeline.slice_spp` of the samples and the ``independent`` sampler (one
    slice: the scene at the window's middle, with ``seed``, every sample and ``render``'s sampler).
    A static scene ignores ``window_s``.

    Returns
    -------
    ndarray, shape (H, W, 3), float32, in units of each channel's own primary
    """
    if is_moving(scene):
        return _exposure_integral(scene, drive, sensor, seed=seed, render=render, window_s=window_s)
    scene = scene_at(scene, 0.0)  # zero velocities: static
    camera, lateral_px = scene.rig.camera, sensor.camera_lens.lateral_colour_px
    # the renders cover the field the camera's lens records (wider than its pinhole image
    # where the lens is barrel-distorted): every recorded pixel sees the scene
    field = lens_field(camera, lateral_colour_px=lateral_px)
    if field is not camera:
        scene = dataclasses.replace(scene, rig=dataclasses.replace(scene.rig, camera=field))
    translucent_scene = scene
    # the renders do not depend on what happens under the surface (applied after them)
    scene = opaque(scene)
    ambient = max(scene.ambient_rgb) > 0
    dark = dataclasses.replace(scene, ambient_rgb=(0.0, 0.0, 0.0))
    kw = {"spp": render.spp, "max_depth": render.max_depth, "sampler": render.sampler, "cache": render.cache}
    # the ambient light, smooth and faint, at fewer samples (simbench.sim.mitsuba_dict.ambient_spp)
    akw = {**kw, "spp": ambient_spp(render.spp, render.sampler)}
    lazy = isinstance(drive, ProjectorDrive)
    if not sensor.crosstalk:
        q = cached_radiance(dark, drive.image() if lazy else drive, seed=seed, **kw)
        if ambient:
            flat = uniform_ambient(scene, max_depth=render.max_depth)
            q = q + (flat if flat is not None else cached_radiance(scene, None, seed=_ambient_seed(seed), **akw))
    else:
        weights = channel_weights(sensor, scene.rig)
        q = np.zeros((scene.rig.camera.height_px, scene.rig.camera.width_px, 3), np.float32)
        response = one_pass_response(dark)
        # the ambient light in one pass too where no pixel sees the environment itself: with the
        # same white material and seed, channel c of its render is the environment's channel c
        # on a white surface, which each primary's material render scales by k[c, p]
        a_c = uniform_ambient(_white_scene(scene), max_depth=render.max_depth) if response is not None else None
        ambient_once = ambient and a_c is not None
        if response is not None:
            mix = weights * response  # [c, p]
            if any(drive.primary(p) is not None for p in range(3)) if lazy else drive.any():
                s_p = cached_radiance(_white_scene(dark), drive.image() if lazy else drive, seed=seed, **kw)
                q += s_p @ mix.T.astype(np.float32)
            if ambient_once:
                # the environment on the white plane that fills the view: L_c everywhere, exactly
                # (uniform_ambient), not a render's estimate of it
                q += a_c * mix.sum(axis=1).astype(np.float32)
        once = response is None and single_bounce(dark, max_depth=render.max_depth)
        # a grey drive lighting surfaces that the light leaves after one bounce: the three
        # primaries' renders are one render of the reflectances each channel records of them
        grey = _grey_drive(drive) if once else None
        if grey is not None:
            mixed, scale = grey_scene(dark, weights)
            q += cached_radiance(mixed, grey, seed=seed, **kw) * np.float32(scale)
        # the ambient light, which no drive colours, likewise where it bounces once
        ambient_per_primary = ambient and not ambient_once and not once
        if ambient and not ambient_once and once:
            q += cached_radiance(grey_ambient_scene(scene, weights), None, seed=_ambient_seed(seed), **akw)
        if (response is None and grey is None) or ambient_per_primary:
            for p in range(3):
                r = np.zeros_like(q)
                if response is None and grey is None:
                    mono = drive.primary(p) if lazy else mono_drive(drive, p)
                    # the same seed for each primary: the sum has one render's sampling pattern; a
                    # primary the drive leaves off (calibration frames) lights nothing
                    if mono is not None if lazy else mono.any():
                        r = cached_radiance(_primary_scene(dark, p), mono, seed=seed, **kw)
                if ambient_per_primary:
                    r = r + cached_radiance(_primary_scene(scene, p), None, seed=_ambient_seed(seed), **akw)
                q += r * weights[:, p].astype(np.float32)
    q = with_translucency(q, translucent_scene, cache=render.cache)
    return camera_lens_image(q, camera, lateral_colour_px=lateral_px).astype(np.float32, copy=False)


def _exposure_integral(scene, drive, sensor, *, seed: int, render: RenderSettings, window_s) -> np.ndarray:
    """:func:`render_channels` of a moving scene: the mean over the exposure's time slices."""
    if window_s is None:
        raise ValueError(
            f"scene {scene.name!r} moves: its capture needs the exposure window it integrates (a system with a "
            "time model)"
        )
    t0, t1 = (float(x) for x in window_s)
    if not (math.isfinite(t0) and math.isfinite(t1) and t1 >= t0):
        raise ValueError(f"exposure window must be (start, end) with end >= start, got {window_s!r}")
    n = slice_count(scene, scene.rig.camera, (t0, t1))
    if n == 1:
        return render_channels(scene_at(scene, 0.5 * (t0 + t1)), drive, sensor, seed=seed, render=render)
    # independent sampling: any per-slice count, and each slice's samples at random positions
    # (stratification within a 1-sample slice means nothing).  The slices are not cached one by
    # one: no other capture renders the same instant with the same drive and seed, and at the
    # motion study's sizes storing each (an fsync'd file per slice and primary) cost as much as a
    # third of rendering it; the integral is one entry instead (issue 38)
    settings = dataclasses.replace(render, spp=slice_spp(render.spp, n), sampler="independent", cache=None)

    def integral() -> np.ndarray:
        total = None
        for i, t in enumerate(slice_times((t0, t1), n)):
            q = render_channels(scene_at(scene, float(t)), drive, sensor, seed=slice_seed(seed, i), render=settings)
            total = q.astype(np.float64) if total is None else total + q
        return (total / n).astype(np.float32)

    cache = render.cache
    if cache is None or cache.root is None:
        return integral()
    parts = _capture_key(scene, drive, sensor, seed=seed, render=render, window_s=(t0, t1))
    return cache.get_or_make("exposure", parts, lambda: {"radiance": integral()})["radiance"]


def _capture_key(scene, drive, sensor, *, seed: int, render: RenderSettings, window_s) -> dict:
    """The cache key's parts shared by a recording and an exposure integral: what
    :func:`render_channels` reads (the scene's render fingerprint, the drive's inputs or an array's
    digest, the render seed and settings, a moving scene's window, the sensor model), the versions
    of the libraries a recording uses, the renderer and the bytes of the code between a scene and
    a recording.  ``window_s`` None: no window (a static scene's recording keeps its key)."""
    return {
        "scene": scene_fingerprint(scene),
        "drive": drive.inputs() if isinstance(drive, ProjectorDrive) else array_digest(drive),
        "render": {"seed": int(seed), "spp": int(render.spp), "sampler": render.sampler, "max_depth": render.max_depth},
        **({} if window_s is None else {"window_s": [float(x) for x in window_s]}),
        "sensor": sensor_to_dict(sensor),
        "code": sim_code_digest(),
        **recording_libraries(),
        **renderer_id(),
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
    window_s: tuple[float, float] | None = None,
) -> list[np.ndarray]:
    """``[record(render_channels(...), rng=n) for n in rngs]``: one render of the scene
    recorded once per noise seed, each recording looked up in / stored to ``render.cache``; a
    moving scene integrated over ``window_s`` (:func:`render_channels`).

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
            q = render_channels(scene, drive, sensor, seed=seed, render=render, window_s=window_s)
        return record(q, sensor=sensor, scene=scene, rng=n)

    cache = render.cache
    if cache is None or cache.root is None:
        return [recorded(n) for n in rngs]
    # the window only for a moving scene, so that static recordings keep their keys
    window = window_s if is_moving(scene) else None
    base = {
        **_capture_key(scene, drive, sensor, seed=seed, render=render, window_s=window),
        "exposure": _recording_settings(sensor, scene),
    }
    out = []
    for n in rngs:
        key = seed_key(n)
        if key is None:
            out.append(recorded(n))
        else:
            out.append(
                cache.get_or_make("recording", {**base, "rng": key}, lambda n=n: {"image": recorded(n)})["image"]
            )
    return out


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
