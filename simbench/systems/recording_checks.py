"""What a recording shows that its scene and sensor files did not say: objects no pixel sees, lit
surface beyond the decoder's working range, a clipped or dark capture (the Python API warns of
them as :class:`simbench.SimbenchWarning`; ``simbench ablate`` tables them beside each run)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from simbench.decode.params import DecoderParams
    from simbench.sim.scene import SceneSpec
    from simbench.sim.sensor import SensorModel
    from simbench.sim.truth import GroundTruth

__all__ = [
    "OUT_OF_RANGE_SHARE",
    "CLIPPED_CAPTURE_SHARE",
    "DARK_CAPTURE_LEVEL",
    "CLIPPED_REFERENCE_SHARE",
    "recording_warnings",
    "exposure_warnings",
]


# a share of the lit pixels beyond the decoder's working range worth a warning (the hard scenes'
# goal for wrong depths: 0.1 % of the decoded pixels)
OUT_OF_RANGE_SHARE = 0.001


def recording_warnings(spec: SceneSpec, gt: GroundTruth, decoder: DecoderParams | None = None) -> list[str]:
    """What the ground truth of a recording shows that its scene file did not (a new user's audit,
    2026-11-30, each recorded and decoded without a word): an object no pixel sees (outside the
    view, or hidden behind another), and - with ``decoder``, the colour-fringe sensor's - lit
    surface beyond the decoder's working range (``depth_range_m``), where the pattern's code
    repeats: such a pixel decodes a whole code cycle off, a confident wrong depth inside the
    range (a wall at 2.5 m read at 0.83 m, 78 % of it at confidence 6), or not at all."""
    out = []
    seen = np.unique(np.asarray(gt.object_id)[np.asarray(gt.object_id) >= 0])
    unseen = [o.name for i, o in enumerate(spec.objects) if i not in set(seen.tolist())]
    if unseen and seen.size:  # (none seen at all: the render's own error says it)
        out.append(
            f"no pixel sees object(s) {', '.join(repr(n) for n in unseen)} (outside the camera's view, or hidden "
            "behind another object)"
        )
    if decoder is not None:
        near, far = decoder.depth_range_m
        z = np.asarray(gt.depth_m, np.float64)[np.asarray(gt.lit, bool)]
        outside = (z < near) | (z > far)
        if z.size and outside.mean() > OUT_OF_RANGE_SHARE:
            out.append(
                f"{100 * outside.mean():.1f} % of the lit pixels lie outside the decoder's working range "
                f"{near:g}-{far:g} m (DecoderParams.depth_range_m; the lit surface spans {z.min():.3g}-{z.max():.3g} "
                "m): the pattern's code repeats every cycle, so there a pixel decodes a whole cycle off - a wrong "
                "depth inside the range, at "
                "full confidence - or not at all. Place the scene within the range, or decode with a range that holds "
                "it (simbench decode --near/--far), no wider than one code cycle of disparity"
            )
    return out


# a recording with more than this share of its pixels clipped in some channel is warned of (a
# glossy board's highlight clips well under it; an audit's capture under ambient light twice the
# projector's white was 100 % clipped, recorded without a word), and one whose brightest value is
# under DARK_CAPTURE_LEVEL of full scale
CLIPPED_CAPTURE_SHARE = 0.05
DARK_CAPTURE_LEVEL = 0.02
# ... and the reference plane's capture - the white board the auto exposure puts at 70 % of the full
# well: none of it clips unless something else adds light (a docs check: room light at 0.5 of the
# projector's white clipped 3.2 % of it, under the capture's bound)
CLIPPED_REFERENCE_SHARE = 0.01


def exposure_warnings(
    raw: np.ndarray,
    scene: SceneSpec,
    sensor: SensorModel,
    *,
    what: str = "capture",
    clipped_share: float = CLIPPED_CAPTURE_SHARE,
) -> list[str]:
    """What a recording's exposure spoiled: a capture clipped over more than
    :data:`CLIPPED_CAPTURE_SHARE` of its pixels (with the reasons the sensor model gives: the
    auto exposure meters the projector's white on the board, not the room's light or the dark
    current), or one nearly black.  ``raw``: the capture as recorded (integer codes of
    ``sensor``'s ADC, clipped at its top or the full well's code if lower; or floats in [0, 1];
    (H, W, 3), or (K, H, W) frames, whose pixels count once a frame).  Phase shifting's frames
    are grey (the channels' mean): a pixel clipped in one channel only does not show in them.
    ``what``: the image's name in the warning, ``clipped_share`` its bound (the reference plane's
    capture is checked too, at :data:`CLIPPED_REFERENCE_SHARE`: the white board the auto exposure
    is set on is where room light clips first)."""
    from simbench.sim.sensor import PhysicalCamera

    a = np.asarray(raw)
    cam = sensor.camera
    top, black = 1.0, 0.0
    if np.issubdtype(a.dtype, np.integer):
        top = float(cam.max_dn)
        if isinstance(cam, PhysicalCamera):
            # a full well below the ADC's top (a gain set low) clips there; the black level is no signal
            top = min(top, float(round(cam.offset_dn + cam.gain * cam.full_well_e)))
            black = float(cam.offset_dn)
    full = a >= top
    clipped = full.any(axis=-1) if a.ndim == 3 and a.shape[-1] == 3 else full
    share = float(clipped.mean()) if clipped.size else 0.0
    out = []
    if share > clipped_share:
        why = []
        if isinstance(cam, PhysicalCamera):
            from simbench.sim.photometry import exposure_s, white_board

            t = exposure_s(sensor, scene.rig, **white_board(scene))
            if cam.exposure_s is None:
                why.append(
                    f"the auto exposure ({t * 1e3:.3g} ms) brings the white board to "
                    f"{100 * cam.auto_exposure_fraction:.0f} % of the full well under the projector's white alone "
                    "(docs/sensor-model.md)"
                )
                limit = 1.0 / cam.auto_exposure_fraction - 1.0
                if sensor.ambient_ratio > limit:
                    why.append(
                        f"the room's light ([ambient] ratio {sensor.ambient_ratio:g} of the projector's white) takes "
                        f"it past the full well (above {limit:.2f}): lower the ratio, or set [camera] exposure_s"
                    )
            else:
                why.append(f"the exposure set, {t:.4g} s ([camera] exposure_s, seconds)")
            dark = cam.dark_current_e_s * t
            if dark > 0.1 * cam.full_well_e:
                why.append(f"dark current alone fills {100 * min(1.0, dark / cam.full_well_e):.0f} % of the full well")
        out.append(
            f"{100 * share:.1f} % of the {what}'s pixels are clipped in some channel"
            + (f": {'; '.join(why)}" if why else "")
            + " - their fringe is lost and a decode leaves them out"
        )
    elif a.size and float(a.max()) - black < DARK_CAPTURE_LEVEL * (top - black):
        above = f" ({black:g} the black level)" if black else ""
        out.append(
            f"the {what} is dark: its brightest value is {float(a.max()):.4g} of {top:g}{above} - too short an "
            "exposure, too little light or too little gain for a fringe above the noise"
        )
    return out
