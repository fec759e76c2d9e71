"""Sensor models: the physical camera and projector between the pattern and the recorded pixels,
as one frozen configuration (:class:`SensorModel`) read from a TOML preset.

Presets live in ``simbench/presets/<name>.toml`` (``ideal``, ``minimal``, ``paper``, ``paper_sim``); a path to
any TOML file with the same layout works too.  Every effect is switchable:

=====================  =================================================================
effect                 switch (TOML)
=====================  =================================================================
camera noise           ``[camera] noise``  (EMVA 1288: shot, dark, full well, ADC, PRNU/DSNU)
white balance          ``[camera] white_balance`` (``off`` / ``one_push``)
colour filter array    ``[camera] cfa`` (``none`` / ``RGGB`` ...) and ``demosaic``
spectral crosstalk     ``[spectral] crosstalk``
projector transfer     ``[projector] transfer`` (``linear`` / ``gamma``), ``gamma``
projector black level  ``[projector] contrast_ratio`` (``inf`` = off)
projector timing       ``[projector] timing`` (``triggered`` / ``video``), ``frame_rate_hz``
DMD layout             ``[projector] dmd`` (``square`` / ``diamond``)
camera defocus         ``[camera.lens] defocus``, ``f_number``, ``focus_m``
projector defocus      ``[projector.lens] defocus``, ``f_number``, ``focus_m``
lens distortion        ``[camera.lens] distortion``, ``[projector.lens] distortion``
lateral colour         ``[camera.lens] lateral_colour_px``, ``[projector.lens] lateral_colour_px``
ambient light          ``[ambient] ratio`` (to the projector's white irradiance at Z0)
=====================  =================================================================

The photometric chain of the ``emva`` camera: the projector's white gives ``lumens / A``
lux at 1 m (``A`` = its frustum's cross-section at 1 m, from the rig), split into primaries
(:func:`simbench.sim.photometry.primary_irradiance_w_m2`); a rendered radiance of 1 for primary
``p`` is the radiance ``E_p / pi`` of a white Lambertian surface 1 m in front of it, which the
camera equation turns into photons per pixel (:func:`simbench.sim.photometry.photons_per_unit_radiance`)
and the channel's quantum efficiency into electrons (the whole chain: :mod:`simbench.sim.photometry`).
The exposure time is ``auto`` by default: what brings the brightest channel of the white reference board at Z0 to
``auto_exposure_fraction`` of the full well, as an operator would set it once for the rig.
White balance ``one_push`` sets the red and blue channel gains once, on the same white board
under the projector's full white, so that its three channels read alike
(:func:`simbench.sim.photometry.white_balance_gains`); the auto exposure then holds for the balanced channels.
"""

from __future__ import annotations

import dataclasses
import hashlib
import logging
import math
import os
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

from simbench import validate
from simbench.io import ADC_BITS, read_toml
from simbench.sim.projector import DMD_LAYOUTS, TIMINGS, TRANSFERS
from simbench.rig import Intrinsics, Rig
from simbench.sim.camera import (
    CFA_PATTERNS,
    DEMOSAIC_METHODS,
    MAX_EXPOSURE_S,
    MAX_FULL_WELL_E,
    MAX_NOISE_E,
    MIN_PIXEL_PITCH_UM,
    SimpleCamera,
)

log = logging.getLogger(__name__)

__all__ = [
    "Lens",
    "PhysicalCamera",
    "ProjectorModel",
    "SensorModel",
    "check_rig_lens",
    "left_out_keys",
    "Effect",
    "EFFECT_TABLE",
    "PRESETS_DIR",
    "SENSOR_PRESETS",
    "get_sensor",
    "load_sensor",
    "sensor_from_dict",
    "sensor_to_dict",
    "apply_to_rig",
    "WHITE_BALANCE_MODES",
    "EFFECTS",
    "with_effects",
    "PAPER_LATERAL_COLOUR_PX",
    "with_lateral_colour",
]

PRESETS_DIR = Path(__file__).resolve().parents[1] / "presets"
SENSOR_PRESETS = ("ideal", "minimal", "paper", "paper_sim")
_NO_DISTORTION = (0.0, 0.0, 0.0, 0.0, 0.0)
# Point Grey Flea3 USB 3.0 Technical Reference (rev. 9/27/2012), Sec. 7.8 "White Balance": off
# (one gain for every pixel of the Bayer tiling) or red and blue gains relative to green, set by
# hand or by One Push on a white target; we model off and One Push.
WHITE_BALANCE_MODES = ("off", "one_push")


def _set(obj, values: dict) -> None:
    """Store validated (normalised) field values on a frozen dataclass."""
    for name, value in values.items():
        object.__setattr__(obj, name, value)


@dataclass(frozen=True)
class Lens:
    """A lens: photometry (f-number, transmission), thin-lens defocus, Brown-Conrady distortion,
    lateral colour.

    ``focal_length_mm`` is derived from the device's focal length in pixels and its pixel pitch.
    ``defocus`` switches the blur on; the f-number also sets the camera's exposure.
    ``lateral_colour_px`` is each colour channel's (R, G, B) radial displacement, in the device's
    pixels, at its image corner farthest from the principal point (positive outward;
    :mod:`simbench.optics`); (0, 0, 0) = none.
    """

    f_number: float = 4.0
    transmission: float = 0.9
    defocus: bool = False
    focus_m: float = 1.0
    distortion: tuple[float, float, float, float, float] = _NO_DISTORTION
    lateral_colour_px: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        v = validate
        _set(
            self,
            {
                "f_number": v.number(self.f_number, "f_number", lo=0.5, hi=64.0),
                "transmission": v.number(self.transmission, "transmission", lo=0.0, hi=1.0, lo_open=True),
                "defocus": v.boolean(self.defocus, "defocus"),
                # assumption: machine-vision lenses focus from ~0.1 m; beyond 1 km is infinity for
                # any scene within the scenes' 100 m (a focus of 1e20 m made every capture black)
                "focus_m": v.number(self.focus_m, "focus_m", lo=0.05, hi=1e3),
                # assumption: |coefficient| <= 10; beyond, Brown-Conrady folds over inside any normal view
                "distortion": v.numbers(self.distortion, "distortion (k1, k2, p1, p2, k3)", 5, lo=-10.0, hi=10.0),
                # assumption: a lens whose colours part by more than 50 px at the corner images nothing
                "lateral_colour_px": v.numbers(
                    list(self.lateral_colour_px)
                    if isinstance(self.lateral_colour_px, tuple)
                    else self.lateral_colour_px,
                    "lateral_colour_px (R, G, B)",
                    3,
                    lo=-50.0,
                    hi=50.0,
                ),
            },
        )

    def aperture_m(self, focal_px: float, pixel_pitch_um: float) -> float:
        """Aperture diameter F / N (m) for a device of focal length ``focal_px``."""
        return focal_px * pixel_pitch_um * 1e-6 / self.f_number


def _bits(bits: object) -> int:
    """The ADC's bits, checked (the offset's bound needs them before the other fields)."""
    return validate.choice(validate.integer(bits, "bits"), "bits", ADC_BITS)


@dataclass(frozen=True)
class PhysicalCamera:
    """A colour camera after EMVA 1288 with a colour filter array (see :mod:`simbench.sim.camera`).

    ``qe`` is each channel's quantum efficiency for the projector primary of its own colour;
    ``gain_dn_per_e`` None = full well maps to the top of the ADC range; ``exposure_s`` None =
    auto exposure (module docstring).
    """

    pixel_pitch_um: float
    qe: tuple[float, float, float]
    full_well_e: float
    dark_noise_e: float
    bits: int = 8
    gain_dn_per_e: float | None = None
    offset_dn: float = 0.0
    dark_current_e_s: float = 0.0
    prnu: float = 0.0
    dsnu_e: float = 0.0
    fixed_pattern_seed: int = 0
    exposure_s: float | None = None
    auto_exposure_fraction: float = 0.7
    noise: bool = True
    cfa: str = "none"
    demosaic: str = "bilinear"
    white_balance: str = "off"

    def __post_init__(self) -> None:
        v = validate
        # Physical ranges (issue 33: offset_dn, dark_current_e_s or dsnu_e = 1e30 validated and
        # made every capture 255).  Each bound is far outside any camera sold, inside what the
        # model means:
        # - full well: machine-vision and scientific sensors hold 2-500 ke- (EMVA 1288 datasheets;
        #   large-pixel CCDs ~1 Me-): at most 1e7 e-;
        # - read (dark) noise and DSNU: a few e- (CMOS) to tens of e- (old CCDs): at most 1e4 e-;
        # - dark current: 1-100 e-/s uncooled at room temperature, ~1e4 e-/s hot: at most 1e6 e-/s;
        # - gain: at most 1e4 DN/e- (a 16-bit ADC over a 6.5 e- full well);
        # - black level (offset): a few % of the ADC range; at most half of it, else the capture
        #   has no room for a signal;
        # - pixel pitch: the smallest pixels made are ~0.56 um (2023 smartphone sensors), the
        #   largest ~25 um; under MIN_PIXEL_PITCH_UM is a unit slip (3.45 um written 0.00345, in mm:
        #   an audit's auto exposure came to 13106 s);
        # - exposure: at most MAX_EXPOSURE_S.
        _set(
            self,
            {
                "pixel_pitch_um": v.number(self.pixel_pitch_um, "pixel_pitch_um", lo=MIN_PIXEL_PITCH_UM, hi=100.0),
                "qe": v.numbers(self.qe, "qe", 3, lo=0.0, hi=1.0, lo_open=True),
                "full_well_e": v.number(self.full_well_e, "full_well_e", lo=0.0, lo_open=True, hi=MAX_FULL_WELL_E),
                "dark_noise_e": v.number(self.dark_noise_e, "dark_noise_e", lo=0.0, hi=MAX_NOISE_E),
                "bits": v.choice(v.integer(self.bits, "bits"), "bits", ADC_BITS),
                "gain_dn_per_e": v.optional(
                    v.number, self.gain_dn_per_e, "gain_dn_per_e", lo=0.0, lo_open=True, hi=1e4
                ),
                "offset_dn": v.number(self.offset_dn, "offset_dn", lo=0.0, hi=0.5 * ((1 << _bits(self.bits)) - 1)),
                "dark_current_e_s": v.number(self.dark_current_e_s, "dark_current_e_s", lo=0.0, hi=1e6),
                "prnu": v.number(self.prnu, "prnu", lo=0.0, hi=1.0),
                "dsnu_e": v.number(self.dsnu_e, "dsnu_e", lo=0.0, hi=MAX_NOISE_E),
                "fixed_pattern_seed": v.integer(self.fixed_pattern_seed, "fixed_pattern_seed", lo=0, hi=2**63 - 1),
                "exposure_s": v.optional(
                    v.number, self.exposure_s, "exposure_s", lo=0.0, hi=MAX_EXPOSURE_S, lo_open=True
                ),
                "auto_exposure_fraction": v.number(
                    self.auto_exposure_fraction, "auto_exposure_fraction", lo=0.0, hi=1.0, lo_open=True
                ),
                "noise": v.boolean(self.noise, "noise"),
                "cfa": v.choice(self.cfa, "cfa", CFA_PATTERNS),
                "demosaic": v.choice(self.demosaic, "demosaic", DEMOSAIC_METHODS),
                "white_balance": v.choice(self.white_balance, "white_balance", WHITE_BALANCE_MODES),
            },
        )

    @property
    def max_dn(self) -> int:
        return (1 << self.bits) - 1

    @property
    def gain(self) -> float:
        return self.gain_dn_per_e if self.gain_dn_per_e is not None else self.max_dn / self.full_well_e


# assumption: pico-projector lenses are fast, about f/2 (the paper preset's [projector.lens])
PROJECTOR_F_NUMBER = 2.0


@dataclass(frozen=True)
class ProjectorModel:
    """The projector's physics (see :mod:`simbench.sim.projector`)."""

    lumens: float = 150.0
    transfer: str = "linear"
    gamma: float = 2.2
    contrast_ratio: float = math.inf
    dmd: str = "square"
    pixel_pitch_um: float = 5.4
    timing: str = "triggered"
    frame_rate_hz: float = 60.0
    lens: Lens = field(default_factory=lambda: Lens(f_number=PROJECTOR_F_NUMBER))

    def __post_init__(self) -> None:
        v = validate
        _set(
            self,
            {
                # assumption: at most 1e6 lm, 13x the brightest cinema projectors (~75,000 lm)
                "lumens": v.number(self.lumens, "lumens", lo=0.0, lo_open=True, hi=1e6),
                "transfer": v.choice(self.transfer, "transfer", TRANSFERS),
                # assumption: display gammas lie in (0, 10]; 2.2 is the video standard
                "gamma": v.number(self.gamma, "gamma", lo=0.0, hi=10.0, lo_open=True),
                "contrast_ratio": v.number(self.contrast_ratio, "contrast_ratio", lo=1.0, allow_inf=True),
                "dmd": v.choice(self.dmd, "dmd", DMD_LAYOUTS),
                # (DMD micromirrors 5.4-13.7 um, LCoS pixels ~3-8 um: MIN_PIXEL_PITCH_UM is far below)
                "pixel_pitch_um": v.number(self.pixel_pitch_um, "pixel_pitch_um", lo=MIN_PIXEL_PITCH_UM, hi=100.0),
                "timing": v.choice(self.timing, "timing", TIMINGS),
                # assumption: video inputs run at up to a few hundred frames per second
                "frame_rate_hz": v.number(self.frame_rate_hz, "frame_rate_hz", lo=1.0, hi=1000.0),
            },
        )
        if not isinstance(self.lens, Lens):
            raise ValueError(f"lens must be a Lens, got {type(self.lens).__name__}")


@dataclass(frozen=True)
class SensorModel:
    """Everything between the 8-bit pattern and the recorded image (module docstring)."""

    name: str
    camera: PhysicalCamera | SimpleCamera
    camera_lens: Lens = Lens()
    projector: ProjectorModel = ProjectorModel()
    crosstalk: bool = False
    ambient_ratio: float = 0.0
    description: str = ""

    def __post_init__(self) -> None:
        _set(
            self,
            {
                "crosstalk": validate.boolean(self.crosstalk, "crosstalk"),
                # assumption: room light up to 100x the projector's white at Z0 (daylight on a pico projector)
                "ambient_ratio": validate.number(self.ambient_ratio, "ambient ratio", lo=0.0, hi=100.0),
            },
        )
        if isinstance(self.camera, SimpleCamera) and self.crosstalk:
            raise ValueError("spectral crosstalk needs the physical (emva) camera model")

    @property
    def is_physical(self) -> bool:
        return isinstance(self.camera, PhysicalCamera)


# ---------------------------------------------------------------------------------------
# TOML


def _table(data: dict, key: str, where: str) -> dict:
    t = data.get(key, {})
    if not isinstance(t, dict):
        raise ValueError(f"{where}: [{key}] must be a table")
    return t


def _build(cls, table: dict, where: str, *, convert: dict | None = None):
    allowed = [f.name for f in dataclasses.fields(cls)]
    unknown = sorted(set(table) - set(allowed))
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {unknown}; valid keys: {allowed}")
    required = [
        f.name
        for f in dataclasses.fields(cls)
        if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
    ]
    missing = [k for k in required if k not in table]
    if missing:
        raise ValueError(f"{where}: missing key(s) {missing}")
    kwargs = dict(table)
    try:
        for k, fn in (convert or {}).items():
            if k in kwargs:
                try:
                    kwargs[k] = fn(kwargs[k])
                except (TypeError, ValueError) as exc:
                    raise ValueError(f"{k}: {exc}") from None
        return cls(**kwargs)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {exc}") from None


def _inf_or_number(v):
    if v == "inf":
        return math.inf
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ValueError(f"expected a number or 'inf', got {v!r}")
    return float(v)


def _auto_or_number(v):
    if v == "auto":
        return None
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ValueError(f"expected a number or 'auto', got {v!r}")
    return float(v)


def sensor_from_dict(data: dict, *, where: str = "sensor") -> SensorModel:
    """Validate a sensor TOML table (layout: ``simbench/presets/paper.toml``)."""
    keys = ("name", "description", "camera", "projector", "spectral", "ambient")
    unknown = sorted(set(data) - set(keys))
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {unknown}; valid keys: {list(keys)}")
    cam = dict(_table(data, "camera", where))
    cam_lens = _build(Lens, _table(cam, "lens", f"{where}.camera"), f"{where}.camera.lens")
    model = cam.pop("model", "emva")
    cam.pop("lens", None)
    if model == "simple":
        camera = _build(SimpleCamera, cam, f"{where}.camera")
    elif model == "emva":
        camera = _build(
            PhysicalCamera,
            cam,
            f"{where}.camera",
            convert={"exposure_s": _auto_or_number, "qe": tuple, "gain_dn_per_e": _auto_or_number},
        )
    else:
        raise ValueError(f"{where}.camera.model must be 'emva' or 'simple', got {model!r}")
    prj = dict(_table(data, "projector", where))
    # the projector lens's own default f-number where the file gives none (an audit: a file without
    # [projector.lens] got the camera lens's f/4, the code's projector f/2)
    prj_lens = _build(
        Lens,
        {"f_number": PROJECTOR_F_NUMBER, **_table(prj, "lens", f"{where}.projector")},
        f"{where}.projector.lens",
    )
    prj.pop("lens", None)
    projector = _build(
        ProjectorModel, {**prj, "lens": prj_lens}, f"{where}.projector", convert={"contrast_ratio": _inf_or_number}
    )
    spectral = _table(data, "spectral", where)
    ambient = _table(data, "ambient", where)
    for t, allowed, name in ((spectral, ("crosstalk",), "spectral"), (ambient, ("ratio",), "ambient")):
        bad = sorted(set(t) - set(allowed))
        if bad:
            raise ValueError(f"{where}.{name}: unknown key(s) {bad}; valid keys: {list(allowed)}")
    try:
        crosstalk = validate.boolean(spectral.get("crosstalk", False), f"{where}.spectral.crosstalk")
        ratio = validate.number(ambient.get("ratio", 0.0), f"{where}.ambient.ratio", lo=0.0, hi=100.0)
    except ValueError as exc:
        raise ValueError(str(exc)) from None
    try:
        return SensorModel(
            name=str(data.get("name", "custom")),
            camera=camera,
            camera_lens=cam_lens,
            projector=projector,
            crosstalk=crosstalk,
            ambient_ratio=float(ratio),
            description=str(data.get("description", "")),
        )
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None


def sensor_to_dict(sensor: SensorModel) -> dict:
    """Plain data (JSON/TOML) of a sensor model; :func:`sensor_from_dict` reads it back."""

    def enc(v):
        if isinstance(v, float) and math.isinf(v):
            return "inf"
        if isinstance(v, tuple):
            return list(v)
        return v

    def lens(x: Lens) -> dict:
        # no lateral colour is left out, so the dicts (and cache keys) of models without it are
        # what they were before it was modelled
        return {k: enc(v) for k, v in dataclasses.asdict(x).items() if k != "lateral_colour_px" or any(v)}

    cam = {k: enc(v) for k, v in dataclasses.asdict(sensor.camera).items() if v is not None}
    cam = {"model": "emva" if sensor.is_physical else "simple", **cam}
    if sensor.is_physical:
        cam.setdefault("exposure_s", "auto")
    cam["lens"] = lens(sensor.camera_lens)
    prj = {
        k: enc(getattr(sensor.projector, k))
        for k in ("lumens", "transfer", "gamma", "contrast_ratio", "dmd", "pixel_pitch_um", "timing", "frame_rate_hz")
    }
    prj["lens"] = lens(sensor.projector.lens)
    return {
        "name": sensor.name,
        "description": sensor.description,
        "camera": cam,
        "projector": prj,
        "spectral": {"crosstalk": sensor.crosstalk},
        "ambient": {"ratio": sensor.ambient_ratio},
    }


def load_sensor(path: str | Path) -> SensorModel:
    """Read a sensor TOML file; errors name the file and the field.  A file outside the
    presets that leaves keys out is told which values stand in for them (a warning): a
    copy of ``paper.toml`` with ``cfa`` deleted records without a mosaic."""
    path = Path(path)
    data = read_toml(path, what="sensor")
    data.setdefault("name", path.stem)
    sensor = sensor_from_dict(data, where=f"{path}: sensor")
    if path.resolve().parent != PRESETS_DIR.resolve():
        left = left_out_keys(data, sensor)
        said = hashlib.sha256(repr((str(path.resolve()), left)).encode()).hexdigest()[:16]
        # once a run: a command loads its sensor more than once, and a pool's workers inherit
        # what their parent said through the environment
        told = os.environ.get(_LEFT_OUT_VARIABLE, "").split()
        if left and said not in told:
            os.environ[_LEFT_OUT_VARIABLE] = " ".join([*told, said])
            log.warning(
                "sensor %s leaves out %d key(s), which take these values (an effect left out is off; "
                "docs/sensor-model.md): %s",
                path,
                len(left),
                ", ".join(left),
            )
    return sensor


_LEFT_OUT_VARIABLE = "SIMBENCH_SENSOR_FILES_TOLD"  # (internal: the files load_sensor has warned of)


def left_out_keys(data: dict, sensor: SensorModel) -> list[str]:
    """``table.key = value`` for each key of ``sensor``'s camera model, lenses, projector,
    spectral and ambient tables that ``data`` (a sensor TOML table) does not give: the values
    the model took for them."""
    simple = not sensor.is_physical  # its exposure is a fraction of full scale: no lens photometry or crosstalk
    tables = {
        "camera": ([f.name for f in dataclasses.fields(type(sensor.camera))], sensor.camera),
        "camera.lens": ([f.name for f in dataclasses.fields(Lens)], sensor.camera_lens),
        "projector": ([f.name for f in dataclasses.fields(ProjectorModel) if f.name != "lens"], sensor.projector),
        # (a projector's lumens are its output: its lens's transmission is in them already)
        "projector.lens": (
            [f.name for f in dataclasses.fields(Lens) if f.name != "transmission"],
            sensor.projector.lens,
        ),
    }
    if simple:
        del tables["camera.lens"]
    out = []
    for table, (names, obj) in tables.items():
        given = data
        for part in table.split("."):
            given = given.get(part, {}) if isinstance(given, dict) else {}
        for name in names:
            if name not in given:
                value = getattr(obj, name)
                if isinstance(value, tuple):
                    value = list(value)
                if isinstance(value, float) and math.isinf(value):
                    value = "inf"
                out.append(f"{table}.{name} = {'auto' if value is None else repr(value)}")
    for table, key, value in (("spectral", "crosstalk", sensor.crosstalk), ("ambient", "ratio", sensor.ambient_ratio)):
        if key not in data.get(table, {}) and not (simple and table == "spectral"):
            out.append(f"{table}.{key} = {value!r}")
    return out


def get_sensor(name_or_path: str | Path) -> SensorModel:
    """A preset by name (:data:`SENSOR_PRESETS`) or a sensor TOML file."""
    key = str(name_or_path)
    if key in SENSOR_PRESETS:
        return load_sensor(PRESETS_DIR / f"{key}.toml")
    path = Path(key)
    if path.suffix.lower() != ".toml":
        raise ValueError(f"unknown sensor {key!r}: give a preset ({', '.join(SENSOR_PRESETS)}) or a .toml file")
    return load_sensor(path)


# ---------------------------------------------------------------------------------------
# geometry and photometry


def check_rig_lens(rig: Rig, sensor: SensorModel, *, where: str) -> None:
    """ValueError when ``rig`` states a lens distortion other than ``sensor``'s: a render takes
    its lenses from the sensor model (:func:`apply_to_rig`), so the rig's would be dropped
    without a word (a calibrated rig.toml given to ``calibrate --rig`` or as a scene's rig)."""
    for name, intr, lens in (
        ("camera", rig.camera, sensor.camera_lens),
        ("projector", rig.projector, sensor.projector.lens),
    ):
        if intr.has_distortion and tuple(intr.distortion) != tuple(lens.distortion):
            raise ValueError(
                f"{where}: the rig's {name} distortion {list(intr.distortion)} is not the lens of sensor model "
                f"{sensor.name!r} ({list(lens.distortion)}); a render takes its lenses from the sensor model: give "
                f"the distortion as the sensor file's [{name}.lens] distortion, and the rig without it"
            )


def apply_to_rig(rig: Rig, sensor: SensorModel) -> Rig:
    """The rig with the sensor's lens distortion (what calibration would record in the rig
    file: the decoder reads it back from there)."""

    def with_dist(intr: Intrinsics, d) -> Intrinsics:
        if tuple(d) == intr.distortion:
            return intr
        return dataclasses.replace(intr, distortion=tuple(d))

    cam = with_dist(rig.camera, sensor.camera_lens.distortion)
    prj = with_dist(rig.projector, sensor.projector.lens.distortion)
    if cam is rig.camera and prj is rig.projector:
        return rig
    return dataclasses.replace(rig, camera=cam, projector=prj)


# ---------------------------------------------------------------------------------------
# effects, one at a time (the error budget and ablations)


@dataclass(frozen=True)
class Effect:
    """One physical effect of a sensor model: ``description`` for tables, ``fields`` the dotted
    paths into :class:`SensorModel` that carry it (``camera.noise``, ``projector.lens.defocus``,
    ``crosstalk``): :func:`with_effects` copies exactly these from one model to another."""

    description: str
    fields: tuple[str, ...]


_CAMERA_NOISE = (
    "noise",
    "dark_noise_e",
    "dark_current_e_s",
    "prnu",
    "dsnu_e",
    "fixed_pattern_seed",
    "bits",
    "gain_dn_per_e",
    "offset_dn",
    "full_well_e",
)

# Lateral colour of the paper's lenses, not yet part of the `paper` preset (turning it on there
# re-renders every capture; until then it is the budget's and Table 3's what-if row, "lateral
# colour").  Assumption, an argued bound: neither lens is named in the paper (the Flea3 takes any
# C-mount lens; the LightCrafter 4500's projection optics are TI's), and no per-channel data is
# published for either.  A lens sold for a 5.3 um-pixel 1.2-MP sensor resolves its pixels at full
# field, so its red and blue images cannot part by much more than a pixel there; we take half a
# pixel between the red (620 nm) and blue (455 nm) primaries at the corner, red outward (the
# usual sign of an undercorrected achromat), green between them, and the same in DMD pixels for
# the projector.  The ablation study `lateral_colour` sweeps the magnitude.
PAPER_LATERAL_COLOUR_PX = {"camera": (0.25, 0.0, -0.25), "projector": (0.25, 0.0, -0.25)}


def with_lateral_colour(
    sensor: SensorModel, *, camera_px: tuple[float, float, float], projector_px: tuple[float, float, float]
) -> SensorModel:
    """``sensor`` with its camera and projector lenses' lateral colour set (R, G, B radial shifts
    at the image corner, :class:`Lens`)."""
    cam = dataclasses.replace(sensor.camera_lens, lateral_colour_px=tuple(camera_px))
    prj = dataclasses.replace(
        sensor.projector, lens=dataclasses.replace(sensor.projector.lens, lateral_colour_px=tuple(projector_px))
    )
    return dataclasses.replace(sensor, camera_lens=cam, projector=prj)


# the effects the error budget and the ablations switch on one at a time; adding one is one entry
EFFECT_TABLE: dict[str, Effect] = {
    "noise": Effect("camera noise (EMVA 1288: shot, dark, PRNU/DSNU)", tuple(f"camera.{k}" for k in _CAMERA_NOISE)),
    "white_balance": Effect("camera white balance (One Push on the white reference)", ("camera.white_balance",)),
    "cfa": Effect("Bayer colour filter + demosaicing", ("camera.cfa", "camera.demosaic")),
    "crosstalk": Effect("spectral crosstalk (LED primaries x camera sensitivities x surface)", ("crosstalk",)),
    "transfer": Effect("projector transfer curve", ("projector.transfer", "projector.gamma")),
    "black_level": Effect("projector black level (finite contrast)", ("projector.contrast_ratio",)),
    "timing": Effect(
        "projector bit-plane timing against the camera exposure", ("projector.timing", "projector.frame_rate_hz")
    ),
    "dmd": Effect("DMD diamond pixel layout", ("projector.dmd",)),
    "camera_defocus": Effect(
        "camera defocus (thin lens)", ("camera_lens.defocus", "camera_lens.focus_m", "camera_lens.f_number")
    ),
    "projector_defocus": Effect(
        "projector defocus", ("projector.lens.defocus", "projector.lens.focus_m", "projector.lens.f_number")
    ),
    "distortion": Effect(
        "lens distortion (camera + projector), undistorted by the decoder",
        ("camera_lens.distortion", "projector.lens.distortion"),
    ),
    "lateral_colour": Effect(
        "lateral chromatic aberration (camera + projector lenses), not corrected by the decoder",
        ("camera_lens.lateral_colour_px", "projector.lens.lateral_colour_px"),
    ),
    "ambient": Effect("ambient light", ("ambient_ratio",)),
}
# name -> description (tables, help texts)
EFFECTS = {name: e.description for name, e in EFFECT_TABLE.items()}


def _get_path(obj, path: str):
    for part in path.split("."):
        obj = getattr(obj, part)
    return obj


def _replace_path(obj, path: str, value):
    head, _, rest = path.partition(".")
    return dataclasses.replace(obj, **{head: _replace_path(getattr(obj, head), rest, value) if rest else value})


def with_effects(
    base: SensorModel, source: SensorModel, effects: Iterable[str], *, name: str | None = None
) -> SensorModel:
    """``base`` with the named effects (:data:`EFFECT_TABLE`) taken from ``source`` (both
    physical): every field of each effect copied from ``source``."""
    if not (base.is_physical and source.is_physical):
        raise ValueError("effects move between physical (emva) sensor models only")
    bad = [e for e in effects if e not in EFFECT_TABLE]
    if bad:
        raise ValueError(f"unknown effect(s) {bad}; valid: {list(EFFECT_TABLE)}")
    out = base
    for e in effects:
        for path in EFFECT_TABLE[e].fields:
            out = _replace_path(out, path, _get_path(source, path))
    return dataclasses.replace(
        out,
        name=name or f"{base.name}+{'+'.join(effects)}",
        description=f"{base.name} with {', '.join(effects)} from {source.name}",
    )
