"""Ablation sweeps (simbench.experiments.ablate): validation, expansion, failures, resume,
process pool vs Dask LocalCluster."""

from __future__ import annotations

import csv
import json
import math
import re

import pytest

from simbench.experiments.ablate import BUILTIN_STUDIES, check_sweep, expand, load_sweep, run_sweep, sweep_from_dict

FAST_BASE = {"run.camera_scale": 0.5, "run.spp": 4, "sensor.preset": "minimal"}


def _sweep(**kw):
    data = {
        "name": "t",
        "description": "test",
        "base": dict(FAST_BASE),
        "axis": [{"name": "decoder.voting", "values": [True, False]}],
    }
    data.update(kw)
    return sweep_from_dict(data)


def test_unknown_parameters_are_rejected_with_the_valid_names():
    with pytest.raises(ValueError, match="unknown sweep parameter 'decoder.votes'.*decoder.voting"):
        _sweep(axis=[{"name": "decoder.votes", "values": [1]}])
    with pytest.raises(ValueError, match="unknown sweep parameter 'sensor.lens.f_number'"):
        _sweep(base={"sensor.lens.f_number": 2.0})
    with pytest.raises(ValueError, match="unknown key"):
        sweep_from_dict({"name": "x", "axes": []})
    with pytest.raises(ValueError, match="same number of values"):
        _sweep(
            combine="zip",
            axis=[{"name": "decoder.voting", "values": [True, False]}, {"name": "pattern.order", "values": [3]}],
        )
    with pytest.raises(ValueError, match="at least one"):
        _sweep(axis=[])


def test_grid_and_zip_expansion_with_common_seeds():
    axes = [{"name": "decoder.voting", "values": [True, False]}, {"name": "pattern.period_px", "values": [15, 21, 31]}]
    grid = expand(_sweep(axis=axes, repeats=2))
    assert len(grid) == 12
    assert len({r["key"] for r in grid}) == 12
    # repetition r has one seed across parameter sets; repetitions differ
    assert len({r["seed"] for r in grid if r["repeat"] == 0}) == 1
    assert {r["seed"] for r in grid if r["repeat"] == 0} != {r["seed"] for r in grid if r["repeat"] == 1}
    z = expand(
        _sweep(
            axis=[
                {"name": "decoder.voting", "values": [True, False]},
                {"name": "pattern.period_px", "values": [15, 21]},
            ],
            combine="zip",
        )
    )
    assert [(r["params"]["decoder.voting"], r["params"]["pattern.period_px"]) for r in z] == [(True, 15), (False, 21)]


def test_the_paper_decoders_added_checks_are_an_axis():
    """decoder.without switches the named checks off (simbench.decode.without_checks); an unknown
    name fails the sweep's check before any run."""
    from simbench.decode import PAPER_ADDED_CHECKS, DecoderParams
    from simbench.experiments.ablate.mapping import decoder_for

    assert decoder_for({"decoder.without": "none"}) == DecoderParams()
    assert decoder_for({"decoder.without": "max_residual"}).max_residual == float("inf")
    both = decoder_for({"decoder.without": ["min_support", "link_check"], "decoder.voting": False})
    assert both.min_support == 1 and not both.link_check and not both.voting
    everything = decoder_for({"decoder.without": "all"})
    for check in PAPER_ADDED_CHECKS.values():
        assert all(getattr(everything, k) == v for k, v in check.off.items())
    with pytest.raises(ValueError, match="unknown decoder check.*'colour'.*valid"):
        check_sweep(_sweep(axis=[{"name": "decoder.without", "values": ["none", "colour"]}]))


def test_subsurface_is_a_scene_axis():
    from simbench.experiments.ablate import DEFAULTS
    from simbench.experiments.ablate.mapping import scene_for

    marble = scene_for({**DEFAULTS, "scene.name": "discontinuity", "scene.subsurface": "marble"})
    assert {o.material.subsurface for o in marble.objects} == {"marble"}
    opaque = scene_for({**DEFAULTS, "scene.name": "discontinuity", "scene.subsurface": "none"})
    assert {o.material.subsurface for o in opaque.objects} == {None}
    with pytest.raises(ValueError, match="unknown subsurface medium 'chalk'"):
        check_sweep(_sweep(axis=[{"name": "scene.subsurface", "values": ["chalk"]}]))


def test_builtin_studies_load():
    """Every built-in study expands and passes the check a sweep gets before it runs (a study
    naming a value the code no longer accepts fails here, not after a make ablations)."""
    for name in BUILTIN_STUDIES:
        sweep = load_sweep(name)
        assert sweep.name == name and expand(sweep)
        check_sweep(sweep)


def _table(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.mark.slow
def test_a_value_that_cannot_run_fails_the_sweep_before_any_run(tmp_path):
    """Issue 33: an invalid value was a failed row after the other runs (exit 0, files
    written); now the whole sweep is checked first and nothing is run or written."""
    sweep = _sweep(axis=[{"name": "decoder.sigma_periods", "values": [0.25, -1.0]}])
    with pytest.raises(ValueError, match=r"sweep 't', run 1 \{'decoder.sigma_periods': -1.0\}: sigma_periods"):
        run_sweep(sweep, out_dir=tmp_path / "out", cache_dir=tmp_path / "cache", progress=lambda s: None)
    assert not (tmp_path / "out").exists() and not (tmp_path / "cache").exists()
    unknown = _sweep(axis=[{"name": "decoder.phase_method", "values": ["gabor", "hilbert"]}])
    with pytest.raises(ValueError, match="phase_method must be one of.*'wfr'.*'hilbert'|'hilbert'.*'wfr'"):
        check_sweep(unknown)


def test_failing_run_is_recorded_and_the_sweep_goes_on(tmp_path):
    """A run that fails when it runs (not a value the check could see) is a row with its
    error; the others run, and the report lists the errors."""
    from tests.ablate_helpers import fails_on_marker

    sweep = _sweep(axis=[{"name": "scene.name", "values": ["ok", "fail"]}])
    rows = run_sweep(sweep, out_dir=tmp_path, cache_dir=None, progress=lambda s: None, run_fn=fails_on_marker)
    assert rows[0]["error"] == "" and "RuntimeError: failed on purpose" in rows[1]["error"]
    assert "Errors:" in (tmp_path / "t.md").read_text()


@pytest.mark.slow
def test_phase_method_axis(tmp_path, monkeypatch, variant):
    """Every registered phase method runs through a sweep; the decoder-only axis renders the scene
    once (one capture and one reference radiance in the cache) (an unknown method is refused before
    any run: test_a_value_that_cannot_run_fails_the_sweep_before_any_run)."""
    import simbench.cache

    monkeypatch.setattr(simbench.cache, "PROGRESS_MIN_S", 0.0)  # every entry, on any machine
    sweep = _sweep(axis=[{"name": "decoder.phase_method", "values": ["gabor", "ftp", "wfr"]}])
    lines = []
    rows = run_sweep(sweep, out_dir=tmp_path, cache_dir=tmp_path / "cache", progress=lines.append)
    assert len(list((tmp_path / "cache").glob("radiance-*.npz"))) == 2
    # the first run's renders said so as they were made; the others read them from the cache
    assert any(re.fullmatch(r"\[ablate t run 0\] radiance made in \d+\.\d s \(\d+ s so far\)", x) for x in lines)
    assert not any(x.startswith("[ablate t run 1] radiance") for x in lines)
    for r in rows[:3]:
        assert (
            r["error"] == "" and r["completeness"] > 0.95 and r["stripe_order_errors"] == 0 and r["gt_mae_mm"] < 1.0
        )  # small, few-spp renders
    assert len({r["gt_mae_mm"] for r in rows[:3]}) == 3  # the axis reaches the decoder
    # both protocols, the board placed off the reference plane (same placement in every run)
    for r in rows[:3]:
        assert r["ref_completeness"] > 0.95 and r["ref_gt_mae_mm"] < 1.0 and r["ref_gt_mae_mm"] != r["gt_mae_mm"]
    assert len({r["placement_seed"] for r in rows[:3]}) == 1 and rows[0]["placement_seed"] != ""
    table = _table(tmp_path / "t.csv")
    assert {"ref_plane_mae_mm", "ref_completeness", "placement_seed"} <= set(table[0])


@pytest.mark.slow
def test_interrupted_sweep_resumes_without_redoing_runs(tmp_path, variant):
    sweep = _sweep(
        axis=[
            {"name": "decoder.voting", "values": [True, False]},
            {"name": "decoder.neighbour_reach", "values": [0, 3]},
        ]
    )
    cache = tmp_path / "cache"
    full = tmp_path / "full"
    run_sweep(sweep, out_dir=full, cache_dir=cache, progress=lambda s: None)

    part = tmp_path / "part"
    seen = []

    def stop_after_two(msg):
        seen.append(msg)
        if sum("] run " in m for m in seen) == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_sweep(sweep, out_dir=part, cache_dir=cache, progress=stop_after_two)
    # an interruption in the middle of writing leaves a cut line: that run is redone
    with open(part / "t.runs.jsonl", "a") as f:
        f.write('{"key": "cut')
    messages = []
    run_sweep(sweep, out_dir=part, cache_dir=cache, progress=messages.append)
    assert "4 runs, 2 already done, 2 to run" in messages[0]
    assert sum("] run " in m for m in messages) == 2
    assert (part / "t.csv").read_bytes() == (full / "t.csv").read_bytes()
    assert len([json.loads(x) for x in (part / "t.runs.jsonl").read_text().splitlines()[:2]]) == 2
    # the variant the runs were made with is in the provenance (the second audit: it was not)
    assert json.loads((part / "t.provenance.json").read_text())["variant"] == [variant]


@pytest.mark.slow
def test_process_pool_and_dask_local_cluster_give_identical_tables(tmp_path, variant):
    """The issue's acceptance: a two-axis sweep of 24 runs, identical tables both ways."""
    distributed = pytest.importorskip("distributed")
    sweep = _sweep(
        axis=[
            {"name": "decoder.sigma_periods", "values": [0.2, 0.25, 0.3]},
            {"name": "decoder.neighbour_reach", "values": [0, 1, 2, 3]},
        ],
        repeats=2,
    )
    assert len(expand(sweep)) == 24
    cache = tmp_path / "cache"
    run_sweep(sweep, out_dir=tmp_path / "pool", cache_dir=cache, workers=2, progress=lambda s: None)
    with (
        distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster,
        distributed.Client(cluster) as client,
    ):
        run_sweep(sweep, out_dir=tmp_path / "dask", cache_dir=cache, scheduler=client, progress=lambda s: None)
    a, b = _table(tmp_path / "pool" / "t.csv"), _table(tmp_path / "dask" / "t.csv")
    assert len(a) == 24 and a == b
    assert all(r["error"] == "" for r in a)
    assert (tmp_path / "pool" / "t.md").read_text() == (tmp_path / "dask" / "t.md").read_text()


# ------------------------------------------------------------------ dying workers


def _marker_sweep(names):
    return sweep_from_dict(
        {"name": "w", "description": "runner test", "axis": [{"name": "scene.name", "values": list(names)}]}
    )


def _run_markers(names, out_dir, run_fn, *, workers: int, variant: str | None = None) -> list[dict]:
    """The marker sweep over ``names`` run quietly with ``run_fn`` (tests/ablate_helpers.py)."""
    kw = {"variant": variant} if variant else {}
    return run_sweep(
        _marker_sweep(names),
        out_dir=out_dir,
        cache_dir=None,
        workers=workers,
        progress=lambda s: None,
        run_fn=run_fn,
        **kw,
    )


def test_a_killed_worker_costs_its_run_one_retry_and_the_table_is_complete(tmp_path, variant):
    from tests import ablate_helpers

    names = [str(tmp_path / "ok1"), str(tmp_path / "die1"), str(tmp_path / "ok2"), str(tmp_path / "ok3")]
    rows = _run_markers(names, tmp_path / "out", ablate_helpers.dies_once, workers=2, variant=variant)
    assert [r["error"] for r in rows] == ["", "", "", ""]
    assert (tmp_path / "die1").exists()  # it did die once
    _run_markers(names, tmp_path / "ref", ablate_helpers.quick_run, workers=1)
    assert (tmp_path / "out" / "w.csv").read_bytes() == (tmp_path / "ref" / "w.csv").read_bytes()


@pytest.mark.parametrize("workers", [1, 2])
def test_a_runs_own_progress_lines_reach_the_sweeps_progress(tmp_path, variant, workers):
    """A cold run renders for minutes: its lines (run_one's cache entries made) reach the sweep's
    ``progress`` from this process and from pool workers, named by the sweep and run (a new
    user's audit: a 36-spp run was silent for minutes)."""
    import os

    from tests import ablate_helpers

    lines = []
    names = [str(tmp_path / "a"), str(tmp_path / "b")]
    run_sweep(
        _marker_sweep(names), out_dir=tmp_path, cache_dir=None, workers=workers, variant=variant,
        progress=lines.append, run_fn=ablate_helpers.talking_run,
    )  # fmt: skip
    inside = sorted(x for x in lines if "inside" in x)
    assert [x.split(",")[0] for x in inside] == ["[ablate w run 0] inside", "[ablate w run 1] inside"]
    assert (str(os.getpid()) in inside[0]) == (workers == 1)


def test_a_run_that_kills_its_worker_twice_is_recorded_as_failed(tmp_path, variant):
    from simbench.experiments.ablate import WORKER_DIED
    from tests import ablate_helpers

    names = [str(tmp_path / "ok1"), str(tmp_path / "die1"), str(tmp_path / "ok2")]
    rows = _run_markers(names, tmp_path / "out", ablate_helpers.always_dies, workers=2, variant=variant)
    assert [r["error"] for r in rows] == ["", WORKER_DIED, ""]
    assert WORKER_DIED in (tmp_path / "out" / "w.md").read_text()


def _descendants(pid):
    import psutil

    try:
        return psutil.Process(pid).children(recursive=True)
    except psutil.NoSuchProcess:
        return []


def test_killing_the_sweep_leaves_no_process_behind(tmp_path):
    """kill -9 of the parent: its pool workers (and multiprocessing's resource tracker) end too."""
    import os
    import signal
    import subprocess
    import sys
    import textwrap
    import time

    import psutil

    code = textwrap.dedent(
        f"""
        import sys
        sys.path.insert(0, {str(__import__("pathlib").Path(__file__).resolve().parents[1])!r})
        from simbench.experiments.ablate import sweep_from_dict, run_sweep
        from tests import ablate_helpers
        names = [{str(tmp_path)!r} + "/started_" + n for n in "abc"]
        sweep = sweep_from_dict({{"name": "k", "axis": [{{"name": "scene.name", "values": names}}]}})
        run_sweep(sweep, out_dir={str(tmp_path / "out")!r}, cache_dir=None, workers=2, variant="scalar_rgb",
                  progress=print, run_fn=ablate_helpers.slow_run)
        """
    )
    proc = subprocess.Popen(
        [sys.executable, "-c", code], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True
    )
    try:
        deadline = time.monotonic() + 120
        kids = []
        while time.monotonic() < deadline:
            kids = _descendants(proc.pid)
            # two workers running a run each (each touched its file) plus the resource tracker
            if len(list(tmp_path.glob("started_*"))) == 2:
                break
            time.sleep(0.2)
        assert len(kids) >= 2, "the pool did not start"
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
        gone, alive = psutil.wait_procs(kids, timeout=30)
        assert not alive, [p.cmdline()[:3] for p in alive]
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


def test_board_form_and_projector_timing_are_sweepable():
    """Issue 17's new effects are axes: the boards' form (run.*) and the projector's timing
    (sensor.projector.timing, frame_rate_hz) reach the run's config and sensor."""
    from simbench.experiments.ablate.mapping import sensor_for as _sensor
    from simbench.experiments.ablate import DEFAULTS

    sw = sweep_from_dict(
        {
            "name": "t",
            "axis": [
                {"name": "run.board_bow_mm_per_m", "values": [0.0, 1.0]},
                {"name": "sensor.projector.timing", "values": ["triggered", "video"]},
            ],
        }
    )
    runs = expand(sw)
    assert {(r["params"]["run.board_bow_mm_per_m"], r["params"]["sensor.projector.timing"]) for r in runs} >= {
        (0.0, "triggered"),
        (1.0, "video"),
    }
    sensor = _sensor({**DEFAULTS, "sensor.projector.timing": "video", "sensor.projector.frame_rate_hz": 120.0})
    assert sensor.projector.timing == "video" and sensor.projector.frame_rate_hz == 120.0
    with pytest.raises(ValueError, match="timing"):
        _sensor({**DEFAULTS, "sensor.projector.timing": "free"})


def test_a_termination_inside_a_run_stops_the_sweep_instead_of_recording_a_failure(monkeypatch, tmp_path):
    """Issue 33 audit: SIGTERM raised inside a Mitsuba render comes back wrapped as a
    RuntimeError, which run_one recorded as a failed run before going on with the sweep."""
    from simbench import termination
    from simbench.experiments.ablate import run_one
    from simbench.experiments.common import Session

    def render_interrupted(self, *args, **kwargs):
        termination.request()
        raise RuntimeError("drjit.custom(<_RenderOp>): _Terminated")

    monkeypatch.setattr(Session, "capture", render_interrupted)
    params = expand(_sweep(axis=[{"name": "decoder.voting", "values": [True]}]))[0]["params"]
    try:
        with pytest.raises(RuntimeError, match="_Terminated"):
            run_one(params, seed=1, cache_dir=None)
    finally:
        termination._REQUESTED.clear()
    assert "error" in run_one({**params, "run.spp": 0}, seed=1, cache_dir=None)  # without it: a recorded failure


@pytest.mark.parametrize("signum", [15, 2], ids=["SIGTERM", "Ctrl-C"])
def test_a_termination_stops_a_whole_sweep_and_its_runs_are_redone(monkeypatch, tmp_path, signum):
    """A new user's audit: `ablate` (one worker) went on after Ctrl-C and SIGTERM - the worker
    layer recorded the re-raised, re-wrapped error as a failed run - and a restart counted the
    failed runs as done.  Now the sweep stops, and a failed run is run again by the next start."""
    import json

    from simbench import termination
    from simbench.experiments.ablate import execute

    sw = _sweep(axis=[{"name": "decoder.voting", "values": [True, False]}])
    calls = []

    def interrupted(params, *, seed, cache_dir, label=""):
        calls.append(params)
        termination.request(signum)
        raise RuntimeError("drjit.custom(<_RenderOp>): KeyboardInterrupt")

    try:
        with pytest.raises(RuntimeError, match="KeyboardInterrupt"):
            execute.run_sweep(sw, out_dir=tmp_path, cache_dir=None, run_fn=interrupted)
    finally:
        termination._REQUESTED.clear()
    assert len(calls) == 1 and not (tmp_path / f"{sw.name}.runs.jsonl").exists()
    # a failed run's record (as the old code wrote) is not a finished run
    runs = expand(sw)
    (tmp_path / f"{sw.name}.runs.jsonl").write_text(json.dumps({"key": runs[0]["key"], "run": 0, "error": "x"}) + "\n")
    assert set(execute._load_done(tmp_path / f"{sw.name}.runs.jsonl")) == set()


def test_speed_is_an_axis():
    """Issue 37's ablation axis: scene.speed_m_s moves the first object (scene.motion: lateral or
    axial), validated; speed 0 is the static scene, its cache keys unchanged."""
    from simbench.experiments.ablate.mapping import scene_for
    from simbench.sim.scene import scene_fingerprint

    still = scene_for({"scene.name": "motion_board"})
    assert scene_fingerprint(scene_for({"scene.name": "motion_board", "scene.speed_m_s": 0.0})) == scene_fingerprint(
        still
    )
    axial = scene_for({"scene.name": "motion_board", "scene.speed_m_s": 0.5, "scene.motion": "axial"})
    assert axial.objects[0].motion.velocity_m_s == (0.0, 0.0, -0.5) and axial.objects[1].motion is None
    lateral = scene_for({"scene.name": "motion_board", "scene.speed_m_s": 0.2})
    assert lateral.objects[0].motion.velocity_m_s == (0.2, 0.0, 0.0)
    away = scene_for({"scene.name": "motion_board", "scene.speed_m_s": -0.3, "scene.motion": "axial"})
    assert away.objects[0].motion.velocity_m_s == (-0.0, -0.0, 0.3)  # a negative speed: the other way
    for bad, match in (
        ({"scene.speed_m_s": -60.0}, "scene.speed_m_s must be a finite number in"),
        ({"scene.speed_m_s": math.nan}, "scene.speed_m_s must be a finite number in"),
        ({"scene.speed_m_s": 0.1, "scene.motion": "up"}, "scene.motion must be one of"),
        ({"scene.motion": "sideways"}, "scene.motion must be one of"),
        # a third new user's audit: a direction without a speed moved nothing, without a word
        ({"scene.motion": "axial"}, "scene.motion gives the direction of scene.speed_m_s"),
    ):
        with pytest.raises(ValueError, match=match):
            scene_for({"scene.name": "motion_board", **bad})
    sweep = sweep_from_dict({"name": "speed", "axis": [{"name": "scene.speed_m_s", "values": [0.0, 0.3]}]})
    assert [r["params"]["scene.speed_m_s"] for r in expand(sweep)] == [0.0, 0.3]


def test_spin_is_an_axis_and_keeps_the_translation():
    """scene.spin_deg_s turns the first object about the vertical axis through it (0: not turning),
    with a speed's translation kept; validated."""
    from simbench.experiments.ablate.mapping import scene_for
    from simbench.sim.scene import scene_fingerprint

    still = scene_for({"scene.name": "motion_board"})
    assert scene_fingerprint(scene_for({"scene.name": "motion_board", "scene.spin_deg_s": 0.0})) == scene_fingerprint(
        still
    )
    both = scene_for({"scene.name": "motion_board", "scene.speed_m_s": 0.2, "scene.spin_deg_s": -90.0})
    m = both.objects[0].motion
    assert m.velocity_m_s == (0.2, 0.0, 0.0) and m.angular_velocity_deg_s == -90.0 and m.axis == (0.0, 1.0, 0.0)
    assert m.centre_m is None  # about the object's own position
    with pytest.raises(ValueError, match="scene.spin_deg_s must be a finite number in"):
        scene_for({"scene.name": "motion_board", "scene.spin_deg_s": 1e6})


def test_a_speed_sets_the_velocity_of_a_scene_files_own_motion(tmp_path):
    """A scene file whose object moves and turns: speed 0 stops its translation (a sweep's still
    row is still - an audit found it moving with the file's velocity) and keeps its rotation;
    another speed replaces the velocity and keeps the rotation too."""
    from simbench.experiments.ablate.mapping import scene_for

    path = tmp_path / "turning.toml"
    path.write_text(
        """name = "turning"
[[object]]
type = "box"
name = "box"
center_m = [0.0, 0.0, 1.0]
size_m = [0.1, 0.1, 0.1]
velocity_m_s = [0.5, 0.0, 0.0]
angular_velocity_deg_s = 200.0

[[object]]
type = "plane"
name = "wall"
center_m = [0.0, 0.0, 1.3]
size_m = [2.0, 2.0]
"""
    )
    file_motion = scene_for({"scene.name": str(path)}).objects[0].motion
    assert file_motion.velocity_m_s == (0.5, 0.0, 0.0) and file_motion.angular_velocity_deg_s == 200.0
    still = scene_for({"scene.name": str(path), "scene.speed_m_s": 0.0}).objects[0].motion
    assert still.velocity_m_s == (0.0, 0.0, 0.0) and still.angular_velocity_deg_s == 200.0
    fast = scene_for({"scene.name": str(path), "scene.speed_m_s": 0.2, "scene.motion": "axial"}).objects[0].motion
    assert fast.velocity_m_s == (0.0, 0.0, -0.2) and fast.angular_velocity_deg_s == 200.0
    assert fast.axis == file_motion.axis


def test_the_documented_sweep_file_loads_as_written(tmp_path):
    """The module's example sweep (docs/ablations.md points to it) parses as written; a sweep key
    written after an [[axis]] table - TOML makes it the axis's - is named in the error (the audit
    copied an example that did so and got 'needs exactly name and values')."""
    import textwrap

    import simbench.experiments.ablate as ablate

    doc = ablate.__doc__
    example = textwrap.dedent(doc.split("A sweep file (TOML)::", 1)[1].split("\nParameters", 1)[0])
    (tmp_path / "doc.toml").write_text(example)
    sweep = load_sweep(tmp_path / "doc.toml")
    assert sweep.combine == "grid" and len(expand(sweep)) == 5 * 2 * sweep.repeats  # runs: the grid, each repeated
    late = example.replace('combine = "grid"', "") + '\ncombine = "zip"\n'
    (tmp_path / "late.toml").write_text(late)
    with pytest.raises(ValueError, match=r"axis 2 holds \['combine'\] beside 'name' and 'values'"):
        load_sweep(tmp_path / "late.toml")


def test_a_runs_log_key_covers_the_files_its_values_name(tmp_path):
    """A second new user's audit: a resumed sweep kept its runs' results after the sensor file
    they name was changed (read noise 10 -> 400 e-: GT MAE 0.2486 mm kept, 0.5332 fresh)."""
    from simbench.experiments.ablate.execute import _named_files_digest
    from simbench.sim.sensor import PRESETS_DIR

    sensor = tmp_path / "mine.toml"
    sensor.write_text((PRESETS_DIR / "minimal.toml").read_text())
    params = {"sensor.preset": str(sensor), "scene.name": "white_plane"}
    before = _named_files_digest(params)
    assert len(before) == 8 and before == _named_files_digest(dict(params))
    sensor.write_text(sensor.read_text() + "\n# read noise changed\n")
    assert _named_files_digest(params) != before
    assert _named_files_digest({"sensor.preset": "minimal"}) != _named_files_digest({"sensor.preset": "paper"})
    assert _named_files_digest({"decoder.voting": True}) == ""
    # the file its sensor.effects take their values from too (a third audit: a resume after the
    # source file's dark noise went 20 -> 200 e- kept GT MAE 0.3647 mm, 0.4821 fresh)
    source = {"sensor.source": str(sensor), "sensor.effects": ["noise"], "scene.name": "white_plane"}
    before = _named_files_digest(source)
    sensor.write_text(sensor.read_text() + "\n# dark noise changed\n")
    assert _named_files_digest(source) != before


def test_a_pattern_axis_takes_whole_numbers_only():
    """A third new user's audit: pattern.period_px = 21.9 ran as 21 (cast), and the table said
    21.9; a string "21" passed too.  They are refused as `render --period 21.7` refuses them."""
    from simbench.experiments.ablate.mapping import decoder_for

    assert decoder_for({"pattern.period_px": 22.0}).pattern.period_px == 22
    for bad in (21.9, "21", True):
        with pytest.raises(ValueError, match="pattern.period_px must be an integer"):
            decoder_for({"pattern.period_px": bad})
    with pytest.raises(ValueError, match="pattern.order must be an integer"):
        decoder_for({"pattern.order": 3.7})
    with pytest.raises(ValueError, match="pattern.channels must be a string"):
        decoder_for({"pattern.channels": 3})


def test_builtin_runs_every_built_in_study_and_the_files_named_beside_it(tmp_path, monkeypatch):
    """`ablate builtin mine.toml`: every built-in study, then the file's (a second audit: 'builtin'
    was read as a file of that name unless it stood alone)."""
    import simbench.experiments.ablate as ablate
    from simbench.cli import main

    (tmp_path / "mine.toml").write_text('name = "mine"\n[[axis]]\nname = "decoder.voting"\nvalues = [true, false]\n')
    ran = []
    monkeypatch.setattr(ablate, "run_sweep", lambda sweep, **kw: ran.append(sweep.name) or [])
    monkeypatch.setattr("simbench.variant.select_variant", lambda v: None)
    assert main(["ablate", "builtin", str(tmp_path / "mine.toml"), "--out", str(tmp_path / "out")]) == 0
    assert ran == [*BUILTIN_STUDIES, "mine"]


def test_an_interrupt_while_the_report_is_made_leaves_the_previous_set_whole(tmp_path, monkeypatch):
    """A new user's audit: Ctrl-C while a rerun's report was written left its table and Markdown
    beside the previous run's provenance (whose hash of the table then failed).  The set is now
    written all or nothing."""
    import hashlib

    from simbench.experiments.ablate import report
    from tests.ablate_helpers import quick_run

    run_sweep(_sweep(seed=6), out_dir=tmp_path, cache_dir=None, progress=lambda s: None, run_fn=quick_run)
    before = {p.name: p.read_bytes() for p in tmp_path.glob("t.*") if not p.name.endswith(".jsonl")}
    assert set(before) == {"t.csv", "t.timings.csv", "t.md", "t.png", "t.pdf", "t.provenance.json"}

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(report, "_plot", interrupted)  # the table and the Markdown are made by then
    with pytest.raises(KeyboardInterrupt):
        run_sweep(_sweep(seed=3), out_dir=tmp_path, cache_dir=None, progress=lambda s: None, run_fn=quick_run)
    after = {p.name: p.read_bytes() for p in tmp_path.glob("t.*") if not p.name.endswith(".jsonl")}
    assert after == before
    hashes = json.loads(before["t.provenance.json"])["files"]
    assert hashes == {n: hashlib.sha256(before[n]).hexdigest() for n in hashes} and "t.csv" in hashes
    assert not list(tmp_path.glob(".*.tmp"))


def test_the_plot_draws_combinations_with_the_same_values_as_one_line_naming_them_all():
    """A factor that changes nothing (here decoder.voting) gives one line per value of the others,
    labelled with every combination it stands for; a combination that differs stays a line of
    its own (the design_choices study drew eight lines on top of each other, two visible)."""
    from simbench.experiments.ablate.report import plot_series

    sweep = _sweep(
        axis=[
            {"name": "decoder.intensity_mode", "values": ["overlay", "blue"]},
            {"name": "decoder.voting", "values": [True, False]},
            {"name": "scene.name", "values": ["plane_white", "plane_pink", "plane_red"]},
        ]
    )
    mae = {("overlay", "plane_white"): 0.4, ("blue", "plane_white"): 1.0, ("overlay", "plane_pink"): 1.1}
    mae |= {("blue", "plane_pink"): 0.38, ("overlay", "plane_red"): 0.5, ("blue", "plane_red"): 0.6}
    rows = []
    for mode in ("overlay", "blue"):
        for voting in ("on", "off"):
            for name in ("plane_white", "plane_pink", "plane_red"):
                for rep in range(2):
                    value = mae[mode, name] + 0.01 * rep
                    if name == "plane_red" and voting == "off":
                        value += 0.1  # voting matters on this one
                    row = {"decoder.intensity_mode": mode, "decoder.voting": voting, "scene.name": name}
                    rows.append({**row, "repeat": rep, "error": "", "gt_mae_mm": value})
    x_vals, lines = plot_series(sweep, rows)
    assert x_vals == ["overlay", "blue"]
    labels = [label for label, *_ in lines]
    assert labels == [
        "voting=on|off, name=plane_white (2 sets, the same values)",
        "voting=on|off, name=plane_pink (2 sets, the same values)",
        "voting=on, name=plane_red",
        "voting=off, name=plane_red",
    ], labels
    _, mean, lo, hi = lines[0]
    assert (
        mean == pytest.approx([0.405, 1.005]) and lo == pytest.approx([0.4, 1.0]) and hi == pytest.approx([0.41, 1.01])
    )


def test_a_resume_reuses_only_the_runs_its_own_code_made(tmp_path, monkeypatch):
    """Until 2026-11-30 a resumed sweep kept every finished run whatever code had made it (the
    built-in studies' logs predated a decoder change that moved the paper sensor's results) and
    wrote the sweep's provenance with the new commit.  Runs of another code digest, or logged
    before the digest was kept, run again and the line says why; the provenance names the code."""
    from simbench.experiments.ablate import execute
    from tests.ablate_helpers import quick_run

    sweep = _sweep(seed=7)
    messages = []
    run_sweep(sweep, out_dir=tmp_path, cache_dir=None, progress=messages.append, run_fn=quick_run)
    log = tmp_path / "t.runs.jsonl"
    code = execute.code_digest()
    assert [json.loads(x)["code"] for x in log.read_text().splitlines()] == [code, code]
    assert json.loads((tmp_path / "t.provenance.json").read_text())["code"] == [code]
    messages.clear()
    run_sweep(sweep, out_dir=tmp_path, cache_dir=None, progress=messages.append, run_fn=quick_run)
    assert "2 runs, 2 already done, 0 to run" in messages[0] and "another version" not in messages[0]
    # another version of the code
    monkeypatch.setattr(execute, "code_digest", lambda: "0123456789abcdef")
    messages.clear()
    run_sweep(sweep, out_dir=tmp_path, cache_dir=None, progress=messages.append, run_fn=quick_run)
    assert "2 runs, 0 already done, 2 to run (2 of them finished by another version of simbench's code" in messages[0]
    assert json.loads((tmp_path / "t.provenance.json").read_text())["code"] == ["0123456789abcdef"]
    # a log from before the digest was kept
    monkeypatch.undo()
    recs = [json.loads(x) for x in log.read_text().splitlines()]
    log.write_text("".join(json.dumps({k: v for k, v in r.items() if k != "code"}) + "\n" for r in recs))
    messages.clear()
    run_sweep(sweep, out_dir=tmp_path, cache_dir=None, progress=messages.append, run_fn=quick_run)
    assert "0 already done, 2 to run (2 of them" in messages[0]
    # the code digest follows every module of the package
    assert len(code) == 16 and code == execute.code_digest()


def test_a_sweep_takes_a_scene_of_ones_own_by_its_path_and_its_key_follows_the_mesh_it_names(tmp_path, monkeypatch):
    """A new user's audit (2026-11-30): `scene.name` took only a scene of scenes/ (a researcher's
    own scene could not be swept without copying it into the checkout), and a resume after the
    mesh a scene names changed kept the old mesh's results (the key hashed the scene file alone)."""
    import shutil

    from simbench.experiments.ablate.execute import _named_files_digest
    from simbench.experiments.ablate.mapping import scene_for

    from .conftest import ROOT

    shutil.copy(ROOT / "scenes" / "meshes" / "cone.ply", tmp_path / "blob.ply")
    (tmp_path / "mine.toml").write_text(
        'rig = "paper"\nreference_depth_m = 1.0\n[[object]]\ntype = "mesh"\nname = "blob"\nfile = "blob.ply"\n'
        "translate_m = [0.0, 0.0, 1.0]\nrgb = [0.8, 0.8, 0.8]\n"
    )
    monkeypatch.chdir(tmp_path)
    for value in ("mine.toml", str(tmp_path / "mine.toml")):
        params = {"scene.name": value}
        assert [o.name for o in scene_for(params).objects] == ["blob"]
    params = {"scene.name": "mine.toml"}
    before = _named_files_digest(params)
    shutil.copy(ROOT / "scenes" / "meshes" / "pear.ply", tmp_path / "blob.ply")  # the mesh, not the scene file
    assert _named_files_digest(params) != before
    with pytest.raises(ValueError, match="no scene file 'other.toml'"):
        scene_for({"scene.name": "other.toml"})
    with pytest.raises(ValueError, match="not a name of scenes/"):
        scene_for({"scene.name": "white plane"})
    # a sweep naming it runs: the values are checked before the first run
    check_sweep(_sweep(base={**FAST_BASE, "scene.name": "mine.toml"}))


def test_ablate_exits_1_when_a_run_failed(tmp_path, monkeypatch, capsys):
    """A third new user's audit: every run failing still exited 0 behind a table of n/a; the
    tables are written, and the exit status says that runs failed (a rerun retries them)."""
    import simbench.experiments.ablate as ablate_module

    from simbench.cli import main

    study = tmp_path / "s.toml"
    study.write_text('name = "s"\n[base]\n"run.spp" = 4\n[[axis]]\nname = "decoder.voting"\nvalues = [true, false]\n')

    def rows(failing):
        def run(sweep, **kw):
            return [{"decoder.voting": v, "error": "ValueError: x" if v in failing else ""} for v in (True, False)]

        return run

    monkeypatch.setattr(ablate_module, "run_sweep", rows({False}))
    assert main(["ablate", str(study), "--out", str(tmp_path / "o"), "--no-cache"]) == 1
    assert "1 run(s) failed" in capsys.readouterr().err
    monkeypatch.setattr(ablate_module, "run_sweep", rows(set()))
    assert main(["ablate", str(study), "--out", str(tmp_path / "o"), "--no-cache"]) == 0
    # one sweep command at a time into a folder (the same audit: two at once each did every run, and
    # the run log held each twice)
    from simbench.io import claim_output

    with claim_output(tmp_path / "o"):
        assert main(["ablate", str(study), "--out", str(tmp_path / "o"), "--no-cache"]) == 2
    assert "another process is writing it now" in capsys.readouterr().err


def test_the_table_says_n_a_where_a_metric_was_not_measured():
    """A plane fit of a scene that is not a plane is NaN (metrics.score_depth): the sweep's table
    says n/a there, not 'nan', and says what n/a means; measured values print as numbers."""
    from simbench.experiments.ablate.report import _markdown

    sweep = _sweep(axis=[{"name": "scene.name", "values": ["step", "plane_white"]}])
    keys = ("plane_mae_mm", "gt_mae_mm", "gt_rmse_mm", "gt_p95_mm", "edge5_mae_mm", "outlier_share")
    keys += ("completeness", "stripe_order_errors", "ref_plane_mae_mm", "ref_gt_mae_mm", "ref_completeness")
    rows = []
    for name, plane in (("step", float("nan")), ("plane_white", 0.4125)):
        rec = {k: 0.5 for k in keys} | {"plane_mae_mm": plane, "ref_plane_mae_mm": plane}
        rows.append({"scene.name": name, "repeat": 0, "error": "", **rec})
    text = _markdown(sweep, rows, "simbench ablate x.toml")
    step = next(line for line in text.splitlines() if line.startswith("| step"))
    white = next(line for line in text.splitlines() if line.startswith("| plane_white"))
    assert "nan" not in text
    assert step.split("|")[2].strip() == "n/a" and step.split("|")[10].strip() == "n/a", step
    assert white.split("|")[2].strip() == "0.4125", white
    assert "`n/a`: not measured" in text


@pytest.mark.slow
def test_a_run_records_what_the_decoder_says_of_the_pattern_on_the_rig(tmp_path, variant):
    """A code cycle shorter than the working range's disparity (period 8: 64 projector px against
    158) gets `simbench decode`'s warning in the run's row, the CSV and the table, beside the
    numbers it explains (a pattern designer's audit: a period-8 run's 113 mm MAE came without a
    word); the paper's pattern gets none."""
    sweep = _sweep(axis=[{"name": "pattern.period_px", "values": [8, 21]}])
    rows = run_sweep(sweep, out_dir=tmp_path, cache_dir=tmp_path / "cache", progress=lambda s: None)
    fine, paper = rows
    assert fine["error"] == "" and paper["error"] == ""
    assert (
        fine["warnings"].startswith("the pattern's code repeats every 64 projector px")
        and "whole cycle off" in (fine["warnings"])
    )
    assert paper["warnings"] == ""
    table = _table(tmp_path / "t.csv")
    assert table[0]["warnings"] == fine["warnings"] and table[1]["warnings"] == ""
    text = (tmp_path / "t.md").read_text()
    assert "Warnings (the decoder's checks of the pattern on the rig" in text and "what the recording shows" in text
    assert "- `pattern.period_px = 8`: the pattern's code repeats" in text and "`pattern.period_px = 21`" not in text
    # and what the recording shows (a third new user's audit: a board at 1.9 m, past the working
    # range, tabled a 0.147 mm plane fit - every pixel a code cycle off - under an empty warnings column)
    far = _sweep(axis=[{"name": "scene.depth_m", "values": [1.9]}])
    (row,) = run_sweep(far, out_dir=tmp_path / "far", cache_dir=tmp_path / "cache", progress=lambda s: None)
    assert "of the lit pixels lie outside the decoder's working range 0.75-1.75 m" in row["warnings"], row["warnings"]


def test_the_plot_says_its_axes_in_words_with_units():
    """A figure audit (2026-11-30): the ablation plots' axes read raw keys ('gt_mae_mm',
    'pattern.order'), completeness was drawn as 0-1 and categories were joined by lines.  The axes
    say what they are, with units (shares as %), and the parameter's key beside its words."""
    from simbench.experiments.ablate.report import axis_words, metric_words

    assert metric_words("gt_mae_mm") == ("depth error against ground truth, MAE (mm), triangulation", 1.0)
    assert metric_words("ref_completeness") == ("completeness (% of the lit pixels), reference plane", 100.0)
    assert metric_words("outlier_share")[1] == 100.0
    assert axis_words("pattern.period_px") == "fringe period T (projector px) [pattern.period_px]"
    assert axis_words("sensor.camera.dark_noise_e") == "sensor.camera.dark_noise_e"  # (its key holds its unit)
    # a decoder field in its own docstring's words (a new user's audit: decoder axes read the bare key)
    assert axis_words("decoder.voting") == "Majority vote of codes per stripe (paper Sec. 5.2) [decoder.voting]"
    assert (
        axis_words("decoder.sigma_periods") == "Gabor envelope sigma along x in fringe periods [decoder.sigma_periods]"
    )
    assert axis_words("decoder.no_such_field") == "decoder.no_such_field"
