"""The multi-shot reference as a depth system: N-step phase shifting with complementary
Gray-code unwrapping (:mod:`simbench.decode.temporal`) on the proposed sensor's projector and
camera, triangulated with the rig.

It sees a scene exactly as the proposed sensor does (same rig, sensor model, lenses, ambient
light: :meth:`simbench.systems.proposed.ColourFringeSystem.prepare`) and projects grey frames
(the same drive in the three primaries); the camera records each, and the decoder reads the
mean of the three colour channels.  It needs ``N + bits`` exposures of a static scene (12 with
the defaults: 4 steps, and 8 Gray-code bits for the 174 half periods of 1824 columns): the
price single-shot sensing avoids.  No reference plane: the column is triangulated with the rig
(paper Eq. 15's geometry).
"""

from __future__ import annotations

import dataclasses
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from simbench.decode.temporal import (
    PhaseShiftSpec,
    decode_phase_shift,
    gray_code_min_snr,
    grey_frame,
    phase_shift_frames,
)
from simbench.io import camera_full_scale
from simbench.sim.mitsuba_dict import RenderSettings
from simbench.sim.scene import SceneSpec
from simbench.systems import SystemDepth, SystemInfo, SystemOptions

if TYPE_CHECKING:
    from simbench.cache import RenderCache

__all__ = ["PhaseShiftSystem", "DEPTH_RANGE_M", "reference_spec"]

# depths outside are invalid (the working range of simbench.decode.DecoderParams' default)
DEPTH_RANGE_M = (0.75, 1.75)


def reference_spec() -> PhaseShiftSpec:
    """The reference's sequence (4 steps, the paper's period, 8 Gray-code bits at the paper
    projector's width), its pixels judged against their own noise: valid where the modulation SNR
    reaches what the Gray code needs for <= 0.1 % misread period numbers
    (:func:`simbench.decode.temporal.gray_code_min_snr`, 4.09), with no absolute floor.  Until
    2026-11-30 it was the absolute ``B >= 0.02`` of :class:`PhaseShiftSpec`: a level that suits a
    white board, which dropped a 20:1 print's ink (``B`` ~0.017 at ~11 times its noise, not one
    pixel of it 5 mm wrong when kept: ``scenes/hard_chart_high.toml``, 54 % of the chart scored)."""
    base = PhaseShiftSpec()
    return dataclasses.replace(
        base, min_modulation=0.0, min_snr=gray_code_min_snr(steps=base.steps, bits=base.gray_bits)
    )


@lru_cache(maxsize=2)
def _frames_u8(spec: PhaseShiftSpec) -> np.ndarray:
    """:meth:`PhaseShiftSystem.frames_u8`: made once per sequence and process (~0.4 s at the
    paper projector's size; every system instance and acquisition of a run shares them)."""
    from simbench.pattern import grey_drive

    frames = grey_drive(phase_shift_frames(spec))
    frames.setflags(write=False)
    return frames


# the frames' digests per sequence, kept for the process
_digests: dict[PhaseShiftSpec, tuple[str, ...]] = {}


def _frame_digests(spec: PhaseShiftSpec, cache: "RenderCache | None" = None) -> tuple[str, ...]:
    """:func:`simbench.cache.array_digest` of each of :func:`_frames_u8`, once per process and,
    with a ``cache``, kept there (keyed by the sequence, the code that makes the frames and
    numpy's version): a warm run then never makes the frames (0.6 s per process)."""
    if spec not in _digests:
        from simbench.cache import array_digest, source_digest
        from simbench.decode import temporal
        from simbench import pattern

        def make() -> dict[str, np.ndarray]:
            text = "".join(array_digest(f) for f in _frames_u8(spec))
            return {"digests": np.frombuffer(text.encode(), np.uint8)}

        if cache is None or cache.root is None:
            arrays = make()
        else:
            parts = {
                "spec": dataclasses.asdict(spec),
                "code": source_digest([temporal.__file__, pattern.__file__, __file__]),
                "numpy": np.__version__,
            }
            arrays = cache.get_or_make("frame_digests", parts, make)
        text = bytes(np.asarray(arrays["digests"], np.uint8)).decode()
        _digests[spec] = tuple(text[i : i + 64] for i in range(0, len(text), 64))
    return _digests[spec]


def _confidence_text(s: PhaseShiftSpec) -> str:
    holes = []
    if s.min_snr > 0:
        holes.append(f"pixels below {s.min_snr:.3g} are holes")
    if s.min_modulation > 0:
        holes.append(f"pixels whose modulation B is below {s.min_modulation:g} (full-scale units) are holes")
    return (
        f"modulation SNR of the {s.steps}-step fit: the fringe modulation B over each frame's noise as the "
        f"fit's residual shows it (simbench.decode.temporal.fit_noise)" + "".join("; " + h for h in holes)
    )


class PhaseShiftSystem:
    """The multi-shot reference (module docstring); ``options`` gives the sensor model and the
    camera scale (the proposed sensor's), ``spec`` the sequence."""

    name = "phase_shift"
    seed_prefix = "phase_shift/"

    def __init__(self, options: SystemOptions | None = None, *, spec: PhaseShiftSpec | None = None) -> None:
        from simbench.systems.proposed import ColourFringeSystem

        self._optics = ColourFringeSystem(options)
        self.sensor = self._optics.sensor
        self.spec = spec if spec is not None else reference_spec()
        self._spec_given = spec is not None

    def spec_for(self, scene: SceneSpec) -> PhaseShiftSpec:
        """The sequence for ``scene``'s projector: the one given, or the default sequence at the
        projector's size (a new user's audit: a rig with a 1280x800 projector was refused, "pattern
        size (1140, 1824) differs", with no option to change it - the proposed sensor's pattern
        follows the projector, and so does this one now)."""
        size = tuple(scene.rig.projector.size_hw)
        if tuple(self.spec.size_hw) == size:
            return self.spec
        if self._spec_given:
            raise ValueError(f"pattern size {self.spec.size_hw} differs from the projector's {size}")
        return dataclasses.replace(self.spec, size_hw=size)

    def info(self) -> SystemInfo:
        """The system as it records with its own sequence - the default one at the paper
        projector's size unless a sequence was given; a scene's projector of another width takes
        another number of Gray-code frames (:meth:`spec_for`, ``.captures``)."""
        s = self.spec
        return SystemInfo(
            name=self.name,
            label=f"{s.steps}-step phase shifting + Gray code (simulated)",
            size_hw=self._optics.info().size_hw,
            captures=s.captures,
            period_px=s.period_px,
            uses_scene_rig=True,
            recording_options=("sensor", "camera_scale"),  # its own sequence, not the coded pattern
            confidence=_confidence_text(s),
            numbers={
                "steps": (s.steps, "assumption: the common choice; N steps are blind to fringe harmonics up to N - 2"),
                "period_px": (s.period_px, "the paper's period (same spatial frequency as the proposed pattern)"),
                "gray_bits": (s.gray_bits, "complementary Gray code over the projector width (Zhang et al. 2012)"),
            },
        )

    def frames_u8(self, scene: SceneSpec | None = None) -> np.ndarray:
        """The projector frames as 8-bit RGB drives, shape (K, Hp, Wp, 3), read-only: those it
        projects on ``scene`` (:meth:`spec_for`), else its own sequence's."""
        return _frames_u8(self.spec if scene is None else self.spec_for(scene))

    def prepare(self, scene: SceneSpec) -> SceneSpec:
        return self._optics.prepare(scene)

    def calibration_key(self, scene: SceneSpec) -> None:
        return None

    def calibrate(self, scene: SceneSpec, *, seeds: object, render: RenderSettings) -> None:
        return None  # triangulation with the rig: nothing to record

    def acquire(
        self,
        scene: SceneSpec,
        calibration: None,
        *,
        render_seed: int,
        noise_seeds: list[int],
        render: RenderSettings,
    ) -> list[np.ndarray]:
        """Every frame rendered once (the same sampler seed: one static scene) and recorded
        once per noise seed with its own camera noise (:func:`simbench.seeds.frame_seed`);
        each recording has shape (K, H, W), float32 grey in [0, 1]."""
        from simbench.seeds import frame_seed
        from simbench.sim.capture import record_channels
        from simbench.sim.drive import DriveImage, ProjectorDrive, exposure_phase
        from simbench.sim.timeline import is_moving, scene_at

        spec = self.spec_for(scene)
        phase = exposure_phase(render_seed)
        windows = self.frame_windows_s(scene) if is_moving(scene) else None
        frames = []  # per projector frame, its recording per noise seed (grey)
        for k, digest in enumerate(_frame_digests(spec, render.cache)):
            frame = DriveImage(digest, lambda k=k: _frames_u8(spec)[k])  # made only for a render not cached
            window = None if windows is None else windows[k]
            # the projector's defocus follows the geometry at the frame's mid-exposure
            posed = scene if window is None else scene_at(scene, 0.5 * (window[0] + window[1]))
            drive = ProjectorDrive(posed, frame, self.sensor, cache=render.cache, phase=phase)
            seeds = [frame_seed(n, k) for n in noise_seeds]
            recordings = record_channels(
                scene, drive, self.sensor, seed=render_seed, render=render, rngs=seeds, window_s=window
            )
            # (a 10-, 12- or 14-bit camera's digital numbers at its own full scale, not uint16's)
            bits = self.sensor.camera.bits
            frames.append([grey_frame(camera_full_scale(r, bits=bits)) for r in recordings])
        return [np.stack([f[i] for f in frames]) for i in range(len(noise_seeds))]

    def frame_period_s(self, scene: SceneSpec) -> float:
        """Time from one frame's start to the next: the camera's exposure, or the frame period of
        the slower device when that is longer (the Flea3's 60 frames/s at full resolution; the
        LightCrafter 4500's 8-bit patterns at up to 120 Hz: :data:`simbench.literature.FLEA3_MAX_FPS`).
        Assumption: the projector triggers the camera and the next pattern follows the readout
        at once (no dark time; the camera's readout overlaps the next exposure)."""
        from simbench.literature import FLEA3_MAX_FPS, LIGHTCRAFTER_8BIT_PATTERN_HZ

        exposure = self._optics.capture_window_s(scene)[1]
        return max(exposure, 1.0 / min(FLEA3_MAX_FPS, LIGHTCRAFTER_8BIT_PATTERN_HZ))

    def frame_windows_s(self, scene: SceneSpec) -> list[tuple[float, float]]:
        """The time model: frame k exposes from k P to k P + T (P :meth:`frame_period_s`, T the
        camera's exposure, the proposed sensor's camera: global shutter)."""
        exposure = self._optics.capture_window_s(scene)[1]
        period = self.frame_period_s(scene)
        return [(k * period, k * period + exposure) for k in range(self.spec_for(scene).captures)]

    def capture_window_s(self, scene: SceneSpec) -> tuple[float, float]:
        """From the first frame's start to the last one's end (12 frames: ~0.33 s at the paper
        sensor's ~27 ms auto exposure)."""
        windows = self.frame_windows_s(scene)
        return (windows[0][0], windows[-1][1])

    def decode(self, raw: np.ndarray, calibration: None = None, *, scene: SceneSpec) -> SystemDepth:
        """Undistort each frame with the camera's lens (as the rig file records it), decode
        the columns (:func:`simbench.decode.temporal.decode_phase_shift`) and triangulate."""
        from simbench.optics import undistort_image
        from simbench.rig import triangulate_columns

        frames = np.asarray(raw, dtype=np.float32)
        cam = scene.rig.camera
        if frames.shape[1:] != cam.size_hw:
            raise ValueError(f"frames of shape {frames.shape[1:]} do not match the camera's {cam.size_hw}")
        if cam.has_distortion:
            frames = np.stack([undistort_image(f, cam) for f in frames])
        r = decode_phase_shift(frames, spec=self.spec_for(scene))
        z = triangulate_columns(r.column_px, scene.rig)
        near, far = DEPTH_RANGE_M
        with np.errstate(invalid="ignore"):
            valid = r.valid & (z >= near) & (z <= far)
        return SystemDepth(
            depth_m=np.where(valid, z, np.nan).astype(np.float32),
            valid=valid,
            confidence=r.snr.astype(np.float32),
            column_px=np.where(valid, r.column_px, np.nan),
            detail=r,
        )

    def bench_inputs(self, *, scene: str = "plane", seed: int = 0) -> tuple[np.ndarray, None, SceneSpec]:
        """(frames, None, scene) of a plane at 1.1 m in the paper's rig made in numpy
        (:mod:`simbench.sim.synthetic`), with the minimal camera's noise; deterministic for a seed."""
        from simbench.sim.sensor import get_sensor
        from simbench.sim.projector import transfer_curve
        from simbench.rig import paper_rig
        from simbench.sim.camera import simple_camera
        from simbench.sim.synthetic import synthetic_plane_capture

        if scene != "plane":
            raise ValueError(f"the {self.name} benchmark has only the plane, not {scene!r}")
        rig = paper_rig()
        cam = get_sensor("minimal").camera
        rng = np.random.default_rng(seed)
        drives = np.stack([transfer_curve(frame, transfer="linear") for frame in self.frames_u8()])
        radiance = synthetic_plane_capture(drives, rig, point_m=(0, 0, 1.1), supersample=2)[0]
        frames = [grey_frame(simple_camera(rad / 1.21, camera=cam, rng=rng)) for rad in radiance]
        return np.stack(frames), None, SceneSpec(name="bench_plane", rig=rig, objects=())

    def write_recording(
        self,
        out_dir: Path,
        raw: np.ndarray,
        calibration: None,
        *,
        scene: SceneSpec,
        gt: object,
        meta: dict,
        overwrite: bool = False,
    ) -> dict[str, Path]:
        """``frames.npy`` ((K, H, W) float32 grey), ``rig.toml``, ground truth, ``device.json``."""
        from simbench.systems.recording import write_device_recording
        from simbench.io import save_npy
        from simbench.rig import save_rig

        writers = {
            "frames": lambda d: save_npy(d / "frames.npy", np.asarray(raw, np.float32)),
            "rig": lambda d: save_rig(scene.rig, d / "rig.toml"),
        }
        spec = self.spec_for(scene)
        return write_device_recording(out_dir, self.name, spec, writers, gt=gt, info=meta, overwrite=overwrite)

    def read_recording(self, in_dir: Path) -> tuple[np.ndarray, None, SceneSpec]:
        from simbench.systems.recording import read_device_info
        from simbench.io import load_npy
        from simbench.rig import load_rig

        d = Path(in_dir)
        self.spec, info = read_device_info(d, self.name, PhaseShiftSpec)
        self._spec_given = True  # the folder's own sequence
        rig = load_rig(d / "rig.toml")
        frames = load_npy(d / "frames.npy", expected_shape=(self.spec.captures, *rig.camera.size_hw))
        return frames, None, SceneSpec(name=str(info.get("scene", d.name)), rig=rig, objects=())
