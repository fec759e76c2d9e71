"""The simulated competitors (simbench.systems.kinect, simbench.systems.tof): Kinect-v1-like speckle
structured light and SR4000-like time of flight.  Fast tests run the decoders on numpy-made frames; the slow ones
render with Mitsuba and hold the issue's validation checks against published measurements."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from simbench.systems import kinect, tof
from simbench.experiments.bench import competitor_inputs
from simbench.literature import nguyen_kinect_sigma_mm
from simbench.rig import Intrinsics, register_depth
from simbench.sim.photometry import LIGHT_M_S

from .conftest import SCENES

# ---------------------------------------------------------------------------------- Kinect


def test_kinect_disparity_positions_cover_the_depth_range():
    m = kinect.KinectModel()
    d0 = m.first_disparity_px
    lo = m.fb_px_m * (1 / m.max_depth_m - 1 / m.reference_depth_m)
    hi = m.fb_px_m * (1 / m.min_depth_m - 1 / m.reference_depth_m)
    # the parabola needs a neighbour either side of the extreme disparities
    assert d0 + 1 <= lo and hi <= d0 + m.disparities - 2
    assert m.disparities * m.subpixel_steps < 2**m.code_bits


def test_kinect_dot_pattern_is_seeded_tiled_with_bright_centres():
    m = kinect.KinectModel()
    a, b = kinect.dot_pattern(m), kinect.dot_pattern(m)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, kinect.dot_pattern(dataclasses.replace(m, pattern_seed=1)))
    t = m.texels_per_dot
    tw, th = m.tile_wh
    assert a.shape == (th * m.tiles_wh[1] * t, tw * m.tiles_wh[0] * t)
    # the 3x3 tiles repeat (away from the black border)
    assert np.allclose(a[10 : th * t - 10, tw * t + 10 : 2 * tw * t - 10], a[10 : th * t - 10, 10 : tw * t - 10])
    centre = a[(th // 2) * t + t // 2, (tw // 2) * t + t // 2]
    assert centre == pytest.approx(1.0, abs=0.05)
    lit_share = (a[t // 2 :: t, t // 2 :: t] > 0.2).mean()
    assert lit_share == pytest.approx(m.dot_fraction, rel=0.15)


def test_speckle_statistics_match_gamma_theory():
    """Integrated speckle of M grains: mean 1, variance 1/M (Goodman)."""
    m = kinect.KinectModel()
    grains = m.speckle_grains_per_pixel
    s = kinect.speckle((400, 500), grains_per_pixel=grains, rng=3)
    assert s.mean() == pytest.approx(1.0, abs=0.005)
    assert s.var() == pytest.approx(1.0 / grains, rel=0.03)
    # depolarising surfaces double the grains
    assert grains == pytest.approx(2 * (10.4 / (2.44 * 0.83 * 2.0)) ** 2)


def test_kinect_recovers_a_known_disparity_from_numpy_frames():
    """Reference and a capture displaced by a plane's disparity (numpy, no renderer): the
    matcher returns it to its 1/8-px code and the depth of the plane."""
    model, raw, cal = competitor_inputs("kinect")
    res = kinect.match(raw, cal.reference, model=model)
    true_d = model.fb_px_m * (1 / 1.1 - 1 / model.reference_depth_m)
    d = res.disparity_px[res.valid]
    assert res.valid.mean() > 0.5
    assert np.median(np.abs(d - true_d)) <= 1 / 8
    assert np.mean(np.abs(d - true_d) < 0.5) > 0.97
    assert np.nanmedian(res.depth_m) == pytest.approx(1.1, abs=0.004)
    # codes are 1/8-px steps; invalid = 2047
    assert np.all(res.code[~res.valid] == 2047)
    assert np.allclose((res.disparity_px[res.valid] - model.first_disparity_px) * 8, res.code[res.valid])


def test_kinect_ncc_is_the_exact_normalised_cross_correlation_up_to_the_matched_columns_ends():
    """The best score of every matched pixel is the NCC of its 9x9 window with the reference's,
    computed plainly - at the outermost matched columns too (a third audit: the product's box
    filter reflected the matched columns' ends, and 4 columns a side read up to 2.2, their
    wrong matches 5 mm MAE); an NCC is never above 1."""
    model, raw, cal = competitor_inputs("kinect")
    res = kinect.match(raw, cal.reference, model=model)
    assert np.nanmax(res.ncc) <= 1.0 + 1e-5
    img, ref = raw.astype(np.float64), cal.reference.astype(np.float64)
    b = model.window_px // 2

    def ncc(r: int, x: int, s: int) -> float:
        a = img[r - b : r + b + 1, x - b : x + b + 1]
        c = ref[r - b : r + b + 1, x - s - b : x - s + b + 1]
        a, c = a - a.mean(), c - c.mean()
        return float((a * c).sum() / np.sqrt((a * a).sum() * (c * c).sum()))

    cols = np.flatnonzero(np.isfinite(res.ncc[100]))
    for x in (*cols[:5], *cols[-5:]):
        best = max(ncc(100, x, model.first_disparity_px + k) for k in range(model.disparities))
        assert res.ncc[100, x] == pytest.approx(best, abs=1e-4), x


def test_kinect_without_noise_is_exact_to_the_quantisation():
    clean = dataclasses.replace(kinect.KinectModel(), speckle=False, noise=False)
    _, raw, cal = competitor_inputs("kinect", model=clean)
    res = kinect.match(raw, cal.reference, model=clean)
    true_d = clean.fb_px_m * (1 / 1.1 - 1 / clean.reference_depth_m)
    err = np.abs(res.disparity_px[res.valid] - true_d)
    assert res.valid.mean() > 0.85
    # the nearest 1/8-px code is within 1/16 px of the truth; the interpolation adds little
    assert np.mean(err <= 1 / 16 + 0.01) > 0.9
    assert np.percentile(err, 99) <= 0.25


def test_kinect_marks_dark_and_saturated_frames_invalid_without_crashing():
    model, raw, cal = competitor_inputs("kinect")
    dark = np.zeros_like(raw)
    full = np.full_like(raw, 1023)
    for frame in (dark, full):
        res = kinect.match(frame, cal.reference, model=model)
        assert not res.valid.any()
        assert np.isnan(res.depth_m).all()
    with pytest.raises(ValueError, match="shape"):
        kinect.match(raw[:100], cal.reference, model=model)
    with pytest.raises(ValueError, match="finite"):
        kinect.match(np.full(raw.shape, np.nan), cal.reference, model=model)


def test_kinect_matching_is_deterministic():
    model, raw, cal = competitor_inputs("kinect")
    a = kinect.match(raw, cal.reference, model=model)
    b = kinect.match(raw, cal.reference, model=model)
    assert np.array_equal(a.code, b.code) and np.array_equal(a.valid, b.valid)


def test_kinect_model_rejects_bad_parameters():
    with pytest.raises(ValueError, match="window_px"):
        kinect.KinectModel(window_px=8)
    with pytest.raises(ValueError, match="bit codes"):
        kinect.KinectModel(disparities=300)
    with pytest.raises(ValueError, match="focal_px"):
        kinect.KinectModel(focal_px=-1.0)


# -------------------------------------------------------------------------------------- ToF


def _plane_phasor(model, z_m):
    cam = model.camera
    yy, xx = np.indices(cam.size_hw)
    ray = np.sqrt(((xx - cam.cx_px) / cam.focal_px) ** 2 + ((yy - cam.cy_px) / cam.focal_px) ** 2 + 1)
    return np.exp(1j * 2 * np.pi * model.modulation_hz * 2 * z_m * ray / LIGHT_M_S), ray


def test_tof_noise_free_taps_decode_to_the_true_depth():
    model = tof.ToFModel(noise=False)
    z, ray = _plane_phasor(model, 1.234)
    taps = tof.record_taps(np.full(model.camera.size_hw, 0.5), z, model=model, rng=0)
    res = tof.decode_taps(taps, model=model)
    assert res.valid.all()
    assert np.allclose(res.depth_m, 1.234, atol=1e-5)
    assert np.allclose(res.distance_m, 1.234 * ray, atol=1e-5)


def test_tof_phase_noise_matches_shot_noise_theory():
    """sigma_d = c / (4 pi f) * sqrt(N/2 + 2 sigma_r^2) / (N m / 2) for four samples."""
    model = tof.ToFModel()
    z, _ = _plane_phasor(model, 1.0)
    z = np.full(model.camera.size_hw, z[72, 88])
    amp = np.full(model.camera.size_hw, 0.3)
    stack = np.stack(
        [tof.decode_taps(tof.record_taps(amp, z, model=model, rng=s), model=model).distance_m for s in range(6)]
    )
    n = 0.3 * tof.electrons_per_radiance(model)
    theory = (
        LIGHT_M_S
        / (4 * np.pi * model.modulation_hz)
        * np.sqrt(n / 2 + 2 * model.read_noise_e**2)
        / (n * model.demodulation_contrast / 2)
    )
    assert stack.std() == pytest.approx(theory, rel=0.05)


def test_tof_mixed_phasors_give_flying_pixels():
    """Half a pixel at 1.0 m and half at 1.5 m: the phasor sum lands in between."""
    model = tof.ToFModel(noise=False)
    near, _ = _plane_phasor(model, 1.0)
    far, _ = _plane_phasor(model, 1.5)
    mixed = 0.5 * near + 0.5 * far
    res = tof.decode_taps(tof.record_taps(np.full(model.camera.size_hw, 0.5), mixed, model=model, rng=0), model=model)
    assert np.all((res.depth_m[70:74, 86:90] > 1.05) & (res.depth_m[70:74, 86:90] < 1.45))


def test_tof_flags_saturated_and_dark_pixels():
    model = tof.ToFModel()
    z, _ = _plane_phasor(model, 1.0)
    amp = np.full(model.camera.size_hw, 0.3)
    amp[:10] = 0.0
    amp[-10:] = 1e6
    res = tof.decode_taps(tof.record_taps(amp, z, model=model, rng=1), model=model)
    assert not res.valid[:10].any() and not res.valid[-10:].any()
    assert res.valid[20:-20].all()
    with pytest.raises(ValueError, match="shape"):
        tof.decode_taps(np.zeros((10, 10, 4)), model=model)


def test_tof_field_of_view_and_range():
    m = tof.ToFModel()
    assert m.camera.fov_x_deg == pytest.approx(43.6)
    assert m.unambiguous_range_m == pytest.approx(4.9965, abs=1e-3)


# ------------------------------------------------------------------------------------ both


def test_tof_unambiguous_range_is_half_the_modulation_wavelength():
    # c / 2f: 7.49 m at 20 MHz, 5.0 m at the SR4000's 30 MHz (its datasheet's calibrated range)
    assert tof.ToFModel(modulation_hz=30e6).unambiguous_range_m == pytest.approx(5.0, abs=0.01)
    assert tof.ToFModel(modulation_hz=20e6).unambiguous_range_m == pytest.approx(7.49, abs=0.01)


def test_register_depth_resamples_between_cameras_sharing_a_centre():
    src = Intrinsics.centred(176, 144, 220.0)
    dst = Intrinsics.centred(640, 480, 571.0)
    yy, xx = np.indices(src.size_hw)
    depth = (1.0 + 0.001 * xx).astype(np.float32)  # depth grows along x
    out = register_depth(depth, source=src, target=dst)
    assert out.shape == dst.size_hw
    # the centre maps to the centre; the target is wider than the source: NaN outside
    assert out[240, 320] == pytest.approx(depth[72, 88], abs=0.0011)
    assert np.isnan(out).any() or dst.fov_x_deg <= src.fov_x_deg
    same = register_depth(depth, source=src, target=src)
    assert np.array_equal(same, depth)
    with pytest.raises(ValueError, match="does not match"):
        register_depth(depth[:10], source=src, target=dst)


@pytest.mark.parametrize("device", ["kinect", "tof"])
def test_recording_files_round_trip(tmp_path, device):
    from types import SimpleNamespace

    from simbench.systems import get_system, system_of_recording

    system = get_system(device)
    raw, cal, scene = system.bench_inputs()
    hw = system.model.camera.size_hw
    gt = SimpleNamespace(depth_m=np.full(hw, 1.1, np.float32), lit=np.ones(hw, bool), object_id=np.zeros(hw, np.int16))
    system.write_recording(tmp_path, raw, cal, scene=scene, gt=gt, meta={"seed": 1})
    assert np.array_equal(np.load(tmp_path / "gt_lit.npy"), gt.lit)  # what `score` reads beside gt_depth.npy
    assert system_of_recording(tmp_path) == device
    other = get_system(device)
    raw2, cal2, scene2 = other.read_recording(tmp_path)
    assert other.model == system.model and scene2.rig == scene.rig
    assert np.array_equal(raw2, raw)
    a = system.decode(raw, cal, scene=scene)
    b = other.decode(raw2, cal2, scene=scene2)
    assert np.array_equal(np.nan_to_num(a.depth_m), np.nan_to_num(b.depth_m))


# ------------------------------------------------------------------------- Mitsuba renders


@pytest.mark.slow
def test_kinect_plane_error_within_2x_of_nguyen_2012(variant):
    """The competitor issue's check: simulated plane RMSE at 0.9-1.4 m within 2x of the real
    Kinect's axial noise sigma_z = 1.2 + 1.9 (z - 0.4)^2 mm (Nguyen, Izadi & Lovell 2012)."""
    from simbench.metrics import depth_errors
    from simbench.sim.scene import load_scene
    from simbench.sim.capture import cached_ground_truth

    model = kinect.KinectModel()
    cal = kinect.calibrate(model, spp=16, seed=11)
    for z_cm in (90, 120, 140):
        scene = kinect.device_scene(load_scene(SCENES / f"plane_depth_{z_cm:03d}cm.toml"), model)
        ir = kinect.capture(scene, model, cal, spp=16, seed=100 + z_cm, noise_seeds=[5])[0]
        res = kinect.match(ir, cal.reference, model=model)
        gt = cached_ground_truth(scene)
        e = depth_errors(res.depth_m, gt.depth_m, region=gt.lit)
        nguyen = float(nguyen_kinect_sigma_mm(z_cm / 100))
        assert nguyen / 2 <= e["rmse_mm"] <= 2 * nguyen, (z_cm, e["rmse_mm"], nguyen)
        # the side bands without a full search range are invalid, the rest decodes
        assert e["completeness"] > 0.8


@pytest.mark.slow
def test_tof_wall_sigma_within_1_5x_of_chiabrando_2009(variant):
    """The competitor issue's check: per-pixel temporal sigma on a white wall at 1.3 m within
    1.5x of the SR4000's 4.0 mm (Chiabrando et al. 2009, 8.5 ms integration)."""
    from simbench.sim.scene import load_scene

    model = tof.ToFModel()
    scene = tof.device_scene(load_scene(SCENES / "plane_depth_130cm.toml"), model)
    taps = tof.capture(scene, model, spp=16, seed=3, noise_seeds=list(range(20)))
    stack = np.stack([tof.decode_taps(t, model=model).depth_m for t in taps])
    centre = stack[:, 52:92, 68:108]
    sigma_mm = float(np.mean(np.std(centre, axis=0, ddof=1))) * 1000
    assert 4.0 / 1.5 <= sigma_mm <= 4.0 * 1.5, sigma_mm
    assert abs(float(np.nanmean(centre)) - 1.3) < 0.003


@pytest.mark.slow
def test_tof_flying_pixels_at_the_depth_step(variant):
    """At the cube/cuboid/wall edges, footprint mixing puts pixels between the surfaces."""
    from simbench.sim.scene import load_scene
    from simbench.sim.capture import cached_ground_truth

    from simbench.sim.scene import with_subsurface

    model = tof.ToFModel(noise=False)
    # opaque: a translucent face reads farther by its medium's delay (tested on its own)
    scene = tof.device_scene(with_subsurface(load_scene(SCENES / "discontinuity.toml"), None), model)
    taps = tof.capture(scene, model, spp=16, seed=3, noise_seeds=[0])[0]
    res = tof.decode_taps(taps, model=model)
    gt = cached_ground_truth(scene)
    err = np.abs(res.depth_m - gt.depth_m)
    edge = np.zeros_like(gt.lit)
    jump = np.abs(np.diff(gt.depth_m, axis=1)) > 0.05
    edge[:, 1:] |= jump
    edge[:, :-1] |= jump
    interior = ~edge & gt.lit
    # away from edges a noise-free ToF is accurate; at edges it mixes (errors of centimetres)
    assert np.nanmedian(err[interior]) < 0.002
    assert np.nanmax(err[edge]) > 0.02


@pytest.mark.slow
@pytest.mark.parametrize("device", ["kinect", "tof"])
def test_cli_system_render_decode_score(tmp_path, capsys, variant, device):
    from simbench.cli import main

    assert (
        main(
            [
                "render",
                "--system",
                device,
                str(SCENES / "discontinuity.toml"),
                "--out",
                str(tmp_path / "rec"),
                "--spp",
                "4",
            ]
        )
        == 0
    )
    assert (
        main(["decode", str(tmp_path / "rec"), "--out", str(tmp_path / "d.npy"), "--ply", str(tmp_path / "c.ply")]) == 0
    )
    capsys.readouterr()
    gt_file = str(tmp_path / "rec" / "gt_depth.npy")
    assert main(["score", str(tmp_path / "d.npy"), "--gt", gt_file, "--edge-band", "5", "--json"]) == 0
    # the command line scores what the Python API scores: the lit pixels, off the objects' edges
    # (a third audit: without gt_lit.npy and gt_object_id.npy in the folder it scored every pixel
    # with a depth, shadows too - 0.46 against 0.27 mm MAE)
    import simbench

    rec = simbench.record(SCENES / "discontinuity.toml", system=device, spp=4, cache=".cache/simbench")
    api = simbench.score(simbench.depth(rec), rec, edge_band_px=5)
    cli = json.loads(capsys.readouterr().out)
    assert cli.pop("region") == str(tmp_path / "rec" / "gt_lit.npy")  # (the region's file: the API's has no name)
    assert cli == {k: (None if isinstance(v, float) and not np.isfinite(v) else v) for k, v in api.items()}
    assert np.array_equal(np.load(tmp_path / "rec" / "gt_lit.npy"), rec.gt.lit)
    depth = np.load(tmp_path / "d.npy")
    assert depth.dtype == np.float32 and np.isfinite(depth).mean() > 0.8
    # the confidence map beside the depth, in the system's unit; a threshold above the
    # system's own turns the least confident decoded pixels into holes, and keeps their confidence
    conf = np.load(tmp_path / "d_confidence.npy")
    assert conf.dtype == np.float32 and conf.shape == depth.shape
    cut = float(np.quantile(conf[np.isfinite(depth)], 0.25))
    out = tmp_path / "cut.npy"
    assert main(["decode", str(tmp_path / "rec"), "--out", str(out), "--min-confidence", str(cut)]) == 0
    kept = np.isfinite(np.load(out))
    assert np.array_equal(kept, np.isfinite(depth) & (conf >= np.float32(cut)))
    assert np.array_equal(np.load(tmp_path / "cut_confidence.npy"), conf, equal_nan=True)
    assert main(["decode", str(tmp_path / "missing"), "--out", str(tmp_path / "x.npy")]) == 2


def test_kinect_dot_drive_is_keyed_by_a_digest_kept_per_model(monkeypatch):
    """The dot projector's drive enters the render cache's key by its digest, made once per
    model and process: the digest of the drive itself, and a later lookup builds no drive."""
    from simbench.systems import kinect
    from simbench.cache import array_digest

    model = kinect.KinectModel()
    kinect._dot_drive_digest.cache_clear()
    digest = kinect._dot_drive_digest(model)
    assert digest == array_digest(np.repeat(kinect.dot_pattern(model)[..., None], 3, axis=2))
    monkeypatch.setattr(kinect, "dot_pattern", lambda m: (_ for _ in ()).throw(AssertionError("drive built")))
    assert kinect._dot_drive_digest(model) == digest
    other = dataclasses.replace(model, pattern_seed=model.pattern_seed + 1)
    monkeypatch.undo()
    assert kinect._dot_drive_digest(other) != digest


def test_tof_reads_a_translucent_plane_farther_by_its_medium_delay(variant):
    """Every ray's phasor on a translucent object carries the medium's modulation transfer (the
    mean over the bands, NIR as their mean): the decoded distance grows by its phase, c arg / 4 pi f."""
    import math

    from simbench.sim.scene import load_scene, with_subsurface
    from simbench.sim.subsurface import MEDIA, modulation_transfer

    model = tof.ToFModel(noise=False)
    scene = tof.device_scene(load_scene(SCENES / "white_plane.toml"), model)
    z0 = tof.footprint_phasor(scene, model)
    z1 = tof.footprint_phasor(with_subsurface(scene, "marble"), model)
    want = np.mean([modulation_transfer(MEDIA["marble"], c, frequency_hz=model.modulation_hz) for c in range(3)])
    lit = np.abs(z0) > 0
    np.testing.assert_allclose(z1[lit], z0[lit] * want, rtol=1e-9)
    amp = np.where(lit, 1.0, 0.0)
    d0 = tof.decode_taps(tof.record_taps(amp, z0, model=model, rng=0), model=model).distance_m
    d1 = tof.decode_taps(tof.record_taps(amp, z1, model=model, rng=0), model=model).distance_m
    bias = np.angle(want) * LIGHT_M_S / (4 * math.pi * model.modulation_hz)
    assert 0.005 < bias < 0.03  # marble: ~1.5 cm at 30 MHz
    np.testing.assert_allclose(np.nanmedian(d1 - d0), bias, rtol=1e-3)


def test_kinect_sees_a_translucent_plane_blurred(variant):
    """The Kinect's IR render passes through the scene's translucency: on a marble plane the
    dots spread, so the image's contrast drops while its mean (the reflected light) stays."""
    from simbench.sim.scene import load_scene, with_subsurface

    model = kinect.KinectModel()
    scene = kinect.device_scene(load_scene(SCENES / "white_plane.toml"), model)
    kw = {"spp": 1, "seed": 5, "max_depth": 2, "sampler": "independent", "cache": None}
    opaque = kinect._render(scene, model, **kw)
    marble = kinect._render(with_subsurface(scene, "marble"), model, **kw)
    assert np.std(marble) < 0.75 * np.std(opaque)  # measured 0.58 (1.75 mm pixels, ~mm profile)
    assert np.mean(marble) == pytest.approx(np.mean(opaque), rel=0.02)
