"""The render-noise study's protocol (simbench.experiments.render_noise): the spreads it takes, why
both arms are recorded with the camera's noise on, and the committed tables it wrote."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest

from simbench.experiments.render_noise import (
    MARGIN,
    REPEATS,
    TARGET_RATIO,
    cheapest_meeting,
    noise_spreads,
)

from .conftest import ROOT


def _maps(rng, *, shape, camera, render, quantise=None):
    """REPEATS recordings of one render and REPEATS - 1 more renders recorded once: values (m) of
    a flat map plus each render's noise and each recording's camera noise (SDs in m); with
    ``quantise`` (m per DN) recorded by rounding to DN, as an 8-bit camera does."""
    base = rng.uniform(0.0, 1.0, shape) * (quantise or 1e-3)
    renders = [base + rng.normal(0.0, render, shape) for _ in range(REPEATS)]
    maps = [renders[0] + rng.normal(0.0, camera, shape) for _ in range(REPEATS)]
    maps += [r + rng.normal(0.0, camera, shape) for r in renders[1:]]
    if quantise:
        maps = [np.round(m / quantise) * quantise for m in maps]
    return np.stack(maps)


def test_noise_spreads_recovers_a_known_render_to_camera_noise_ratio():
    """Independent pixels with 0.1 mm of camera noise and 0.03 mm of render noise: the camera arm
    reads 0.1 mm and the render noise 0.03 mm, each to a few per cent (40 000 pixels: the variance
    of a 3-sample spread is known to 0.5 %, the difference of two to ~9 % of the render's
    variance)."""
    rng = np.random.default_rng(7)
    maps = _maps(rng, shape=(200, 200), camera=1e-4, render=3e-5)
    out = noise_spreads(maps, recordings=REPEATS, region=np.ones((200, 200), bool))
    assert out["pixels"] == 40_000 and out["jumps"] == 0.0
    assert out["camera_sd_mm"] == pytest.approx(0.1, rel=0.02)
    assert out["total_sd_mm"] == pytest.approx(math.hypot(0.1, 0.03), rel=0.02)
    assert out["render_sd_mm"] == pytest.approx(0.03, rel=0.15)
    assert out["ratio"] == pytest.approx(out["render_sd_mm"] / out["camera_sd_mm"])


def test_noise_spreads_leaves_out_stripe_order_jumps_and_undecoded_pixels():
    """A pixel a period off in one map, or undecoded in one, or outside the region, is left out of
    both arms; the jumps' share is of the decoded pixels, and the rest give the same spreads."""
    rng = np.random.default_rng(8)
    maps = _maps(rng, shape=(100, 100), camera=1e-4, render=5e-5)
    region = np.ones((100, 100), bool)
    region[:, :10] = False
    clean = noise_spreads(maps, recordings=REPEATS, region=region)
    spoilt = maps.copy()
    spoilt[1, 50, 20:30] += 0.021  # a period of depth, 21 mm, on 10 pixels of one recording
    spoilt[4, 60, 20:25] -= 0.021
    spoilt[2, 70, 20:24] = np.nan
    out = noise_spreads(spoilt, recordings=REPEATS, region=region)
    assert out["pixels"] == clean["pixels"] - 19
    assert out["jumps"] == pytest.approx(15 / (clean["pixels"] - 4))
    assert out["camera_sd_mm"] == pytest.approx(clean["camera_sd_mm"], rel=0.01)
    assert out["render_sd_mm"] == pytest.approx(clean["render_sd_mm"], rel=0.05)
    with pytest.raises(ValueError, match="recordings"):
        noise_spreads(maps, recordings=len(maps), region=region)
    with pytest.raises(ValueError, match="recordings"):
        noise_spreads(maps, recordings=1, region=region)


def test_quantisation_inflates_a_sub_dn_render_noise_recorded_noise_free_and_camera_noise_dithers_it():
    """Why both arms are recorded with the camera's noise on.  A render noise of 0.3 DN recorded
    noise-free by an 8-bit camera: the rounding turns it into whole-DN steps at the pixels near a
    rounding edge, a variance that grows about as the noise, not as its square - read as 1.3-1.5x
    its SD here, over levels spread evenly between DNs (0.1 DN: ~2.4x; 0.8 DN: ~1.06x) - the
    study's protocol until 2026-12-05.  Under 1.5 DN of camera noise (the paper
    camera's is ~1-2 DN on a lit board) the rounding adds its 1/12 DN^2 to both arms alike and
    the difference gives the render noise back."""
    rng = np.random.default_rng(9)
    shape = (300, 300)
    dn = 1e-3  # 1 DN written as 1 mm of "depth", so the spreads read in DN
    everywhere = np.ones(shape, bool)
    free = _maps(rng, shape=shape, camera=0.0, render=0.3 * dn, quantise=dn)
    # noise-free: every map a render of its own, the spread of those alone
    renders_only = free[[0, REPEATS, REPEATS + 1]]
    sd_free = float(np.sqrt(np.mean(np.var(renders_only, axis=0, ddof=1)))) / dn
    assert 1.3 < sd_free / 0.3 < 1.5
    dithered = _maps(rng, shape=shape, camera=1.5 * dn, render=0.3 * dn, quantise=dn)
    out = noise_spreads(dithered, recordings=REPEATS, region=everywhere, jump_mm=1e9)
    assert out["camera_sd_mm"] == pytest.approx(math.sqrt(1.5**2 + 1 / 12), rel=0.02)
    assert out["render_sd_mm"] == pytest.approx(0.3, rel=0.15)


def test_the_cheapest_setting_meeting_the_target_is_the_fewest_samples_within_the_margin():
    rows = [
        {"scene": "plane_white", "sampler": "independent", "spp": 16, "ratio": 0.9},
        {"scene": "plane_white", "sampler": "multijitter", "spp": 16, "ratio": MARGIN * TARGET_RATIO + 1e-3},
        {"scene": "plane_white", "sampler": "orthogonal", "spp": 25, "ratio": 0.25},
        {"scene": "plane_white", "sampler": "multijitter", "spp": 36, "ratio": 0.2},
        {"scene": "discontinuity", "sampler": "multijitter", "spp": 4, "ratio": 0.1},
    ]
    assert cheapest_meeting(rows) == ("orthogonal", 25)
    assert cheapest_meeting(rows, scene="discontinuity") == ("multijitter", 4)
    assert cheapest_meeting(rows[:2]) is None


@pytest.mark.parametrize("folder", ["results/quick", "results"])
def test_the_committed_render_noise_table_follows_from_its_spreads(folder):
    """render_noise.csv (`simbench reproduce all`, with --quick in results/quick): every setting's
    render noise is the root of the difference of its two spreads' variances, its ratio and
    target test follow, the run's own setting is marked once per scene, the seeds are recorded,
    and the Markdown holds the table and names the cheapest setting that meets the target."""
    from simbench.experiments.render_noise import SCENES

    with open(ROOT / folder / "render_noise.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    run = json.loads((ROOT / folder / "render_noise.provenance.json").read_text())["config"]
    assert {r["scene"] for r in rows} == set(SCENES)
    for name in SCENES:
        own = [r for r in rows if r["scene"] == name and r["run_setting"] == "True"]
        assert [(r["sampler"], int(r["spp"])) for r in own] == [(run["sampler"], run["spp"])]
    for r in rows:
        render, camera, total, ratio = (float(r[k]) for k in ("render_sd_mm", "camera_sd_mm", "total_sd_mm", "ratio"))
        assert render >= 0 and camera > 0 and int(r["pixels"]) > 0 and 0 <= float(r["jumps"]) < 0.05
        # (6 significant digits: each square known to 1e-5 of itself)
        assert render**2 == pytest.approx(max(total**2 - camera**2, 0.0), abs=2e-5 * (total**2 + camera**2))
        assert ratio == pytest.approx(render / camera, rel=1e-4)
        assert r["meets_target"] == str(ratio <= TARGET_RATIO)
        assert len(r["render_seeds"].split()) == REPEATS and len(r["noise_seeds"].split()) == 2 * REPEATS - 1
    md = (ROOT / folder / "render_noise.md").read_text()
    assert all(f"| {r['spp']} | {float(r['render_sd_mm']):.4f} | {float(r['camera_sd_mm']):.4f} |" in md for r in rows)
    best = cheapest_meeting([{**r, "spp": int(r["spp"]), "ratio": float(r["ratio"])} for r in rows])
    assert (f"cheapest setting that meets it so is `{best[0]}` at {best[1]} spp" if best else "no setting meets") in md


def test_measure_noise_renders_each_setting_and_records_its_first_render_again(monkeypatch):
    """measure_noise's wiring, with the scene, the recording and the decoding stubbed: a part
    ``scene/sampler_spp`` forks the session to that sampler and spp (the camera unchanged), records
    its first render REPEATS times and each other render once under labels of their own, decodes
    every capture by triangulation with the fork's decoder, and gives the recordings of the first
    render as the camera's arm: here 2 mm between one render's recordings and 4 mm between
    renders, so camera 2 mm, both 4 mm, render sqrt(12) mm; the seeds are the captures'."""
    from types import SimpleNamespace

    import simbench.experiments.render_noise as rn
    from simbench.experiments.common import RunConfig

    calls, decoded = [], []
    shape = (6, 8)

    class Sess:
        def __init__(self, config, *, forked=False):
            self.config, self.forked = config, forked
            self.sensor = SimpleNamespace(is_physical=True)

        def raw_scene(self, name):
            return f"raw {name}"

        def place(self, scene, label, objects):
            assert objects == rn.SCENES["plane_white"][1]
            return f"placed {scene} {label}"

        def prepare(self, scene):
            return f"prepared {scene}"

        def fork(self, sensor, *, config):
            assert sensor is self.sensor and not self.forked
            return Sess(config, forked=True)

        def capture(self, scene, label, *, repeats=1):
            assert self.forked, "a setting's captures are the forked session's"
            calls.append((self.config.sampler, self.config.spp, label, repeats))
            render = int(label.rsplit("/", 1)[1])
            gt = SimpleNamespace(lit=np.ones(shape, bool), depth_m=np.ones(shape), object_id=np.ones(shape, np.int32))
            return [
                SimpleNamespace(gt=gt, seeds={"render": 100 + render, "noise": 10 * render + k}) for k in range(repeats)
            ]

        def decode(self, cap, params, *, mode):
            assert self.forked and params is self.config.decoder and mode == "calibrated"
            render, noise = cap.seeds["render"] - 100, cap.seeds["noise"] % 10
            decoded.append((render, noise))
            return SimpleNamespace(depth_m=np.full(shape, 1.0 + 0.002 * noise + 0.004 * render))

    run = RunConfig()
    out = rn.measure_noise(Sess(run), "plane_white/ldsampler_64")
    label = "render_noise/plane_white/render"
    assert calls == [
        ("ldsampler", 64, f"{label}/0", rn.REPEATS),
        ("ldsampler", 64, f"{label}/1", 1),
        ("ldsampler", 64, f"{label}/2", 1),
    ]
    assert decoded == [(0, 0), (0, 1), (0, 2), (1, 0), (2, 0)]
    assert out["camera_sd_mm"] == pytest.approx(2.0) and out["total_sd_mm"] == pytest.approx(4.0)
    assert out["render_sd_mm"] == pytest.approx(math.sqrt(12.0)) and out["ratio"] == pytest.approx(math.sqrt(3.0))
    assert out["pixels"] == shape[0] * shape[1] and out["jumps"] == 0.0
    assert out["render_seeds"] == "100 101 102" and out["noise_seeds"] == "0 1 2 10 20"
    with pytest.raises(ValueError, match="physical"):
        s = Sess(run)
        s.sensor.is_physical = False
        rn.measure_noise(s, "plane_white/multijitter_36")
