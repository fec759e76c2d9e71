"""What a capture file went through before the decoder saw it (ours; the paper's decoder has no
such checks): lossy JPEG compression and clipped channels.  Both leave a fringe that decodes at a
fringe SNR above the operating point but biased, so the colour-robust decoder's confidence does
not show it; `simbench decode` and :func:`simbench.depth` warn instead.

Measured on the 25 rendered hard scenes (``results/hard_scenes.md``), their 8-bit captures
re-encoded by OpenCV's JPEG or scaled before clipping, decoded by the colour-robust decoder at
its operating point (decoded pixels more than 5 mm wrong, off the depth edges' 5-px band):

========================  =====================================================
clean                     at most 0.05 % (``hard_stairs_deep``)
JPEG quality 50           up to 1.64 % (4 scenes over 0.1 %), fringe SNR up to 13.7
JPEG quality 75           up to 1.08 % (3 scenes over 0.1 %), fringe SNR up to 15.7
JPEG quality 90 / 95      up to 0.11 / 0.13 %
exposed 2x (clipped)      up to 0.20 %, fringe SNR up to 63
exposed 3x (clipped)      up to 0.84 % (3 scenes over 0.1 %)
========================  =====================================================

The JPEG bias is a phase error of 0.6-1.5 projector px over whole 8x8 blocks (the quantised
cosine coefficients of a fringe whose blue channel JPEG codes mostly in its subsampled chroma); a
clipped run of samples leaves its neighbours' window fits a fringe cut off on one side (-1.7 px
beside one, ``hard_stairs_deep`` exposed 2x).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

__all__ = [
    "JPEG_BLOCK_PX",
    "BLOCK_RATIO_WARN",
    "block_artifacts",
    "compression_doubt",
    "CLIPPED_SHARE_WARN",
    "clipped_share",
    "clipping_doubt",
]

# JPEG's block (ITU-T T.81: 8x8 samples of each component)
JPEG_BLOCK_PX = 8
# the block ratio a capture is warned of from: clean rendered captures (25 hard scenes) read
# 1.00-1.01; re-encoded by OpenCV at JPEG quality 98 1.07-1.55, at 95 1.14 and more, at 90 1.32
# and more; the benchmark plane (tests/test_integrity.py) at 98, 95 and 90 1.38, 2.5 and 5.3, at
# 75 and below inf
BLOCK_RATIO_WARN = 1.1
# the share of clipped pixels a capture is warned of from: a glossy board's highlight clips
# 2.4 % of hard_glossy_005 with no wrong pixel; exposed 2x, 5-21 % of a scene clip and the
# phase beside them is biased (see the module's table)
CLIPPED_SHARE_WARN = 0.05


def block_artifacts(image: np.ndarray) -> float:
    """How strongly ``image`` shows JPEG's 8x8 block grid: at the grid offset where it is
    largest, the median over the blocks of the step across a block's last row boundary (the mean
    over the row and the channels of the absolute difference) over the median of the steps across
    its boundaries 1, 3 and 5 (the same parity: a demosaiced or subsampled image's every-other-row
    pattern cancels).  Rows, not columns: the pattern's stripes run down the image, so within a
    block the rows hardly change and a block's edge stands out.

    Parameters
    ----------
    image : ndarray, shape (H, W, 3) or (H, W), any real dtype

    Returns
    -------
    float; ~1 for an image without blocks, inf for one flat within its blocks but not at their
    edges, NaN for one too small (under 17 rows: two block edges) or flat
    """
    x = np.asarray(image)
    if x.dtype not in (np.uint8, np.uint16, np.float32):
        x = x.astype(np.float32)
    h = x.shape[0]
    if h < 2 * JPEG_BLOCK_PX + 1 or x.size == 0:
        return float("nan")
    flat = np.ascontiguousarray(x).reshape(h, -1)
    # OpenCV's saturating absolute difference and row mean: ~4 ms of a 1280x960 capture (numpy: ~28)
    diff = cv2.absdiff(flat[1:], flat[:-1])
    step = cv2.reduce(diff, 1, cv2.REDUCE_AVG, dtype=cv2.CV_64F).ravel()  # step[i]: rows i | i + 1
    b = JPEG_BLOCK_PX
    best = float("nan")
    for off in range(b):
        n = (step.size - off) // b
        if n < 2:
            continue
        blocks = step[off : off + b * n].reshape(n, b)
        inner, edge = np.median(blocks[:, 1 : b - 1 : 2], axis=1), blocks[:, b - 1]
        # a block flat within but stepping at its edge (compressed hard) counts as inf; one flat
        # throughout not at all; the median over the blocks: an albedo edge along a row does not count
        seen = (inner > 0) | (edge > 0)
        if not seen.any():
            continue
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = float(np.median(edge[seen] / inner[seen]))
        if not math.isnan(ratio) and not ratio <= best:  # NaN best: the first number
            best = ratio
    return best


def compression_doubt(ratio: float, *, what: str = "capture") -> str:
    """Why the image seems JPEG-compressed (:func:`block_artifacts` at or beyond
    :data:`BLOCK_RATIO_WARN`), or ""."""
    if not ratio >= BLOCK_RATIO_WARN:
        return ""
    how = "flat within them" if math.isinf(ratio) else f"{ratio:.2f}x those within them"
    return (
        f"the {what} shows JPEG's 8x8 blocks (steps at the blocks' edges {how}; an uncompressed capture: "
        "~1.0x): lossy compression biases the fringe's phase over whole blocks at a "
        "confidence above the operating point (the hard scenes re-encoded at quality 75: up to 1.1 % of the kept "
        "pixels more than 5 mm off; at 95: 0.13 %). Record PNG or TIFF, uncompressed"
    )


def clipped_share(image: np.ndarray, *, saturation_level: float = 1.0) -> float:
    """The share of ``image``'s pixels with a channel at or above ``saturation_level`` of full
    scale (uint8 / 255, uint16 / 65535, float as is), as the decoder's certainty reads clipping
    (:func:`simbench.decode.phase.certainty_map`).

    Parameters
    ----------
    image : ndarray, shape (H, W, 3) or (H, W), uint8, uint16 or float
    saturation_level : float
        ``DecoderParams.saturation_level``.
    """
    img = np.asarray(image)
    if img.size == 0:
        return 0.0
    full = float(np.iinfo(img.dtype).max) if img.dtype.kind in "ui" else 1.0
    level = np.float64(saturation_level) * full
    if img.ndim == 3 and img.shape[2] == 3 and img.dtype in (np.uint8, np.uint16, np.float32):
        peak = cv2.max(cv2.max(img[..., 0], img[..., 1]), img[..., 2])  # OpenCV's: ~10x numpy's any()
    else:
        peak = img.max(axis=2) if img.ndim == 3 else img
    return float(np.count_nonzero(peak >= level)) / float(peak.size)


def clipping_doubt(share: float, *, what: str = "capture") -> str:
    """Why the image's clipping biases the decode (:func:`clipped_share` at or beyond
    :data:`CLIPPED_SHARE_WARN`), or ""."""
    if not share >= CLIPPED_SHARE_WARN:
        return ""
    return (
        f"{100 * share:.1f} % of the {what}'s pixels are clipped in a colour channel: their samples are skipped, and "
        "the phase beside a clipped run is biased at a confidence above the operating point (the hard scenes "
        "exposed 2x: up to 0.2 % of the kept pixels more than 5 mm off, at a fringe SNR up to 63). Expose shorter"
    )
