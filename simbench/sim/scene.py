"""Scene specifications (TOML files in ``scenes/``) and their Mitsuba dictionaries.

A scene file::

    name = "white_plane"
    description = "..."
    rig = "paper"                 # a rig preset or a rig .toml path (relative to this file)
    reference_depth_m = 1.0       # Z0 of the reference-plane capture (paper Sec. 5.4)

    [projector]
    scale = 1.0                   # radiance scale of the pattern (1 = unit irradiance*pi at 1 m)

    [ambient]
    rgb = [0.0, 0.0, 0.0]         # constant environment radiance

    [[object]]
    type = "plane"                # plane | box | sphere | mesh
    name = "wall"
    center_m = [0.0, 0.0, 1.0]
    size_m = [1.5, 1.2]           # plane: (x, y) extent; box: (x, y, z) extent
    rotation_deg = [0, 30, 0]     # about x, y, z; R = Rz @ Ry @ Rx
    rgb = [0.8, 0.8, 0.8]         # linear diffuse reflectance (two-sided Lambertian; one number: a grey)

Instead of ``rgb`` an object may give ``srgb8 = [255, 0, 0]``, an 8-bit sRGB colour as printed
on a colour board (paper Table 1), turned into a reflectance by :func:`paint_reflectance`, or
``spectrum = "ColorChecker N Ohta/red"``, a measured reflectance spectrum
(:data:`simbench.sim.spectral.MEASURED_DATASETS`) used as it is by the spectral (crosstalk) path.
``material`` is ``diffuse`` (default) or ``plastic``: a smooth or rough dielectric coating
(Mitsuba ``roughplastic``, interior IOR 1.49, GGX ``roughness`` alpha, default 0.1) over a
diffuse base of colour ``rgb``; it gives the specular highlights of glazed pots and book covers.
``material = "metal"`` is a bare metal (Mitsuba ``roughconductor``, GGX ``roughness`` alpha,
default 0.1) named by ``metal = "aluminium"`` (:data:`simbench.sim.spectral.METALS`: its measured
complex refractive index gives its colour and its Fresnel reflectance); it takes no colour key.
``subsurface = "marble"`` makes an object translucent: the light it reflects leaves displaced by
the dipole profile of that medium (:mod:`simbench.sim.subsurface`, whose ``MEDIA`` lists the names).

A plane may also have a form error, as real boards do (:func:`board_form_m`): ``bow_m_per_m``
(sag of a spherical bow over a 1 m chord, positive bulging towards the camera),
``waviness_m`` (amplitude of a ripple across the board's x axis), ``waviness_period_m``
(default :data:`WAVINESS_PERIOD_M`) and ``waviness_phase_rad``; such a plane is rendered as a
displaced grid mesh (:data:`BOARD_GRID`, :data:`RIPPLE_CELLS`).

A ``target`` is a printed calibration checkerboard (:mod:`simbench.calibration`): a plane of
``squares = [columns, rows]`` squares of side ``square_m`` inside a white margin of
``margin_squares`` squares, the dark squares of reflectance ``ink_rgb`` (default: the paint
minimum, :data:`PAINT_MIN_REFLECTANCE`), the paper of the material's ``rgb``; it takes a
plane's ``center_m``, ``rotation_deg`` and form keys, and its square in the top left corner
(board x and y smallest) is dark.

Spheres take ``center_m`` and ``radius_m``; meshes take ``file`` (PLY/OBJ, relative to the
scene file), ``scale`` (uniform, mesh units to metres), ``translate_m`` and ``rotation_deg``.
A plane's, box's, target's or sphere's ``center_m`` left out is ``[0, 0, 1]``, 1 m ahead on the
camera's axis; a plane's or box's ``size_m`` and a sphere's ``radius_m`` must be given.
All coordinates are in the camera frame (x right, y down, z forward, metres).
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np

from simbench import validate
from simbench.cache import file_digest, foreign_code_digest
from simbench.extensions import after_load, load_extensions
from simbench.io import read_toml
from simbench.rig import Rig, get_rig, rig_to_dict, rotation_xyz_deg
from simbench.seeds import RngLike
from simbench.sim.motion import Motion

log = logging.getLogger(__name__)

__all__ = [
    "Material",
    "SceneObject",
    "SceneSpec",
    "OBJECT_KINDS",
    "ObjectKind",
    "OBJECT_KIND_TABLE",
    "check_mesh_file",
    "load_scene",
    "scene_from_dict",
    "reference_scene",
    "Placement",
    "board_form",
    "board_form_m",
    "BOARD_FORM_KEYS",
    "place_objects",
    "object_to_mitsuba",
    "paint_reflectance",
    "linear_srgb8",
    "metal_rgb",
    "target_texture",
    "target_size_m",
    "scene_fingerprint",
]

BOARD_FORM_KEYS = ("bow_m_per_m", "waviness_m", "waviness_period_m", "waviness_phase_rad")
_COMMON_KEYS = ("type", "name", "rgb", "srgb8", "spectrum", "material", "roughness", "metal", "subsurface")
# an object's rigid motion (simbench.sim.motion)
MOTION_KEYS = ("velocity_m_s", "angular_velocity_deg_s", "rotation_axis", "rotation_centre_m")
MATERIALS = ("diffuse", "plastic", "metal")
_GLOSSY = ("plastic", "metal")  # the materials with a roughness

# Reflectance range of matte paint, used by paint_reflectance.  Assumptions, argued from
# physics: even a saturated paint reflects the ~4 % of a dielectric binder's surface (Fresnel
# reflectance at normal incidence for n = 1.5 is ((n-1)/(n+1))^2 = 0.04), scattered diffusely
# by the matte surface, in the bands its pigment absorbs; a good matte white reaches ~0.8-0.9
# (0.8 = our white plane, the same as the reference board).
PAINT_MIN_REFLECTANCE = 0.04
PAINT_MAX_REFLECTANCE = 0.80

# Form error of a board (assumptions, argued): the ripple of a laminated or painted panel has a
# wavelength of centimetres (the spacing of press rollers and core cells); 50 mm is our stated
# middle of that range.  The grid that renders a formed board has at least BOARD_GRID cells a
# side, and RIPPLE_CELLS per ripple period across x: piecewise flat, the ripple then deviates
# from its sine by at most 1 - cos(pi / 16) = 1.9 % of its amplitude, the bow's paraboloid by
# at most pv / (2 * BOARD_GRID^2) = 0.01 % of its peak-to-valley pv over the board.
WAVINESS_PERIOD_M = 0.05
BOARD_GRID = 64
RIPPLE_CELLS = 16
MAX_FORM_M = 0.02  # a board bent by more than 2 cm is not a board (validation bound)
# The form error of the error budget's boards (assumption: the paper does not describe its
# boards; 0.5 mm per metre is a stiff panel stored upright, a 0.05 mm ripple a good
# laminate's.  The flatness study, simbench reproduce flatness, spans 0-2 mm per metre and
# 0.02-0.2 mm, so a reader can take the figure of their own board.)
BUDGET_BOW_M_PER_M = 0.0005
BUDGET_WAVINESS_M = 0.00005


def board_form_m(
    x_m: np.ndarray,
    y_m: np.ndarray,
    *,
    size_m: tuple[float, float],
    bow_m_per_m: float = 0.0,
    waviness_m: float = 0.0,
    waviness_period_m: float = WAVINESS_PERIOD_M,
    waviness_phase_rad: float = 0.0,
) -> np.ndarray:
    """Height of a board's surface above its nominal plane (towards the camera), metres.

    ``x_m, y_m`` are in the board's own frame (centre 0, extent ``size_m``).  The bow is a
    paraboloid (a sphere of large radius) whose sag over a 1 m chord through the centre is
    ``bow_m_per_m`` - a flatness of "so many mm per metre", the same curvature whatever the
    board's size: ``bow_m_per_m * (c - r^2 / (0.5 m)^2)``, with ``c`` keeping the board's mean
    height at 0 (its ``center_m`` stays its mean plane).  The ripple is
    ``waviness_m * sin(2 pi x / waviness_period_m + waviness_phase_rad)``, across the board's
    x axis: the direction in which a fringe sensor's phase runs, where a ripple reads as depth.
    """
    sx, sy = size_m
    x = np.asarray(x_m, np.float64)
    y = np.asarray(y_m, np.float64)
    mean_r2 = (sx * sx + sy * sy) / 12.0  # mean of x^2 + y^2 over the board
    h = bow_m_per_m * (mean_r2 - (x * x + y * y)) / 0.25
    if waviness_m:
        h = h + waviness_m * np.sin(2.0 * np.pi * x / waviness_period_m + waviness_phase_rad)
    return h


def _board_form(d: dict, where: str) -> dict:
    """The form keys of a plane, validated; only those that change the board are kept, so that
    a flat board keeps the parameters (and render-cache keys) it always had."""
    p = {}
    bow = validate.number(d.get("bow_m_per_m", 0.0), f"{where}: bow_m_per_m", lo=-MAX_FORM_M, hi=MAX_FORM_M)
    wav = validate.number(d.get("waviness_m", 0.0), f"{where}: waviness_m", lo=0.0, hi=MAX_FORM_M)
    period = validate.number(
        d.get("waviness_period_m", WAVINESS_PERIOD_M), f"{where}: waviness_period_m", lo=0.001, hi=10.0
    )
    phase = validate.number(d.get("waviness_phase_rad", 0.0), f"{where}: waviness_phase_rad", lo=-100.0, hi=100.0)
    if bow:
        p["bow_m_per_m"] = bow
    if wav:
        p.update(waviness_m=wav, waviness_period_m=period, waviness_phase_rad=phase)
    return p


def linear_srgb8(srgb8: Sequence[int]) -> tuple[float, float, float]:
    """The linear values of the 8-bit sRGB colour ``srgb8`` (IEC 61966-2-1 decoding curve):
    (255, 0, 0) -> (1, 0, 0).  A renderer's material colour as the paper's 3ds Max simulation
    (Sec. 5.5) would take a colour-picker value; no real surface reflects so purely
    (:func:`paint_reflectance`)."""
    return tuple(float(round(x, 6)) for x in _srgb_decode(srgb8))


def _srgb_decode(srgb8: Sequence[int]) -> np.ndarray:
    """The sRGB decoding curve of a checked 8-bit colour (unrounded)."""
    v = np.asarray(
        validate.numbers(list(srgb8) if isinstance(srgb8, np.ndarray) else srgb8, "srgb8", 3, lo=0.0, hi=255.0),
        dtype=np.float64,
    )
    if not np.array_equal(v, np.round(v)):
        raise ValueError(f"srgb8 holds 8-bit integers 0-255 (rgb takes reflectances in [0, 1]), got {list(srgb8)!r}")
    c = v / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def paint_reflectance(srgb8: Sequence[int]) -> tuple[float, float, float]:
    """Linear diffuse reflectance of a matte paint printed as 8-bit sRGB ``srgb8``.

    ``rho = rho_min + (rho_max - rho_min) * linear(srgb8 / 255)`` per channel, with the sRGB
    decoding curve (IEC 61966-2-1, :func:`linear_srgb8`) and the paint range above: pure red
    (255, 0, 0) becomes (0.80, 0.04, 0.04), not (1, 0, 0): no real paint is spectrally pure.

    Examples
    --------
    >>> paint_reflectance((255, 0, 0))
    (0.8, 0.04, 0.04)
    >>> paint_reflectance((128, 128, 128))
    (0.204054, 0.204054, 0.204054)
    """
    lin = _srgb_decode(srgb8)
    rho = PAINT_MIN_REFLECTANCE + (PAINT_MAX_REFLECTANCE - PAINT_MIN_REFLECTANCE) * lin
    return tuple(float(round(x, 6)) for x in rho)


@dataclass(frozen=True)
class Material:
    """A material (see module docstring): ``diffuse`` (two-sided Lambertian), ``plastic``
    (rough dielectric coating over a diffuse base) or ``metal`` (rough conductor); ``rgb`` is
    the linear diffuse reflectance in [0, 1] (a metal's: its normal-incidence reflectance per
    camera channel, for information and for the competitors' NIR albedo), ``roughness`` the GGX
    alpha of the coating or of the metal's surface."""

    kind: str = "diffuse"
    rgb: tuple[float, float, float] = (0.8, 0.8, 0.8)
    roughness: float = 0.1
    # the coating's or the metal's specular tint; only the spectral-crosstalk renders set it
    # (light of one primary seen through the camera's channels), scene files cannot
    specular_rgb: tuple[float, float, float] = (1.0, 1.0, 1.0)
    # a measured reflectance spectrum "<dataset>/<patch>" (simbench.sim.spectral.MEASURED_DATASETS);
    # rgb is then its linear sRGB, and the spectral path uses the spectrum itself
    spectrum: str | None = None
    # a translucent medium of simbench.sim.subsurface.MEDIA under the surface (None: opaque)
    subsurface: str | None = None
    # the metal of a ``metal`` material (simbench.sim.spectral.METALS)
    metal: str | None = None
    # the projector primary whose band the metal's optical constants are averaged over (None:
    # the projector's white); only the spectral-crosstalk renders set it, scene files cannot
    metal_primary: int | None = None

    def __post_init__(self) -> None:
        if self.kind not in MATERIALS:
            raise ValueError(f"unknown material {self.kind!r}; valid: {list(MATERIALS)}")
        if self.subsurface is not None:
            from simbench.sim.subsurface import get_medium

            get_medium(self.subsurface)
        if (self.kind == "metal") != (self.metal is not None):
            raise ValueError("a metal material needs its metal, and only a metal material takes one")
        if self.metal is not None:
            from simbench.sim.spectral import METALS

            if self.metal not in METALS:
                raise ValueError(f"unknown metal {self.metal!r}; valid: {list(METALS)}")
            if self.subsurface is not None:
                raise ValueError("a metal is opaque: it takes no subsurface medium")
        if self.metal_primary is not None and (self.metal is None or self.metal_primary not in (0, 1, 2)):
            raise ValueError(f"metal_primary must be 0, 1 or 2 on a metal, got {self.metal_primary!r}")
        object.__setattr__(self, "rgb", validate.numbers(self.rgb, "rgb reflectance", 3, lo=0.0, hi=1.0))
        object.__setattr__(self, "roughness", validate.number(self.roughness, "roughness", lo=0.001, hi=1.0))
        object.__setattr__(self, "specular_rgb", validate.numbers(self.specular_rgb, "specular_rgb", 3, lo=0.0, hi=1.0))


@dataclass(frozen=True)
class SceneObject:
    """One object: its kind, geometry parameters (see module docstring) and material."""

    kind: str
    name: str
    params: tuple[tuple[str, object], ...]
    material: Material = Material()
    # rigid motion at constant velocity (simbench.sim.motion.Motion); None = static
    motion: Motion | None = None

    def get(self, key: str, default=None) -> object:
        return dict(self.params).get(key, default)


@dataclass(frozen=True)
class SceneSpec:
    name: str
    rig: Rig
    objects: tuple[SceneObject, ...]
    reference_depth_m: float = 1.0
    projector_scale: float = 1.0
    ambient_rgb: tuple[float, float, float] = (0.0, 0.0, 0.0)
    # camera thin lens (aperture radius m, focus distance m); None = pinhole.  Set by the
    # sensor model (simbench.sim.sensor), not by scene files.
    camera_lens: tuple[float, float] | None = None
    description: str = ""
    base_dir: Path = field(default=Path("."), compare=False)


# Physical ranges of scene geometry (issue 33: objects at z = 1e308, spheres of radius 1e30 and
# rotations of 1e308 deg validated and rendered an empty image).  Assumption: structured light
# works within 100 m of the camera (the same bound as reference_depth_m), so positions lie within
# +-SCENE_EXTENT_M on each axis and sizes up to it; an angle beyond one turn is a typo, not a pose.
SCENE_EXTENT_M = 100.0
MAX_ANGLE_DEG = 360.0
# a mesh's unit: from micrometres (1e-6) to kilometres (1e3) per file unit
MESH_SCALE_RANGE = (1e-6, 1e3)
# Assumption: the projector scale multiplies the sensor model's projector output (the
# LightCrafter 4500's 150 lm by default); 1000x is 150,000 lm, twice the brightest cinema
# projectors (~75,000 lm), so a larger factor is an error, not a projector
MAX_PROJECTOR_SCALE = 1e3


def _vec(v: object, n: int, where: str, *, positive: bool = False) -> tuple[float, ...]:
    """A position (or, ``positive``, a size) in metres within the scene's extent."""
    lo = 0.0 if positive else -SCENE_EXTENT_M
    return validate.numbers(v, where, n, lo=lo, hi=SCENE_EXTENT_M, lo_open=positive)


def _angles(v: object, where: str) -> tuple[float, ...]:
    return validate.numbers(v, where, 3, lo=-MAX_ANGLE_DEG, hi=MAX_ANGLE_DEG)


def _object_from_dict(d: object, index: int, base_dir: Path) -> SceneObject:
    where = f"object[{index}]"
    if not isinstance(d, dict):
        raise ValueError(f"{where}: expected a table")
    kind = d.get("type")
    if not isinstance(kind, str):  # a list or table is no kind (and no key to look one up by)
        raise ValueError(f"{where}: type must be a string naming one of {sorted(OBJECT_KINDS)}, got {kind!r}")
    if kind not in OBJECT_KINDS:
        load_extensions()  # object kinds of installed packages (simbench.extensions), once per process
    if kind not in OBJECT_KINDS:
        raise ValueError(f"{where}: unknown type {kind!r}; valid types: {sorted(OBJECT_KINDS)}")
    allowed = _COMMON_KEYS + MOTION_KEYS + OBJECT_KINDS[kind]
    unknown = sorted(set(d) - set(allowed))
    if unknown:
        raise ValueError(f"{where} ({kind}): unknown key(s) {unknown}; valid keys: {list(allowed)}")
    name = d.get("name", f"{kind}{index}")
    if not isinstance(name, str) or not name.strip():
        raise ValueError(f"{where}: name must be a non-empty string, got {name!r}")
    where = f"object[{index}] {name!r}"
    p = OBJECT_KIND_TABLE[kind].parse(d, where, base_dir)
    try:
        given = [k for k in ("rgb", "srgb8", "spectrum") if k in d]
        if len(given) > 1:
            raise ValueError(
                f"give one of rgb (reflectance), srgb8 (paint colour) or spectrum (measured), not {' and '.join(given)}"
            )
        spectrum = None
        if "spectrum" in d:
            from simbench.sim.spectral import measured_linear_srgb

            if not isinstance(d["spectrum"], str):
                raise ValueError(f"spectrum must be a string '<dataset>/<patch>', got {d['spectrum']!r}")
            spectrum = d["spectrum"]
            rgb = measured_linear_srgb(spectrum)
        else:
            rgb = paint_reflectance(d["srgb8"]) if "srgb8" in d else _reflectance(d.get("rgb", (0.8, 0.8, 0.8)))
        mat_kind = str(d.get("material", "diffuse"))
        if "roughness" in d and mat_kind not in _GLOSSY:
            raise ValueError(f"roughness applies to material = {' or '.join(map(repr, _GLOSSY))} only")
        metal = None
        if mat_kind == "metal":
            if given:
                raise ValueError(f"a metal's colour is its metal's: remove {' and '.join(given)}")
            metal = d.get("metal", "aluminium")
            if not isinstance(metal, str):
                raise ValueError(f"metal must be a name, got {metal!r}")
            rgb = metal_rgb(metal)
        elif "metal" in d:
            raise ValueError("metal applies to material = 'metal' only")
        mat = Material(
            kind=mat_kind,
            rgb=rgb,
            roughness=d.get("roughness", 0.1),
            spectrum=spectrum,
            subsurface=d.get("subsurface"),
            metal=metal,
        )
        motion = _motion(d)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {exc}") from None
    return SceneObject(kind=kind, name=name, params=tuple(sorted(p.items())), material=mat, motion=motion)


def _motion(d: dict) -> Motion | None:
    """An object table's motion keys (:data:`MOTION_KEYS`) as a :class:`Motion`; None when it
    does not move (no keys, or zero velocities: a static object keeps its cache keys)."""
    if not any(k in d for k in MOTION_KEYS):
        return None
    if ("rotation_axis" in d or "rotation_centre_m" in d) and not d.get("angular_velocity_deg_s"):
        raise ValueError("rotation_axis and rotation_centre_m need a non-zero angular_velocity_deg_s")
    motion = Motion(
        velocity_m_s=d.get("velocity_m_s", (0.0, 0.0, 0.0)),
        angular_velocity_deg_s=d.get("angular_velocity_deg_s", 0.0),
        axis=d.get("rotation_axis", (0.0, 1.0, 0.0)),
        centre_m=d.get("rotation_centre_m"),
    )
    return None if motion.is_static else motion


_SCENE_KEYS = ("name", "description", "rig", "reference_depth_m", "projector", "ambient", "object")


def scene_from_dict(data: dict, *, base_dir: Path = Path("."), where: str = "scene") -> SceneSpec:
    """Validate a scene table (see module docstring) into a :class:`SceneSpec`."""
    unknown = sorted(set(data) - set(_SCENE_KEYS))
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {unknown}; valid keys: {list(_SCENE_KEYS)}")
    objs = data.get("object", [])
    if not isinstance(objs, list) or not objs:
        raise ValueError(f"{where}: needs at least one [[object]]")
    try:
        rig = get_rig(data.get("rig", "paper"), base_dir=base_dir)
        objects = tuple(_object_from_dict(o, i, base_dir) for i, o in enumerate(objs))
        proj = data.get("projector", {})
        amb = data.get("ambient", {})
        if not isinstance(proj, dict) or sorted(set(proj) - {"scale"}):
            raise ValueError("[projector] takes only: scale")
        if not isinstance(amb, dict) or sorted(set(amb) - {"rgb"}):
            raise ValueError("[ambient] takes only: rgb")
        scale = validate.number(proj.get("scale", 1.0), "projector.scale", lo=0.0, lo_open=True, hi=MAX_PROJECTOR_SCALE)
        # assumption: structured light works within 100 m
        z0 = validate.number(data.get("reference_depth_m", 1.0), "reference_depth_m", lo=0.0, hi=100.0, lo_open=True)
        ambient = validate.numbers(amb.get("rgb", (0, 0, 0)), "ambient.rgb", 3, lo=0.0)
    except (FileNotFoundError, ValueError) as exc:
        raise type(exc)(f"{where}: {exc}") from None
    names = [o.name for o in objects]
    if len(set(names)) != len(names):
        raise ValueError(f"{where}: object names must be unique, got {names}")
    for key in ("name", "description"):
        if key in data and not isinstance(data[key], str):
            raise ValueError(f"{where}: {key} must be a string, got {data[key]!r}")
    return SceneSpec(
        name=str(data.get("name", "scene")),
        rig=rig,
        objects=objects,
        reference_depth_m=float(z0),
        projector_scale=float(scale),
        ambient_rgb=ambient,
        description=str(data.get("description", "")),
        base_dir=base_dir,
    )


def load_scene(path: str | Path) -> SceneSpec:
    """Read and validate a scene TOML file; errors name the file and the problem."""
    path = Path(path)
    data = read_toml(path, what="scene")
    data.setdefault("name", path.stem)
    return scene_from_dict(data, base_dir=path.parent, where=str(path))


def with_subsurface(scene: SceneSpec, medium: str | None, *, names: Sequence[str] | None = None) -> SceneSpec:
    """``scene`` with the objects ``names`` (all when None) given the subsurface ``medium`` (a
    name of :data:`simbench.sim.subsurface.MEDIA`; None: opaque), every other field as it was."""
    objects = tuple(
        dataclasses.replace(o, material=dataclasses.replace(o.material, subsurface=medium))
        if names is None or o.name in names
        else o
        for o in scene.objects
    )
    return dataclasses.replace(scene, objects=objects)


def reference_scene(scene: SceneSpec, *, albedo: float = 0.8, form: dict | None = None) -> SceneSpec:
    """The reference-plane scene of paper Sec. 5.4: a white fronto-parallel plane at Z0.

    The plane is sized to fill the camera's view with a wide margin; ``albedo`` is an
    assumption (a matte white board), stated in the render metadata.  ``form`` gives it a form
    error (the keys of :func:`board_form`; its bow is over the whole board, of which the
    camera sees the middle two thirds).
    """
    z0 = scene.reference_depth_m
    cam = scene.rig.camera
    half_w = 1.5 * z0 * max(cam.cx_px + 1, cam.width_px - cam.cx_px) / cam.focal_px
    half_h = 1.5 * z0 * max(cam.cy_px + 1, cam.height_px - cam.cy_px) / cam.focal_px
    plane = SceneObject(
        kind="plane",
        name="reference_plane",
        params=tuple(
            sorted(
                {
                    "center_m": (0.0, 0.0, z0),
                    "size_m": (2 * half_w, 2 * half_h),
                    "rotation_deg": (0.0, 0.0, 0.0),
                    **_board_form(form or {}, "reference plane"),
                }.items()
            )
        ),
        material=Material("diffuse", (albedo, albedo, albedo)),
    )
    return SceneSpec(
        name=f"{scene.name}_reference",
        rig=scene.rig,
        objects=(plane,),
        reference_depth_m=z0,
        projector_scale=scene.projector_scale,
        ambient_rgb=scene.ambient_rgb,
        camera_lens=scene.camera_lens,
        description=f"reference plane at {z0} m",
        base_dir=scene.base_dir,
    )


@dataclass(frozen=True)
class Placement:
    """How precisely a lab places a test object: uniform errors within +-``depth_m`` along the
    camera axis and +-``tilt_deg`` about the object's own x and y axes.

    The defaults are an assumption argued from a hand set-up like the paper's (Sec. 5.5-6): a
    board is put at "1.0 m" with a tape measure (EU MID class II tolerance +-(0.3 + 0.2 L) mm,
    0.5 mm at 1 m) from a rig whose depth origin, the camera's entrance pupil, lies somewhere
    inside the lens and is not marked: +-10 mm; it is squared to the rig by eye or with a
    set square against the rig's rail: +-2 deg.  Neither is the paper's number (it gives none).

    ``bow_m_per_m`` and ``waviness_m`` give every placed plane a form error (:func:`board_form_m`):
    a bow of that sag per metre, bulging towards or away from the camera (seeded), and a ripple
    of that amplitude with a seeded phase; 0 (the default) = flat boards.
    """

    depth_m: float = 0.010
    tilt_deg: float = 2.0
    bow_m_per_m: float = 0.0
    waviness_m: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "depth_m", validate.number(self.depth_m, "placement depth_m", lo=0.0, hi=1.0))
        object.__setattr__(self, "tilt_deg", validate.number(self.tilt_deg, "placement tilt_deg", lo=0.0, hi=45.0))
        object.__setattr__(
            self, "bow_m_per_m", validate.number(self.bow_m_per_m, "board bow_m_per_m", lo=0.0, hi=MAX_FORM_M)
        )
        object.__setattr__(
            self, "waviness_m", validate.number(self.waviness_m, "board waviness_m", lo=0.0, hi=MAX_FORM_M)
        )


def board_form(*, bow_m_per_m: float, waviness_m: float, rng: RngLike) -> dict:
    """The form keys of one board of a batch whose boards bow by ``bow_m_per_m`` (sag over a
    1 m chord) and ripple by
    ``waviness_m``: the bow's sign and the ripple's phase drawn from ``rng`` (a Generator)."""
    sign = 1.0 if rng.random() < 0.5 else -1.0
    phase = float(rng.uniform(0.0, 2.0 * np.pi))
    form = {}
    if bow_m_per_m:
        form["bow_m_per_m"] = sign * bow_m_per_m
    if waviness_m:
        form.update(waviness_m=waviness_m, waviness_period_m=WAVINESS_PERIOD_M, waviness_phase_rad=phase)
    return form


def place_objects(
    scene: SceneSpec, names: Iterable[str], *, placement: Placement, rng: RngLike
) -> tuple[SceneSpec, dict]:
    """``scene`` with each named object moved as a lab would have placed it: its own seeded
    depth offset and tilt (:class:`Placement`), independent of the reference plane.  Planes,
    boxes and meshes tilt about their own x and y axes (a mesh about its file's origin); a
    sphere only moves in depth (its tilt is drawn, so that the other objects' draws do not
    depend on it, and recorded as 0).

    Returns
    -------
    scene : SceneSpec
    offsets : dict of name -> {"depth_m": float, "tilt_deg": [about x, about y]}
    """
    rng = np.random.default_rng(rng)
    wanted = list(names)
    known = {o.name: o for o in scene.objects}
    missing = [n for n in wanted if n not in known]
    if missing:
        raise ValueError(f"{scene.name}: no object(s) {missing} to place; objects: {list(known)}")
    offsets, objects = {}, []
    for o in scene.objects:
        if o.name not in wanted:
            objects.append(o)
            continue
        dz = float(rng.uniform(-placement.depth_m, placement.depth_m))
        tx, ty = (float(t) for t in rng.uniform(-placement.tilt_deg, placement.tilt_deg, size=2))
        p = dict(o.params)
        kind = OBJECT_KIND_TABLE[o.kind]
        cx, cy, cz = p[kind.position_key]
        p[kind.position_key] = (cx, cy, cz + dz)
        if not kind.tilts:
            tx = ty = 0.0
        else:
            rx, ry, rz = p["rotation_deg"]
            p["rotation_deg"] = (rx + tx, ry + ty, rz)
        objects.append(dataclasses.replace(o, params=tuple(sorted(p.items()))))
        offsets[o.name] = {"depth_m": dz, "tilt_deg": [tx, ty]}
    if placement.bow_m_per_m or placement.waviness_m:
        # drawn after every placement, so that flat and formed boards sit in the same poses
        for i, o in enumerate(objects):
            if o.name in wanted and o.kind == "plane":
                form = board_form(bow_m_per_m=placement.bow_m_per_m, waviness_m=placement.waviness_m, rng=rng)
                objects[i] = dataclasses.replace(o, params=tuple(sorted({**dict(o.params), **form}.items())))
                offsets[o.name].update(form)
    return dataclasses.replace(scene, objects=tuple(objects)), offsets


def _to_world(mi, *, translate, rotation_deg, scale) -> object:
    m = np.eye(4)
    m[:3, :3] = rotation_xyz_deg(rotation_deg) @ np.diag(np.broadcast_to(np.asarray(scale, float), 3))
    m[:3, 3] = translate
    return mi.ScalarTransform4f(m.tolist())


def metal_rgb(name: str) -> tuple[float, float, float]:
    """A metal's normal-incidence reflectance per camera channel (the diagonal of
    :func:`simbench.sim.spectral.metal_crosstalk`), rounded to 6 digits: its ``Material.rgb``."""
    from simbench.sim.spectral import METALS, metal_crosstalk

    if name not in METALS:
        raise ValueError(f"unknown metal {name!r}; valid: {list(METALS)}")
    return tuple(float(round(x, 6)) for x in np.clip(np.diag(metal_crosstalk(name)), 0.0, 1.0))


def _bsdf(mat: Material) -> dict:
    rgb = {"type": "rgb", "value": list(mat.rgb)}
    if mat.kind == "metal":
        from simbench.sim.spectral import metal_ior_rgb

        eta, k = metal_ior_rgb(mat.metal, primary=mat.metal_primary)
        inner = {
            "type": "roughconductor",
            "distribution": "ggx",
            "alpha": mat.roughness,
            "eta": {"type": "rgb", "value": list(eta)},
            "k": {"type": "rgb", "value": list(k)},
            "specular_reflectance": {"type": "rgb", "value": list(mat.specular_rgb)},
        }
        return {"type": "twosided", "bsdf": inner}
    if mat.kind == "plastic":
        # polypropylene-like coating (IOR 1.49); nonlinear=False: the base colour is the
        # reflectance the user asked for, not darkened by internal scattering
        inner = {
            "type": "roughplastic",
            "distribution": "ggx",
            "alpha": mat.roughness,
            "int_ior": 1.49,
            "nonlinear": False,
            "diffuse_reflectance": rgb,
        }
        if mat.specular_rgb != (1.0, 1.0, 1.0):
            inner["specular_reflectance"] = {"type": "rgb", "value": list(mat.specular_rgb)}
    else:
        inner = {"type": "diffuse", "reflectance": rgb}
    return {"type": "twosided", "bsdf": inner}


def object_to_mitsuba(obj: SceneObject, *, key: str | None = None) -> object:
    """Mitsuba plugin dictionary of one object (a variant must be set); a plane with a form
    error is a Mesh instance instead, with id ``key`` (the key it gets in the scene dict, which
    names a dict entry's shape)."""
    import mitsuba as mi

    out = _object_kind(obj.kind).to_mitsuba(mi, obj, _bsdf(obj.material), key or obj.name)
    # a kind's own code may return anything: Mitsuba crashed the process on None (an extender's audit,
    # 2026-11-30: exit 139, no message)
    if not (isinstance(out, dict) and isinstance(out.get("type"), str)) and not isinstance(out, mi.Object):
        raise ValueError(
            f"object {obj.name!r}: the {obj.kind!r} kind's to_mitsuba returned {type(out).__name__}, not a Mitsuba "
            "plugin dict (with its 'type') or object"
        )
    return out


# ---------------------------------------------------------------------------------------
# object kinds: how each is read from a scene file, placed and handed to Mitsuba


def _parse_board(d: dict, where: str, base_dir: Path, *, dims: int) -> dict:
    p: dict[str, object] = {"center_m": _vec(d.get("center_m", (0, 0, 1)), 3, f"{where}.center_m")}
    if "size_m" not in d:
        raise ValueError(f"{where}: missing size_m")
    p["size_m"] = _vec(d["size_m"], dims, f"{where}.size_m", positive=True)
    p["rotation_deg"] = _angles(d.get("rotation_deg", (0, 0, 0)), f"{where}.rotation_deg")
    return p


def _parse_plane(d: dict, where: str, base_dir: Path) -> dict:
    return {**_parse_board(d, where, base_dir, dims=2), **_board_form(d, where)}


def target_size_m(squares: tuple[int, int], square_m: float, margin_squares: int) -> tuple[float, float]:
    """Printed size (x, y) of a checkerboard target with its margin, metres."""
    return tuple(float((n + 2 * margin_squares) * square_m) for n in squares)


def target_texture(
    squares: tuple[int, int], margin_squares: int, *, paper_rgb: Sequence[float], ink_rgb: Sequence[float]
) -> np.ndarray:
    """The printed target, one texel per square: shape (rows + 2 m, columns + 2 m, 3) float32,
    row 0 at the board's smallest y; the first square of the checkerboard is dark."""
    cols, rows = squares
    m = margin_squares
    tex = np.empty((rows + 2 * m, cols + 2 * m, 3), np.float32)
    tex[:] = np.asarray(paper_rgb, np.float32)
    j, i = np.mgrid[0:rows, 0:cols]
    tex[m : m + rows, m : m + cols][(i + j) % 2 == 0] = np.asarray(ink_rgb, np.float32)
    return tex


def _parse_target(d: dict, where: str, base_dir: Path) -> dict:
    # assumption: a checkerboard has 2-64 squares a side of 1 mm - 0.5 m
    squares = _squares(d.get("squares"), where)
    square_m = validate.number(d.get("square_m"), f"{where}: square_m", lo=0.001, hi=0.5)
    margin = validate.integer(d.get("margin_squares", 1), f"{where}: margin_squares", lo=0, hi=10)
    ink = validate.numbers(d.get("ink_rgb", (PAINT_MIN_REFLECTANCE,) * 3), f"{where}: ink_rgb", 3, lo=0.0, hi=1.0)
    p: dict[str, object] = {
        "center_m": _vec(d.get("center_m", (0, 0, 1)), 3, f"{where}.center_m"),
        "rotation_deg": _angles(d.get("rotation_deg", (0, 0, 0)), f"{where}.rotation_deg"),
        "squares": squares,
        "square_m": square_m,
        "margin_squares": margin,
        "ink_rgb": ink,
        "size_m": target_size_m(squares, square_m, margin),
    }
    return {**p, **_board_form(d, where)}


def _squares(value: object, where: str) -> tuple[int, int]:
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise ValueError(f"{where}: squares must be a list of 2 integers [columns, rows], got {value!r}")
    return tuple(validate.integer(n, f"{where}: squares", lo=2, hi=64) for n in value)


def _parse_box(d: dict, where: str, base_dir: Path) -> dict:
    return _parse_board(d, where, base_dir, dims=3)


def _parse_sphere(d: dict, where: str, base_dir: Path) -> dict:
    if "radius_m" not in d:  # (as a plane's size_m: an audit read "got None" as a bad value)
        raise ValueError(f"{where}: missing radius_m")
    return {
        "center_m": _vec(d.get("center_m", (0, 0, 1)), 3, f"{where}.center_m"),
        "radius_m": validate.number(d.get("radius_m"), f"{where}: radius_m", lo=0.0, lo_open=True, hi=SCENE_EXTENT_M),
    }


# Assumption: the largest mesh a scene may hold.  Mitsuba keeps 32-bit vertex indices and
# (llvm/cuda variants) the whole mesh in memory with its BVH, ~100 bytes a face: 2**25 faces
# (33.5 M, ~3.4 GB) fits this project's 24 GiB machines with room for the films; a scanned
# statue at 0.1 mm holds ~10 M.  The file bound keeps an accidental multi-gigabyte file from
# being read whole before that check (binary PLY: 12 bytes a vertex, 13 a face).
MESH_MAX_FACES = 1 << 25
MESH_MAX_VERTICES = 1 << 25
MESH_MAX_FILE_BYTES = 2 << 30


@lru_cache(maxsize=32)
def check_mesh_file(path: str, mtime_ns: int = 0, size: int = 0) -> tuple[int, int]:
    """Check a PLY/OBJ mesh before it reaches Mitsuba, whose loaders trust the file: a face
    that indexes a missing vertex crashes the process or renders garbage.  Returns
    ``(vertices, faces)``; ``mtime_ns`` and ``size`` only key the memo (a changed file is read
    again).

    Checked: the file's size (:data:`MESH_MAX_FILE_BYTES`), that it parses (trimesh, without
    merging or repairing anything), at least one face, vertex and face counts
    (:data:`MESH_MAX_VERTICES`, :data:`MESH_MAX_FACES`), every face index within the vertex
    list, every vertex finite, and at least one face of non-zero area.  Single zero-area
    faces are legal (scanned meshes have them; they are never hit) and only logged.

    Raises
    ------
    ValueError
        The mesh fails a check (one line naming the file and what is wrong).
    """
    name = Path(path).name
    if size > MESH_MAX_FILE_BYTES:
        raise ValueError(
            f"mesh {name}: {size / 2**30:.1f} GiB, larger than the {MESH_MAX_FILE_BYTES >> 30} GiB allowed"
        )
    import trimesh

    try:
        mesh = trimesh.load(path, process=False, validate=False, force="mesh")
        vertices = np.asarray(mesh.vertices, dtype=np.float64)
        faces = np.asarray(mesh.faces)
    except Exception as exc:  # noqa: BLE001 - any parser failure is a malformed file
        first = (str(exc).splitlines() or [type(exc).__name__])[0]
        raise ValueError(f"mesh {name}: not a readable {Path(path).suffix[1:].upper()} mesh ({first})") from None
    if faces.ndim != 2 or faces.shape[0] == 0 or faces.shape[1] != 3:
        raise ValueError(f"mesh {name}: no triangle faces (faces of shape {faces.shape})")
    if len(vertices) > MESH_MAX_VERTICES or len(faces) > MESH_MAX_FACES:
        raise ValueError(
            f"mesh {name}: {len(vertices)} vertices and {len(faces)} faces; at most {MESH_MAX_VERTICES} and "
            f"{MESH_MAX_FACES} are allowed"
        )
    bad = (faces < 0) | (faces >= len(vertices))
    if bad.any():
        f = int(np.argmax(bad.any(axis=1)))
        raise ValueError(
            f"mesh {name}: face {f} indexes vertex {int(faces[f][bad[f]][0])}, but the mesh has {len(vertices)} "
            f"vertices (0..{len(vertices) - 1}); {int(bad.any(axis=1).sum())} faces index missing vertices"
        )
    if not np.isfinite(vertices).all():
        v = int(np.argmax(~np.isfinite(vertices).all(axis=1)))
        raise ValueError(f"mesh {name}: vertex {v} is not finite ({vertices[v].tolist()})")
    tri = vertices[faces]
    area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    if not (area2 > 0).any():
        raise ValueError(f"mesh {name}: every one of its {len(faces)} faces has zero area (nothing to render)")
    if not (area2 > 0).all():
        log.info("mesh %s: %d of %d faces have zero area", name, int((area2 == 0).sum()), len(faces))
    return len(vertices), len(faces)


def _reflectance(value: object) -> object:
    """A scene's ``rgb``: a list of three reflectances, or one number for a grey (``rgb = 0.85``,
    as scenes/README.md writes plaster); anything else as given, for the material's check to name."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return (value, value, value)
    return tuple(value) if isinstance(value, list) else value


def _parse_mesh(d: dict, where: str, base_dir: Path) -> dict:
    if "file" not in d:
        raise ValueError(f"{where}: missing file")
    path = Path(str(d["file"]))
    if not path.is_absolute():
        path = base_dir / path
    if not path.exists():
        # (a relative path is the scene file's folder's: an audit, 2026-12-05, copied a library
        # scene elsewhere and read only "not found")
        raise FileNotFoundError(
            f"{where}: mesh file not found: {path}"
            + (
                ""
                if Path(str(d["file"])).is_absolute()
                else f" (a relative mesh path is taken from the scene file's folder, {base_dir})"
            )
        )
    if not path.is_file():
        what = "a folder" if path.is_dir() else "not a regular file (a pipe or device?)"
        raise ValueError(f"{where}: mesh file {path} is {what}")
    if path.suffix.lower() not in (".ply", ".obj"):
        raise ValueError(f"{where}: mesh must be .ply or .obj, got {path.name}")
    st = path.stat()
    try:
        check_mesh_file(str(path.resolve()), st.st_mtime_ns, st.st_size)
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None
    return {
        "file": str(path.resolve()),
        "scale": validate.number(
            d.get("scale", 1.0), f"{where}: scale", lo=MESH_SCALE_RANGE[0], hi=MESH_SCALE_RANGE[1]
        ),
        "translate_m": _vec(d.get("translate_m", (0, 0, 0)), 3, f"{where}.translate_m"),
        "rotation_deg": _angles(d.get("rotation_deg", (0, 0, 0)), f"{where}.rotation_deg"),
    }


def _plane_to_mitsuba(mi, obj: SceneObject, bsdf: dict, key: str):
    if any(obj.get(k) for k in BOARD_FORM_KEYS):
        return _formed_board(mi, obj, bsdf, key)
    sx, sy = obj.get("size_m")
    # Mitsuba's rectangle spans [-1, 1]^2 with normal +z; flip it to face the camera.
    tw = _to_world(mi, translate=obj.get("center_m"), rotation_deg=obj.get("rotation_deg"), scale=(sx / 2, sy / 2, 1.0))
    return {"type": "rectangle", "to_world": tw, "flip_normals": True, "bsdf": bsdf}


def _target_to_mitsuba(mi, obj: SceneObject, bsdf: dict, key: str):
    tex = target_texture(
        obj.get("squares"), obj.get("margin_squares"), paper_rgb=obj.material.rgb, ink_rgb=obj.get("ink_rgb")
    )
    # nearest texels: the squares' edges are sharp; the path tracer's samples antialias them
    reflectance = {
        "type": "bitmap",
        "bitmap": mi.Bitmap(tex),
        "raw": True,
        "filter_type": "nearest",
        "wrap_mode": "clamp",
    }
    textured = {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": reflectance}}
    if any(obj.get(k) for k in BOARD_FORM_KEYS):
        return _formed_board(mi, obj, textured, key, texcoords=True)
    return _plane_to_mitsuba(mi, obj, textured, key)


def _box_to_mitsuba(mi, obj: SceneObject, bsdf: dict, key: str):
    tw = _to_world(
        mi, translate=obj.get("center_m"), rotation_deg=obj.get("rotation_deg"), scale=np.asarray(obj.get("size_m")) / 2
    )
    return {"type": "cube", "to_world": tw, "bsdf": bsdf}


def _sphere_to_mitsuba(mi, obj: SceneObject, bsdf: dict, key: str):
    return {"type": "sphere", "center": list(obj.get("center_m")), "radius": obj.get("radius_m"), "bsdf": bsdf}


def _mesh_to_mitsuba(mi, obj: SceneObject, bsdf: dict, key: str):
    path = obj.get("file")
    arrays = mesh_arrays(path)
    if arrays is None:  # triangles with their vertex normals: Mitsuba's loader reads the file as it is
        tw = _to_world(
            mi, translate=obj.get("translate_m"), rotation_deg=obj.get("rotation_deg"), scale=obj.get("scale")
        )
        return {
            "type": Path(path).suffix.lower()[1:],
            "filename": path,
            "to_world": tw,
            "bsdf": bsdf,
            "face_normals": False,
        }
    vertices, faces, normals = arrays
    rot = rotation_xyz_deg(obj.get("rotation_deg"))
    world = (vertices * float(obj.get("scale"))) @ rot.T + np.asarray(obj.get("translate_m"), np.float64)
    props = mi.Properties()
    props.set_id(key)
    props["bsdf"] = mi.load_dict(bsdf)
    mesh = mi.Mesh(key, vertex_count=len(world), face_count=len(faces), has_vertex_normals=True, props=props)
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(world.astype(np.float32).ravel())
    params["vertex_normals"] = mi.Float((normals @ rot.T).astype(np.float32).ravel())
    params["faces"] = mi.UInt32(faces.astype(np.uint32).ravel())
    params.update()
    return mesh


def mesh_arrays(path: str) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(vertices, triangles, vertex normals) of a mesh file that Mitsuba's loaders would not read as
    it is - or not the same way twice - and None for one they would: triangles only, a normal at
    every vertex, no relative OBJ indices.

    A new user's audit (2026-11-30): a PLY of quads or an OBJ with relative (negative) indices,
    legal files that trimesh reads, failed inside Mitsuba with its loader's messages ("trailing
    tokens after end of PLY file", "reference to invalid vertex 4294967293"), and a mesh without
    vertex normals rendered 3-547 pixels apart between cold runs: Mitsuba computes the missing
    normals in parallel, its sums in no fixed order.  Such a file is read by trimesh (its polygons
    split into triangles, indices resolved) and given the angle-weighted vertex normals of
    Thürmer & Wüthrich (1998), the weighting Mitsuba uses, summed in face order
    (:func:`vertex_normals`): the same bits every run."""
    p = Path(path)
    st = p.stat()
    return _mesh_arrays(str(p), st.st_mtime_ns, st.st_size)


@lru_cache(maxsize=8)
def _mesh_arrays(path: str, mtime_ns: int, size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    if _loader_reads_as_is(path):
        return None
    import trimesh

    mesh = trimesh.load(path, process=False, validate=False, force="mesh")
    vertices = np.asarray(mesh.vertices, np.float64)
    faces = np.asarray(mesh.faces, np.int64)
    out = (vertices, faces, vertex_normals(vertices, faces))
    for a in out:
        a.setflags(write=False)
    return out


def _loader_reads_as_is(path: str) -> bool:
    """Whether Mitsuba's PLY/OBJ loader reads ``path`` as it is and the same way every run: a PLY
    whose header gives vertex normals (nx ny nz) and whose faces are all triangles, or an OBJ
    whose faces are triangles naming a normal at each corner, none by a relative index."""
    if path.lower().endswith(".ply"):
        with open(path, "rb") as f:
            header = b""
            while b"end_header" not in header and len(header) < 1 << 16:
                chunk = f.readline()
                if not chunk:
                    break
                header += chunk
            text = header.decode("ascii", "replace")
            names = {line.split()[-1] for line in text.splitlines() if line.startswith("property")}
            if not {"nx", "ny", "nz"} <= names:
                return False
            # every face a triangle: the face list's counts, read after the vertices
            return _ply_faces_are_triangles(path, text)
    with open(path, encoding="utf-8", errors="replace") as f:
        has_normals = False
        for line in f:
            if line.startswith("vn "):
                has_normals = True
            elif line.startswith("f "):
                corners = line.split()[1:]
                if len(corners) != 3 or any(c.startswith("-") or c.count("/") != 2 or c.endswith("/") for c in corners):
                    return False
        return has_normals


def _ply_faces_are_triangles(path: str, header: str) -> bool:
    """Whether every face of a PLY file has three corners (trimesh splits larger ones silently,
    Mitsuba's loader refuses them): the header's face count against the triangles
    :func:`check_mesh_file` read (its memo: the file is not parsed again)."""
    declared = [int(line.split()[2]) for line in header.splitlines() if line.startswith("element face")]
    st = Path(path).stat()
    return bool(declared) and check_mesh_file(path, st.st_mtime_ns, st.st_size)[1] == declared[0]


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit vertex normals, each the sum of its faces' unit normals weighted by the face's angle at
    the vertex (Thürmer & Wüthrich 1998), accumulated in face order (``np.add.at``: the same bits
    every run); (0, 0, 1) at a vertex no face of non-zero area touches."""
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64)
    tri = v[f]  # (F, 3 corners, xyz)
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    length = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.divide(n, length, out=np.zeros_like(n), where=length > 0)
    out = np.zeros_like(v)
    for k in range(3):
        e1 = tri[:, (k + 1) % 3] - tri[:, k]
        e2 = tri[:, (k + 2) % 3] - tri[:, k]
        l1 = np.linalg.norm(e1, axis=1)
        l2 = np.linalg.norm(e2, axis=1)
        ok = (l1 > 0) & (l2 > 0)
        cos = np.where(ok, np.einsum("ij,ij->i", e1, e2) / np.where(ok, l1 * l2, 1.0), 1.0)
        angle = np.arccos(np.clip(cos, -1.0, 1.0))
        np.add.at(out, f[:, k], n * angle[:, None])
    length = np.linalg.norm(out, axis=1, keepdims=True)
    return np.where(length > 0, out / np.where(length > 0, length, 1.0), np.array([0.0, 0.0, 1.0]))


@dataclass(frozen=True)
class ObjectKind:
    """One kind of scene object: the ``keys`` a scene file may give it (besides the common
    ones), ``parse(table, where, base_dir)`` -> its checked parameters, ``to_mitsuba(mi, obj,
    bsdf, key)`` -> its Mitsuba plugin dict or object, the parameter placement moves in depth
    (``position_key``) and whether placement tilts it (``tilts``; a sphere does not)."""

    keys: tuple[str, ...]
    parse: Callable[[dict, str, Path], dict]
    to_mitsuba: Callable
    position_key: str = "center_m"
    tilts: bool = True
    # parameters holding reflectances besides the material's (seen through the camera's
    # channels like it: simbench.sim.capture's crosstalk path maps them too)
    colour_keys: tuple[str, ...] = ()


# adding an object kind is one entry here
OBJECT_KIND_TABLE: dict[str, ObjectKind] = {
    "plane": ObjectKind(("center_m", "size_m", "rotation_deg", *BOARD_FORM_KEYS), _parse_plane, _plane_to_mitsuba),
    "box": ObjectKind(("center_m", "size_m", "rotation_deg"), _parse_box, _box_to_mitsuba),
    "target": ObjectKind(
        ("center_m", "rotation_deg", "squares", "square_m", "margin_squares", "ink_rgb", *BOARD_FORM_KEYS),
        _parse_target,
        _target_to_mitsuba,
        colour_keys=("ink_rgb",),
    ),
    "sphere": ObjectKind(("center_m", "radius_m"), _parse_sphere, _sphere_to_mitsuba, tilts=False),
    "mesh": ObjectKind(
        ("file", "scale", "translate_m", "rotation_deg"), _parse_mesh, _mesh_to_mitsuba, position_key="translate_m"
    ),
}


class _KindKeys(Mapping):
    """kind -> the keys a scene file may give it: a view of :data:`OBJECT_KIND_TABLE`, so that a kind
    added there is read at once (a copy made at import refused one: an extender's audit)."""

    def __getitem__(self, name: str) -> tuple[str, ...]:
        return OBJECT_KIND_TABLE[name].keys

    def __iter__(self):
        return iter(OBJECT_KIND_TABLE)

    def __len__(self) -> int:
        return len(OBJECT_KIND_TABLE)


OBJECT_KINDS: Mapping[str, tuple[str, ...]] = _KindKeys()
_BUILTIN_KINDS = dict(OBJECT_KIND_TABLE)


def _keep_builtin_kinds() -> None:
    for name, kind in _BUILTIN_KINDS.items():
        if OBJECT_KIND_TABLE.get(name) is not kind:
            log.warning(
                "a simbench extension replaced the object kind %r: left as simbench's (register yours under a name "
                "of its own)",
                name,
            )
            OBJECT_KIND_TABLE[name] = kind


after_load(_keep_builtin_kinds)


def _object_kind(name: str) -> ObjectKind:
    """The registered kind ``name`` (an installed package's kinds imported first where it is unknown:
    a worker's unpickled scene)."""
    if name not in OBJECT_KIND_TABLE:
        load_extensions()
    return OBJECT_KIND_TABLE[name]


def _formed_board(mi, obj: SceneObject, bsdf: dict, key: str, *, texcoords: bool = False):
    """A plane with a form error as a Mitsuba mesh: a grid (:data:`BOARD_GRID`,
    :data:`RIPPLE_CELLS`) displaced by :func:`board_form_m` towards the camera (local -z: the
    plane faces the camera along -z before its rotation), placed like the flat plane."""
    sx, sy = obj.get("size_m")
    form = {k: obj.get(k) for k in BOARD_FORM_KEYS if obj.get(k) is not None}
    cells_x = BOARD_GRID
    if form.get("waviness_m"):
        cells_x = max(cells_x, math.ceil(RIPPLE_CELLS * sx / form["waviness_period_m"]))
    nx, ny = cells_x + 1, BOARD_GRID + 1
    x, y = np.meshgrid(np.linspace(-sx / 2, sx / 2, nx), np.linspace(-sy / 2, sy / 2, ny))
    z = -board_form_m(x, y, size_m=(sx, sy), **form)
    local = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
    world = local @ rotation_xyz_deg(obj.get("rotation_deg")).T + np.asarray(obj.get("center_m"), np.float64)
    a = (np.arange(ny - 1)[:, None] * nx + np.arange(nx - 1)[None, :]).ravel()  # each cell's first vertex
    faces = np.concatenate([np.stack([a, a + 1, a + nx], 1), np.stack([a + 1, a + nx + 1, a + nx], 1)])
    props = mi.Properties()
    props.set_id(key)
    props["bsdf"] = mi.load_dict(bsdf)
    mesh = mi.Mesh(
        key,
        vertex_count=nx * ny,
        face_count=len(faces),
        has_vertex_normals=False,
        has_vertex_texcoords=texcoords,
        props=props,
    )
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(world.astype(np.float32).ravel())
    if texcoords:
        # the flat rectangle's texture coordinates: (x / sx + 1/2, y / sy + 1/2) in the board frame
        uv = np.stack([x.ravel() / sx + 0.5, y.ravel() / sy + 0.5], axis=1)
        params["vertex_texcoords"] = mi.Float(uv.astype(np.float32).ravel())
    params["faces"] = mi.UInt32(faces.astype(np.uint32).ravel())
    params.update()
    return mesh


def scene_fingerprint(scene: SceneSpec) -> dict:
    """Everything about a scene that affects a render, as plain JSON-able data."""
    objects = []
    for o in scene.objects:
        params = dict(o.params)
        if o.kind == "mesh":
            p = Path(params["file"])
            st = p.stat()
            params["file"] = {"name": p.name, "sha256": file_digest(str(p), st.st_mtime_ns, st.st_size)}
            if mesh_arrays(str(p)) is not None:  # (only then: the library's meshes keep their cache keys)
                params["file"]["read"] = "trimesh, angle-weighted vertex normals"
        material = [o.material.kind, list(o.material.rgb), o.material.roughness]
        if o.material.specular_rgb != (1.0, 1.0, 1.0):
            material.append(list(o.material.specular_rgb))
        if o.material.spectrum is not None:
            material.append({"spectrum": o.material.spectrum})
        if o.material.metal is not None:
            from simbench.sim.spectral import metal_ior_rgb

            # by value, so that changed optical constants are a new render input
            eta, k = metal_ior_rgb(o.material.metal, primary=o.material.metal_primary)
            material.append({"metal": o.material.metal, "eta": list(eta), "k": list(k)})
        if o.material.subsurface is not None:
            from simbench.sim.subsurface import get_medium

            # by value, so that a medium whose coefficients change is a new render input
            medium = dataclasses.asdict(get_medium(o.material.subsurface))
            material.append({"subsurface": o.material.subsurface, **medium})
        entry = {"kind": o.kind, "name": o.name, "params": params, "material": material}
        kind = _object_kind(o.kind)
        foreign = foreign_code_digest(kind.parse, kind.to_mitsuba)
        if foreign is not None:  # a user's own kind, by its code (only then: simbench's keep their keys)
            entry["kind_code"] = foreign
        if o.motion is not None:  # only when it moves, so that static scenes keep their cache keys
            entry["motion"] = o.motion.to_dict()
        objects.append(entry)
    return {
        "rig": rig_to_dict(scene.rig),
        "objects": objects,
        "projector_scale": scene.projector_scale,
        "ambient_rgb": list(scene.ambient_rgb),
        # only when set, so that pinhole scenes keep their cache keys
        **({"camera_lens": list(scene.camera_lens)} if scene.camera_lens is not None else {}),
    }
