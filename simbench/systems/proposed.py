"""The proposed sensor as a depth system: the paper's colour sequence coded fringe pattern
projected by a DLP projector, recorded by a colour camera, decoded by the paper's pipeline.

Calibration is the paper's Sec. 5.4: one capture of a white reference plane at the scene's Z0
(albedo :data:`simbench.sim.photometry.REFERENCE_ALBEDO`) per rig and lighting, decoded once per
decoder setting; a decoder that unmixes the primaries also needs the plane under a black frame
and under each primary at full drive (Caspi et al. 1998's calibration of the coupling matrix;
four frames once per calibration, the measurement stays single-shot).

References
----------
.. [1] F. Li, B. Zhang, G. Shi, Y. Niu, R. Li, L. Yang, X. Xie, "Single-Shot Dense Depth Sensing
   with Color Sequence Coded Fringe Pattern", Sensors 17(11), 2558, 2017.
.. [2] D. Caspi, N. Kiryati, J. Shamir, "Range imaging with adaptive color structured light",
   IEEE TPAMI 20(5), 470-480, 1998.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from simbench.manifest import read_manifest
from simbench.sim.scene import SceneSpec, reference_scene
from simbench.systems import RECORDING_MANIFESTS, RenderSettings, SystemDepth, SystemInfo, SystemOptions
from simbench.systems.proposed_folder import (
    RENDER_MANIFEST,
    describe_pattern,
    pattern_record,
    recorded_adc_bits,
    recorded_pattern,
    recorded_z0,
)

if TYPE_CHECKING:
    from simbench.cache import RenderCache
    from simbench.decode.params import DecoderParams
    from simbench.decode.pipeline import ReferenceMap
    from simbench.sim.sensor import SensorModel
    from simbench.pattern import PatternSpec
    from simbench.sim.truth import GroundTruth
    from simbench.systems.files import DecodeRequest, FileDecode

_log = logging.getLogger(__name__)

__all__ = [
    "ColourFringeSystem",
    "ReferenceCalibration",
    "BENCH_SCENES",
    "BENCH_SHADOW",
    "pattern_record",
    "recorded_pattern",
    "recorded_z0",
    "recorded_adc_bits",
    "describe_pattern",
    "Acquisition",
    "acquire",
    "acquire_with_calibration",
    "write_acquisition",
    "RENDER_MANIFEST",
]

BENCH_SCENES = ("plane", "shadow")
# the ``shadow`` benchmark scene's region without projector light (rows, columns)
BENCH_SHADOW = (slice(330, 630), slice(440, 840))


@lru_cache(maxsize=8)
def pattern_u8(spec: PatternSpec) -> np.ndarray:
    """The projector's 8-bit frame of ``spec`` (:func:`simbench.pattern.fringe_pattern`,
    quantised), made once per process and pattern (read-only: every system built with the
    pattern shares it; an experiment builds dozens)."""
    from simbench.pattern import fringe_pattern, quantize

    frame = quantize(fringe_pattern(spec))
    frame.setflags(write=False)
    return frame


@lru_cache(maxsize=8)
def pattern_digest(spec: PatternSpec) -> str:
    """:func:`simbench.cache.array_digest` of :func:`pattern_u8`, once per process and pattern."""
    from simbench.cache import array_digest

    return array_digest(pattern_u8(spec))


@lru_cache(maxsize=64)
def _with(params: DecoderParams, **changes) -> DecoderParams:
    """``dataclasses.replace(params, **changes)``, once per distinct call: each replace validates
    every field again (~0.1 ms, serial work before a decode's band threads start)."""
    return dataclasses.replace(params, **changes)


@dataclass
class ReferenceCalibration:
    """The proposed sensor's calibration: the recorded reference plane (``image``), with the
    calibration frames (``frames``: name -> image, :data:`simbench.pattern.CALIBRATION_FRAMES`)
    when a decoder unmixes the primaries; decoded reference maps are kept per decoder setting
    (and in the render cache: :func:`simbench.decode.persist.lookup_decoded_reference`)."""

    rig: object
    image: np.ndarray
    frames: dict = field(default_factory=dict)
    cache: object = None
    # the bits of the camera's ADC (None: the images' dtype's range): a 10-, 12- or 14-bit camera's
    # uint16 images hold its digital numbers (simbench.io.adc_full_scale)
    adc_bits: int | None = None
    _maps: dict = field(default_factory=dict, repr=False)

    def reference_map(self, params, *, rig=None) -> ReferenceMap:
        """The reference decoded with ``params`` (mode and Z0 as given) and ``rig`` (the rig the
        decoder believes; None = the rig the reference was recorded with)."""
        from simbench.decode.persist import lookup_decoded_reference

        rig = self.rig if rig is None else rig
        if rig.camera.size_hw != self.rig.camera.size_hw:
            raise ValueError(
                f"rig camera {rig.camera.size_hw} does not match the reference's {self.rig.camera.size_hw}"
            )
        from simbench.decode.params import phase_method_code

        # a user's phase method edited and registered again under its name decodes afresh
        key = (params, rig, phase_method_code(params.phase_method))
        if key not in self._maps:
            from simbench.io import adc_full_scale

            def scaled(img, name):
                return None if img is None else adc_full_scale(img, bits=self.adc_bits, where=name)

            primaries = dark = None  # a decoder that does not unmix reads the reference alone
            if params.unmix:
                if not self.frames:
                    raise ValueError(
                        "this decoder unmixes the primaries: the calibration needs its frames (calibrate with "
                        "frames=True)"
                    )
                primaries = [scaled(self.frames[k], f"calibration frame {k}") for k in ("red", "green", "blue")]
                dark = scaled(self.frames.get("dark"), "calibration frame dark")
            ref, store = lookup_decoded_reference(
                scaled(self.image, "reference"),
                rig=rig,
                params=params,
                primaries=primaries,
                dark=dark,
                cache=self.cache,
            )
            store()
            self._maps[key] = ref
        return self._maps[key]


class ColourFringeSystem:
    """The proposed sensor (module docstring); ``options`` gives its sensor model, decoder,
    camera scale and reference-board form."""

    name = "proposed"
    # the proposed sensor's captures keep the labels experiments give them
    seed_prefix = ""
    manifest_name = "meta.json"  # RENDER_MANIFEST: its folders' manifest

    def __init__(self, options: SystemOptions | None = None) -> None:
        from simbench.decode import DecoderParams
        from simbench.sim.sensor import get_sensor

        options = options or SystemOptions()
        self.sensor = options.sensor if options.sensor is not None else get_sensor("paper")
        self.decoder = options.decoder if options.decoder is not None else DecoderParams()
        self.camera_scale = float(options.camera_scale)
        self.reference_form = dict(options.reference_form)
        self.pattern = self.decoder.pattern
        self.pattern_u8 = pattern_u8(self.pattern)

    def info(self) -> SystemInfo:
        from simbench.rig import paper_rig, scale_camera

        cam = scale_camera(paper_rig(), self.camera_scale).camera if self.camera_scale != 1 else paper_rig().camera
        return SystemInfo(
            name=self.name,
            label="proposed (Li et al.)",
            size_hw=cam.size_hw,
            captures=1,
            period_px=self.pattern.period_px,
            uses_scene_rig=True,
            recording_options=("sensor", "pattern", "calibration_frames", "camera_scale"),
            confidence=(
                "fringe SNR: the RMS of the fitted fringe over the RMS of the local fit's residual "
                "(simbench.decode.phase.fringe_snr); "
                + (
                    f"pixels below {self.decoder.min_confidence:g} are holes"
                    if self.decoder.min_confidence > 0
                    else "no threshold (the paper's decoder describes none)"
                )
            ),
            numbers={
                "period_px": (self.pattern.period_px, "paper Sec. 3 (T = 21 projector px)"),
                "debruijn_order": (self.pattern.order, "paper Eq. 7-8 (B(2, 3))"),
                "camera_wh": ((1280, 960), "paper Sec. 6 (Point Grey Flea3)"),
                "projector_wh": ((1824, 1140), "paper Sec. 6 (TI DLP LightCrafter 4500)"),
            },
        )

    def prepare(self, scene: SceneSpec) -> SceneSpec:
        """The scene with the run's camera resolution, the rendered rig and the sensor model's
        lenses and ambient light (:func:`simbench.sim.capture.physical_scene`)."""
        from simbench.sim.mitsuba_dict import realised_rig
        from simbench.rig import check_stripe_baseline, scale_camera
        from simbench.sim.capture import physical_scene

        check_stripe_baseline(scene.rig)  # before minutes of rendering what no decoder reads
        rig = scene.rig if self.camera_scale == 1 else scale_camera(scene.rig, self.camera_scale)
        return physical_scene(dataclasses.replace(scene, rig=realised_rig(rig)), self.sensor)

    def reference_label(self, scene: SceneSpec) -> str:
        """The seed label of the reference capture: one per rig and lighting."""
        return f"reference/{scene.rig.name}/{scene.reference_depth_m:g}/{scene.projector_scale:g}/{scene.ambient_rgb}"

    def calibration_key(self, scene: SceneSpec) -> tuple:
        """One reference capture per rig, lighting, reference-board form and sensor model."""
        return (
            self.sensor,
            scene.rig,
            scene.reference_depth_m,
            scene.projector_scale,
            scene.ambient_rgb,
            tuple(sorted(self.reference_form.items())),
        )

    def calibrate(
        self, scene: SceneSpec, *, seeds, render: RenderSettings, frames: bool | None = None
    ) -> ReferenceCalibration:
        """Record the reference plane behind ``scene`` (prepared) and, with ``frames`` (default:
        when the decoder unmixes), the calibration frames; seeds from :meth:`reference_label`."""
        from simbench.io import stored_adc_bits
        from simbench.pattern import calibration_frames
        from simbench.sim.photometry import REFERENCE_ALBEDO

        ref_scene = reference_scene(scene, albedo=REFERENCE_ALBEDO, form=self.reference_form)
        label = self.reference_label(scene)
        image = self._record(ref_scene, label, seeds=seeds, render=render)
        cal = {}
        if self.decoder.unmix if frames is None else frames:
            for name, drive in calibration_frames(self.pattern_u8).items():
                cal[name] = self._record(ref_scene, f"{label}/{name}", seeds=seeds, render=render, pattern_u8=drive)
        return ReferenceCalibration(
            rig=scene.rig,
            image=image,
            frames=cal,
            cache=render.cache,
            adc_bits=stored_adc_bits(self.sensor.camera.bits),
        )

    def _record(self, scene: SceneSpec, label: str, *, seeds, render: RenderSettings, pattern_u8=None) -> np.ndarray:
        render_seed, noise = seeds.capture(label)
        return self.acquire(
            scene, None, render_seed=render_seed, noise_seeds=noise, render=render, pattern_u8=pattern_u8
        )[0]

    def acquire(
        self,
        scene: SceneSpec,
        calibration,
        *,
        render_seed: int,
        noise_seeds: list[int],
        render: RenderSettings,
        pattern_u8: np.ndarray | None = None,
    ) -> list[np.ndarray]:
        """One render of ``scene`` (prepared) lit by the pattern (or ``pattern_u8``), recorded
        once per noise seed (a static scene measured again differs by camera noise only;
        recordings cached, :func:`simbench.sim.capture.record_channels`)."""
        from simbench.sim.capture import record_channels
        from simbench.sim.drive import DriveImage, ProjectorDrive, exposure_phase
        from simbench.sim.timeline import is_moving, scene_at

        pattern = pattern_u8
        if pattern is None:  # the run's pattern, by its kept digest: made only for a render not cached
            pattern = DriveImage(pattern_digest(self.pattern), lambda: self.pattern_u8)
        window = self.capture_window_s(scene) if is_moving(scene) else None
        # the projector's defocus follows the geometry at mid-exposure (the drive is one image)
        posed = scene if window is None else scene_at(scene, 0.5 * (window[0] + window[1]))
        drive = ProjectorDrive(posed, pattern, self.sensor, cache=render.cache, phase=exposure_phase(render_seed))
        return record_channels(
            scene, drive, self.sensor, seed=render_seed, render=render, rngs=noise_seeds, window_s=window
        )

    def capture_window_s(self, scene: SceneSpec) -> tuple[float, float]:
        """The time model: the capture is one exposure of the camera, from 0 to its exposure
        time (:func:`simbench.sim.photometry.exposure_s`: the auto exposure on the white board,
        ~27 ms with the paper sensor model).  The Flea3 FL3-U3-13E4C has a global shutter (Sony ICX445
        CCD: every pixel integrates over the same window; Point Grey Flea3 USB 3.0 Technical
        Reference), so there is no rolling-shutter skew."""
        from simbench.sim.photometry import exposure_s, white_board

        if not self.sensor.is_physical:
            raise ValueError(
                f"a moving scene needs a physical (emva) camera's exposure time; the sensor model {self.sensor.name!r} "
                "has a simple camera, without one: record it with --sensor paper (or ideal, or a sensor TOML whose "
                '[camera] model = "emva")'
            )
        return (0.0, float(exposure_s(self.sensor, scene.rig, **white_board(scene))))

    def decode(
        self,
        raw: np.ndarray,
        calibration: ReferenceCalibration | None,
        *,
        scene: SceneSpec,
        params=None,
        mode: str | None = None,
    ) -> SystemDepth:
        """``raw`` decoded with ``params`` (default: the system's decoder; Z0 = the scene's
        reference depth) in ``mode`` (``reference`` or ``calibrated``; None = the params'), with
        ``scene.rig`` (which may be a calibrated rig rather than the one the scene was rendered
        with; the reference map is then decoded with it too)."""
        from simbench.decode import decode
        from simbench.io import camera_full_scale

        params = params if params is not None else self.decoder
        params = _with(params, z0_m=scene.reference_depth_m, mode=mode or params.mode)
        # a 10-, 12- or 14-bit camera's digital numbers, read against its own full scale (any other
        # camera's images by their dtype's range, as the decoder reads arrays)
        raw = camera_full_scale(raw, bits=self.sensor.camera.bits)
        ref = None
        if params.mode == "reference" or params.unmix:
            if calibration is None:
                raise ValueError(
                    f"decoding in {params.mode} mode{' with unmixing' if params.unmix else ''} needs the reference "
                    f"calibration"
                )
            ref = calibration.reference_map(_with(params, mode="reference"), rig=scene.rig)
        r = decode(raw, rig=scene.rig, params=params, reference=ref)
        return SystemDepth(depth_m=r.depth_m, valid=r.valid, confidence=r.confidence, column_px=r.column_px, detail=r)

    def bench_inputs(
        self, *, scene: str = "plane", seed: int = 0, frames: bool = False
    ) -> tuple[np.ndarray, ReferenceCalibration, SceneSpec]:
        """(capture, calibration, scene) of the decoder benchmark (``simbench bench``), made in
        numpy without the renderer (:mod:`simbench.sim.synthetic`), deterministic for a seed: the
        paper's rig, a plane at 1.1 m, the reference at 1.0 m, the minimal camera's noise.

        ``scene``: ``plane`` (fully lit) or ``shadow`` (:data:`BENCH_SHADOW` gets no projector
        light, which sends the decoder down the path every scene with shadows takes).
        ``frames``: the calibration also holds the reference plane under black and each primary
        (:data:`simbench.pattern.CALIBRATION_FRAMES`), which the colour-robust decoder needs.
        """
        from simbench.sim.sensor import get_sensor
        from simbench.sim.projector import transfer_curve
        from simbench.rig import paper_rig
        from simbench.sim.camera import simple_camera
        from simbench.sim.synthetic import synthetic_plane_capture

        if scene not in BENCH_SCENES:
            raise ValueError(f"unknown benchmark scene {scene!r}; valid: {list(BENCH_SCENES)}")
        rig = paper_rig()
        pattern = dataclasses.replace(self.pattern, size_hw=rig.projector.size_hw)
        drive = transfer_curve(pattern_u8(pattern), transfer="linear")
        cam = get_sensor("minimal").camera
        rad, _, _ = synthetic_plane_capture(drive, rig, point_m=(0, 0, 1.1), supersample=2)
        ref_rad, _, _ = synthetic_plane_capture(drive, rig, point_m=(0, 0, 1.0), supersample=2)
        if scene == "shadow":
            rad = rad.copy()
            rad[BENCH_SHADOW] = 0.0
        rng = np.random.default_rng(seed)
        capture = simple_camera(rad / 1.21, camera=cam, rng=rng)
        reference = simple_camera(ref_rad, camera=cam, rng=rng)
        extra = {}
        if frames:
            from simbench.pattern import calibration_frames

            for name, frame in calibration_frames(pattern_u8(pattern)).items():
                flat, _, _ = synthetic_plane_capture(
                    transfer_curve(frame, transfer="linear"), rig, point_m=(0, 0, 1.0), supersample=2
                )
                extra[name] = simple_camera(flat, camera=cam, rng=rng)
        return (
            capture,
            ReferenceCalibration(rig=rig, image=reference, frames=extra),
            SceneSpec(name=f"bench_{scene}", rig=rig, objects=(), reference_depth_m=1.0),
        )

    def write_recording(
        self,
        out_dir: Path,
        raw: np.ndarray,
        calibration: ReferenceCalibration,
        *,
        scene: SceneSpec,
        gt,
        meta: dict,
        overwrite: bool = False,
    ) -> dict[str, Path]:
        acq = Acquisition(
            scene=scene,
            pattern=self.pattern_u8,
            capture=raw,
            reference=calibration.image,
            gt=gt,
            meta=meta,
            calibration=calibration.frames,
        )
        return write_acquisition(acq, out_dir, overwrite=overwrite)

    def decode_files(self, request: DecodeRequest) -> FileDecode:
        """A capture image (with a rig) or a recording folder decoded from its files, with the
        request's options (:func:`simbench.systems.proposed_folder.decode_capture_files`)."""
        from simbench.systems.proposed_folder import decode_capture_files

        return decode_capture_files(request)

    def read_recording(self, in_dir: Path) -> tuple[np.ndarray, ReferenceCalibration, SceneSpec]:
        """(capture, calibration, scene) of a folder written by :meth:`write_recording`
        (``simbench render``); the scene carries the recorded rig and Z0, no objects.  The
        manifest and every file are checked (:func:`simbench.manifest.read_manifest`), and a
        folder recorded with another pattern than this system's is refused (it would decode
        wrongly without a word).  A 10-, 12- or 14-bit camera's capture comes as float32 of its full
        scale (:func:`simbench.io.adc_full_scale`), the calibration with its ``adc_bits``."""
        from simbench.io import adc_full_scale, load_image
        from simbench.rig import load_rig

        d = Path(in_dir)
        meta = read_manifest(d / RENDER_MANIFEST)
        recorded = recorded_pattern(meta, where=str(d / RENDER_MANIFEST))
        if recorded != self.pattern:
            raise ValueError(
                f"{d}: recorded with the pattern {describe_pattern(recorded)}, but this system decodes "
                f"{describe_pattern(self.pattern)}"
            )
        rig = load_rig(d / "rig.toml")
        z0 = recorded_z0(meta, where=str(d / RENDER_MANIFEST))
        bits = recorded_adc_bits(meta, where=str(d / RENDER_MANIFEST))
        capture = adc_full_scale(
            load_image(d / "capture.png", expected_size_hw=rig.camera.size_hw), bits=bits, where=str(d / "capture.png")
        )
        frames = {}
        for name in (n for n in ("dark", "red", "green", "blue") if (d / f"calibration_{n}.png").is_file()):
            frames[name] = load_image(d / f"calibration_{name}.png", expected_size_hw=rig.camera.size_hw)
        cal = ReferenceCalibration(
            rig=rig,
            image=load_image(d / "reference.png", expected_size_hw=rig.camera.size_hw),
            frames=frames,
            adc_bits=bits,
        )
        return capture, cal, SceneSpec(name=str(meta.get("scene", d.name)), rig=rig, objects=(), reference_depth_m=z0)


@dataclass(frozen=True)
class Acquisition:
    """A capture, its reference-plane capture, ground truth and everything to reproduce them."""

    scene: SceneSpec
    pattern: np.ndarray  # (Hp, Wp, 3) uint8, what the projector is sent
    capture: np.ndarray  # (H, W, 3) recorded image
    reference: np.ndarray  # (H, W, 3) recorded image of the reference plane
    gt: GroundTruth
    meta: dict = field(default_factory=dict)
    # the reference plane under each of simbench.pattern.CALIBRATION_FRAMES (colour-robust decoder)
    calibration: dict = field(default_factory=dict)


def acquire(scene: SceneSpec, **options: object) -> Acquisition:
    """:func:`acquire_with_calibration`'s acquisition alone (the same keyword options)."""
    return acquire_with_calibration(scene, **options)[0]


def acquire_with_calibration(
    scene: SceneSpec,
    *,
    pattern: PatternSpec,
    sensor: SensorModel,
    spp: int,
    seed: int,
    max_depth: int = 6,
    sampler: str = "independent",
    with_reference: bool = True,
    with_calibration: bool = False,
    cache: RenderCache | None = None,
) -> tuple[Acquisition, ReferenceCalibration | None]:
    """Render and record a scene (and its reference plane) lit by the pattern: the proposed
    sensor's recording (:class:`ColourFringeSystem`) through the one acquisition path
    (:func:`simbench.systems.acquire`), seeds derived from ``seed`` and the labels
    ``capture/<scene name>`` and the reference's (:mod:`simbench.seeds`).  Returns the
    acquisition and the reference calibration it recorded (None without ``with_reference``), which
    :meth:`ColourFringeSystem.decode` decodes with.

    A Mitsuba variant must already be selected (:func:`simbench.variant.select_variant`).
    Renders and ground truth come from ``cache`` when it holds them.
    """
    import mitsuba as mi

    from simbench.decode import DecoderParams
    from simbench.sim.sensor import sensor_to_dict
    from simbench.sim.mitsuba_dict import realised_rig
    from simbench.sim.photometry import exposure_s, white_balance_gains
    from simbench.seeds import SeedLog
    from simbench.sim.photometry import REFERENCE_ALBEDO, white_board
    from simbench.sim.keys import versions
    from simbench.sim.timeline import is_moving, slice_count
    from simbench.systems import acquire as acquire_recording

    rig = realised_rig(scene.rig)
    if rig != scene.rig:
        _log.warning(
            "projector principal point rendered at (%s, %s) instead of (%s, %s); rig.toml records the rendered one",
            rig.projector.cx_px,
            rig.projector.cy_px,
            scene.rig.projector.cx_px,
            scene.rig.projector.cy_px,
        )
    if tuple(pattern.size_hw) != scene.rig.projector.size_hw:
        raise ValueError(f"pattern size {pattern.size_hw} differs from the projector's {scene.rig.projector.size_hw}")
    if with_calibration and not with_reference:
        raise ValueError("calibration frames are taken of the reference plane: they need with_reference")
    system = ColourFringeSystem(SystemOptions(sensor=sensor, decoder=DecoderParams(pattern=pattern)))
    seeds = SeedLog(seed)
    render = RenderSettings(spp=spp, sampler=sampler, max_depth=max_depth, cache=cache)
    scene = system.prepare(scene)
    calibration = (
        system.calibrate(scene, seeds=seeds, render=render, frames=with_calibration) if with_reference else None
    )
    rec = acquire_recording(system, scene, f"capture/{scene.name}", seeds=seeds, render=render, prepared=True)[0]
    meta = {
        "scene": scene.name,
        "pattern": pattern_record(pattern),
        "sensor": sensor_to_dict(sensor),
        "exposure_s": exposure_s(sensor, scene.rig, **white_board(scene)) if sensor.is_physical else None,
        "white_balance_gains": white_balance_gains(sensor, scene.rig, **white_board(scene)).tolist(),
        "spp": int(spp),
        "sampler": sampler,
        "max_depth": int(max_depth),
        "seed": int(seed),
        "seeds": dict(seeds.used),
        "reference_depth_m": scene.reference_depth_m,
        "reference_albedo": REFERENCE_ALBEDO,
        "variant": mi.variant(),
        "versions": versions(),
    }
    if is_moving(scene):  # how the blur was integrated (docs/motion.md): the window and its slice count
        window = system.capture_window_s(scene)
        meta["capture_window_s"] = [float(window[0]), float(window[1])]
        meta["time_slices"] = slice_count(scene, scene.rig.camera, window)
    reference = calibration.image if calibration is not None else np.zeros_like(rec.raw)
    acq = Acquisition(
        scene=scene,
        pattern=system.pattern_u8,
        capture=rec.raw,
        reference=reference,
        gt=rec.gt,
        meta=meta,
        calibration=calibration.frames if calibration is not None else {},
    )
    return acq, calibration


def write_acquisition(acq: Acquisition, out_dir: str | Path, *, overwrite: bool = False) -> dict[str, Path]:
    """Write an acquisition as the files of ``simbench render``, the folder whole or not at all
    (:func:`simbench.io.output_directory`: built beside ``out_dir`` and swapped in; an earlier
    render there is replaced, any other non-empty folder refused).  ``meta.json`` lists every
    file with its SHA-256, so a reader can tell a folder's files belong together."""

    from simbench.io import output_directory, save_exr, save_json, save_npy, save_png
    from simbench.manifest import seal_manifest
    from simbench.rig import save_rig

    out = Path(out_dir)
    with output_directory(out, manifest=RECORDING_MANIFESTS, overwrite=overwrite) as tmp:
        names = {
            "capture": "capture.png",
            "reference": "reference.png",
            "gt_depth": "gt_depth.npy",
            "gt_depth_exr": "gt_depth.exr",
            "gt_column": "gt_column.npy",
            "gt_lit": "gt_lit.npy",
            "gt_object_id": "gt_object_id.npy",
            "rig": "rig.toml",
            **{f"calibration_{k}": f"calibration_{k}.png" for k in acq.calibration},
            **({"gt_motion": "gt_motion.npy"} if acq.gt.motion_px is not None else {}),
        }
        for k, img in acq.calibration.items():
            save_png(tmp / f"calibration_{k}.png", img)
        save_png(tmp / names["capture"], acq.capture)
        save_png(tmp / names["reference"], acq.reference)
        save_npy(tmp / names["gt_depth"], acq.gt.depth_m)
        save_exr(tmp / names["gt_depth_exr"], acq.gt.depth_m)
        save_npy(tmp / names["gt_column"], acq.gt.column_px)
        save_npy(tmp / names["gt_lit"], acq.gt.lit)
        save_npy(tmp / names["gt_object_id"], acq.gt.object_id)
        if acq.gt.motion_px is not None:  # a moving scene: each pixel's image motion over the capture
            save_npy(tmp / names["gt_motion"], acq.gt.motion_px)
        save_rig(acq.scene.rig, tmp / names["rig"])
        save_json(tmp / RENDER_MANIFEST, seal_manifest(tmp, {"system": "proposed", **acq.meta}, names))
    return {**{k: out / n for k, n in names.items()}, "meta": out / RENDER_MANIFEST}
