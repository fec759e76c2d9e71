"""The colour-robust decoder beyond the paper's scenes (issue 17), on rendered scenes of our
own (``scenes/robust_*.toml`` and ``scenes/step.toml``): saturated hues outside Table 1, a dark
board, printed albedo edges, boards tilted 45 deg about either axis, stepped geometry.

Each is rendered at the full run's resolution and sensor (1280x960, ``paper``) with the
default sampler at 16 instead of 36 spp (a noisier capture than the full run's, so the bounds
hold a fortiori; it halves the test's time), and decoded by triangulation (paper Eq. 15) and
against the reference plane.
The bound of the issue: completeness >= 97 % of the lit pixels off a 5-px band at the edges,
MAE against ground truth <= 0.6 mm, no stripe-order errors; and issue 35's: at the decoder's
operating point (``ROBUST_MIN_CONFIDENCE``) at most 0.1 % of the decoded pixels more than 5 mm
from ground truth.  The band lies along every edge
of the ground truth (depth discontinuities and object boundaries, :func:`simbench.metrics.
edge_band`), the printed chart's tile edges included; completeness and MAE are both taken off
it.  (Counting the pixels beside the printed edges as well, the chart decodes at ~96 %: the
phase fit fails within ~4-10 px of an edge, more beside the saturated red and orange tiles.)
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from simbench.decode import robust_params
from simbench.metrics import depth_errors, edge_band, wrong_pixels

pytestmark = pytest.mark.slow

MIN_COMPLETENESS = 0.97
MAX_MAE_MM = 0.6
MAX_WRONG_SHARE = 0.001  # of the decoded pixels, more than WRONG_MM wrong (issue 35)
WRONG_MM = 5.0
BAND_PX = 5

PASSING = [
    "robust_orange",
    "robust_purplish_blue",
    "robust_violet",
    "robust_dark",
    "robust_tilt_x45",
    # in neither list from 2026-11-25 (its xfail removed, the scene not added here) to 2026-11-29:
    # 99.72 % complete, MAE 0.24 / 0.25 mm, none > 5 mm wrong, both modes
    "robust_tilt_y45",
    # a strict xfail until 2026-11-29 (below), then: 97.53 % complete, 0.043 % / 0.040 % > 5 mm
    # wrong, MAE 0.37 / 0.35 mm, both modes (16 spp)
    "robust_printed",
    "step",
    # 2026-11-26: 97.43 % complete, none > 5 mm wrong, both modes (96.39 % once the captures lost
    # their black end columns, 97.43 % with the narrow window's SNR beside the depth edges)
    "robust_staircase",
]
# Known shortfalls, kept as strict xfails so that a fix shows up (and must then move the scene
# to PASSING).  (robust_staircase was one from issue 17 to 2026-11-26: slivers between the image
# border and projector shadows, stripes dropped beside a shadowless depth edge, then pixels under
# the operating point beside the edges - 89.4 % at first.)
SHORTFALLS: dict[str, str] = {
    # robust_printed, from 2026-11-25 to 2026-11-29: 95.5 % complete and 0.12 % / 0.13 % > 5 mm wrong
    # at the operating point (before the albedo flattening 95.2 % and 0.50 %; with no threshold
    # 97.9 % but 1.2 %); 95.6 % and 0.10 % once the captures lost their black end columns; 96.71 %
    # and 0.097 % with the steps' cuts placed at their edges and the straddling pixels skipped;
    # 96.82 % and 0.042 % with the gain's fade without a jump; then 97.53 % and 0.043 % once the
    # blue fringe confirms the cuts (the code runs of its red, orange and purple tiles had cut them).
}


@pytest.fixture(scope="module")
def session(variant, tmp_path_factory):
    from simbench.experiments.common import RunConfig, Session

    return Session(
        RunConfig(spp=16), out_dir=tmp_path_factory.mktemp("robust"), cache_dir=None, progress=lambda _: None
    )


_CAPTURES: dict = {}


def _capture(session, name: str):
    """The scene's capture, rendered once per module (the session has no render cache)."""
    if name not in _CAPTURES:
        _CAPTURES[name] = session.capture(session.scene(name), f"robust/{name}")[0]
    return _CAPTURES[name]


def _scores(session, name: str) -> dict:
    cap = _capture(session, name)
    gt = cap.gt
    band = edge_band(gt.depth_m, object_id=gt.object_id, band_px=BAND_PX)
    params = robust_params(session.config.decoder)
    out = {}
    for mode in ("calibrated", "reference"):
        r = session.decode(cap, params, mode=mode)
        region = gt.lit & ~band
        decoded = region & np.isfinite(r.depth_m)
        wrong = float(np.mean(np.abs(r.depth_m - gt.depth_m)[decoded] > WRONG_MM / 1000.0)) if decoded.any() else 1.0
        out[mode] = {"wrong_share": wrong} | depth_errors(
            r.depth_m,
            gt.depth_m,
            region=gt.lit & ~band,
            column_px=r.column_px,
            gt_column_px=gt.column_px,
            period_px=session.config.decoder.period_px,
        )
    return out


def _check(scores: dict, name: str) -> None:
    for mode, m in scores.items():
        what = (
            f"{name} ({mode}): completeness {100 * m['completeness']:.2f} %, MAE {m['mae_mm']:.3f} mm, "
            f"{m['stripe_order_errors']} stripe-order errors, {100 * m['wrong_share']:.3f} % > {WRONG_MM:g} mm wrong"
        )
        assert m["completeness"] >= MIN_COMPLETENESS, what
        assert m["mae_mm"] <= MAX_MAE_MM, what
        assert m["stripe_order_errors"] == 0, what
        assert m["wrong_share"] <= MAX_WRONG_SHARE, what


def test_every_robustness_scene_is_held_to_the_bound_or_a_known_shortfall():
    """A scene of ``scenes/robust_*.toml`` in neither list goes untested (robust_tilt_y45 did, for
    four days, after its xfail was removed)."""
    from pathlib import Path

    scenes = {p.stem for p in (Path(__file__).resolve().parents[1] / "scenes").glob("robust_*.toml")}
    assert scenes <= set(PASSING) | set(SHORTFALLS), sorted(scenes - set(PASSING) - set(SHORTFALLS))
    assert not set(PASSING) & set(SHORTFALLS)


@pytest.mark.parametrize("name", PASSING)
def test_robust_decoder_holds_beyond_the_papers_scenes(session, name):
    _check(_scores(session, name), name)


@pytest.mark.parametrize(
    "name",
    [
        pytest.param(n, marks=pytest.mark.xfail(reason=why, strict=True, raises=AssertionError))
        for n, why in SHORTFALLS.items()
    ],
)
def test_robust_decoder_known_shortfalls(session, name):
    _check(_scores(session, name), name)


@pytest.mark.parametrize("name", ["robust_printed", "robust_staircase", "step"])
def test_robust_decode_is_the_same_for_any_thread_count(session, name):
    """The rendered scenes with albedo steps and projector shadows (the albedo flattening's 2-D
    windows) decode to the same bits in 1, 2 and 5 row bands (2026-11-26: 2 bands moved ~14-50 k
    pixels of these scenes against 1, before the bands carried the gain's rows)."""
    from simbench.decode.bands import row_bands

    cap = _capture(session, name)
    params = robust_params(session.config.decoder)
    one = session.decode(cap, dataclasses.replace(params, threads=1), mode="calibrated")
    for threads in (2, 5):
        p = dataclasses.replace(params, threads=threads)
        assert len(row_bands(*cap.gt.depth_m.shape, p, cap.scene.rig)[0]) == threads
        r = session.decode(cap, p, mode="calibrated")
        assert np.array_equal(r.depth_m, one.depth_m, equal_nan=True), threads
        assert np.array_equal(r.confidence, one.confidence, equal_nan=True), threads


# at a quarter of the paper's resolution (the motion study's, 320x240: a 5.4-px fringe period)
QUARTER_WRONG_SHARE = {"motion_board": 0.002, "bust": 0.0045}


@pytest.mark.parametrize("name", sorted(QUARTER_WRONG_SHARE))
def test_a_quarter_resolution_capture_keeps_few_confident_wrong_depths_at_its_edges(session, name):
    """The colour-robust decoder's confidence terms at a quarter of the paper's resolution: every
    decoded pixel of the motion study's still board before a wall and of the bust, at the
    operating point, against the truth.  Measured 2026-11-30 (16 spp): the board 0.093 / 0.122 %
    of its decoded pixels > 5 mm wrong (calibrated / reference), the bust 0.283 / 0.278 % (of
    which ~49 pixels, 0.08 %, on its outline, decoded within ~5 mm of the wall's depth beside it:
    pixels that see both, whose truth - the ray through the pixel's centre - meets the bust).
    Before the crease and edge terms' step became an angle (DecoderParams.edge_step_px: a fixed 3
    projector px, under this camera's fronto-parallel slope of 3.85, broke every run) and the edge
    term read down the columns too: 0.744 / 0.753 % and 0.592 / 0.568 %.  Bounds: about twice
    what is measured."""
    sub = session.fork(session.sensor, config=dataclasses.replace(session.config, camera_scale=0.25))
    cap = sub.capture(sub.scene(name), f"quarter/{name}")[0]
    params = robust_params(sub.config.decoder)
    for mode in ("calibrated", "reference"):
        r = sub.decode(cap, params, mode=mode)
        decoded = np.isfinite(r.depth_m)
        # as the motion study counts it: a depth where the truth sees nothing is wrong too
        wrong = float(wrong_pixels(r.depth_m, cap.gt.depth_m, wrong_m=WRONG_MM / 1000.0).sum() / decoded.sum())
        assert decoded.mean() > 0.8, (mode, decoded.mean())
        assert wrong <= QUARTER_WRONG_SHARE[name], f"{name} ({mode}): {100 * wrong:.3f} % > {WRONG_MM:g} mm wrong"
