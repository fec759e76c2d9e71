"""Depth systems (simbench.systems): the registry, and a fourth system registered by a test alone
that runs through Table 3's scoring and the CLI without any change to library code."""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from simbench.rig import Intrinsics, Rig
from simbench.sim.scene import SceneSpec
from simbench.systems import (
    DepthSystem,
    SystemDepth,
    SystemInfo,
    get_system,
    register_system,
    system_names,
    unregister_system,
)

SCENES = Path(__file__).resolve().parents[1] / "scenes"


@dataclass(frozen=True)
class IdealModel:
    width_px: int = 320
    height_px: int = 240
    focal_px: float = 300.0

    @property
    def camera(self) -> Intrinsics:
        return Intrinsics.centred(self.width_px, self.height_px, self.focal_px)


class IdealDepthCamera:
    """A noiseless depth camera: it records the true z-depth at its pixels."""

    name = "ideal_depth"
    seed_prefix = "ideal_depth/"

    def __init__(self, options=None) -> None:
        self.model = IdealModel()

    def info(self) -> SystemInfo:
        return SystemInfo(name=self.name, label="ideal depth camera", size_hw=self.model.camera.size_hw, captures=1)

    def prepare(self, scene: SceneSpec) -> SceneSpec:
        cam = self.model.camera
        # a co-located light the size of the view (Rig needs a baseline: 1 mm)
        rig = Rig(
            camera=cam,
            projector=Intrinsics.centred(cam.width_px + 40, cam.height_px + 40, cam.focal_px),
            position_m=(0.001, 0.0, 0.0),
            name="ideal",
        )
        return dataclasses.replace(scene, rig=rig, camera_lens=None, ambient_rgb=(0.0, 0.0, 0.0))

    def calibration_key(self, scene):
        return None

    def calibrate(self, scene, *, seeds, render):
        return None

    def acquire(self, scene, calibration, *, render_seed, noise_seeds, render):
        from simbench.sim.capture import cached_ground_truth

        depth = cached_ground_truth(scene, cache=render.cache).depth_m
        return [depth.astype(np.float32) for _ in noise_seeds]

    def decode(self, raw, calibration, *, scene=None) -> SystemDepth:
        d = np.asarray(raw, np.float32)
        return SystemDepth(depth_m=d, valid=np.isfinite(d))

    def bench_inputs(self, *, scene="plane", seed=0):
        return (
            np.full(self.model.camera.size_hw, 1.1, np.float32),
            None,
            self.prepare(
                SceneSpec(name="bench", rig=Rig(self.model.camera, self.model.camera, (0.001, 0.0, 0.0)), objects=())
            ),
        )

    def write_recording(self, out_dir, raw, calibration, *, scene, gt, meta, overwrite=False):
        from simbench.systems.recording import write_device_recording
        from simbench.io import save_npy

        writers = {"depth": lambda d: save_npy(d / "depth.npy", raw)}
        return write_device_recording(out_dir, self.name, self.model, writers, gt=gt, info=meta, overwrite=overwrite)

    def read_recording(self, in_dir):
        from simbench.systems.recording import read_device_info
        from simbench.io import load_npy

        self.model, _ = read_device_info(in_dir, self.name, IdealModel)
        return (
            load_npy(Path(in_dir) / "depth.npy"),
            None,
            self.prepare(
                SceneSpec(name="rec", rig=Rig(self.model.camera, self.model.camera, (0.001, 0.0, 0.0)), objects=())
            ),
        )


@pytest.fixture
def ideal_system():
    register_system("ideal_depth", IdealDepthCamera)
    yield "ideal_depth"
    unregister_system("ideal_depth")


def test_builtin_systems_are_registered_and_describe_themselves():
    assert system_names()[:4] == ["proposed", "kinect", "tof", "phase_shift"]
    assert get_system("phase_shift").info().captures == 12
    for name in ("proposed", "kinect", "tof"):
        system = get_system(name)
        assert isinstance(system, DepthSystem) and system.name == name
        info = system.info()
        assert info.name == name and info.captures == 1 and len(info.size_hw) == 2 and info.numbers
    assert get_system("proposed").info().size_hw == (960, 1280)
    assert get_system("kinect").info().size_hw == (480, 640)
    assert get_system("tof").info().size_hw == (144, 176)


def test_unknown_system_lists_the_registered_ones():
    with pytest.raises(
        ValueError, match=r"unknown depth system 'lidar'; registered: \['proposed', 'kinect', 'tof', 'phase_shift'\]"
    ):
        get_system("lidar")


def test_registry_rejects_duplicates_and_wrong_objects(ideal_system):
    with pytest.raises(ValueError, match="already registered"):
        register_system("ideal_depth", IdealDepthCamera)
    with pytest.raises(ValueError, match="identifier"):
        register_system("not a name", IdealDepthCamera)
    register_system("broken", lambda options: object())
    try:
        with pytest.raises(TypeError, match="not a DepthSystem"):
            get_system("broken")
    finally:
        unregister_system("broken")


@pytest.mark.parametrize("name", ["proposed", "kinect", "tof", "phase_shift"])
def test_bench_inputs_decode_to_the_plane(name):
    """Every built-in system decodes its benchmark plane at 1.1 m (the benchmark's input)."""
    system = get_system(name)
    raw, cal, scene = system.bench_inputs()
    depth = system.decode(raw, cal, scene=scene)
    assert depth.depth_m.dtype == np.float32 and depth.depth_m.shape == system.info().size_hw
    assert depth.valid.mean() > 0.8
    assert np.nanmedian(depth.depth_m) == pytest.approx(1.1, abs=0.005)


@pytest.mark.slow
def test_a_system_that_does_not_say_gets_no_exposure_warning_on_frames_that_are_no_image(
    ideal_system, tmp_path, variant
):
    """An extender's audit (2026-11-30): the ideal depth camera (recording_options None: every
    record() option handed on) records (H, W) metres; at 1 m and beyond they were checked as a
    camera's image in [0, 1] - "50 % of the capture's pixels are clipped ... auto exposure".  Its
    record gives no warning (pytest turns one into an error)."""
    import simbench

    from .test_bad_inputs import PLANE, TINY_RIG

    (tmp_path / "rig.toml").write_text(TINY_RIG)
    (tmp_path / "s.toml").write_text('rig = "rig.toml"\n' + PLANE.replace("[0.0, 0.0, 1.0]", "[0.0, 0.0, 1.2]"))
    rec = simbench.record(tmp_path / "s.toml", system=ideal_system, spp=1, cache=None)
    assert np.nanmin(rec.raw) == pytest.approx(1.2, abs=0.01)


def test_bench_runs_a_registered_system(ideal_system):
    from simbench.experiments.bench import run_decode_benchmark

    res = run_decode_benchmark(repeats=2, warmup=0, device=ideal_system)
    assert res["device"] == ideal_system and res["size_wh"] == [320, 240]


@pytest.mark.slow
def test_a_fourth_system_runs_through_table3_and_the_cli(ideal_system, tmp_path, variant, capsys):
    """Done-when of the depth-systems issue: a system registered in the test alone goes through
    Table 3's scoring (beside the proposed sensor) and `simbench render/decode`."""
    from simbench.cli import main
    from simbench.experiments.common import RunConfig, Session
    from simbench.experiments.table3 import run_table3

    cfg = RunConfig.preset(quick=True, camera_scale=0.25, compare_rigs=False)
    session = Session(
        cfg, out_dir=tmp_path / "out", cache_dir=tmp_path / "cache", progress=lambda s: None, command="test"
    )
    (tmp_path / "out").mkdir()
    metrics = run_table3(session, systems=(ideal_system,))
    # a noiseless camera with the true depth: the plane fit sees only the faces' flatness
    for obj in ("cube", "cuboid"):
        assert metrics[f"table3/{obj}/{ideal_system}_gt_mae_mm"] == 0.0
        assert metrics[f"table3/{obj}/{ideal_system}_completeness"] == 1.0
        assert metrics[f"table3/{obj}/{ideal_system}_plane_mae_mm"] < 0.01
    md = (tmp_path / "out" / "table3.md").read_text()
    assert "ideal depth camera: plane fit (mm)" in md and "Kinect" not in md.split("\n\n")[3]
    rows = (tmp_path / "out" / "table3.csv").read_text().splitlines()
    assert f"{ideal_system}_mm" in rows[0] and "kinect_mm" not in rows[0]
    assert f"{ideal_system}/table3/discontinuity" in session.seeds_used

    rec = tmp_path / "rec"
    assert (
        main(
            [
                "render",
                "--system",
                ideal_system,
                str(SCENES / "discontinuity.toml"),
                "--out",
                str(rec),
                "--cache",
                str(tmp_path / "cache"),
            ]
        )
        == 0
    )
    assert json.loads((rec / "device.json").read_text())["device"] == ideal_system
    assert main(["decode", str(rec), "--out", str(tmp_path / "d.npy")]) == 0
    assert "ideal depth camera" in capsys.readouterr().out
    depth, gt = np.load(tmp_path / "d.npy"), np.load(rec / "gt_depth.npy")
    assert np.array_equal(np.isfinite(depth), np.isfinite(gt)) and np.nanmax(np.abs(depth - gt)) == 0.0


def _plugin_site(tmp_path, package: str, entry_points: str):
    """A folder for PYTHONPATH holding an installed package's dist-info: ``package`` with the
    ``simbench.systems`` entry points ``entry_points`` (lines ``name = module:attribute``)."""
    site = tmp_path / "site"
    info = site / f"{package.replace('-', '_')}-0.1.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {package}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(f"[simbench.systems]\n{entry_points}\n")
    return site


def test_an_installed_plugins_system_runs_in_a_fresh_simbench_process(tmp_path, variant):
    """docs/extending.md: a package's entry point in the group ``simbench.systems`` registers its
    system in every process - `simbench render --system NAME` in a fresh process takes it (a third
    audit: register_system alone reaches only the process that calls it, and the docs promised the
    command line).  The plugin here: a dist-info folder on PYTHONPATH naming this file's ideal
    depth camera."""
    import os
    import subprocess
    import sys

    site = _plugin_site(
        tmp_path,
        "simbench-ideal-plugin",
        "ideal_depth = tests.test_systems:IdealDepthCamera\nmy-sensor = nowhere:Nothing",
    )
    root = Path(__file__).resolve().parents[1]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), str(root)])}
    simbench = [str(Path(sys.executable).parent / "simbench")]
    run = dict(cwd=tmp_path, env=env, capture_output=True, text=True)
    r = subprocess.run(
        [*simbench, "render", "--system", "ideal_depth", str(SCENES / "white_plane.toml"), "--out", "rec"], **run
    )
    assert r.returncode == 0, r.stderr
    # a broken plugin beside it is named and left out; the rest of simbench works
    assert "depth system plugin my-sensor = 'nowhere:Nothing' of simbench-ideal-plugin ignored" in r.stderr
    assert json.loads((tmp_path / "rec" / "device.json").read_text())["device"] == "ideal_depth"
    r = subprocess.run([*simbench, "decode", "rec", "--out", "d.npy"], **run)
    assert r.returncode == 0 and "ideal depth camera" in r.stdout, r.stderr
    # without the plugin: unknown, the registered names listed
    r = subprocess.run([*simbench, "decode", "rec", "--out", "e.npy"], **{**run, "env": os.environ})
    assert r.returncode == 2 and "unknown depth system 'ideal_depth'" in r.stderr


def test_a_broken_plugin_is_named_as_the_plugins_fault_not_simbenchs(tmp_path, monkeypatch, capsys):
    """A fourth audit: a plugin that failed to import, a factory that raised, an entry point naming
    no system, or a bug inside a plugin's own method were each reported as "simbench: internal
    error ... please report it", naming neither the plugin nor its package."""
    from types import SimpleNamespace

    import simbench.systems as systems
    from simbench.cli import _report_error

    site = _plugin_site(
        tmp_path, "brk-plugins", "boom = brk_boom:Thing\nnumber = brk_parts:NUMBER\nfaulty = brk_parts:faulty"
    )
    (site / "brk_boom.py").write_text('raise RuntimeError("boom at import")\n')
    (site / "brk_parts.py").write_text(
        "NUMBER = 42\n\n\ndef faulty(options):\n    return Faulty()\n\n\n"
        "class Faulty:\n    def decode(self):\n        return {}['missing']\n"
    )
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.setattr(systems, "_SYSTEMS", dict(systems._SYSTEMS))
    monkeypatch.setattr(systems, "_PLUGINS", {})
    monkeypatch.setattr(systems, "_plugins_read", False)
    with pytest.raises(ValueError, match=r"plugin 'boom' \(brk_boom:Thing of brk-plugins\) could not be built: Runt"):
        systems.get_system("boom")
    with pytest.raises(ValueError, match=r"plugin 'number' .* TypeError: 'int' object is not callable"):
        systems.get_system("number")
    with pytest.raises(ValueError, match=r"plugin 'faulty' .* returned a Faulty, not a DepthSystem"):
        systems.get_system("faulty")
    # a failure inside the plugin's own code, met later
    import brk_parts

    try:
        brk_parts.Faulty().decode()
    except KeyError as exc:
        assert _report_error(exc, SimpleNamespace(debug=False)) == 1
    err = capsys.readouterr().err
    # (two entry points of one module: both named)
    assert err.startswith("simbench: error in the depth system plugins 'number', 'faulty' (code of brk-plugins: brk_")
    assert "report it to the plugin's authors" in err
    # simbench's own failure stays its internal error
    with pytest.raises(ValueError) as own:
        systems.get_system(None)  # type: ignore[arg-type]
    assert systems.plugin_in_traceback(own.value) is None
    # a system registered later under a plugin's name is no longer the plugin's
    systems.register_system("faulty", lambda options: 42, replace=True)
    with pytest.raises(TypeError, match="the factory of depth system 'faulty' returned a int"):
        systems.get_system("faulty")
