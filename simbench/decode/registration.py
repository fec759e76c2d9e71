"""The capture's colour registration: where its code channels' fringe lies against its fringe
channel's (ours; the paper's decoder has no such check).

The pattern's code channels carry the fringe too: ``R + G = I = B`` (paper Eq. 7-8), and each
code channel alone is ``C I``, whose code ``C`` (stripes exactly one period wide) has no component
at the fringe's frequency, so at that frequency every channel holds the fringe in one phase,
whatever the code, the surface colour or the crosstalk.  A capture whose channels are shifted
against each other - a lens's lateral colour, a demosaicing or a processing step that moved one
channel - shows it as a phase difference between the code channels' sum and the fringe channel.
Where the fringe channel moved, every depth is biased: a blue channel shifted by one camera pixel
put the colour-robust decoder's depth of the dark measured blue board 4.8 mm off (38 % of its
pixels > 5 mm wrong) at full fringe SNR, a bias no window's fit can see.

The offset is measured in tiles (:func:`registration_px`), against the reference capture's own
in reference mode (the same camera's lateral colour is in both and cancels in the match).  The
light moves a tile's offset too where the code channels' light took another path than the
fringe's (interreflection in a corner, a glossy face), so the capture's shift is the median of
its tiles (:func:`registration_shift_px`), and the colour-robust decoder caps every pixel's
confidence by it (:func:`registration_cap`, ``DecoderParams.registration_doubt``).  One
measurement cannot tell which channel moved, and a phase read from the channels' overlay (paper
Eq. 9) moves by a share of the shift whichever did (the paper's decoder: half a pixel for the
blue channel moved one), so the doubt is the most it can be: the whole shift.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from simbench.decode.params import STABILITY_KAPPA_RAD

__all__ = [
    "REGISTRATION_FLOOR_PX",
    "REGISTRATION_WARN_PX",
    "registration_px",
    "registration_change",
    "registration_cap",
    "registration_shift_px",
    "NONLINEAR_FRINGE_RATIO",
    "fringe_harmonic_ratio",
    "encoding_doubt",
    "registration_doubt",
]

# every 8th row is read (the offset is a smooth field: six rendered scenes' medians moved by
# <= 0.01 px from every 4th row's; ~4 ms of a 1280x960 capture, every 4th row took ~8 ms)
REGISTRATION_ROW_STEP = 8
# the demodulated channels are averaged along the row over 8 fringe periods, one cycle of B(2,3):
# the box nulls the fringe's second harmonic and the code's lines, at multiples of an eighth of
# the fringe's frequency, where the camera's period is the one demodulated at (a board facing
# the rig; on one turned 20 degrees the tiles read up to 0.11 px off, tests/test_registration.py).
# Over 4 periods the lines next to the fringe's, f +- f/8, passed at 64 %: tiles at the image's
# sides read 0.04-0.05 px off on saturated boards facing the rig
REGISTRATION_BOX_PERIODS = 8
# tiles about 16 fringe periods square (1280x960 at the paper's ~21 px period: 4 x 3 tiles), so
# that a field that varies over the image (lateral colour grows towards the corners) is seen
REGISTRATION_TILE_PERIODS = 16
# a tile's offset is read only where its fringe is coherent across its pixels (the magnitude of the
# sum of the cross products over the sum of their magnitudes; 0.96-1.0 on every lit clean capture
# measured, noise alone ~0): others take the whole image's, and an image whose own is below this
# has no measurable fringe (nothing is doubted)
REGISTRATION_MIN_COHERENCE = 0.5
# Estimation noise: clean captures (paper sensor, 36 spp), against their reference capture, of 15
# scenes (the white, dark, purplish-blue and dark measured blue boards, the saturated orange board,
# the printed chart, the step, the staircase, the bust, both clutter scenes, the 45-, 55-grey- and
# 90-degree corners and the V-groove) read a median tile within +-0.02 px but the 45-degree
# corner's, +0.11 px (its interreflection); single tiles up to 0.48 px off (a box face in the pink
# and cyan clutter, the 45-degree corner).  The blue channel shifted by 0.25 / 0.5 / 1 px read a
# median of 0.23-0.26 / 0.49-0.52 / 0.98-1.02 px, but the orange board's 0.15 / 0.50 / 1.01 px
# (its blue channel holds its red and green light's crosstalk, which stays) and the 45-degree
# corner's 0.15 / 0.40 / 1.06 px.
# A shift up to this floor is taken as noise; beyond it the excess is the doubt.
REGISTRATION_FLOOR_PX = 0.15
# a shift this large is named in a warning (twice the floor: ~1.4 mm at 1 m on the paper's rig
# had the fringe channel moved)
REGISTRATION_WARN_PX = 0.3


def _box(period_px: float) -> tuple[int, int]:
    """The row average's window (width, height) for OpenCV: :data:`REGISTRATION_BOX_PERIODS`."""
    return (max(1, int(round(REGISTRATION_BOX_PERIODS * period_px))), 1)


def _less_mean(a: np.ndarray, box: tuple[int, int]) -> np.ndarray:
    """A channel less its local mean along the row: the box spans whole periods only to the pixel,
    and a bright flat channel, a saturated one, read as a coherent fringe through it."""
    return a - cv2.blur(a, box)


def _phasor(a: np.ndarray, omega: float, box: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """``a`` times exp(-i omega x), averaged along the row: its local phasor at ``omega`` (rad per
    px), as (cosine part, sine part): the phasor is ``cos - i sin``."""
    wx = omega * np.arange(a.shape[1], dtype=np.float64)
    return cv2.blur(a * np.cos(wx).astype(np.float32), box), cv2.blur(a * np.sin(wx).astype(np.float32), box)


def _edge(box: tuple[int, int], w: int) -> int:
    """The columns at each end of a row not counted: within half a box the average reads the
    border's reflection (tiles there read 0.03-0.05 px off on saturated boards)."""
    return min(box[0] // 2, (w - 1) // 2)


def _tile_edges(n_px: int, period_px: float) -> np.ndarray:
    n = max(1, round(n_px / (REGISTRATION_TILE_PERIODS * period_px)))
    return np.linspace(0, n_px, n + 1).round().astype(int)


def registration_px(image: np.ndarray, *, order: list[int], period_px: float) -> np.ndarray:
    """The code channels' fringe position relative to the fringe channel's, per tile.

    Parameters
    ----------
    image : ndarray, shape (H, W, 3), any dtype the decoder takes
        A capture (undistorted), channels in its own order.
    order : list of int
        The capture's channel indices of code 1, code 0 and the fringe.
    period_px : float
        The fringe's period in camera pixels (``DecoderParams.camera_period``).

    Returns
    -------
    ndarray, shape (TY, TX), float64, camera px
        Positive where the code channels' fringe lies to the right of the fringe channel's;
        a tile whose fringe is incoherent takes the image's value; all NaN when the image's is.
    """
    rows = np.asarray(image)[::REGISTRATION_ROW_STEP]
    # the channels as captured, not unmixed: the coupling matrix is the white reference plane's,
    # and on a dark blue board the unmixed code channels held a negative share of the blue one's
    # fringe, which doubled a shift of the blue channel (crosstalk left in only dilutes it)
    sub = np.ascontiguousarray(rows[..., order], dtype=np.float32)
    w = sub.shape[1]
    omega = 2.0 * np.pi / float(period_px)
    box = _box(period_px)
    code_sum = np.ascontiguousarray(sub[..., 0] + sub[..., 1])
    sc, ss = _phasor(_less_mean(code_sum, box), omega, box)
    fc, fs = _phasor(_less_mean(np.ascontiguousarray(sub[..., 2]), box), omega, box)
    # (sc - i ss) * conj(fc - i fs): the code channels' phasor against the fringe channel's,
    # summed per tile (the rows' ends not counted, :func:`_edge`)
    edge = _edge(box, w)
    keep = np.s_[:, edge : w - edge]
    re = sc[keep] * fc[keep] + ss[keep] * fs[keep]
    im = sc[keep] * fs[keep] - ss[keep] * fc[keep]
    mag = np.hypot(re, im)
    ye = _tile_edges(image.shape[0], period_px) // REGISTRATION_ROW_STEP
    ye[-1] = sub.shape[0]
    xe = np.clip(_tile_edges(w, period_px) - edge, 0, re.shape[1])
    ye, xe = ye[:-1][np.diff(ye) > 0], xe[:-1][np.diff(xe) > 0]

    def tiles(a: np.ndarray) -> np.ndarray:
        return np.add.reduceat(np.add.reduceat(a, ye, axis=0, dtype=np.float64), xe, axis=1)

    sums = [tiles(a) for a in (re, im, mag)]

    def offset(r: float, i: float, m: float) -> float:
        if m <= 0.0 or math.hypot(r, i) < REGISTRATION_MIN_COHERENCE * m:
            return math.nan
        # a shift s of the code channels to the right turns their phasor by -omega s
        return -math.atan2(i, r) / omega

    whole = offset(*(float(t.sum()) for t in sums))
    out = np.full(sums[0].shape, whole)
    if math.isnan(whole):
        return out
    for a, b in np.ndindex(out.shape):
        own = offset(*(float(t[a, b]) for t in sums))
        if not math.isnan(own):
            out[a, b] = own
    return out


def registration_change(capture_px: np.ndarray, reference_px: np.ndarray | None, *, period_px: float) -> np.ndarray:
    """The capture's registration (:func:`registration_px`) against the reference's, wrapped to
    half a period (``reference_px`` None, of another tiling or NaN: against 0 - calibrated mode,
    where the rig's model has no channel offsets)."""
    change = np.asarray(capture_px, np.float64)
    if reference_px is not None and np.shape(reference_px) == change.shape:
        ref = np.asarray(reference_px, np.float64)
        change = change - np.where(np.isfinite(ref), ref, 0.0)
    return (change + 0.5 * period_px) % period_px - 0.5 * period_px


def registration_shift_px(change_px: np.ndarray | None) -> float:
    """The capture's misregistration as one shift: the median of its tiles'
    :func:`registration_change` (NaN when none was measured).  A channel shifted in processing
    moves every tile alike; a tile's own offset also holds what the light did there - a 45-degree
    corner's interreflection, a glossy box face's - which the median of the image's tiles does not
    follow (tiles of clean captures up to 0.48 px off, their median within 0.02 px but the 45-degree
    corner's, 0.11 px; constants above).  A lens's lateral colour, which varies over the image,
    is left to the reference (in reference mode the reference capture holds it too)."""
    if change_px is None:
        return math.nan
    finite = np.asarray(change_px, np.float64)
    finite = finite[np.isfinite(finite)]
    return float(np.median(finite)) if finite.size else math.nan


def registration_cap(change_px: np.ndarray | None, *, period_px: float) -> float | None:
    """The confidence cap of every pixel: :data:`STABILITY_KAPPA_RAD` over the phase bias the
    fringe would carry had it moved by the capture's shift (:func:`registration_shift_px`) beyond
    :data:`REGISTRATION_FLOOR_PX` (the stability and crease terms' scale); None where it is
    within the floor or not measured (nothing capped)."""
    excess = abs(registration_shift_px(change_px)) - REGISTRATION_FLOOR_PX
    if not excess > 0.0:
        return None
    return float(np.float32(STABILITY_KAPPA_RAD / (2.0 * np.pi * excess / float(period_px))))


def registration_doubt(change_px: np.ndarray | None, *, against_reference: bool, what: str = "capture") -> str:
    """Why the capture's colour channels seem misregistered, from its :func:`registration_change`
    (``against_reference``: the reference capture's subtracted), or "" when its shift (the median
    tile, :func:`registration_shift_px`) is under :data:`REGISTRATION_WARN_PX`."""
    shift = registration_shift_px(change_px)
    if not abs(shift) >= REGISTRATION_WARN_PX:
        return ""
    change = np.asarray(change_px, np.float64)
    lo, hi = float(np.nanmin(change)), float(np.nanmax(change))
    against = "more than the reference capture's do" if against_reference else "where the pattern has them aligned"
    return (
        f"the {what}'s code channels' fringe lies {shift:+.2f} camera px ({lo:+.2f} to {hi:+.2f} over the image) "
        f"from its fringe channel's, {against}: are its colour channels misregistered (a lens's lateral "
        "colour; a demosaicing, resizing or processing step that shifted one channel)? Had the fringe channel "
        "moved, its depths carry a bias of about that many pixels' disparity (the colour-robust decoder's "
        "confidence says so: registration_doubt)"
    )


# The fringe's linearity.  The pattern's fringe is a cosine of the projector's drive; a capture
# whose values encode light non-linearly (an sRGB camera's 8-bit output, a camera's gamma) bends
# it, and its second harmonic, phase-locked to the first (a symmetric bend: cos 2 phi), grows.
# Measured as the coherent ratio sum(H2 conj(H1)^2) / sum(|H1|^3) over the fringe channel's rows
# (demodulated as the registration's): clean captures of the white, dark, dark measured blue and
# saturated orange boards, the printed chart, the step, the bust, the 90-degree corner, the pink
# and cyan clutter and their reference planes, within +-0.007 (the 45-degree corner: no fringe at
# the period, not judged); the same encoded by sRGB -0.13 to -0.17 (gamma 2.2: -0.13 to -0.16; the
# benchmark's darker synthetic plane -0.24), but the 90-degree corner's 0.00 (its faces' fringe runs far off
# the period demodulated at, and the reference plane's -0.17 tells it).  Over this ratio's
# magnitude the decode warns.
NONLINEAR_FRINGE_RATIO = 0.05
# below this share of the channel's RMS in its first harmonic's phasor there is no fringe to judge
# (a noise image read a ratio of +0.05)
FRINGE_PRESENCE = 0.2


def fringe_harmonic_ratio(image: np.ndarray, *, order: list[int], period_px: float) -> float:
    """The fringe channel's second harmonic against its first (constants above): ~0 for a
    linear capture of the pattern, negative where the image's values compress the light (sRGB,
    gamma > 1); NaN where no fringe is read.

    Parameters
    ----------
    image : ndarray, shape (H, W, 3)
        A capture, channels in its own order (``order``: code 1, code 0, fringe).
    period_px : float
        The fringe's period in camera pixels.
    """
    a = np.ascontiguousarray(np.asarray(image)[::REGISTRATION_ROW_STEP, :, order[2]], dtype=np.float32)
    w = a.shape[1]
    box = _box(period_px)
    a = _less_mean(a, box)

    def harmonic(k: int) -> np.ndarray:
        c, s = _phasor(a, k * 2.0 * np.pi / float(period_px), box)
        return c - 1j * s

    edge = _edge(box, w)
    h1, h2 = harmonic(1)[:, edge : w - edge], harmonic(2)[:, edge : w - edge]
    norm = float(np.sum(np.abs(h1) ** 3))
    # a fringe is there: its first harmonic's phasor (A/2 for a cosine of amplitude A) against the
    # channel's RMS (A/sqrt 2): 0.71 for a clean fringe, ~0.05 for noise (the box's average)
    rms = float(np.sqrt(np.mean(a[:, edge : w - edge] ** 2)))
    if not norm > 0.0 or not float(np.mean(np.abs(h1))) > FRINGE_PRESENCE * rms:
        return math.nan
    return float(np.real(np.sum(h2 * np.conj(h1) ** 2)) / norm)


def encoding_doubt(ratio: float, *, what: str = "capture", encoding: str = "linear") -> str:
    """Why the image's fringe seems bent (:func:`fringe_harmonic_ratio` beyond
    :data:`NONLINEAR_FRINGE_RATIO`), read with ``encoding`` (:data:`simbench.io.ENCODINGS`), or
    "".  Negative: the values compress the light (an encoding left in, clipping); positive: they
    expand it (an image linearised that was linear: +0.27 for the benchmark's plane read as sRGB)."""
    if not abs(ratio) > NONLINEAR_FRINGE_RATIO:
        return ""
    head = (
        f"the {what}'s fringe holds a second harmonic {ratio:+.2f} of its first (a linear capture of the pattern: "
        "within +-0.01)"
    )
    if ratio < 0.0 and encoding == "linear":
        why = (
            "are its values gamma-encoded (an sRGB camera's, a camera's gamma)? Then give --encoding srgb or "
            "--encoding gamma=G; else is it saturated, or the projector's output not linear in its drive?"
        )
    elif ratio < 0.0:
        why = (
            f"--encoding {encoding} leaves it compressed: is its encoding another (a larger gamma), or is it saturated?"
        )
    elif encoding == "linear":
        why = "its values expand the light: is the projector's output or the camera's response not linear?"
    else:
        why = f"--encoding {encoding} expands it: was the image linear already (then leave --encoding out)?"
    return f"{head}: {why} A bent fringe loses the colour-robust decoder pixels and biases the depth"
