"""What the paper-reproduction experiments share: run configuration, seeds, the render cache,
the calibration (one reference-plane capture per run, as in the paper's Sec. 5.4), decoding,
and result files with provenance.

Seeds: every capture's seeds derive from the run's base seed and the capture's label
(:mod:`simbench.seeds`), so a capture keeps its seeds when experiments are added, removed or
run alone; every result row records them.
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
import logging
import re
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from simbench import validate
from simbench.cache import RenderCache
from simbench.calibration import CalibrationResult, CalibrationTarget, get_target
from simbench.calibration.procedure import (
    CALIBRATION_CORNER_SPP,
    CALIBRATION_MAX_DEPTH,
    CALIBRATION_SAMPLER,
    CALIBRATION_SPP,
    DEFAULT_POSES,
    DEFAULT_TARGET,
)
from simbench.decode import DecoderParams
from simbench.decode.pipeline import DecodeResult, ReferenceMap
from simbench.sim.sensor import SensorModel, get_sensor, sensor_to_dict
from simbench.io import json_bytes, write_files
from simbench.report import figure_png, markdown_table, table_text
from simbench.metrics import depth_errors, edge_band
from simbench.metrics import score as metrics_score
from simbench.sim.mitsuba_dict import DEFAULT_SAMPLER, DEFAULT_SPP, check_sampler
from simbench.rig import Rig
from simbench.pattern import PatternSpec
from simbench.sim.scene import Placement, SceneSpec, board_form, load_scene, place_objects
from simbench.seeds import DEFAULT_SEED, SeedLog, derive_seed
from simbench.sim.keys import versions
from simbench.systems import (
    DepthSystem,
    Recording,
    RenderSettings,
    SystemDepth,
    SystemOptions,
    acquire,
    get_system,
)

if TYPE_CHECKING:
    from simbench.rig import Intrinsics

log = logging.getLogger(__name__)

__all__ = [
    "SCENES_DIR",
    "library_scene_path",
    "RunConfig",
    "Capture",
    "Session",
    "Split",
    "score",
    "scene_errors",
    "made_by",
    "sensor_caveat",
    "calibration_summary",
    "calibration_sentence",
    "other_rig",
    "RIGS",
    "scene_file",
    "table_text",
    "markdown_table",
    "figure_png",
    "git_commit",
    "git_state",
]

SCENES_DIR = Path(__file__).resolve().parents[2] / "scenes"
# a scene of the library by name: a file name's stem, no folder (nothing outside SCENES_DIR)
_SCENE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*")


def library_scene_path(name: object) -> Path:
    """The file of the library scene ``name`` (``scenes/NAME.toml``).

    A name is a file stem of ``scenes/``: a path (``../elsewhere/evil``, ``/etc/x``), an empty
    name or a non-string is refused, so a name can neither read a file outside the library nor,
    where it names an output (``NAME.png``), write outside its folder.

    Raises
    ------
    ValueError
        ``name`` is not a scene name, or no such scene exists (the error lists those that do).
    """
    available = sorted(p.stem for p in SCENES_DIR.glob("*.toml"))
    if not isinstance(name, str) or not _SCENE_NAME.fullmatch(name) or ".." in name:
        raise ValueError(
            f"scene name {name!r} is not a name of scenes/ (no folders or paths; give a scene file as a path where a "
            f"command takes one); scenes: {available}"
        )
    path = SCENES_DIR / f"{name}.toml"
    if not path.is_file():
        raise ValueError(f"no scene {name!r} in {SCENES_DIR}; scenes: {available}")
    return path


def _library_name(scene: str | Path) -> bool:
    """Whether ``scene``, as given, is the bare name of a library scene (``step``)."""
    name = str(scene)
    return "/" not in name and "\\" not in name and (SCENES_DIR / f"{name}.toml").is_file()


def scene_file(scene: str | Path) -> Path:
    """The scene file a command or :func:`simbench.record` is given: a path, as it is, or else a
    library scene's name (``step``: ``scenes/step.toml`` of the repository, from any working
    folder).

    Raises
    ------
    FileNotFoundError
        Neither; the message says how to reach the library (a new user's audit, 2026-11-30:
        the README's ``scenes/step.toml`` run from another folder said only "not found").
    """
    path = Path(scene)
    if path.exists() and not (path.is_dir() and _library_name(scene)):
        return path
    # a folder is no scene: a library scene's name that a folder of the working folder shares
    # (a recording named after its scene, `render step --out step`) still names the scene (an audit,
    # 2026-12-05: the error advised the name, which then read "a folder, not a scene file")
    try:
        return library_scene_path(str(scene))
    except ValueError:  # no name of the library (a path, or no such scene)
        pass
    if (SCENES_DIR / f"{path.stem}.toml").is_file():
        hint = (
            f"relative paths start from the working folder; the library's scene of that name is "
            f"{SCENES_DIR / (path.stem + '.toml')}: give that path, or its name `{path.stem}` from any folder"
        )
    else:
        some = ", ".join(sorted(p.stem for p in SCENES_DIR.glob("*.toml"))[:6])
        hint = f"a library scene may be given by name from any folder ({some}, ...: {SCENES_DIR})"
    raise FileNotFoundError(f"scene file not found: {scene} ({hint})")


# the rigs a decoder may be given (RunConfig.rig)
RIGS = ("true", "calibrated")
# a calibration pose that took this long gets a progress line (one made, not one read from the cache)
POSE_PROGRESS_S = 1.0


@dataclass(frozen=True)
class RunConfig:
    """Settings of a reproduction run (``quick`` = the reduced CI run).

    sensor : sensor model, a preset of :func:`simbench.sim.sensor.get_sensor` (``paper``: the
        Flea3 + LightCrafter physics; ``minimal``: noise only; ``ideal``: nothing) or a TOML file
    camera_scale : camera resolution factor (0.5 = 640x480 for quick runs)
    spp, sampler, max_depth : path tracing samples per pixel, Mitsuba sample generator
        (:data:`simbench.sim.mitsuba_dict.DEFAULT_SAMPLER` and ``DEFAULT_SPP``: measured to keep render
        noise below a third of camera noise on the white board) and path length
    seed : base seed of every capture
    fig9_repeats : noise realisations per depth in Fig. 9 (the paper: "more than 10 times")
    edge_band_px : band at depth edges left out of error statistics
    decoder : the paper's decoder settings (the colour-robust decoder is
        :func:`simbench.decode.robust_params` of them)
    robust_decoder : the colour-robust decoder's settings where the run changes them
        (``reproduce --decoder``: the same assignments on top of its own); None = :meth:`robust`'s
        default, :func:`simbench.decode.robust_params` of ``decoder``
    placement_depth_mm, placement_tilt_deg : how precisely test objects are placed
        (:class:`simbench.sim.scene.Placement`: each object gets its own seeded error within these
        bounds, independent of the reference plane; 0 = exactly on the nominal pose)
    board_bow_mm_per_m, board_waviness_mm : form error of every placed board and of the reference
        board (:func:`simbench.sim.scene.board_form_m`: the bow's sag over a 1 m chord, the
        ripple's amplitude; seeded bow sign and ripple phase per board); 0 = flat
    rig : the rig the proposed sensor and the multi-shot reference decode with: ``"true"`` (the
        rig the scene is rendered with) or ``"calibrated"`` (the one ``simbench calibrate``
        estimates through the run's sensor model; :meth:`Session.calibrated_rig`)
    calibration_poses, calibration_bow_mm_per_m, calibration_waviness_mm : that calibration's
        effort: target poses and the printed target's form error (the default target,
        :mod:`simbench.calibration`)
    compare_rigs : Table 1, Table 3 and Fig. 9 also decode every capture with the other rig
        (:func:`other_rig`); costs one calibration per run (~4 min at 1280x960 on 2 cores, cached)
    """

    quick: bool = False
    sensor: str = "paper"
    camera_scale: float = 1.0
    spp: int = DEFAULT_SPP
    sampler: str = DEFAULT_SAMPLER
    max_depth: int = 6
    seed: int = DEFAULT_SEED
    fig9_repeats: int = 10
    edge_band_px: int = 5
    ply_stride: int = 3
    placement_depth_mm: float = 10.0
    placement_tilt_deg: float = 2.0
    board_bow_mm_per_m: float = 0.0
    board_waviness_mm: float = 0.0
    decoder: DecoderParams = field(default_factory=DecoderParams)
    robust_decoder: DecoderParams | None = None
    rig: str = "true"
    calibration_poses: int = DEFAULT_POSES
    calibration_bow_mm_per_m: float = 0.0
    calibration_waviness_mm: float = 0.0
    compare_rigs: bool = True

    def __post_init__(self) -> None:
        check_sampler(self.sampler, self.spp)
        self.placement  # validates the placement and board form
        validate.choice(self.rig, "rig", RIGS)
        validate.integer(self.calibration_poses, "calibration_poses", lo=3, hi=200)
        validate.boolean(self.compare_rigs, "compare_rigs")
        self.calibration_target()  # validates the target's form

    def figure_note(self) -> str:
        """What a figure's title adds to tell a run's figures from the full reproduction's: the
        quick run's camera size and samples (a figure audit, 2026-11-30: results/quick's figures
        bore the full run's titles), else ""."""
        if not self.quick and self.camera_scale == 1.0 and self.spp == DEFAULT_SPP:
            return ""
        from simbench.rig import paper_rig

        cam = paper_rig().camera
        w, h = (round(self.camera_scale * n) for n in (cam.width_px, cam.height_px))
        return f" [{'quick run: ' if self.quick else ''}{w}x{h}, {self.spp} spp]"

    def robust(self) -> DecoderParams:
        """The colour-robust decoder's settings for this run: ``robust_decoder``, else
        :func:`simbench.decode.robust_params` of the paper's."""
        from simbench.decode import robust_params

        return self.robust_decoder if self.robust_decoder is not None else robust_params(self.decoder)

    def calibration_target(self) -> CalibrationTarget:
        """The printed target of the run's calibration: the default one with the run's form error."""
        return dataclasses.replace(
            get_target(DEFAULT_TARGET),
            bow_m_per_m=self.calibration_bow_mm_per_m / 1000.0,
            waviness_m=self.calibration_waviness_mm / 1000.0,
        )

    @property
    def placement(self) -> Placement:
        return Placement(
            depth_m=self.placement_depth_mm / 1000.0,
            tilt_deg=self.placement_tilt_deg,
            bow_m_per_m=self.board_bow_mm_per_m / 1000.0,
            waviness_m=self.board_waviness_mm / 1000.0,
        )

    def reference_form(self) -> dict:
        """Form keys of the reference board (:func:`simbench.sim.scene.board_form`, seeded from the
        run's seed: one board for the whole run); empty when boards are flat."""
        p = self.placement
        if not (p.bow_m_per_m or p.waviness_m):
            return {}
        rng = np.random.default_rng(derive_seed(self.seed, "reference/form"))
        return board_form(bow_m_per_m=p.bow_m_per_m, waviness_m=p.waviness_m, rng=rng)

    @classmethod
    def preset(cls, *, quick: bool, **overrides) -> "RunConfig":
        base = (
            cls(
                quick=True,
                camera_scale=0.5,
                spp=4,
                fig9_repeats=3,
                edge_band_px=3,
                ply_stride=4,
                calibration_poses=6,
            )
            if quick
            else cls()
        )
        return dataclasses.replace(base, **overrides)

    def to_dict(self) -> dict:
        """The settings as plain data (provenance).  The decoder's pattern is written as its
        four decoder-relevant fields inline (period_px, order, sequence, channels), the layout
        of every provenance file so far, plus any other pattern field that is not the default."""
        d = asdict(self)
        default = asdict(PatternSpec())
        for key in ("decoder", "robust_decoder"):
            if d[key] is None:  # (the robust decoder's own defaults: written only where changed)
                del d[key]
                continue
            pattern = d[key].pop("pattern")
            inline = {k: pattern.pop(k) for k in ("period_px", "order", "sequence", "channels")}
            extra = {k: v for k, v in pattern.items() if v != default[k]}
            d[key] = {**inline, **({"pattern": extra} if extra else {}), **d[key]}
        return d


# one recording of a scene by a depth system (the proposed sensor's: ``image`` is its capture)
Capture = Recording


def _calibration_settings(sensor: SensorModel, config: RunConfig) -> tuple:
    """What a rig calibration of the run depends on besides the rig: the sensor model and the
    run's calibration settings."""
    keys = ("seed", "camera_scale", "calibration_poses", "calibration_bow_mm_per_m", "calibration_waviness_mm")
    return (sensor, *(getattr(config, k) for k in keys))


class Session:
    """Shared state of one reproduction run: config, cache, seeds, the depth systems and their
    calibrations, progress."""

    def __init__(
        self,
        config: RunConfig,
        *,
        out_dir: str | Path,
        cache_dir: str | Path | None,
        progress: Callable[[str], None] = log.info,
        command: str = "",
        sensor: SensorModel | None = None,
    ) -> None:
        import mitsuba as mi

        self.config = config
        self.out = Path(out_dir)
        self.cache = RenderCache(cache_dir)
        self.progress = progress
        self.command = command or "simbench " + " ".join(sys.argv[1:])
        self.variant = mi.variant()
        self.sensor = sensor if sensor is not None else get_sensor(config.sensor)
        self.seeds = SeedLog(config.seed)
        self._systems: dict[str, DepthSystem] = {}
        self._calibrations: dict = {}
        # the rigs calibrated in this run, per sensor model and calibration settings (a fork at
        # other settings, e.g. the motion study's camera scale, has its own; forks share them)
        self._rig_sets: dict = {}
        self._rigs: dict = self._rig_sets.setdefault(_calibration_settings(self.sensor, config), {})
        self.proposed = self.system("proposed")

    @property
    def render(self) -> RenderSettings:
        return RenderSettings(
            spp=self.config.spp, sampler=self.config.sampler, max_depth=self.config.max_depth, cache=self.cache
        )

    @property
    def seeds_used(self) -> dict[str, dict]:
        """Every seed the run derived, by label (written to the provenance files)."""
        return self.seeds.used

    def fork(self, sensor: SensorModel, *, config: RunConfig | None = None) -> "Session":
        """A session with another sensor model (and optionally other run settings) sharing
        this one's cache, output, seed log and calibrations."""
        other = Session(
            config or self.config,
            out_dir=self.out,
            cache_dir=None,
            progress=self.progress,
            command=self.command,
            sensor=sensor,
        )
        other.cache = self.cache
        other.seeds = self.seeds
        other._calibrations = self._calibrations
        other._rig_sets = self._rig_sets
        other._rigs = self._rig_sets.setdefault(_calibration_settings(other.sensor, other.config), {})
        return other

    def for_target(self) -> "Session":
        """A session for one target of a run: this one's cache, systems and calibrations, with a
        seed log of its own, so that a target's provenance lists the seeds it used (calibrations
        it reuses included) whatever ran before it, in this process or in another."""
        other = copy.copy(self)
        other.seeds = SeedLog(self.config.seed)
        return other

    def system(self, name: str) -> DepthSystem:
        """The registered depth system ``name`` (:mod:`simbench.systems`) set up for this run."""
        if name not in self._systems:
            cfg = self.config
            options = SystemOptions(
                sensor=self.sensor,
                decoder=cfg.decoder,
                camera_scale=cfg.camera_scale,
                reference_form=cfg.reference_form(),
            )
            self._systems[name] = get_system(name, options)
        return self._systems[name]

    def calibration(self, system: DepthSystem, scene: SceneSpec, **options) -> object:
        """``system``'s calibration for ``scene`` (prepared), recorded once per run for each
        calibration key (the system says what it depends on) and render setting (``options`` go
        to its ``calibrate``)."""
        r = self.render
        key = (
            system.name,
            system.calibration_key(scene),
            r.spp,
            r.sampler,
            r.max_depth,
            tuple(sorted(options.items())),
        )
        if key not in self._calibrations:
            log = SeedLog(self.seeds.base)
            self._calibrations[key] = (system.calibrate(scene, seeds=log, render=r, **options), log.used)
        calibration, seeds = self._calibrations[key]
        self.seeds.used.update(seeds)  # every session that uses it records its seeds
        return calibration

    # the rig the decoders believe ------------------------------------------------------
    def calibration_result(self, scene: SceneSpec) -> CalibrationResult:
        """The calibration of ``scene``'s rig (prepared: at the run's camera resolution, with the
        sensor's lenses) as a lab would make it: the run's target and pose count through the
        run's sensor model (:func:`simbench.calibration.calibrate_rig`; seeds from the run's
        base seed, observations in the render cache), made once per rig and run."""
        from simbench.calibration import calibrate_rig

        cfg = self.config
        rig = scene.rig
        # the ideal rig behind the prepared one: the sensor model puts its lenses back
        ideal = Rig(rig.camera.undistorted, rig.projector.undistorted, rig.position_m, rig.rotation_deg, rig.name)
        if ideal not in self._rigs:
            t0 = last = time.perf_counter()

            def pose_done(k: int, n: int) -> None:
                # on a cold cache a pose takes seconds (~20 s at the full resolution); from the
                # cache, all of them a second: no line per pose then
                nonlocal last
                now = time.perf_counter()
                if now - last >= POSE_PROGRESS_S:
                    self.progress(f"[calibration] {k}/{n} poses observed ({now - t0:.0f} s)")
                last = now

            with self.timed(f"[calibration] {cfg.calibration_poses} target poses through sensor model {cfg.sensor}"):
                self._rigs[ideal] = calibrate_rig(
                    ideal,
                    target=cfg.calibration_target(),
                    sensor=self.sensor,
                    poses=cfg.calibration_poses,
                    seed=cfg.seed,
                    render=RenderSettings(
                        spp=CALIBRATION_SPP,
                        sampler=CALIBRATION_SAMPLER,
                        max_depth=CALIBRATION_MAX_DEPTH,
                        cache=self.cache,
                    ),
                    corner_spp=CALIBRATION_CORNER_SPP,
                    progress=pose_done,
                )
        self.seeds.record("calibration", {"base": cfg.seed, "poses": cfg.calibration_poses})
        return self._rigs[ideal]

    def calibrated_rig(self, scene: SceneSpec) -> Rig:
        """The rig :meth:`calibration_result` estimates for ``scene`` (prepared)."""
        return self.calibration_result(scene).rig

    def decode_scene(self, scene: SceneSpec, *, rig: str | None = None) -> SceneSpec:
        """``scene`` (prepared) as a decoder sees it: with the true rig, or with the calibrated
        one (``rig``: ``"true"`` or ``"calibrated"``; None = the run's :attr:`RunConfig.rig`)."""
        choice = validate.choice(rig or self.config.rig, "rig", RIGS)
        if choice == "true":
            return scene
        return dataclasses.replace(scene, rig=self.calibrated_rig(scene))

    # scenes and captures -------------------------------------------------------------
    def raw_scene(self, name: str) -> SceneSpec:
        """A scene of ``scenes/`` as its file says (before :meth:`prepare`)."""
        return load_scene(library_scene_path(name))

    def scene(self, name: str) -> SceneSpec:
        """A scene of ``scenes/`` as the proposed sensor sees it (:meth:`prepare`)."""
        return self.prepare(self.raw_scene(name))

    def prepare(self, scene: SceneSpec) -> SceneSpec:
        """``scene`` with the run's camera resolution, the rendered rig and the sensor model's
        lenses and ambient light (:meth:`simbench.systems.proposed.ColourFringeSystem.prepare`)."""
        return self.proposed.prepare(scene)

    def place(self, scene: SceneSpec, label: str, names) -> SceneSpec:
        """``scene`` with the objects ``names`` placed as a lab would (the run's placement
        tolerance, seeds from ``label``); the offsets are recorded with the seeds."""
        seed = self.seeds.seed(f"{label}/placement")
        placed, offsets = place_objects(scene, names, placement=self.config.placement, rng=seed)
        self.seeds.record(
            f"{label}/placement",
            {"placement": seed, **{f"{n}_{k}": v for n, o in offsets.items() for k, v in o.items()}},
        )
        return placed

    def capture(self, scene: SceneSpec, label: str, *, repeats: int = 1) -> list[Capture]:
        """``repeats`` recordings of ``scene`` (prepared) by the proposed sensor, with seeds
        from ``label`` (:func:`simbench.systems.acquire`)."""
        return acquire(
            self.proposed, scene, label, seeds=self.seeds, render=self.render, repeats=repeats, prepared=True
        )

    def acquire(
        self, name: str, scene: "str | SceneSpec", label: str, *, repeats: int = 1, rig: str | None = None
    ) -> list[tuple[Recording, SystemDepth]]:
        """``repeats`` recordings of ``scene`` (a scene of ``scenes/`` or a loaded, not yet
        prepared scene, e.g. one placed by :meth:`place`) by the system ``name`` at its native
        resolution, each with its depth decoded the system's own way (with ``rig``, see
        :meth:`decode_recording`); seeds from ``system.seed_prefix + label``, the calibration
        recorded once per run."""
        system = self.system(name)
        prepared = system.prepare(self.raw_scene(scene) if isinstance(scene, str) else scene)
        cal = self.calibration(system, prepared)
        recs = acquire(
            system,
            prepared,
            label,
            seeds=self.seeds,
            render=self.render,
            calibration=cal,
            repeats=repeats,
            prepared=True,
        )
        return [(rec, self.decode_recording(name, rec, rig=rig)) for rec in recs]

    def decode_recording(self, name: str, rec: Recording, *, rig: str | None = None) -> SystemDepth:
        """``rec`` of system ``name`` decoded the system's own way; a system that decodes with the
        scene's rig (:attr:`simbench.systems.SystemInfo.uses_scene_rig`) gets the true or the
        calibrated one (``rig``; None = the run's), the others their own devices'."""
        system = self.system(name)
        cal = self.calibration(system, rec.scene)
        scene = self.decode_scene(rec.scene, rig=rig) if system.info().uses_scene_rig else rec.scene
        return system.decode(rec.raw, cal, scene=scene)

    def reference(self, scene: SceneSpec, params: DecoderParams) -> ReferenceMap:
        """The proposed sensor's reference plane behind ``scene`` decoded with ``params``
        (:class:`simbench.systems.proposed.ReferenceCalibration`; with the calibration frames
        when the decoder unmixes)."""
        return self.calibration(self.proposed, scene, frames=bool(params.unmix)).reference_map(params)

    def decode(
        self, cap: Capture, params: DecoderParams, *, mode: str | None = None, rig: str | None = None
    ) -> DecodeResult:
        """``cap`` decoded with ``params`` (Z0 = the scene's reference depth) in ``mode``
        (``reference`` or ``calibrated``; None = ``params.mode``) with the true or the calibrated
        rig (``rig``; None = the run's :attr:`RunConfig.rig`)."""
        mode = mode or params.mode
        cal = (
            self.calibration(self.proposed, cap.scene, frames=bool(params.unmix))
            if mode == "reference" or params.unmix
            else None
        )
        scene = self.decode_scene(cap.scene, rig=rig)
        return self.proposed.decode(cap.raw, cal, scene=scene, params=params, mode=mode).detail

    # provenance --------------------------------------------------------------------------
    def write_results(self, name: str, files: dict[str, bytes | str], extra: dict | None = None) -> list[Path]:
        """A target's files (paths relative to the output folder: their bytes, or text written
        as UTF-8) and ``<name>.provenance.json`` beside them (command, config, seeds, versions,
        each file's SHA-256), written together, all or nothing (:func:`simbench.io.write_files`):
        an interrupted or failed write leaves the previous set whole, never a table beside a
        provenance record whose hashes are another run's.  Returns the files' paths (the
        record's last)."""
        data = {rel: b if isinstance(b, bytes) else b.encode("utf-8") for rel, b in files.items()}
        record = {
            "command": self.command,
            "config": self.config.to_dict(),
            "sensor": sensor_to_dict(self.sensor),
            "variant": self.variant,
            "versions": versions(),
            **git_state(),
            "seeds": dict(sorted(self.seeds_used.items())),
            "files": {str(Path(rel)): hashlib.sha256(b).hexdigest() for rel, b in data.items()},
            **(extra or {}),
        }
        data[f"{name}.provenance.json"] = json_bytes(record)
        return write_files({self.out / rel: b for rel, b in data.items()})

    def timed(self, what: str) -> _Timer:
        return _Timer(self.progress, what)


class _Timer:
    def __init__(self, progress, what: str) -> None:
        self.progress, self.what = progress, what

    def __enter__(self):
        self.t0 = time.perf_counter()
        return self

    def __exit__(self, *exc) -> None:
        if exc[0] is None:
            self.progress(f"{self.what} ({time.perf_counter() - self.t0:.1f} s)")


@dataclass(frozen=True)
class Split:
    """A target measured in parts that depend on nothing but the run's settings: the scenes of
    the hard-scene table, the depths of Fig. 9, the speeds of the motion study.

    ``parts(config)`` names them in the order their results are written; ``measure(session,
    part)`` measures one (renders through the session's cache, seeds from labels, its result
    picklable plain data); ``write(session, results)`` makes the target's files from the results
    in ``parts``' order and returns its metrics.  ``cost(part)``, when given, ranks the parts for
    a pool (the costliest first; equal costs keep ``parts``' order).

    One process measures the parts in order (:meth:`run`); ``simbench reproduce --workers N`` or
    ``--scheduler`` measures them side by side on its workers, each part in a session whose seed
    log is its own (:meth:`measure_part`), and writes here: the same files either way, since a
    part's result and the seeds it records do not depend on where or after what it ran.
    """

    name: str
    parts: Callable[[RunConfig], Sequence[str]]
    measure: Callable[[Session, str], Any]
    write: Callable[[Session, list], dict]
    cost: Callable[[str], float] | None = None

    def measure_part(self, session: Session, part: str, *, index: int, total: int) -> tuple[Any, dict]:
        """(``measure``'s result, the seeds it recorded) for ``part``, the ``index``-th of
        ``total``, measured in a session with a seed log of its own."""
        own = session.for_target()
        with own.timed(f"[{self.name} {index + 1}/{total}] {part}"):
            result = self.measure(own, part)
        return result, own.seeds.used

    def ranked(self, config: RunConfig) -> list[tuple[int, str]]:
        """(index, part) in the order a pool should take them: the costliest first."""
        parts = list(enumerate(self.parts(config)))
        if self.cost is None:
            return parts
        return sorted(parts, key=lambda ip: -self.cost(ip[1]))

    def collect(self, session: Session, measured: Sequence[tuple[Any, dict]]) -> dict:
        """``write`` of the parts' results (in ``parts``' order, with their seeds recorded in
        ``session``'s log)."""
        for _, seeds in measured:
            session.seeds.used.update(seeds)
        return self.write(session, [result for result, _ in measured])

    def run(self, session: Session) -> dict:
        """Every part measured here, in order, then written."""
        parts = list(self.parts(session.config))
        return self.collect(
            session, [self.measure_part(session, p, index=i, total=len(parts)) for i, p in enumerate(parts)]
        )


def score(
    rec: Recording,
    result: SystemDepth | DecodeResult,
    period_px: float | None = None,
    *,
    region: np.ndarray | None = None,
    edge_band_px: int = 0,
) -> dict:
    """:func:`simbench.metrics.score` of a recording's decoded depth (a
    :class:`simbench.systems.SystemDepth` or a :class:`DecodeResult`), with stripe-order errors
    where it has projector columns and ``period_px`` is given."""
    return metrics_score(
        result.depth_m,
        rec.gt,
        camera=rec.scene.rig.camera,
        region=region,
        column_px=getattr(result, "column_px", None) if period_px is not None else None,
        period_px=period_px,
        edge_band_px=edge_band_px,
    )


def made_by(session: "Session", camera: Intrinsics) -> str:
    """The opening of a result file's "Made by" line: command, camera, samples, sensor model."""
    cfg = session.config
    return (
        f"Made by `{session.command}` ({camera.width_px}x{camera.height_px} camera, {cfg.spp} spp {cfg.sampler}, "
        f"sensor model `{cfg.sensor}`, "
    )


def calibration_sentence(session: Session, scene: SceneSpec) -> str:
    """One paragraph: how the run's calibrated rig of ``scene`` (prepared) was made and how far it
    is from the truth."""
    s = calibration_summary(session, scene)
    e = s["errors"]
    rms = s["rms_px"]
    return (
        "The calibrated rig is what `simbench calibrate` estimates through the same sensor model: the default "
        f"target ({s['target']}) at {s['poses']} seeded poses, white frames and phase-shifting + Gray-code "
        "sequences in columns and rows, OpenCV's camera and stereo calibration (`simbench.calibration`). "
        f"Reprojection RMS: camera {rms['camera']:.3f} px, projector {rms['projector']:.3f} px. Against the true "
        f"rig: focal lengths {e['camera_focal_pct']:+.3f} % (camera) and {e['projector_focal_pct']:+.3f} % "
        f"(projector), principal points ({e['camera_cx_px']:+.2f}, {e['camera_cy_px']:+.2f}) px and "
        f"({e['projector_cx_px']:+.2f}, {e['projector_cy_px']:+.2f}) px, baseline {e['baseline_mm']:+.3f} mm, "
        f"projector rotation {e['rotation_deg']:.3f} deg."
    )


def other_rig(session: Session) -> str | None:
    """The rig the extra columns decode with: the calibrated one in a run on the true rig, the
    true one in a run on the calibrated rig; None when the run leaves them out
    (:attr:`RunConfig.compare_rigs`)."""
    if not session.config.compare_rigs:
        return None
    return "calibrated" if session.config.rig == "true" else "true"


def calibration_summary(session: Session, scene: SceneSpec) -> dict:
    """The calibration of ``scene``'s rig (prepared; :meth:`Session.calibration_result`): its
    settings, reprojection RMS and per-parameter errors against the true rig (provenance)."""
    from simbench.calibration import rig_errors

    calibration = session.calibration_result(scene)
    cfg = session.config
    target = cfg.calibration_target()
    truth = scene.rig
    return {
        "target": f"{target.squares[0]} x {target.squares[1]} squares of {1000 * target.square_m:g} mm, bow "
        f"{cfg.calibration_bow_mm_per_m:g} mm/m, waviness {cfg.calibration_waviness_mm:g} mm",
        "poses": cfg.calibration_poses,
        "used_views": list(calibration.used_views),
        "rms_px": calibration.rms_px,
        "errors": rig_errors(calibration.rig, truth),
    }


def sensor_caveat(config: RunConfig) -> list[str]:
    """The Markdown lines that say a run did not use the physical ``paper`` sensor model."""
    if config.sensor == "paper":
        return []
    return [
        "",
        f"**Caveat:** sensor model `{config.sensor}`, not the physical `paper` one: crosstalk, Bayer mosaic, DMD "
        f"grid, defocus and distortion are left out.",
    ]


def scene_errors(rec: Recording, result: DecodeResult, *, period_px: float, edge_band_px: int) -> dict:
    """:func:`simbench.metrics.depth_errors` of a whole scene: over the lit pixels, the error
    statistics off an ``edge_band_px`` band at depth edges (completeness over all of them)."""
    band = edge_band(rec.gt.depth_m, object_id=rec.gt.object_id, band_px=edge_band_px)
    return depth_errors(
        result.depth_m,
        rec.gt.depth_m,
        region=rec.gt.lit,
        exclude=band,
        column_px=result.column_px,
        gt_column_px=rec.gt.column_px,
        period_px=period_px,
    )


def git_commit(root: Path | None = None) -> str:
    """The commit checked out in the project's tree (or ``root``); ``"unknown"`` outside a git
    checkout."""
    try:
        return subprocess.run(
            ["git", "rev-parse", "HEAD"], capture_output=True, text=True, check=True, cwd=root or SCENES_DIR.parent
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


# what makes results: a change here that is not committed is not in ``git_commit``'s tree
SOURCE_PATHS = ("simbench", "scenes", "pyproject.toml", "Makefile")


def git_state(root: Path | None = None) -> dict:
    """``git_commit`` and ``git_uncommitted``: the source paths (:data:`SOURCE_PATHS`) that differ
    from that commit - modified, staged, deleted or untracked (``None`` outside a checkout).

    A result made from an uncommitted tree names a commit whose code did not make it; the list
    says so, where a bare commit hash would be silently wrong (and a commit that never lands
    leaves the list as the only trace that the code was not the commit's).  ``results/`` itself
    is not a source path: a run rewrites it while it runs.
    """
    commit = git_commit(root)
    try:
        # -z: paths as they are (no quoting), a rename's two paths apart; no optional lock, so a
        # run never holds the index a user's own git command is waiting for
        out = subprocess.run(
            ["git", "--no-optional-locks", "status", "--porcelain=v1", "-z", "--untracked-files=all", "--"]
            + list(SOURCE_PATHS),
            capture_output=True,
            check=True,
            cwd=root or SCENES_DIR.parent,
        ).stdout.decode("utf-8", "surrogateescape")
    except (OSError, subprocess.CalledProcessError):
        return {"git_commit": commit, "git_uncommitted": None}
    paths, fields = set(), iter(out.split("\0"))
    for entry in fields:
        if len(entry) > 3:
            paths.add(entry[3:])
            if entry[0] in "RC":  # a rename's or copy's source follows as a field of its own
                paths.add(next(fields, ""))
    return {"git_commit": commit, "git_uncommitted": sorted(paths - {""})}
