"""Row bands: the decoder splits a capture into horizontal bands, overlapping by its filters'
reach, and runs them in parallel threads (:func:`run_bands`) (the compiled stages release the interpreter lock).

The band layout depends on the image, the parameters and the rig only, so a decode's result is
the same for any thread count."""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from functools import lru_cache

import numpy as np

from simbench.decode.color import albedo_gain_reach_rows, column_gain_reach_rows, overlay_weight_reach_rows
from simbench.decode.params import DecoderParams
from simbench.decode.profile import run_in_context
from simbench.pattern import check_channels
from simbench.rig import Rig
from simbench.threads import process_threads


def fit_halo_rows(params: DecoderParams, rig: Rig) -> int:
    """The rows above and below a pixel the phase fit reads: its Gaussian window's radius,
    ``ceil(3 sigma_y)`` (:func:`simbench.decode.phase.gaussian_kernel`)."""
    sy = params.sigma_periods * params.camera_period(rig) * params.sigma_y_ratio
    return int(np.ceil(3.0 * sy))


def code_pool_rows(params: DecoderParams, rig: Rig) -> int:
    """The rows above and below a pixel that vote on its code with ``pool_code``
    (:func:`simbench.decode.color.pool_code_rows`): the phase fit's own reach,
    :func:`fit_halo_rows` - the code reads no row the phase does not already stand on; 0
    without ``pool_code``."""
    return fit_halo_rows(params, rig) if params.pool_code else 0


def row_bands(height: int, width: int, params: DecoderParams, rig: Rig) -> tuple[list[tuple[int, int]], int, int]:
    """Row bands, the halo (rows) each needs, and the worker threads: one band per thread, never
    thinner than 4 phase-fit halos (or 32 rows).

    The halo is what a band's rows read beyond themselves: the phase fit's window (3 sigma_y),
    with ``pool_code`` the rows whose code votes on theirs (:func:`code_pool_rows`: their phase
    must be exact too, so the fit's window beyond them as well), with ``weights_down_columns`` the
    rows the overlay's weights are averaged over
    (:func:`simbench.decode.color.overlay_weight_reach_rows`) and, with the albedo flattening, the rows its gain reads
    (:func:`simbench.decode.color.albedo_gain_reach_rows`: the gain of the fit's rows must be the
    whole image's).  With less, a band's rows near its ends would see a gain made of a truncated
    image, and the result would follow the thread count (it did, until 2026-11-26: the
    colour-robust decoder's depth at up to ~46 rows from a band's end, on every capture with an
    albedo step or a shadow).

    (Bands were once also kept under 4 MiB of float32 image each, because first-touching fresh
    huge pages made single-thread decodes slow; the fresh pages came from a reference cycle that
    kept each decode's images alive, and since that is gone one band per thread is the faster
    plan: single-thread 1280x960 decode 15.8 -> 15.2 ms median, 2 threads unchanged.)"""
    fit_halo = fit_halo_rows(params, rig)
    # the pooled code's rows need their phase exact: their own fit window beyond them
    halo = fit_halo + code_pool_rows(params, rig)
    if params.weights_down_columns:
        # the overlay's weights of those rows are means down the columns: their rows as far again
        # (the flattening's gain below is then needed on these rows too)
        halo += overlay_weight_reach_rows(params.camera_period(rig), params.order)
    if params.albedo_flatten:  # (it needs color_normalize: DecoderParams checks)
        halo += albedo_gain_reach_rows(params.camera_period(rig), params.order)
        if params.albedo_columns:
            # the steps along the rows are looked for in the light the column gain leaves: its
            # rows as far again
            halo += column_gain_reach_rows(params.camera_period(rig))
    most = max(1, height // max(4 * fit_halo, 32))
    threads = max(1, params.threads or process_threads())
    n = min(threads, most)
    edges = np.linspace(0, height, n + 1).round().astype(int)
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])], halo, n


def run_bands(fn, image: np.ndarray, params: DecoderParams, rig: Rig) -> list:
    """Apply ``fn(band_with_halo, order, rows, crop)`` to each band, in parallel threads
    (``image`` is a checked capture, each band a view of its rows; ``order``: the channel
    indices of code 1, code 0 and the fringe)."""
    h = image.shape[0]
    bands, halo, workers = row_bands(h, image.shape[1], params, rig)
    order = list(check_channels(params.channels))

    def work(band):
        r0, r1 = band
        a0, a1 = max(0, r0 - halo), min(h, r1 + halo)
        return fn(image[a0:a1], order, slice(r0, r1), slice(r0 - a0, r1 - a0))

    if workers == 1:
        return [work(b) for b in bands]
    return run_in_context(band_pool(os.getpid(), workers), work, bands)


@lru_cache(maxsize=8)
def band_pool(pid: int, workers: int) -> ThreadPoolExecutor:
    """The row bands' worker threads, kept for the process (``pid``: a forked child makes its
    own; it does not inherit the threads): a pool per decode started two threads each time,
    ~1.3 s of a warm quick run's 252 decodes.  Bands hold no state between decodes."""
    return ThreadPoolExecutor(max_workers=workers, thread_name_prefix="simbench-band")
