"""What the paper-reproduction experiments share: run configuration, seeds, the render cache,
the calibration (one reference-plane capture per run, as in the paper's Sec. 5.4), decoding,
and result files with provenance.

Seeds: every capture's seeds derive from the run's base seed and the capture's label
(``SeedSequence([base, sha256(label)])``), so a capture keeps its seeds when experiments are
added, removed or run alone; every result row records them.
"""

from __future__ import annotations

import csv
import dataclasses
import hashlib
import io
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from simbench.cache import RenderCache
from simbench.decode import DecoderParams, decode
from simbench.decode.persist import cached_decode_reference
from simbench.decode.pipeline import DecodeResult, ReferenceMap
from simbench.io import atomic_write_text, save_json
from simbench.metrics import depth_errors, edge_band, plane_fit_error
from simbench.pattern import PatternSpec, calibration_frames, fringe_pattern, quantize
from simbench.render import DEFAULT_SAMPLER, DEFAULT_SPP, GroundTruth, check_sampler, realised_rig
from simbench.rig import scale_camera
from simbench.scene import Placement, SceneSpec, board_form, load_scene, place_objects, reference_scene
from simbench.device import SensorModel, get_sensor, sensor_to_dict
from simbench.simulate import REFERENCE_ALBEDO, ProjectorDrive, cached_ground_truth, exposure_phase, physical_scene, record, render_channels, versions

__all__ = ["SCENES_DIR", "RunConfig", "Capture", "Session", "score", "label_seed", "write_table", "markdown_table", "figure_png", "git_commit"]

SCENES_DIR = Path(__file__).resolve().parents[2] / "scenes"


@dataclass(frozen=True)
class RunConfig:
    """Settings of a reproduction run (``quick`` = the reduced CI run).

    sensor : sensor model, a preset of :func:`simbench.device.get_sensor` (``paper``: the
        Flea3 + LightCrafter physics; ``minimal``: noise only; ``ideal``: nothing) or a TOML file
    camera_scale : camera resolution factor (0.5 = 640x480 for quick runs)
    spp, sampler, max_depth : path tracing samples per pixel, Mitsuba sample generator
        (:data:`simbench.render.DEFAULT_SAMPLER` and ``DEFAULT_SPP``: measured to keep render
        noise below a third of camera noise on the white board) and path length
    seed : base seed of every capture
    fig9_repeats : noise realisations per depth in Fig. 9 (the paper: "more than 10 times")
    edge_band_px : band at depth edges left out of error statistics
    decoder : the paper's decoder settings (the colour-robust decoder is
        :func:`simbench.decode.robust_params` of them)
    placement_depth_mm, placement_tilt_deg : how precisely test objects are placed
        (:class:`simbench.scene.Placement`: each object gets its own seeded error within these
        bounds, independent of the reference plane; 0 = exactly on the nominal pose)
    board_bow_mm_per_m, board_waviness_mm : form error of every placed board and of the reference
        board (:func:`simbench.scene.board_form_m`: the bow's sag over a 1 m chord, the
        ripple's amplitude; seeded bow sign and ripple phase per board); 0 = flat
    """

    quick: bool = False
    sensor: str = "paper"
    camera_scale: float = 1.0
    spp: int = DEFAULT_SPP
    sampler: str = DEFAULT_SAMPLER
    max_depth: int = 6
    seed: int = 2017
    fig9_repeats: int = 10
    edge_band_px: int = 5
    ply_stride: int = 3
    placement_depth_mm: float = 10.0
    placement_tilt_deg: float = 2.0
    board_bow_mm_per_m: float = 0.0
    board_waviness_mm: float = 0.0
    decoder: DecoderParams = field(default_factory=DecoderParams)

    def __post_init__(self) -> None:
        check_sampler(self.sampler, self.spp)
        self.placement  # validates the placement and board form

    @property
    def placement(self) -> Placement:
        return Placement(
            depth_m=self.placement_depth_mm / 1000.0,
            tilt_deg=self.placement_tilt_deg,
            bow_m_per_m=self.board_bow_mm_per_m / 1000.0,
            waviness_m=self.board_waviness_mm / 1000.0,
        )

    def reference_form(self) -> dict:
        """Form keys of the reference board (:func:`simbench.scene.board_form`, seeded from the
        run's seed: one board for the whole run); empty when boards are flat."""
        p = self.placement
        if not (p.bow_m_per_m or p.waviness_m):
            return {}
        rng = np.random.default_rng(label_seed(self.seed, "reference/form"))
        return board_form(bow_m_per_m=p.bow_m_per_m, waviness_m=p.waviness_m, rng=rng)

    @classmethod
    def preset(cls, *, quick: bool, **overrides) -> "RunConfig":
        base = cls(quick=True, camera_scale=0.5, spp=4, fig9_repeats=3, edge_band_px=3, ply_stride=4) if quick else cls()
        return dataclasses.replace(base, **overrides)

    def to_dict(self) -> dict:
        return asdict(self)  # recurses into the decoder's dataclass


def label_seed(base: int, label: str) -> int:
    """A 32-bit seed for ``label``, independent of which other labels a run uses."""
    h = int.from_bytes(hashlib.sha256(label.encode()).digest()[:8], "little")
    return int(np.random.SeedSequence([int(base), h]).generate_state(1)[0])


@dataclass
class Capture:
    """One recorded capture of a scene with its ground truth and seeds."""

    scene: SceneSpec
    image: np.ndarray
    gt: GroundTruth
    seeds: dict


@dataclass
class CompetitorCapture:
    """One competitor depth map (:mod:`simbench.baselines`) with its scene, truth and seeds."""

    device: str
    scene: SceneSpec
    depth: object  # simbench.baselines.CompetitorDepth
    gt: GroundTruth
    seeds: dict


class Session:
    """Shared state of one reproduction run: config, cache, pattern, calibration, progress."""

    def __init__(self, config: RunConfig, *, out_dir: str | Path, cache_dir: str | Path | None, progress: Callable[[str], None] = print, command: str = "", sensor: SensorModel | None = None) -> None:
        import mitsuba as mi

        self.config = config
        self.out = Path(out_dir)
        self.cache = RenderCache(cache_dir)
        self.progress = progress
        self.command = command or "simbench " + " ".join(sys.argv[1:])
        self.variant = mi.variant()
        self.sensor = sensor if sensor is not None else get_sensor(config.sensor)
        self.pattern = PatternSpec(period_px=config.decoder.period_px, order=config.decoder.order, sequence=config.decoder.sequence, channels=config.decoder.channels)
        self.pattern_u8 = quantize(fringe_pattern(self.pattern))
        self._refs: dict = {}
        self._competitor_cal: dict = {}
        self.seeds_used: dict[str, dict] = {}

    def fork(self, sensor: SensorModel, *, config: RunConfig | None = None) -> "Session":
        """A session with another sensor model (and optionally other run settings) sharing
        this one's cache, output and seed log."""
        other = Session(config or self.config, out_dir=self.out, cache_dir=None, progress=self.progress, command=self.command, sensor=sensor)
        other.cache = self.cache
        other.seeds_used = self.seeds_used
        other._competitor_cal = self._competitor_cal
        return other

    # scenes and captures -------------------------------------------------------------
    def raw_scene(self, name: str) -> SceneSpec:
        """A scene of ``scenes/`` as its file says (before :meth:`prepare`)."""
        return load_scene(SCENES_DIR / f"{name}.toml")

    def scene(self, name: str) -> SceneSpec:
        """A scene of ``scenes/`` with the run's camera resolution, the rendered rig and the
        sensor model's lenses and ambient light (:func:`simbench.simulate.physical_scene`)."""
        return self.prepare(load_scene(SCENES_DIR / f"{name}.toml"))

    def prepare(self, scene: SceneSpec) -> SceneSpec:
        rig = scene.rig if self.config.camera_scale == 1 else scale_camera(scene.rig, self.config.camera_scale)
        return physical_scene(dataclasses.replace(scene, rig=realised_rig(rig)), self.sensor)

    def place(self, scene: SceneSpec, label: str, names) -> SceneSpec:
        """``scene`` with the objects ``names`` placed as a lab would (the run's placement
        tolerance, seeds from ``label``); the offsets are recorded with the seeds."""
        seed = label_seed(self.config.seed, f"{label}/placement")
        placed, offsets = place_objects(scene, names, placement=self.config.placement, rng=seed)
        self.seeds_used[f"{label}/placement"] = {"placement": seed, **{f"{n}_{k}": v for n, o in offsets.items() for k, v in o.items()}}
        return placed

    def capture(self, scene: SceneSpec, label: str, *, repeats: int = 1, pattern_u8: np.ndarray | None = None) -> list[Capture]:
        """``repeats`` recordings of one render of ``scene`` (a static scene measured again
        differs by camera noise only), with seeds from ``label``; ``pattern_u8`` replaces the
        run's pattern (calibration frames)."""
        render_seed = label_seed(self.config.seed, f"{label}/render")
        drive = ProjectorDrive(scene, self.pattern_u8 if pattern_u8 is None else pattern_u8, self.sensor, cache=self.cache, phase=exposure_phase(render_seed))
        q = render_channels(scene, drive, self.sensor, spp=self.config.spp, seed=render_seed, max_depth=self.config.max_depth, sampler=self.config.sampler, cache=self.cache)
        gt = cached_ground_truth(scene, cache=self.cache)
        out = []
        for k in range(repeats):
            noise_seed = label_seed(self.config.seed, f"{label}/noise/{k}")
            seeds = {"render": render_seed, "noise": noise_seed}
            self.seeds_used[f"{label}/{k}" if repeats > 1 else label] = seeds
            out.append(Capture(scene=scene, image=record(q, sensor=self.sensor, scene=scene, rng=noise_seed), gt=gt, seeds=seeds))
        return out

    def competitor(self, device: str, name: "str | SceneSpec", label: str, *, repeats: int = 1) -> list["CompetitorCapture"]:
        """``repeats`` depth maps of scene ``name`` from competitor ``device`` (``kinect`` or
        ``tof``, :mod:`simbench.baselines`; ``name`` a scene of ``scenes/`` or a loaded, not
        yet prepared scene, e.g. one placed by :meth:`place`) at its native resolution, decoded the device's way,
        with ground truth at its pixels.  Seeds derive from ``device/label``; the Kinect's
        factory reference is recorded once per session."""
        from simbench import baselines

        model = baselines.get_device(device)
        if device not in self._competitor_cal:
            cal_seed = label_seed(self.config.seed, f"{device}/calibration")
            self.seeds_used[f"{device}/calibration"] = {"render": cal_seed}
            self._competitor_cal[device] = baselines.calibrate(model, spp=self.config.spp, seed=cal_seed, sampler=self.config.sampler, cache=self.cache)
        cal = self._competitor_cal[device]
        raw = load_scene(SCENES_DIR / f"{name}.toml") if isinstance(name, str) else name
        scene = baselines.device_scene(model, raw)
        render_seed = label_seed(self.config.seed, f"{device}/{label}/render")
        noise_seeds = [label_seed(self.config.seed, f"{device}/{label}/noise/{k}") for k in range(repeats)]
        raws = baselines.acquire(model, scene, cal, spp=self.config.spp, seed=render_seed, noise_seeds=noise_seeds, sampler=self.config.sampler, cache=self.cache)
        gt = cached_ground_truth(scene, cache=self.cache)
        out = []
        for k, (raw, noise_seed) in enumerate(zip(raws, noise_seeds)):
            seeds = {"render": render_seed, "noise": noise_seed}
            self.seeds_used[f"{device}/{label}/{k}" if repeats > 1 else f"{device}/{label}"] = seeds
            out.append(CompetitorCapture(device=device, scene=scene, depth=baselines.decode_raw(model, raw, cal), gt=gt, seeds=seeds))
        return out

    def reference(self, scene: SceneSpec, params: DecoderParams) -> ReferenceMap:
        """The calibration: one capture of the white reference plane at the scene's Z0 per rig
        and lighting (albedo :data:`simbench.simulate.REFERENCE_ALBEDO`), with its own seeds,
        decoded once per decoder setting; for a decoder that unmixes the primaries also the
        plane under a black frame and under each primary at full drive (Caspi et al. 1998's
        calibration of the coupling matrix; four frames once per calibration, the measurement
        stays single-shot)."""
        form = self.config.reference_form()
        key = (scene.rig, scene.reference_depth_m, scene.projector_scale, scene.ambient_rgb, params, tuple(sorted(form.items())))
        if key not in self._refs:
            ref_scene = reference_scene(scene, albedo=REFERENCE_ALBEDO, form=form)
            label = f"reference/{scene.rig.name}/{scene.reference_depth_m:g}/{scene.projector_scale:g}/{scene.ambient_rgb}"
            img = self.capture(ref_scene, label)[0].image
            cal = {}
            if params.unmix:
                for name, drive in calibration_frames(self.pattern_u8).items():
                    cal[name] = self.capture(ref_scene, f"{label}/{name}", pattern_u8=drive)[0].image
            primaries = [cal[k] for k in ("red", "green", "blue")] if cal else None
            self._refs[key] = cached_decode_reference(img, rig=scene.rig, params=params, primaries=primaries, dark=cal.get("dark"), cache=self.cache)
        return self._refs[key]

    def decode(self, cap: Capture, params: DecoderParams, *, mode: str | None = None) -> DecodeResult:
        """``cap`` decoded with ``params`` (Z0 = the scene's reference depth) in ``mode``
        (``reference`` or ``calibrated``; None = ``params.mode``)."""
        params = dataclasses.replace(params, z0_m=cap.scene.reference_depth_m, mode=mode or params.mode)
        ref = self.reference(cap.scene, dataclasses.replace(params, mode="reference")) if params.mode == "reference" or params.unmix else None
        return decode(cap.image, rig=cap.scene.rig, params=params, reference=ref)

    # provenance --------------------------------------------------------------------------
    def provenance(self, name: str, files: list[Path], extra: dict | None = None) -> Path:
        """``<name>.provenance.json`` beside the files: command, config, seeds, versions."""
        record = {
            "command": self.command,
            "config": self.config.to_dict(),
            "sensor": sensor_to_dict(self.sensor),
            "variant": self.variant,
            "versions": versions(),
            "git_commit": git_commit(),
            "seeds": dict(sorted(self.seeds_used.items())),
            "files": {str(p.relative_to(self.out)): hashlib.sha256(p.read_bytes()).hexdigest() for p in files},
            **(extra or {}),
        }
        return save_json(self.out / f"{name}.provenance.json", record)

    def timed(self, what: str):
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


def score(cap: Capture, result: DecodeResult, period_px: float, *, region: np.ndarray | None = None, edge_band_px: int = 0) -> dict:
    """The scores every experiment reports for one decoded capture, over ``region`` (default:
    the pixels ground truth says are seen and lit):

    ``plane_mae_mm`` / ``plane_rms_mm``: the paper's protocol, mean absolute (RMS) residual of
    the decoded points to their least-squares plane (it absorbs any error that is planar, so
    it cannot see a tilt or an offset of the whole board); ``gt_mae_mm``, ``gt_rmse_mm``,
    ``bias_mm``: against rendered ground truth; ``completeness``; ``stripe_order_errors`` (and
    their rate): pixels whose projector column is off by more than half a period.  With
    ``edge_band_px`` also the 95th percentile, the outlier share and ``edge<N>_mae_mm``, the
    MAE outside an N-px band at depth edges (the ablation tables).
    """
    gt = cap.gt
    region = gt.lit if region is None else region
    m = depth_errors(result.depth_m, gt.depth_m, region=region, column_px=result.column_px, gt_column_px=gt.column_px, period_px=period_px)
    fit = plane_fit_error(result.depth_m, cap.scene.rig.camera, mask=region)
    out = {
        "plane_mae_mm": fit["mean_abs_residual_mm"],
        "plane_rms_mm": fit["rms_residual_mm"],
        "gt_mae_mm": m["mae_mm"],
        "gt_rmse_mm": m["rmse_mm"],
        "bias_mm": m["bias_mm"],
        "completeness": m["completeness"],
        "stripe_order_errors": m["stripe_order_errors"],
        "stripe_order_error_rate": m["stripe_order_error_rate"],
    }
    if edge_band_px > 0:
        band = edge_band(gt.depth_m, object_id=gt.object_id, band_px=edge_band_px)
        off_edges = depth_errors(result.depth_m, gt.depth_m, region=region, exclude=band)
        out.update({"gt_p95_mm": m["p95_mm"], "outlier_share": m["outlier_share"], f"edge{edge_band_px}_mae_mm": off_edges["mae_mm"]})
    return out


def figure_png(fig, *, dpi: int) -> bytes:
    """A matplotlib figure as PNG bytes (written atomically by the caller); closes it."""
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    plt.close(fig)
    return buf.getvalue()


def markdown_table(header: list[str], rows: list[list[str]]) -> list[str]:
    out = ["| " + " | ".join(header) + " |", "| " + " | ".join("---" for _ in header) + " |"]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return out


def write_table(path_csv: Path, rows: list[dict], columns: list[str]) -> Path:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=columns, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})
    return atomic_write_text(path_csv, buf.getvalue())


def git_commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, check=True, cwd=SCENES_DIR.parent).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
