"""Depth systems: every sensor the testbed simulates, behind one interface and one registry.

A depth system (:class:`DepthSystem`) says how it sees a scene (:meth:`~DepthSystem.prepare`:
its own camera, emitter and lenses in place of the scene file's rig), how it is calibrated
once (:meth:`~DepthSystem.calibrate`: the proposed sensor's reference plane, the Kinect's factory
reference, nothing for the ToF camera), how it acquires raw data (:meth:`~DepthSystem.acquire`:
renders through the render cache and records one raw frame per noise seed, from seeds it is
given), how it decodes raw data to depth in the common conventions (:meth:`~DepthSystem.decode`:
float32 z-depth in metres at its pixel centres, NaN where invalid) and what it is
(:meth:`~DepthSystem.info`: label, native resolution, captures per depth map, cited device
numbers).  Experiments, the benchmark and the CLI loop over systems by name.

Systems are registered by name (:func:`register_system`, the way Mitsuba registers plugins):
the built-in ones are ``proposed`` (:mod:`simbench.systems.proposed`, the paper's colour
sequence coded fringe sensor), ``kinect`` (:mod:`simbench.systems.kinect`), ``tof``
(:mod:`simbench.systems.tof`) and ``phase_shift`` (:mod:`simbench.systems.phase_shift`, the
multi-shot reference on the proposed sensor's projector and camera).  A new system is one module with a class following
:class:`DepthSystem` plus one :func:`register_system` call; :func:`get_system` builds a system by
name from the run's :class:`SystemOptions` and lists the registered names when one is unknown.
"""

from __future__ import annotations

import dataclasses
import importlib
import logging
import sys
import threading
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np

from simbench.sim.mitsuba_dict import RenderSettings
from simbench.sim.scene import SceneSpec
from simbench.sim.timeline import is_moving, motion_field_px, scene_at

if TYPE_CHECKING:
    from simbench.seeds import SeedLog

__all__ = [
    "SystemOptions",
    "SystemInfo",
    "RenderSettings",
    "SystemDepth",
    "Recording",
    "DepthSystem",
    "acquire",
    "capture_window",
    "register_system",
    "recording_manifest",
    "unregister_system",
    "get_system",
    "system_names",
    "system_of_recording",
    "DEFAULT_SYSTEM",
    "PLUGIN_GROUP",
    "plugin_in_traceback",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SystemOptions:
    """What a run sets for every system; each system uses what applies to it.

    sensor : the proposed sensor's camera/projector model (:class:`simbench.sim.sensor.SensorModel`;
        None = the ``paper`` preset).  The competitors carry their own sensors.
    decoder : the proposed sensor's decoder settings, with the pattern it projects
        (:class:`simbench.decode.DecoderParams`; None = the paper's)
    camera_scale : resolution factor of the proposed sensor's camera (0.5 for quick runs)
    reference_form : form keys of the reference board (:func:`simbench.sim.scene.board_form`)
    """

    sensor: Any = None
    decoder: Any = None
    camera_scale: float = 1.0
    reference_form: dict = field(default_factory=dict)


@dataclass(frozen=True)
class SystemInfo:
    """What a system is: ``label`` for tables and plots, native ``size_hw`` (H, W) of its depth
    map, ``captures`` camera exposures per depth map (1 = single shot), ``numbers``: cited device
    numbers, name -> (value, source); ``period_px``: see below."""

    name: str
    label: str
    size_hw: tuple[int, int]
    captures: int
    numbers: dict[str, tuple[Any, str]] = field(default_factory=dict)
    # what SystemDepth.confidence is, with its unit and the operating point the system's own
    # decoder applies (pixels below it are holes): written beside the depth by `simbench decode`
    confidence: str = ""
    # the fringe period (projector px) of a structured-light system's columns: a decoded column
    # off by more than half of it is a stripe-order error; None = no columns
    period_px: float | None = None
    # the system decodes with the scene's projector-camera rig, the rig a lab estimates with
    # simbench.calibration: experiments can hand it the calibrated rig instead of the true one
    # (the competitors carry their own factory-calibrated devices)
    uses_scene_rig: bool = False
    # what it records with among simbench.api.record's options beyond the scene and the render
    # settings: "sensor" (the sensor model its camera and projector are), "pattern" (the coded
    # pattern it projects), "calibration_frames" (the reference plane under black and each
    # primary), "camera_scale" (the scene rig's camera resolution, scaled: a system recording with
    # the scene's rig); any other given is an error there, not ignored.  None (a system that does not
    # say): every option is handed on, and the system uses what applies to it
    recording_options: tuple[str, ...] | None = None


@dataclass(frozen=True)
class SystemDepth:
    """A decoded depth map in the common conventions: ``depth_m`` (H, W) float32 z-depth in
    metres (NaN invalid), ``valid`` (H, W) bool, ``confidence`` (H, W) float32 in the system's
    own unit or None; ``column_px`` the decoded projector column where the system has one (for
    stripe-order errors); ``detail`` the system's own full result (e.g. a
    :class:`simbench.decode.pipeline.DecodeResult`)."""

    depth_m: np.ndarray
    valid: np.ndarray
    confidence: np.ndarray | None = None
    column_px: np.ndarray | None = None
    detail: Any = None


@dataclass(frozen=True)
class Recording:
    """One recording of a scene by a system: the scene as the system saw it, the raw frame
    (the proposed sensor's colour image, the Kinect's IR image, the ToF camera's tap frames),
    ground truth at the system's pixels and the seeds it was made from."""

    system: str
    scene: SceneSpec
    raw: np.ndarray
    gt: Any  # simbench.sim.truth.GroundTruth
    seeds: dict

    @property
    def image(self) -> np.ndarray:
        return self.raw


@runtime_checkable
class DepthSystem(Protocol):
    """The shape of every depth system (see the module docstring).

    ``name`` is its registry name; ``seed_prefix`` prefixes the labels its captures derive their
    seeds from (:class:`simbench.seeds.SeedLog`), so two systems looking at the same scene under
    the same label draw independent noise.
    """

    name: str
    seed_prefix: str

    def info(self) -> SystemInfo: ...

    def prepare(self, scene: SceneSpec) -> SceneSpec: ...

    def calibration_key(self, scene: SceneSpec) -> Any: ...

    def calibrate(self, scene: SceneSpec, *, seeds, render: RenderSettings) -> Any: ...

    def acquire(
        self, scene: SceneSpec, calibration: Any, *, render_seed: int, noise_seeds: list[int], render: RenderSettings
    ) -> list[np.ndarray]: ...

    def decode(self, raw: np.ndarray, calibration: Any, *, scene: SceneSpec) -> SystemDepth: ...

    def bench_inputs(self, *, scene: str = "plane", seed: int = 0) -> tuple[np.ndarray, Any, SceneSpec | None]: ...

    def write_recording(
        self,
        out_dir: Path,
        raw: np.ndarray,
        calibration: Any,
        *,
        scene: SceneSpec,
        gt,
        meta: dict,
        overwrite: bool = False,
    ) -> dict[str, Path]: ...

    def read_recording(self, in_dir: Path) -> tuple[np.ndarray, Any, SceneSpec | None]: ...


# name -> a factory taking SystemOptions, or "module:attribute" imported on first use (so the
# registry costs nothing until a system is built)
_SYSTEMS: dict[str, Callable[[SystemOptions], DepthSystem] | str] = {}


def register_system(name: str, factory: Callable[[SystemOptions], DepthSystem] | str, *, replace: bool = False) -> None:
    """Register a depth system under ``name``: ``factory(options)`` returns the system (a
    :class:`DepthSystem`); a string ``"module:attribute"`` is imported when first built."""
    if not isinstance(name, str) or not name.isidentifier():
        raise ValueError(f"a system name must be an identifier, got {name!r}")
    if name in _SYSTEMS and not replace:
        raise ValueError(f"a depth system {name!r} is already registered")
    _SYSTEMS[name] = factory
    _PLUGINS.pop(name, None)  # (a plugin's entry is put back by _read_plugins after this call)


def unregister_system(name: str) -> None:
    """Remove ``name`` from the registry (a test's own system, for example)."""
    _SYSTEMS.pop(name, None)
    _PLUGINS.pop(name, None)


# depth systems other installed packages provide, found when the registry is first read: in the
# package's pyproject.toml, [project.entry-points."simbench.systems"] my_sensor = "my_package.my_module:MySensor"
PLUGIN_GROUP = "simbench.systems"
_plugins_read = False
# name -> (the entry point's "module:attribute", the package that declares it)
_PLUGINS: dict[str, tuple[str, str]] = {}
_plugins_lock = threading.Lock()


def _read_plugins() -> None:
    """Register the systems of :data:`PLUGIN_GROUP`'s entry points (once per process), so that
    another process - ``simbench render --system NAME``, a pool or Dask worker - knows them too;
    a name already registered keeps its system (with a warning)."""
    global _plugins_read
    if _plugins_read:
        return
    with _plugins_lock:  # (a Dask worker's threads may ask at once)
        if _plugins_read:
            return
        from importlib.metadata import entry_points

        for ep in entry_points(group=PLUGIN_GROUP):
            package = getattr(ep.dist, "name", None) or "an installed package"
            if ep.name in _SYSTEMS:
                log.warning(
                    "depth system plugin %s = %r of %s ignored: %r is registered already",
                    ep.name,
                    ep.value,
                    package,
                    ep.name,
                )
                continue
            try:
                register_system(ep.name, ep.value)
                _PLUGINS[ep.name] = (ep.value, package)
            except ValueError as exc:  # one broken plugin does not stop the others, nor simbench
                log.warning("depth system plugin %s = %r of %s ignored: %s", ep.name, ep.value, package, exc)
        _plugins_read = True


def system_names() -> list[str]:
    """The registered system names, in registration order (the built-in ones first; installed
    plugins' (:data:`PLUGIN_GROUP`) join when the registry is first read)."""
    _read_plugins()
    return list(_SYSTEMS)


def get_system(name: str, options: SystemOptions | None = None) -> DepthSystem:
    """The depth system ``name`` built for ``options``; ValueError listing the registered names
    when ``name`` is unknown."""
    _read_plugins()
    if name not in _SYSTEMS:
        raise ValueError(f"unknown depth system {name!r}; registered: {system_names()}")
    factory = _SYSTEMS[name]
    try:
        if isinstance(factory, str):
            module, _, attr = factory.partition(":")
            factory = getattr(importlib.import_module(module), attr)
            _SYSTEMS[name] = factory
        system = factory(options or SystemOptions())
    except Exception as exc:
        if name not in _PLUGINS:
            raise
        # another package's code: its failure named as its, not as simbench's own error
        raise ValueError(f"{_plugin_label(name)} could not be built: {type(exc).__name__}: {exc}") from exc
    if not isinstance(system, DepthSystem):
        what = _plugin_label(name) if name in _PLUGINS else f"the factory of depth system {name!r}"
        error = ValueError if name in _PLUGINS else TypeError
        raise error(f"{what} returned a {type(system).__name__}, not a DepthSystem (see docs/extending.md)")
    if system.name != name:
        raise ValueError(f"depth system registered as {name!r} calls itself {system.name!r}")
    return system


def _plugin_label(name: str) -> str:
    value, package = _PLUGINS[name]
    return f"depth system plugin {name!r} ({value} of {package})"


def _plugin_files(name: str) -> tuple[list[Path], list[Path]]:
    """(folders, files) of the plugin's code, as far as it is imported: its top-level package's
    folders, or a top-level module's own file."""
    top = sys.modules.get(_PLUGINS[name][0].partition(":")[0].split(".")[0])
    if top is None:
        return [], []
    folders = [Path(p).resolve() for p in getattr(top, "__path__", None) or []]
    file = getattr(top, "__file__", None)
    return folders, ([Path(file).resolve()] if file and not folders else [])


def plugin_in_traceback(exc: BaseException) -> str | None:
    """The plugin whose code raised ``exc`` (:func:`_plugin_label`; every entry point of that code
    named when several share it): the innermost frame of its traceback that is either a plugin's
    or simbench's own decides; None when it is simbench's (or no plugin is loaded)."""
    ours = Path(__file__).resolve().parents[1]  # the simbench package
    for frame in reversed(traceback.extract_tb(exc.__traceback__)):
        path = Path(frame.filename).resolve()
        names = []
        for name in _PLUGINS:
            folders, files = _plugin_files(name)
            if path in files or any(f in path.parents for f in folders):
                names.append(name)
        if len(names) == 1:
            return _plugin_label(names[0])
        if names:
            packages = sorted({_PLUGINS[n][1] for n in names})
            return f"depth system plugins {', '.join(map(repr, names))} (code of {', '.join(packages)}: {path.name})"
        if ours in path.parents:
            return None
    return None


def acquire(
    system: DepthSystem,
    scene: SceneSpec,
    label: str,
    *,
    seeds: SeedLog,
    render: RenderSettings,
    calibration: Any = None,
    repeats: int = 1,
    prepared: bool = False,
) -> list[Recording]:
    """``repeats`` recordings of ``scene`` by ``system`` (one render, one camera-noise draw
    each): the one acquisition path of the CLI, the experiments and the sweeps.

    ``scene`` is a scene file's scene (``prepared``: already through :meth:`DepthSystem.prepare`);
    seeds derive from ``system.seed_prefix + label`` (:meth:`simbench.seeds.SeedLog.capture`,
    recorded there); ``calibration`` is what :meth:`DepthSystem.calibrate` returned.  Renders
    and ground truth come from ``render.cache`` when it holds them.
    """
    from simbench.sim.capture import cached_ground_truth

    if not prepared:
        scene = system.prepare(scene)
    truth_scene = scene
    if is_moving(scene):
        window = capture_window(system, scene)
        truth_scene = scene_at(scene, 0.5 * (window[0] + window[1]))  # the truth at mid-capture
    render_seed, noise_seeds = seeds.capture(system.seed_prefix + label, repeats=repeats)
    raws = system.acquire(scene, calibration, render_seed=render_seed, noise_seeds=noise_seeds, render=render)
    gt = cached_ground_truth(truth_scene, cache=render.cache)
    if truth_scene is not scene:
        motion = motion_field_px(gt.depth_m, gt.object_id, scene, scene.rig.camera, window)
        gt = dataclasses.replace(gt, motion_px=motion)
    return [
        Recording(system=system.name, scene=scene, raw=raw, gt=gt, seeds={"render": render_seed, "noise": n})
        for raw, n in zip(raws, noise_seeds)
    ]


def capture_window(system: DepthSystem, scene: SceneSpec) -> tuple[float, float]:
    """When ``system`` records ``scene`` (prepared): (start, end) in seconds of its whole capture,
    from its optional ``capture_window_s(scene)`` - the time model a moving scene needs.  A
    system without one refuses moving scenes rather than recording an instant as an exposure."""
    window = getattr(system, "capture_window_s", None)
    if window is None:
        raise ValueError(
            f"the {system.name} system has no time model yet: it cannot record the moving scene {scene.name!r}"
        )
    return window(scene)


# the system a bare capture image belongs to (`simbench decode IMAGE --rig RIG`), and the command
# line's --system default: the paper's sensor
DEFAULT_SYSTEM = "proposed"

# recording folders name their system in one of these files
RECORDING_MANIFESTS = ("device.json", "meta.json")


def recording_manifest(system: DepthSystem) -> str:
    """The manifest file of ``system``'s recording folders (a system may name its own with a
    ``manifest_name`` attribute; the competitors' is ``device.json``)."""
    from simbench.systems.recording import DEVICE_MANIFEST

    return getattr(system, "manifest_name", DEVICE_MANIFEST)


def system_of_recording(in_dir: str | Path) -> str:
    """The system name a recording folder (``simbench render --out``) was written by."""
    from simbench.manifest import json_object

    d = Path(in_dir)
    for manifest in RECORDING_MANIFESTS:
        path = d / manifest
        if path.is_file():
            info = json_object(path)  # its seal is checked by the system's reader
            name = info.get("system", info.get("device", DEFAULT_SYSTEM))
            if not isinstance(name, str) or name not in system_names():
                raise ValueError(f"{path}: unknown depth system {name!r}; registered: {system_names()}")
            return name
    raise FileNotFoundError(
        f"{d} holds no {' or '.join(RECORDING_MANIFESTS)}: not a recording folder (`simbench render --out`)"
    )


register_system("proposed", "simbench.systems.proposed:ColourFringeSystem")
register_system("kinect", "simbench.systems.kinect:KinectSystem")
register_system("tof", "simbench.systems.tof:ToFSystem")
register_system("phase_shift", "simbench.systems.phase_shift:PhaseShiftSystem")
