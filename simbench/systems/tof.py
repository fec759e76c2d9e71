"""An SR4000-like continuous-wave time-of-flight camera, simulated the way the device works.

Device (numbers from the literature where they exist, otherwise stated assumptions):

- 176x144 lock-in pixels of 40 um, field of view 43.6 x 34.6 deg (MESA SR4000 data sheet as
  quoted in the literature); square pixels with the focal length of the horizontal field
  (220 px; the vertical field is then 36.2 deg).
- An 850 nm LED array around the lens, modulated at 30 MHz (the SR4000's default; 5 m
  unambiguous range).  Rendered as Mitsuba's ``projector`` emitter with a uniform texture 1 mm
  beside the camera centre (the ring is centred on the lens: co-located; ``Rig`` needs a
  non-zero baseline), covering the view with a margin.
- Per pixel four samples of the correlation of the returned light with the modulation,
  ``A_k = N/4 (1 + m |Z| cos(phi - k pi/2))`` (4-tap phase measurement, Lange & Seitz 2001):
  ``N`` electrons from the rendered amplitude, ``m`` the demodulation contrast, ``Z`` the
  normalised phasor of the pixel's footprint and ``phi`` its phase.
- Mixed ("flying") pixels: ``Z`` sums phasors ``w_i exp(i 2 pi f L_i / c)`` over
  ``supersample^2`` rays through each pixel's footprint (path ``L_i`` camera -> surface ->
  emitter, weight ``w_i = rho_i cos(theta_i) / r_i^2``, the direct return of a Lambertian
  surface lit by a point-like source); at depth edges foreground and background mix.
- Shot noise (Poisson per sample) and read noise; samples clip at the full well and such pixels
  are flagged invalid, as the device does.
- A translucent object (scene key ``subsurface``) spreads the light it returns
  (:func:`simbench.sim.capture.with_translucency`) and delays it: each of its rays' phasors is
  multiplied by the medium's :func:`simbench.sim.subsurface.modulation_transfer` (dipole diffusion
  in time; NIR as the mean of the three bands), so a translucent surface reads farther away.
- Left out: multipath interference (the indirect light's path lengths are not tracked by the
  renderer; the amplitude is the direct render, max_depth 2), the systematic "wiggling" error
  of non-sinusoidal modulation, and temperature drift.  The scene's NIR reflectance is the mean
  of its RGB reflectance (assumption, as for the Kinect).

Decoding: ``phi = atan2(A1 - A3, A0 - A2)``, amplitude ``sqrt((A0-A2)^2 + (A1-A3)^2) / 2``,
radial distance ``c phi / (4 pi f)``, z-depth along the pixel's ray.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from simbench import validate

from simbench.literature import SR4000_FOV_X_DEG, SR4000_MODULATION_HZ, SR4000_SIZE_WH
from simbench.sim.photometry import LIGHT_M_S, photons_per_unit_radiance
from simbench.rig import Intrinsics, Rig
from simbench.sim.scene import SceneSpec
from simbench.seeds import RngLike

if TYPE_CHECKING:
    from simbench.cache import RenderCache

__all__ = [
    "ToFModel",
    "ToFDepth",
    "tof_rig",
    "device_scene",
    "footprint_phasor",
    "tap_windows_s",
    "moving_tap_means",
    "record_taps",
    "decode_taps",
    "capture",
]


@dataclass(frozen=True)
class ToFModel:
    """SR4000-like device parameters (module docstring for their sources)."""

    width_px: int = SR4000_SIZE_WH[0]
    height_px: int = SR4000_SIZE_WH[1]
    fov_x_deg: float = SR4000_FOV_X_DEG
    modulation_hz: float = SR4000_MODULATION_HZ
    wavelength_nm: float = 850.0
    pixel_pitch_um: float = 40.0
    # assumption: ~1 W of optical power from the LED array (order of the SR4000's 24 LEDs)
    optical_power_w: float = 1.0
    f_number: float = 1.4  # assumption: a fast lens, as lock-in ToF cameras use
    lens_transmission: float = 0.9  # assumption
    qe: float = 0.3  # assumption: silicon at 850 nm
    fill_factor: float = 0.25  # assumption: lock-in pixels carry large in-pixel circuits
    # assumption: demodulation contrast ~40 % at tens of MHz (Lange 2000 reports about that)
    demodulation_contrast: float = 0.4
    # Chiabrando et al. 2009 measured the 1.3 m wall at 8.5 ms integration
    integration_s: float = 8.5e-3
    full_well_e: float = 1.0e6  # assumption, per sample
    read_noise_e: float = 50.0  # assumption
    supersample: int = 4
    emitter_margin: float = 1.2
    min_amplitude_e: float = 200.0  # assumption: below it the phase is noise (confidence map)
    noise: bool = True

    def __post_init__(self) -> None:
        for name in (
            "fov_x_deg",
            "modulation_hz",
            "wavelength_nm",
            "pixel_pitch_um",
            "optical_power_w",
            "f_number",
            "integration_s",
            "full_well_e",
        ):
            # finite and positive; the modulation within 1 GHz (CW ToF cameras modulate at 10-300 MHz,
            # the SR4000 at 30 MHz), the field of view under 180 deg
            hi = {"modulation_hz": 1e9, "fov_x_deg": 179.0}.get(name)
            validate.number(getattr(self, name), f"tof {name}", lo=0.0, lo_open=True, hi=hi)
        for name in ("lens_transmission", "qe", "fill_factor", "demodulation_contrast"):
            v = getattr(self, name)
            if not 0 < v <= 1:
                raise ValueError(f"tof {name} must be in (0, 1], got {v!r}")
        if isinstance(self.supersample, bool) or int(self.supersample) != self.supersample or self.supersample < 1:
            raise ValueError(f"tof supersample must be a positive integer, got {self.supersample!r}")

    @property
    def focal_px(self) -> float:
        return self.width_px / 2.0 / math.tan(math.radians(self.fov_x_deg / 2.0))

    @property
    def camera(self) -> Intrinsics:
        return Intrinsics.centred(self.width_px, self.height_px, self.focal_px)

    @property
    def unambiguous_range_m(self) -> float:
        return LIGHT_M_S / (2.0 * self.modulation_hz)


_EMITTER_OFFSET_M = (0.001, 0.0, 0.0)


def tof_rig(model: ToFModel) -> Rig:
    """The ToF camera and its co-located emitter (a projector slightly wider than the view)."""
    w = int(math.ceil(model.width_px * model.emitter_margin))
    h = int(math.ceil(model.height_px * model.emitter_margin))
    return Rig(
        camera=model.camera,
        projector=Intrinsics.centred(w, h, model.focal_px),
        position_m=_EMITTER_OFFSET_M,
        name="sr4000",
    )


def _emitter_texture(model: ToFModel) -> np.ndarray:
    prj = tof_rig(model).projector
    tex = np.ones((prj.height_px, prj.width_px, 3), np.float32)
    # black border: Mitsuba clamps the texture lookup beyond the frustum
    tex[[0, -1]] = 0.0
    tex[:, [0, -1]] = 0.0
    return tex


def device_scene(scene: SceneSpec, model: ToFModel) -> SceneSpec:
    """``scene`` seen by the ToF camera: its rig, no lens model, no ambient (850 nm filter)."""
    return dataclasses.replace(
        scene, rig=tof_rig(model), camera_lens=None, ambient_rgb=(0.0, 0.0, 0.0), projector_scale=1.0
    )


def electrons_per_radiance(model: ToFModel) -> float:
    """Electrons (all four samples together) per unit rendered radiance: the emitter's
    irradiance at 1 m (optical power over the frustum's cross-section) through the camera
    equation (:func:`simbench.sim.photometry.photons_per_unit_radiance`), QE and fill factor."""
    prj = tof_rig(model).projector
    area_1m = ((prj.width_px - 2) / prj.focal_px) * ((prj.height_px - 2) / prj.focal_px)
    photons = photons_per_unit_radiance(
        irradiance_1m_w_m2=model.optical_power_w / area_1m,
        wavelength_nm=model.wavelength_nm,
        f_number=model.f_number,
        pixel_pitch_um=model.pixel_pitch_um,
        exposure_s=model.integration_s,
        lens_transmission=model.lens_transmission,
    )
    return photons * model.qe * model.fill_factor


def _sub_rays(model: ToFModel) -> np.ndarray:
    s = model.supersample
    cam = model.camera
    off = (np.arange(s) + 0.5) / s - 0.5
    y = (np.arange(cam.height_px)[:, None] + off[None, :]).reshape(-1)
    x = (np.arange(cam.width_px)[:, None] + off[None, :]).reshape(-1)
    xs = (x - cam.cx_px) / cam.focal_px
    ys = (y - cam.cy_px) / cam.focal_px
    # order (H, s, W, s): pixel (r, c) owns rays [r, :, c, :]
    return np.stack(np.broadcast_arrays(xs[None, :], ys[:, None], np.ones((1, 1))), axis=-1).reshape(-1, 3)


def footprint_phasor(scene: SceneSpec, model: ToFModel) -> np.ndarray:
    """Normalised phasor ``Z`` of each pixel's direct return, shape (H, W), complex128
    (0 where nothing in the footprint returns light)."""
    from simbench.sim.truth import trace_rays

    hits = trace_rays(scene, _sub_rays(model))
    # a translucent object delays the light its paths inside it take (simbench.sim.subsurface.
    # modulation_transfer; NIR as the mean of the three bands, as its reflectance); 1 if opaque
    transfer = np.array([_medium_transfer(o, model) for o in scene.objects] + [1.0], dtype=np.complex128)
    p = hits["p"]
    emitter = np.asarray(scene.rig.position_m)
    to_e = emitter[None, :] - p
    r_e = np.linalg.norm(to_e, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        cos_i = np.abs(np.sum(hits["n"] * to_e, axis=1)) / r_e
        albedo = np.array([float(np.mean(o.material.rgb)) for o in scene.objects] + [0.0])
        returns = hits["hit"] & ~hits["occluded"]
        w = np.where(returns, albedo[hits["object_id"]] * cos_i / r_e**2, 0.0)
    path = np.where(returns, np.linalg.norm(p, axis=1) + r_e, 0.0)  # misses carry no weight
    ph = w * np.exp(1j * 2 * np.pi * model.modulation_hz * path / LIGHT_M_S) * transfer[hits["object_id"]]
    s = model.supersample
    shape = (model.height_px, s, model.width_px, s)
    total = ph.reshape(shape).sum(axis=(1, 3))
    weight = w.reshape(shape).sum(axis=(1, 3))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(weight > 0, total / weight, 0.0)


def _medium_transfer(obj, model: ToFModel) -> complex:
    if not obj.material.subsurface:
        return 1.0
    from simbench.sim.subsurface import get_medium, modulation_transfer

    medium = get_medium(obj.material.subsurface)
    return complex(np.mean([modulation_transfer(medium, c, frequency_hz=model.modulation_hz) for c in range(3)]))


def record_taps(amplitude: np.ndarray, phasor: np.ndarray, *, model: ToFModel, rng: RngLike) -> np.ndarray:
    """Four correlation samples (H, W, 4) in electrons (float32), seeded noise.

    ``amplitude`` is the rendered direct return (H, W) (mean over RGB = NIR, module docstring).

    References
    ----------
    .. [1] R. Lange, P. Seitz, "Solid-state time-of-flight range camera", IEEE J. Quantum
       Electronics 37(3), 390-397, 2001.
    """
    a = np.asarray(amplitude, dtype=np.float64)
    if a.shape != (model.height_px, model.width_px) or phasor.shape != a.shape:
        raise ValueError(
            f"amplitude and phasor must have shape {(model.height_px, model.width_px)}, got {a.shape} and "
            f"{phasor.shape}"
        )
    n = np.clip(a, 0, None) * electrons_per_radiance(model)
    m = model.demodulation_contrast * np.abs(phasor)
    phi = np.angle(phasor)
    k = np.arange(4)
    mean = (n / 4.0)[..., None] * (1.0 + m[..., None] * np.cos(phi[..., None] - k * np.pi / 2))
    return _noisy_taps(mean, model=model, rng=rng)


def _noisy_taps(mean: np.ndarray, *, model: ToFModel, rng: RngLike) -> np.ndarray:
    """Shot and read noise on the four samples' means (electrons), clipped at the full well."""
    if model.noise:
        gen = np.random.default_rng(rng)
        taps = gen.poisson(mean).astype(np.float64) + gen.normal(0.0, model.read_noise_e, mean.shape)
    else:
        taps = mean
    return np.minimum(taps, model.full_well_e).astype(np.float32)


@dataclass(frozen=True)
class ToFDepth:
    """depth_m (H, W) float32 z-depth, NaN invalid; distance_m radial; amplitude_e (H, W)
    demodulated amplitude (the confidence); valid (H, W) bool."""

    depth_m: np.ndarray
    distance_m: np.ndarray
    amplitude_e: np.ndarray
    valid: np.ndarray


def decode_taps(taps: np.ndarray, *, model: ToFModel) -> ToFDepth:
    """Four-sample phase -> radial distance -> z-depth (module docstring).

    References
    ----------
    .. [1] R. Lange, P. Seitz, "Solid-state time-of-flight range camera", IEEE J. Quantum
       Electronics 37(3), 390-397, 2001.
    """
    t = np.asarray(taps, dtype=np.float64)
    if t.shape != (model.height_px, model.width_px, 4):
        raise ValueError(f"taps must have shape {(model.height_px, model.width_px, 4)}, got {t.shape}")
    if not np.all(np.isfinite(t)):
        raise ValueError("taps must be finite")
    re = t[..., 0] - t[..., 2]
    im = t[..., 1] - t[..., 3]
    amp = 0.5 * np.hypot(re, im)
    phi = np.mod(np.arctan2(im, re), 2 * np.pi)
    dist = LIGHT_M_S * phi / (4 * np.pi * model.modulation_hz)
    cam = model.camera
    yy, xx = np.indices(cam.size_hw)
    norm = np.sqrt(((xx - cam.cx_px) / cam.focal_px) ** 2 + ((yy - cam.cy_px) / cam.focal_px) ** 2 + 1.0)
    saturated = np.any(t >= model.full_well_e, axis=-1)
    valid = (amp >= model.min_amplitude_e) & ~saturated
    return ToFDepth(
        depth_m=np.where(valid, dist / norm, np.nan).astype(np.float32),
        distance_m=np.where(valid, dist, np.nan).astype(np.float32),
        amplitude_e=amp.astype(np.float32),
        valid=valid,
    )


def tap_windows_s(model: ToFModel) -> list[tuple[float, float]]:
    """The time model: the four correlation samples are taken one after another, sample k over
    ``[k tau, (k + 1) tau)`` with ``tau = integration_s / 4`` (the frame's integration shared by its
    samples, as :func:`electrons_per_radiance` shares its electrons).  Sequential sampling is how
    lock-in ToF cameras with fewer storage sites than samples work (PMD cameras take their
    samples in four sequential stages: Jimenez, Pizarro & Mazo 2014, Image Vis. Comput. 32,
    1127-1143); that the SR4000 does likewise is our assumption."""
    tau = model.integration_s / 4.0
    return [(k * tau, (k + 1) * tau) for k in range(4)]


def _phasor(scene: SceneSpec, model: ToFModel, *, cache: RenderCache | None) -> np.ndarray:
    from simbench.sim.keys import cached_arrays
    from simbench.sim.scene import scene_fingerprint

    parts = {"scene": scene_fingerprint(scene), "supersample": model.supersample, "modulation_hz": model.modulation_hz}
    if any(o.material.subsurface for o in scene.objects):
        # translucent objects' delay (modulation_transfer), a model older phasors lack; opaque
        # scenes keep their keys
        parts["subsurface_delay"] = "dipole-v1"

    def make() -> dict:
        z = footprint_phasor(scene, model)
        return {"re": z.real, "im": z.imag}

    arrays = cached_arrays("tof_phasor", parts, make, cache=cache)
    return arrays["re"] + 1j * arrays["im"]


def moving_tap_means(
    scene: SceneSpec, model: ToFModel, *, spp: int, seed: int, sampler: str, cache: RenderCache | None = None
) -> np.ndarray:
    """The four samples' mean electrons (H, W, 4) of a moving scene: sample k integrates the
    return over its own window (:func:`tap_windows_s`), by time slices as every system's blur
    (:mod:`simbench.sim.motion`): ``A_k = (1/4) mean_t [n(t) + m Re(n(t) Z(t) exp(-i k pi/2))]``,
    ``n`` the return's electrons and ``Z`` the footprint phasor at each slice's instant - so a
    sample sees the depth and the brightness of its own moment (the amplitude changes between
    samples too: a moving object's return brightens as it approaches)."""
    from simbench.seeds import slice_seed
    from simbench.sim.capture import cached_radiance, opaque, with_translucency
    from simbench.sim.motion import MAX_SLICES, slice_times
    from simbench.sim.timeline import scene_at, slice_count, slice_spp

    k_e = electrons_per_radiance(model)
    means = []
    for k, window in enumerate(tap_windows_s(model)):
        n_sl = slice_count(scene, model.camera, window)
        per = spp if n_sl == 1 else slice_spp(spp, n_sl)
        how = sampler if n_sl == 1 else "independent"
        acc_n = acc_nz = 0.0
        for i, t in enumerate(slice_times(window, n_sl)):
            posed = scene_at(scene, float(t))
            s = seed if n_sl == 1 else slice_seed(seed, k * MAX_SLICES + i)
            rad = cached_radiance(
                opaque(posed), _emitter_texture(model), spp=per, seed=s, max_depth=2, sampler=how, cache=cache
            )
            n = np.clip(with_translucency(rad, posed, cache=cache).mean(axis=2).astype(np.float64), 0, None) * k_e
            acc_n = acc_n + n
            acc_nz = acc_nz + n * _phasor(posed, model, cache=cache)
        n_mean, nz_mean = acc_n / n_sl, acc_nz / n_sl
        means.append(0.25 * (n_mean + model.demodulation_contrast * np.real(nz_mean * np.exp(-0.5j * np.pi * k))))
    return np.stack(means, axis=-1)


def capture(
    scene: SceneSpec,
    model: ToFModel,
    *,
    spp: int,
    seed: int,
    noise_seeds: list[int],
    sampler: str = "independent",
    cache: RenderCache | None = None,
) -> list[np.ndarray]:
    """Tap frames (H, W, 4) of ``scene`` (already :func:`device_scene`): one direct-light render
    (``seed``) and one footprint trace, recorded once per noise seed."""
    from simbench.sim.capture import cached_radiance, opaque, with_translucency
    from simbench.sim.timeline import is_moving

    if is_moving(scene):
        means = moving_tap_means(scene, model, spp=spp, seed=seed, sampler=sampler, cache=cache)
        return [_noisy_taps(means, model=model, rng=s) for s in noise_seeds]
    rad = cached_radiance(
        opaque(scene), _emitter_texture(model), spp=spp, seed=seed, max_depth=2, sampler=sampler, cache=cache
    )
    rad = with_translucency(rad, scene, cache=cache).mean(axis=2)
    z = _phasor(scene, model, cache=cache)
    return [record_taps(rad, z, model=model, rng=s) for s in noise_seeds]


class ToFSystem:
    """The SR4000-like ToF camera as a depth system (:mod:`simbench.systems`): no calibration,
    four tap frames per recording, four-sample phase decoding."""

    name = "tof"
    seed_prefix = "tof/"

    def __init__(self, options=None, *, model: ToFModel | None = None) -> None:
        self.model = model if model is not None else ToFModel()

    def info(self):
        from simbench.systems import SystemInfo

        m = self.model
        return SystemInfo(
            name=self.name,
            label="SR4000 ToF (simulated)",
            recording_options=(),  # its own device: no sensor model, pattern or calibration frames
            size_hw=(m.height_px, m.width_px),
            captures=1,
            confidence=(
                f"demodulated amplitude of the four taps (electrons); pixels below {m.min_amplitude_e:g} e- are holes"
            ),
            numbers={
                "size_wh": ((m.width_px, m.height_px), "MESA SR4000 data sheet, as quoted by Chiabrando et al. 2009"),
                "fov_x_deg": (m.fov_x_deg, "MESA SR4000 data sheet, as quoted by Chiabrando et al. 2009"),
                "modulation_hz": (m.modulation_hz, "MESA SR4000 default"),
                "integration_s": (m.integration_s, "Chiabrando et al. 2009"),
            },
        )

    def prepare(self, scene: SceneSpec) -> SceneSpec:
        return device_scene(scene, self.model)

    def calibration_key(self, scene: SceneSpec):
        return None

    def calibrate(self, scene: SceneSpec, *, seeds, render):
        return None  # the device needs none

    def acquire(
        self, scene: SceneSpec, calibration, *, render_seed: int, noise_seeds: list[int], render
    ) -> list[np.ndarray]:
        return capture(
            scene,
            self.model,
            spp=render.spp,
            seed=render_seed,
            noise_seeds=noise_seeds,
            sampler=render.sampler,
            cache=render.cache,
        )

    def capture_window_s(self, scene: SceneSpec) -> tuple[float, float]:
        """The time model (:func:`tap_windows_s`): four samples one after another over the
        integration time (8.5 ms)."""
        windows = tap_windows_s(self.model)
        return (windows[0][0], windows[-1][1])

    def frame_windows_s(self, scene: SceneSpec) -> list[tuple[float, float]]:
        """Each correlation sample's window (:func:`tap_windows_s`), rendered as its own blur."""
        return [tuple(w) for w in tap_windows_s(self.model)]

    def decode(self, raw: np.ndarray, calibration=None, *, scene: SceneSpec | None = None):
        from simbench.systems import SystemDepth

        r = decode_taps(raw, model=self.model)
        return SystemDepth(depth_m=r.depth_m, valid=r.valid, confidence=r.amplitude_e, detail=r)

    def bench_inputs(self, *, scene: str = "plane", seed: int = 0):
        """(tap frames, None, scene) of a plane at 1.1 m made in numpy (deterministic for a
        seed): the four samples of the plane's phasor with shot noise."""
        if scene != "plane":
            raise ValueError(f"the {self.name} benchmark has only the plane, not {scene!r}")
        model = self.model
        rng = np.random.default_rng(seed)
        cam = model.camera
        yy, xx = np.indices(cam.size_hw)
        ray = np.sqrt(((xx - cam.cx_px) / cam.focal_px) ** 2 + ((yy - cam.cy_px) / cam.focal_px) ** 2 + 1)
        path = 2 * 1.1 * ray
        phasor = np.exp(1j * 2 * np.pi * model.modulation_hz * path / LIGHT_M_S)
        amplitude = np.full(cam.size_hw, 0.8 / 1.1**2)
        return (
            record_taps(amplitude, phasor, model=model, rng=rng),
            None,
            SceneSpec(name="bench_plane", rig=tof_rig(model), objects=()),
        )

    def write_recording(
        self, out_dir, raw: np.ndarray, calibration, *, scene: SceneSpec, gt, meta: dict, overwrite: bool = False
    ):
        """``taps.npy`` ((H, W, 4) float32 electrons), ground truth, ``device.json``."""
        from simbench.systems.recording import write_device_recording
        from simbench.io import save_npy

        writers = {"taps": lambda d: save_npy(d / "taps.npy", np.asarray(raw, np.float32))}
        return write_device_recording(out_dir, self.name, self.model, writers, gt=gt, info=meta, overwrite=overwrite)

    def read_recording(self, in_dir):
        from pathlib import Path

        from simbench.systems.recording import read_device_info
        from simbench.io import load_npy

        d = Path(in_dir)
        self.model, info = read_device_info(d, self.name, ToFModel)
        taps = load_npy(d / "taps.npy", expected_shape=(self.model.height_px, self.model.width_px, 4))
        # (read noise makes dim taps slightly negative: a sign is no error, a NaN is)
        if taps.dtype.kind != "f" or not np.isfinite(taps).all():
            raise ValueError(
                f"{d / 'taps.npy'}: taps are finite electron counts (float), got {taps.dtype} with NaN or inf"
            )
        return (
            taps,
            None,
            self.prepare(SceneSpec(name=str(info.get("scene", d.name)), rig=tof_rig(self.model), objects=())),
        )
