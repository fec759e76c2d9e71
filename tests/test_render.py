"""Render tier: full-resolution Mitsuba captures of the pipeline scenes, decoded and scored."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from simbench.decode import DecoderParams, decode
from simbench.pattern import PatternSpec, fringe_pattern, quantize
from simbench.sim.truth import ground_truth
from simbench.sim.mitsuba_dict import DEFAULT_SAMPLER, DEFAULT_SPP, mitsuba_scene
from simbench.sim.render import render_radiance
from simbench.rig import Intrinsics, Rig, scale_camera
from simbench.sim.scene import scene_from_dict
from simbench.sim.projector import transfer_curve
from tests.scoring import acquisition_scores

pytestmark = pytest.mark.slow


def test_white_plane_acceptance(acquisitions):
    """Issue 2: MAE <= 0.3 mm, completeness >= 99 %, no stripe-order error (16 spp, noise on)."""
    acq = acquisitions("white_plane")
    r = decode(acq.capture, rig=acq.scene.rig, params=DecoderParams(), reference=acq.reference)
    m = acquisition_scores(acq, r, band_px=0)
    assert m["gt_mae_mm"] <= 0.3
    assert m["completeness"] >= 0.99
    assert m["stripe_order_errors"] == 0


@pytest.mark.parametrize("name", ["tilted_plane", "sphere", "step"])
def test_shapes_acceptance(acquisitions, name):
    """Issue 2: completeness >= 95 %, order errors <= 0.5 %, MAE <= 1 mm outside a 5-px edge band."""
    acq = acquisitions(name)
    r = decode(acq.capture, rig=acq.scene.rig, params=DecoderParams(), reference=acq.reference)
    m = acquisition_scores(acq, r, band_px=5)
    assert m["completeness"] >= 0.95
    assert m["stripe_order_error_rate"] <= 0.005
    assert m["gt_mae_mm"] <= 1.0


def test_calibrated_mode_on_the_step(acquisitions):
    acq = acquisitions("step")
    r = decode(acq.capture, rig=acq.scene.rig, params=DecoderParams(mode="calibrated"))
    m = acquisition_scores(acq, r, band_px=5)
    assert m["completeness"] >= 0.95 and m["gt_mae_mm"] <= 1.0 and m["stripe_order_error_rate"] <= 0.005


def test_ground_truth_of_a_plane_is_z_depth_and_column(variant, acquisitions):
    acq = acquisitions("white_plane")
    gt = acq.gt
    assert np.allclose(gt.depth_m, 1.0, atol=1e-6)  # z-depth, not ray distance
    rig = acq.scene.rig
    u = np.arange(1280)
    expect = (
        rig.projector.focal_px / rig.camera.focal_px * (u - rig.camera.cx_px)
        - rig.projector.focal_px * 0.093
        + rig.projector.cx_px
    )
    assert np.allclose(gt.column_px[100], expect, atol=1e-3)
    assert gt.lit.all() and (gt.object_id == 0).all()


def test_step_shadow_is_marked_unlit(acquisitions):
    gt = acquisitions("step").gt
    # the near half-plane's edge shadows the far plane between x = -0.0207 m and 0 at z = 1.1 m
    row = gt.lit[480]
    assert not row[600:636].any() and row[560:590].all() and row[650:].all()
    assert set(np.unique(gt.object_id)) == {0, 1}


@pytest.mark.parametrize("spp, camera_scale", [(4, 1.0), (DEFAULT_SPP, 0.5), (DEFAULT_SPP, 0.125)])
def test_render_is_bit_identical_for_a_seed(variant, spp, camera_scale):
    """Also at the run's 36 spp, where in one pass Dr.Jit's work units split pixels' samples
    between threads (18-81 values of a plane differed between renders before the passes, at full
    resolution; this scene in one pass: 161-188 values at 1280x960, 22-26 at 640x480 - so the
    half-size film, a quarter of the time, still shows that failure), and on a small film
    (160x120, the ToF camera's size), which Dr.Jit added into through per-thread copies (most
    values differed between renders in passes before atomic_film_adds)."""
    scene = scene_from_dict(
        {
            "object": [
                {"type": "plane", "center_m": [0, 0, 1.2], "size_m": [3, 3]},
                {"type": "sphere", "center_m": [0, 0, 1], "radius_m": 0.2},
            ]
        }
    )
    scene = dataclasses.replace(scene, rig=scale_camera(scene.rig, camera_scale))
    drive = transfer_curve(quantize(fringe_pattern(PatternSpec())), transfer="linear")
    kw = {"spp": spp, "sampler": DEFAULT_SAMPLER}
    a, b, c = (render_radiance(scene, drive, seed=3, **kw) for _ in range(3))
    assert np.array_equal(a, b) and np.array_equal(a, c)
    assert not np.array_equal(a, render_radiance(scene, drive, seed=4, **kw))


@pytest.mark.parametrize("camera_scale", [0.5, 0.125])
def test_render_is_the_same_bits_on_any_number_of_render_threads(variant, camera_scale):
    """The worker pools give each process its share of the cores (simbench.threads.cores_shared:
    Dr.Jit's pool sized to cores // workers); that must not change a render, so that a run on 16
    workers of a 16-core machine gives a 2-core run's bits.  Dr.Jit's work units depend on the
    thread count for small wavefronts (simbench.sim.mitsuba_dict); the passes keep each pixel's
    samples in one unit whatever it is.  (An image rendered without the passes, 640x480 at
    36 spp, differed between 1, 2 and 16 threads and between reruns on 2: measured 2026-11-27.)"""
    import drjit as dr

    scene = scene_from_dict({"object": [{"type": "plane", "center_m": [0, 0, 1.2], "size_m": [3, 3]}]})
    scene = dataclasses.replace(scene, rig=scale_camera(scene.rig, camera_scale))
    drive = transfer_curve(quantize(fringe_pattern(PatternSpec())), transfer="linear")
    before = dr.thread_count()
    images = []
    try:
        for n in (1, 3, 16):
            dr.set_thread_count(n)
            images.append(render_radiance(scene, drive, seed=3, spp=DEFAULT_SPP, sampler=DEFAULT_SAMPLER))
    finally:
        dr.set_thread_count(before)
    assert all(np.array_equal(images[0], other) for other in images[1:])


_GLOSSY_RENDER = """
import ctypes, hashlib, os, sys
from simbench.variant import select_variant
if not select_variant().startswith("llvm_"):
    print("skip: not an LLVM variant"); sys.exit(0)
import dataclasses
import drjit as dr
if sys.argv[1] == "avx2":
    core = ctypes.CDLL(os.path.join(os.path.dirname(dr.__file__), "libdrjit-core.so"))
    try:
        set_target = core._Z19jit_llvm_set_targetPKcS0_j  # jit_llvm_set_target(cpu, features, width)
    except AttributeError:
        print("skip: this Dr.Jit has no jit_llvm_set_target"); sys.exit(0)
    set_target(b"haswell", b"+avx,+avx2,+fma,+f16c,+sse4.2,+popcnt,+bmi,+bmi2,+lzcnt,+movbe", 16)
from simbench.pattern import PatternSpec, fringe_pattern, quantize
from simbench.rig import scale_camera
from simbench.sim.projector import transfer_curve
from simbench.sim.render import render_radiance
from simbench.sim.scene import scene_from_dict
scene = scene_from_dict({"object": [
    {"type": "sphere", "center_m": [0, 0, 1.0], "radius_m": 0.15, "material": "plastic", "roughness": 0.08},
    {"type": "box", "center_m": [0.2, 0.1, 1.1], "size_m": [0.15, 0.15, 0.15], "material": "metal", "roughness": 0.2},
    {"type": "plane", "center_m": [0, 0, 1.3], "size_m": [3, 3]}]})
scene = dataclasses.replace(scene, rig=scale_camera(scene.rig, 0.125))
drive = transfer_curve(quantize(fringe_pattern(PatternSpec())), transfer="linear")
out = {}
if sys.argv[1] == "thread":  # as a pool's parent runs its tasks: Dr.Jit's flags are per thread
    import threading
    worker = threading.Thread(target=lambda: out.update(img=render_radiance(scene, drive, seed=5, spp=16, max_depth=4)))
    worker.start()
    worker.join()
else:
    out["img"] = render_radiance(scene, drive, seed=5, spp=16, max_depth=4)
print(hashlib.sha256(out["img"].tobytes()).hexdigest())
"""


def test_render_is_the_same_bits_with_avx2_as_with_avx512():
    """Renders must not depend on which x86 CPU makes them, nor on the thread that makes them
    (simbench.sim.mitsuba_dict.jit_arithmetic): a glossy scene (plastic and metal: normalised
    half vectors) rendered with Dr.Jit's kernels compiled for AVX2 alone gives the bits of the
    host's own instruction set at the same vector width, and so does a render on another thread.
    With Dr.Jit's fast math the kernels call AVX-512's reciprocal-square-root estimate (vendor
    bits; an Intel and an AMD CPU rendered these scenes differently), which an AVX2 target cannot
    even compile; and fast math switched off at start-up held for the main thread only (a pool's
    parent renders on another: its renders were fast math's until this test).  Each render in a
    fresh process: the target is process-wide."""
    import subprocess
    import sys

    cpuinfo = Path("/proc/cpuinfo")
    flags = cpuinfo.read_text() if cpuinfo.exists() else ""
    if " avx2" not in flags:
        pytest.skip("needs an x86 CPU with AVX2")
    out = {}
    for target in ("host", "avx2", "thread"):
        res = subprocess.run(
            [sys.executable, "-c", _GLOSSY_RENDER, target], capture_output=True, text=True, timeout=600
        )
        assert res.returncode == 0, f"{target}: exit {res.returncode}: {res.stderr[-2000:]}"
        line = res.stdout.strip().splitlines()[-1]
        if line.startswith("skip:"):
            pytest.skip(line[6:])
        out[target] = line
    assert out["host"] == out["avx2"] == out["thread"]


def test_inverse_square_falloff(variant):
    """Radiance of a white plane lit by a uniform projector falls as 1/z^2 (on axis: exactly)."""
    drive = np.ones((1140, 1824, 3), np.float32)
    vals = []
    for z in (0.8, 1.6):
        s = scene_from_dict({"object": [{"type": "plane", "center_m": [0, 0, z], "size_m": [4, 4], "rgb": [1, 1, 1]}]})
        vals.append(render_radiance(s, drive, spp=4, seed=0, max_depth=2)[470:490, 630:650].mean())
    assert vals[0] / vals[1] == pytest.approx(4.0, rel=1e-3)
    assert vals[0] == pytest.approx(1 / 0.8**2, rel=1e-3)  # albedo 1, pattern 1, scale 1


def test_off_centre_principal_points(variant):
    """Camera and projector principal points away from the image centre: the render and the
    ground truth agree, and the decoder (calibrated mode) recovers the projector column."""
    rig = Rig(
        Intrinsics(640, 480, 1156.266, 300.25, 250.5),
        Intrinsics(912, 570, 1114.0, 480.5, 270.0),
        (0.093, 0, 0),
        (0, 0, 0),
    )
    scene = scene_from_dict({"object": [{"type": "plane", "center_m": [0, 0, 1.0], "size_m": [2, 2]}]})
    scene = dataclasses.replace(scene, rig=rig)
    spec = PatternSpec(size_hw=(570, 912))
    drive = transfer_curve(quantize(fringe_pattern(spec)), transfer="linear")
    _, realised = mitsuba_scene(scene, drive, spp=1, max_depth=1)
    assert realised == rig  # both offsets lie on the half-pixel grid: no snapping
    rad = render_radiance(scene, drive, spp=16, seed=1)
    gt = ground_truth(scene)
    img = np.clip(np.rint(rad * 0.8 * 255), 0, 255).astype(np.uint8)
    r = decode(img, rig=rig, params=DecoderParams(mode="calibrated"))
    ok = r.valid & gt.lit
    assert ok.mean() > 0.9
    err = r.column_px[ok] - gt.column_px[ok]
    assert np.sqrt(np.mean(err**2)) < 0.05


def test_box_mesh_and_ambient(variant, tmp_path):
    """Every object kind renders and has exact ground truth; ambient light lifts shadows."""
    import trimesh

    trimesh.creation.icosphere(subdivisions=4, radius=1.0).export(tmp_path / "ball.ply")
    data = {
        "object": [
            {
                "type": "box",
                "name": "box",
                "center_m": [-0.12, 0, 1.0],
                "size_m": [0.1, 0.1, 0.1],
                "rotation_deg": [0, 0, 0],
            },
            {"type": "mesh", "name": "ball", "file": "ball.ply", "scale": 0.06, "translate_m": [0.12, 0, 1.0]},
            {"type": "plane", "name": "wall", "center_m": [0, 0, 1.3], "size_m": [2, 2]},
        ],
    }
    scene = scene_from_dict(data, base_dir=tmp_path)
    gt = ground_truth(scene)
    ids = gt.object_id
    assert set(np.unique(ids)) == {0, 1, 2}
    # the box's front face is at z = 1.0 - 0.05; the mesh sphere's nearest point at 1.0 - 0.06
    assert np.allclose(gt.depth_m[ids == 0].min(), 0.95, atol=1e-5)
    assert gt.depth_m[ids == 1].min() == pytest.approx(0.94, abs=2e-4)  # tessellation
    drive = transfer_curve(quantize(fringe_pattern(PatternSpec())), transfer="linear")
    dark = render_radiance(scene, drive, spp=4, seed=0)
    lit = render_radiance(dataclasses.replace(scene, ambient_rgb=(0.05, 0.05, 0.05)), drive, spp=4, seed=0)
    shadow = ~gt.lit & (ids == 2)
    assert shadow.sum() > 1000
    assert dark[shadow].mean() < 0.01 < 0.03 < lit[shadow].mean()


@pytest.mark.parametrize("method", ["ftp", "wfr"])
def test_alternative_phase_methods_meet_the_pipeline_limits(acquisitions, method):
    """The ablation's FTP and WFR phase stages pass issue 2's acceptance limits on a render
    (measured at seed 7: white plane MAE 0.14 / 0.065 mm, step 0.22 / 0.27 mm; Gabor 0.047 / 0.068)."""
    params = DecoderParams(phase_method=method)
    acq = acquisitions("white_plane")
    r = decode(acq.capture, rig=acq.scene.rig, params=params, reference=acq.reference)
    m = acquisition_scores(acq, r, band_px=0)
    assert m["gt_mae_mm"] <= 0.3 and m["completeness"] >= 0.99 and m["stripe_order_errors"] == 0
    acq = acquisitions("step")
    r = decode(acq.capture, rig=acq.scene.rig, params=params, reference=acq.reference)
    m = acquisition_scores(acq, r, band_px=5)
    assert m["gt_mae_mm"] <= 1.0 and m["completeness"] >= 0.95 and m["stripe_order_error_rate"] <= 0.005


def test_formed_board_ground_truth_follows_its_form(variant):
    """A bowed, rippled board renders (as a displaced grid mesh) where simbench.sim.scene.board_form_m
    puts it: the ground-truth depth at every pixel within 2 % of the ripple amplitude plus 1 um
    (the piecewise-flat grid: 1 - cos(pi / RIPPLE_CELLS) = 1.9 %), object ids intact."""
    import dataclasses

    from simbench.sim.truth import ground_truth
    from simbench.rig import pixel_rays, scale_camera
    from simbench.sim.scene import board_form_m, scene_from_dict

    form = {"bow_m_per_m": 0.002, "waviness_m": 3e-4, "waviness_phase_rad": 0.3}
    scene = scene_from_dict(
        {"object": [{"type": "plane", "name": "board", "center_m": [0.02, -0.01, 1.0], "size_m": [1.2, 0.9], **form}]}
    )
    scene = dataclasses.replace(scene, rig=scale_camera(scene.rig, 0.25))
    gt = ground_truth(scene)
    ok = gt.object_id == 0
    assert ok.mean() > 0.99
    pts = pixel_rays(scene.rig.camera) * gt.depth_m[..., None].astype(np.float64)
    x, y = pts[..., 0][ok] - 0.02, pts[..., 1][ok] + 0.01
    expect = 1.0 - board_form_m(x, y, size_m=(1.2, 0.9), **form)
    assert np.max(np.abs(gt.depth_m[ok] - expect)) < 0.02 * 3e-4 + 1e-6
    assert np.ptp(gt.depth_m[ok]) > 1e-3  # the form is there: 2 mm/m of bow over the view, and the ripple


def test_the_projector_bitmap_is_made_once_for_a_kept_drive(variant):
    """A read-only drive (a moving capture's, rendered in every time slice) gets the same
    mi.Bitmap in every scene dict - mi.Bitmap copies the texture, 35-45 ms for the Kinect's dots -
    and another drive, or a writable one (which may change under the same object), a Bitmap of
    its own holding its own values."""
    from simbench.sim.mitsuba_dict import mitsuba_scene, projector_texture

    scene = scene_from_dict({"object": [{"type": "plane", "center_m": [0, 0, 1.0], "size_m": [2, 2]}]})
    h, w = scene.rig.projector.size_hw

    def bitmap(drive):
        d, _ = mitsuba_scene(scene, drive, spp=1, max_depth=2)
        return d["projector"]["irradiance"]["bitmap"]

    kept = np.full((h, w, 3), 0.25, np.float32)
    kept.setflags(write=False)
    first = bitmap(kept)
    assert bitmap(kept) is first
    assert np.array_equal(np.array(first), projector_texture(kept, scene.rig.projector)[0])
    other = np.full((h, w, 3), 0.5, np.float32)
    other.setflags(write=False)
    second = bitmap(other)
    assert second is not first and np.array(second).max() == 0.5
    writable = np.full((h, w, 3), 0.75, np.float32)
    a, b = bitmap(writable), bitmap(writable)
    assert a is not b and np.array(a).max() == 0.75
