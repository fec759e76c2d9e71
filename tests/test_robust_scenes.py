"""The colour-robust decoder beyond the paper's scenes (issue 17), on rendered scenes of our
own (``scenes/robust_*.toml`` and ``scenes/step.toml``): saturated hues outside Table 1, a dark
board, printed albedo edges, boards tilted 45 deg about either axis, stepped geometry.

Each is rendered at the full run's resolution and sensor (1280x960, ``paper``) with the
default sampler at 16 instead of 36 spp (a noisier capture than the full run's, so the bounds
hold a fortiori; it halves the test's time), and decoded by triangulation (paper Eq. 15) and
against the reference plane.
The bound of the issue: completeness >= 97 % of the lit pixels off a 5-px band at depth edges,
MAE against ground truth <= 0.6 mm, no stripe-order errors.  The printed chart's albedo
edges are not depth edges: its band is taken at depth edges only, so the pixels next to a
printed edge count.
"""

from __future__ import annotations

import pytest

from simbench.decode import robust_params
from simbench.metrics import depth_errors, edge_band

pytestmark = pytest.mark.slow

MIN_COMPLETENESS = 0.97
MAX_MAE_MM = 0.6
BAND_PX = 5

PASSING = ["robust_orange", "robust_purplish_blue", "robust_violet", "robust_dark", "robust_tilt_x45", "robust_tilt_y45", "step"]
# Known shortfalls, kept as strict xfails so that a fix shows up (and must then move the scene
# to PASSING).  Measured at commit time, calibrated mode:
#   robust_printed: ~88 % - beside every printed edge that runs along the stripes the phase
#     fit fails for ~8 px (the Gabor window straddles two albedos: amplitude/residual checks),
#     which breaks the row's chain of linked stripes; a stripe next to the gap then has no
#     3-stripe De Bruijn window, and a tile cut off between such a gap and the image border
#     (<= 5 stripes) loses its chains to the neighbour correction's support rule;
#   robust_staircase: ~89 % - about one period lost beside each depth edge beyond the 5-px
#     band, and a 4-stripe sliver of wall between the image border and a projector shadow
#     cannot form a 3-stripe De Bruijn window with neighbours it can trust.
SHORTFALLS = {
    "robust_printed": "stripe chains broken beside printed edges along the stripes; ~88 % completeness (issue 17 note)",
    "robust_staircase": "about one period lost beside depth edges, slivers between shadows; ~89 % completeness (issue 17 note)",
}


@pytest.fixture(scope="module")
def session(variant, tmp_path_factory):
    from simbench.experiments.common import RunConfig, Session

    return Session(RunConfig(spp=16), out_dir=tmp_path_factory.mktemp("robust"), cache_dir=None, progress=lambda _: None)


def _scores(session, name: str) -> dict:
    scene = session.scene(name)
    cap = session.capture(scene, f"robust/{name}")[0]
    gt = cap.gt
    band = edge_band(gt.depth_m, object_id=None if name == "robust_printed" else gt.object_id, band_px=BAND_PX)
    params = robust_params(session.config.decoder)
    out = {}
    for mode in ("calibrated", "reference"):
        r = session.decode(cap, params, mode=mode)
        out[mode] = depth_errors(r.depth_m, gt.depth_m, region=gt.lit, exclude=band, column_px=r.column_px, gt_column_px=gt.column_px, period_px=session.config.decoder.period_px)
    return out


def _check(scores: dict, name: str) -> None:
    for mode, m in scores.items():
        what = f"{name} ({mode}): completeness {100 * m['completeness']:.2f} %, MAE {m['mae_mm']:.3f} mm, {m['stripe_order_errors']} stripe-order errors"
        assert m["completeness"] >= MIN_COMPLETENESS, what
        assert m["mae_mm"] <= MAX_MAE_MM, what
        assert m["stripe_order_errors"] == 0, what


@pytest.mark.parametrize("name", PASSING)
def test_robust_decoder_holds_beyond_the_papers_scenes(session, name):
    _check(_scores(session, name), name)


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.xfail(reason=why, strict=True, raises=AssertionError)) for n, why in SHORTFALLS.items()])
def test_robust_decoder_known_shortfalls(session, name):
    _check(_scores(session, name), name)
