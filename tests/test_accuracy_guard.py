"""Accuracy guard for the decoder's speed work (issue 16): the fused C Gabor fit may change the
last bits of the phase, never the accuracy.

Each scene is decoded twice from the same render: with the decoder as it is, and with the phase
stage swapped for its plain OpenCV form (``tests/numpy_reference.py``: separable filters, the
decoder as it was before the C kernel), reference map included.  Against ground truth the fast
decoder must keep the MAE within 5 %, completeness not lower (to 1e-5, a dozen pixels: rounding
may tip a pixel on a validity threshold either way), and add no stripe-order error.  Measured
(minimal sensor, 16 spp; OpenCV form -> C kernel): white board 0.04786 -> 0.04786 mm, 30 deg
board 0.14643 -> 0.14645 mm, sphere 0.16644 -> 0.16643 mm, bust 0.24039 -> 0.24036 mm MAE;
completeness and order errors (bust 122) the same to the digits shown.
"""

import numpy as np
import pytest

from simbench.decode import DecoderParams, decode, params
from simbench.decode.phase import PhaseResult
from tests import numpy_reference as ref
from tests.scoring import acquisition_scores

pytestmark = pytest.mark.slow

# the scenes: the white board, the board turned 30 deg, the sphere before a wall, the bust
SCENES = ("white_plane", "tilted_plane", "sphere", "bust")


def _opencv_gabor(intensity, *, certainty, period_px, sigma_x_px, sigma_y_px, offset=True):
    wrapped, amp, a0, residual, support = ref.gabor_phase(
        intensity, certainty=certainty, period_px=period_px, sigma_x_px=sigma_x_px, sigma_y_px=sigma_y_px
    )
    return PhaseResult(
        wrapped=wrapped, amplitude=amp, offset=a0 if offset else None, residual=residual, support=support
    )


@pytest.mark.parametrize("name", SCENES)
def test_fast_gabor_keeps_the_accuracy_of_the_opencv_form(acquisitions, name, monkeypatch):
    acq = acquisitions(name)
    rig = acq.scene.rig
    fast = acquisition_scores(
        acq, decode(acq.capture, rig=rig, params=DecoderParams(), reference=acq.reference), band_px=5
    )
    with monkeypatch.context() as m:
        m.setitem(params.PHASE_METHODS, "gabor", _opencv_gabor)
        plain = acquisition_scores(
            acq, decode(acq.capture, rig=rig, params=DecoderParams(), reference=acq.reference), band_px=5
        )
    assert np.isfinite(plain["gt_mae_mm"]) and plain["completeness"] > 0.5
    assert fast["gt_mae_mm"] <= 1.05 * plain["gt_mae_mm"], (fast, plain)
    assert fast["completeness"] >= plain["completeness"] - 1e-5, (fast, plain)
    assert fast["stripe_order_errors"] <= plain["stripe_order_errors"], (fast, plain)
