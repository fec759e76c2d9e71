"""The decoder alone, on analytic captures computed in numpy (no Mitsuba)."""

import dataclasses
import os
import re

import numpy as np
import pytest

from simbench.decode import DecoderParams, decode, decode_reference
from simbench.decode.color import Stripes
from simbench.decode.debruijn import (
    contested_positions,
    drop_broken_links,
    keep_certain_sides,
    keep_straddler_parts,
    neighbour_correct,
    stripe_floor,
    uncertain_positions,
    window_positions_of_stripes,
)
from simbench.pattern import PatternSpec, de_bruijn, fringe_pattern, quantize, window_positions
from simbench.rig import paper_rig
from simbench.sim.projector import transfer_curve
from simbench.sim.synthetic import synthetic_plane_capture

RIG = paper_rig()
DRIVE = transfer_curve(quantize(fringe_pattern(PatternSpec())), transfer="linear")


@pytest.fixture(scope="module")
def reference():
    img, _, _ = synthetic_plane_capture(DRIVE, RIG, point_m=(0, 0, 1.0))
    return decode_reference(img, rig=RIG, params=DecoderParams())


def _tilted(angle_deg: float, depth: float = 1.0):
    a = np.radians(angle_deg)
    return synthetic_plane_capture(DRIVE, RIG, normal=(np.sin(a), 0.0, -np.cos(a)), point_m=(0, 0, depth))


@pytest.mark.parametrize("mode", ["calibrated", "reference"])
@pytest.mark.parametrize("depth", [0.9, 1.0, 1.3])
def test_noise_free_plane_recovers_projector_column(mode, depth, reference):
    """Exact tier: the column of every valid pixel within 0.02 px RMS (issue 2)."""
    img, col, z = synthetic_plane_capture(DRIVE, RIG, point_m=(0, 0, depth))
    r = decode(img, rig=RIG, params=DecoderParams(mode=mode), reference=reference)
    lit = np.isfinite(col)
    assert r.valid[lit].mean() > 0.99
    err = r.column_px[r.valid] - col[r.valid]
    assert np.sqrt(np.mean(err**2)) < 0.02
    assert np.all(np.abs(err) < 0.5 * 21)  # no stripe-order error
    # depth error implied by 0.02 px of column error: dZ = Z^2 / (f_p * B) * du
    dz = r.depth_m[r.valid] - z[r.valid]
    assert np.sqrt(np.mean(dz**2)) < 0.02 * depth**2 / (RIG.projector.focal_px * RIG.baseline_m)


def test_noise_free_tilted_plane(reference):
    img, col, z = _tilted(30)
    r = decode(img, rig=RIG, params=DecoderParams(mode="calibrated"))
    assert r.valid.mean() > 0.99
    err = r.column_px[r.valid] - col[r.valid]
    assert np.sqrt(np.mean(err**2)) < 0.05  # the fringe is chirped by the tilt
    assert np.all(np.abs(err) < 10.5)


def test_blue_only_mode_also_decodes(reference):
    img, col, _ = synthetic_plane_capture(DRIVE, RIG, point_m=(0, 0, 1.1))
    r = decode(img, rig=RIG, params=DecoderParams(intensity_mode="blue"), reference=reference)
    err = r.column_px[r.valid] - col[r.valid]
    assert r.valid.mean() > 0.99 and np.sqrt(np.mean(err**2)) < 0.02


@pytest.mark.parametrize(
    "image",
    [
        np.zeros((960, 1280, 3), np.uint8),
        np.full((960, 1280, 3), 255, np.uint8),
        np.random.default_rng(0).integers(0, 256, (960, 1280, 3), dtype=np.uint8),
        np.full((960, 1280, 3), 65535, np.uint16),
        np.zeros((960, 1280, 3), np.float64),
    ],
    ids=["dark", "saturated", "noise", "saturated16", "dark-float"],
)
def test_legal_images_never_crash_and_mark_invalid(image, reference):
    variants = [DecoderParams(mode="reference"), DecoderParams(mode="calibrated")]
    variants += [DecoderParams(mode="calibrated", phase_method=m, color_normalize=True) for m in ("ftp", "wfr")]
    for params in variants:
        r = decode(image, rig=RIG, params=params, reference=reference if params.mode == "reference" else None)
        assert r.depth_m.shape == (960, 1280) and r.depth_m.dtype == np.float32
        assert np.array_equal(np.isfinite(r.depth_m), r.valid)
        if image.max() == 0 or image.min() == image.max():
            assert not r.valid.any()


@pytest.mark.parametrize(
    "image, match",
    [
        (np.zeros((480, 640, 3), np.uint8), "rig's camera"),
        (np.zeros((960, 1280), np.uint8), "shape"),
        (np.full((960, 1280, 3), np.nan, np.float32), "NaN"),
        (np.zeros((960, 1280, 3), np.int32), "dtype"),
    ],
)
def test_illegal_images_raise_clearly(image, match, reference):
    with pytest.raises(ValueError, match=match):
        decode(image, rig=RIG, reference=reference)


def test_reference_mode_needs_reference():
    with pytest.raises(ValueError, match="reference"):
        decode(np.zeros((960, 1280, 3), np.uint8), rig=RIG)


def test_decoder_params_validate():
    with pytest.raises(ValueError, match="gabor"):
        DecoderParams(phase_method="nope")
    with pytest.raises(ValueError, match="overlay"):
        DecoderParams(intensity_mode="nope")
    with pytest.raises(ValueError):
        DecoderParams(depth_range_m=(2.0, 1.0))


def test_decode_is_deterministic(reference):
    img, _, _ = synthetic_plane_capture(DRIVE, RIG, point_m=(0, 0, 1.2), supersample=2)
    a = decode(img, rig=RIG, reference=reference)
    b = decode(img, rig=RIG, reference=reference)
    assert np.array_equal(a.depth_m, b.depth_m, equal_nan=True)


def test_neighbour_correction_repairs_a_wrong_code():
    seq = de_bruijn(3)
    table = window_positions(seq, order=3)
    codes = np.tile(seq, 4)
    linked = np.ones(codes.size, bool)
    linked[0] = False
    truth = (np.arange(codes.size) % 8).astype(np.int32)
    assert np.array_equal(window_positions_of_stripes(codes, linked, order=3, table=table, cycle=8)[1:-1], truth[1:-1])
    bad = codes.copy()
    bad[13] ^= 1  # three windows now read wrong positions
    raw = window_positions_of_stripes(bad, linked, order=3, table=table, cycle=8)
    assert np.sum(raw[1:-1] != truth[1:-1]) >= 2
    fixed, support = neighbour_correct(raw, linked, cycle=8, reach=3)
    assert np.array_equal(fixed, truth)
    off, _ = neighbour_correct(raw, linked, cycle=8, reach=0)
    assert np.array_equal(off, raw)


def test_a_run_is_contested_when_the_stripes_on_both_sides_agree_through_it():
    """Two chains of true positions with a run of four stripes between them that reads another
    stretch of the sequence (W + 4): the run's stripes are contested, every other stripe is
    not; a hidden depth edge (the chain after it a whole other stretch) contests nothing."""
    n, cycle = 40, 8
    truth = np.arange(n, dtype=np.int32) % cycle
    linked = np.ones(n, bool)
    linked[0] = False
    run = slice(18, 22)
    misread = truth.copy()
    misread[run] = (truth[run] + 4) % cycle
    kw = dict(cycle=cycle, reach=cycle, min_support=3)
    got = contested_positions(misread, misread, linked, **kw)
    assert np.array_equal(np.flatnonzero(got), np.arange(18, 22))
    dropped = misread.copy()
    dropped[[17, 22]] = -1  # the link check dropped the broken links' outer stripes
    assert np.array_equal(np.flatnonzero(contested_positions(misread, dropped, linked, **kw)), np.arange(18, 22))
    edge = np.where(np.arange(n) < 20, truth, (truth + 3) % cycle).astype(np.int32)
    assert not contested_positions(edge, edge, linked, **kw).any()
    unlinked = linked.copy()
    unlinked[22] = False  # a chain that ends after the run: nothing on its right agrees
    assert not contested_positions(misread, misread, unlinked, **kw)[run].any()


def test_a_chain_of_stripes_read_from_a_few_pixels_is_uncertain():
    """Exact: a short chain (the rows of a dark print's squares: read of stripes on the ink
    around a whole stripe on the paper) that misreads coherently - every window W + 3, as one
    time in four: the neighbour correction keeps it (its windows vote for one another), and with
    nothing on either side of it no rival contests it.  Its read' codes do not count as read,
    so no window of read codes is left and every stripe of it, the whole one too, is uncertain.
    In a long well-read chain a lone uncertain code costs nothing (the windows around it still
    give its position), a run of them only where fewer than ``min_support`` windows are left
    (the decoder's 1: none); dropped stripes are never uncertain."""
    cycle = 8
    kw = dict(cycle=cycle, reach=3, min_support=3)
    truth = np.arange(6, dtype=np.int32)
    linked = np.ones(6, bool)
    linked[0] = False
    misread = (truth + 3) % cycle
    kept, _ = neighbour_correct(misread, linked, **kw)
    assert np.array_equal(kept, misread)
    assert not contested_positions(misread, kept, linked, **{**kw, "reach": cycle}).any()
    read = np.array([False, False, True, False, False, True])
    assert uncertain_positions(misread, kept, linked, read, order=3, **kw).all()
    assert not uncertain_positions(misread, kept, linked, np.ones(6, bool), order=3, **kw).any()
    dropped = np.full(6, -1, np.int32)
    assert not uncertain_positions(misread, dropped, linked, read, order=3, **kw).any()
    n = 40
    long = np.arange(n, dtype=np.int32) % cycle
    chain = np.ones(n, bool)
    chain[0] = False
    lone = np.ones(n, bool)
    lone[10] = False
    assert not uncertain_positions(long, long, chain, lone, order=3, **kw).any()
    run = np.ones(n, bool)
    run[18:23] = False  # windows 17-23 set aside: stripes 18-22 keep two or fewer within 3, 17 and 23 three
    got = np.flatnonzero(uncertain_positions(long, long, chain, run, order=3, **kw))
    assert got.tolist() == [18, 19, 20, 21, 22]
    one = {**kw, "min_support": 1}  # the decoder's: one window of read codes, stripe 20 has none
    assert np.flatnonzero(uncertain_positions(long, long, chain, run, order=3, **one)).tolist() == [20]
    assert uncertain_positions(misread, kept, linked, read, order=3, **one).all()


@pytest.mark.parametrize("order, windows", [(3, [19, 20, 21]), (4, [18, 19, 20, 21]), (5, [18, 19, 20, 21, 22])])
def test_the_windows_set_aside_are_those_holding_an_unread_code(order, windows):
    """Stripe j's window is stripes j - h .. j - h + order - 1, h = (order - 1) // 2
    (window_positions_of_stripes): one unread code (stripe 20) sets aside exactly the windows
    that hold it - with no correction (reach 0) those stripes are the uncertain ones, for the
    asymmetric even-order window too."""
    n, cycle = 40, 1 << order
    truth = np.arange(n, dtype=np.int32) % cycle
    linked = np.ones(n, bool)
    linked[0] = False
    read = np.ones(n, bool)
    read[20] = False
    got = uncertain_positions(truth, truth, linked, read, order=order, cycle=cycle, reach=0, min_support=1)
    assert np.flatnonzero(got).tolist() == windows


def test_stripe_floor_is_the_lowest_value_over_each_stripes_own_pixels():
    values = np.arange(24, dtype=np.float32).reshape(2, 12)[:, ::-1].copy()
    labels = np.full((2, 12), -1, np.int32)
    labels[0, 0:4], labels[0, 4:12], labels[1, 2:9] = 0, 1, 2
    labels[1, 5] = -1  # a bridged gap inside stripe 2: not its own pixel
    values[0, 6] = np.nan
    stripes = Stripes(
        labels=labels,
        row=np.array([0, 0, 1], np.int32),
        start=np.array([0, 4, 2], np.int32),
        stop=np.array([4, 12, 9], np.int32),
        linked_prev=np.array([False, True, False]),
    )
    floor = stripe_floor(values, stripes)
    assert floor.tolist() == [8.0, 0.0, 15.0]  # row 1 holds 11..0; stripe 2 leaves out column 5 (value 6)
    assert stripe_floor(values, Stripes(labels, *(np.empty(0, np.int32),) * 3, np.empty(0, bool))).size == 0


def test_a_broken_link_gives_back_only_the_stripe_with_no_pixel_under_the_operating_point():
    """Exact: a chain whose W skips one (a depth edge the phase ran on across) between stripes 3
    and 4.  Both are dropped; the one whose every pixel is at or above the operating point comes
    back, when the other has a pixel below it and its own far link holds."""
    p = np.array([0, 1, 2, 3, 5, 6, 7], np.int32)
    linked = np.ones(7, bool)
    linked[0] = False
    dropped = drop_broken_links(p, linked, cycle=8)
    assert dropped.tolist() == [0, 1, 2, -1, -1, 6, 7]
    clean, edge = 20.0, 2.0
    floor = np.full(7, clean, np.float32)
    keep = dict(cycle=8, min_confidence=3.0)
    floor[4] = edge
    assert keep_certain_sides(p, dropped, linked, floor, **keep).tolist() == [0, 1, 2, 3, -1, 6, 7]
    floor[3], floor[4] = edge, clean
    assert keep_certain_sides(p, dropped, linked, floor, **keep).tolist() == [0, 1, 2, -1, 5, 6, 7]
    # nothing marks the edge, or both stripes hold it: both stay dropped
    for f3, f4 in ((clean, clean), (edge, edge), (np.nan, clean)):
        floor[3], floor[4] = f3, f4
        assert keep_certain_sides(p, dropped, linked, floor, **keep).tolist() == dropped.tolist()
    # two clean stripes between two broken links, the edges in their outer neighbours: each one's
    # link away from its edge goes to a stripe the other break dropped, so no surviving chain
    # confirms their W - they stay dropped
    p2 = np.array([0, 1, 3, 4, 6, 7], np.int32)
    linked2 = np.ones(6, bool)
    d2 = drop_broken_links(p2, linked2, cycle=8)
    assert d2.tolist() == [0, -1, -1, -1, -1, 7]
    floor2 = np.array([clean, edge, clean, clean, edge, clean], np.float32)
    assert keep_certain_sides(p2, d2, linked2, floor2, **keep).tolist() == d2.tolist()


def test_a_broken_links_straddling_stripe_keeps_its_own_side_of_the_edge():
    """Exact: one row of seven stripes of 10 px, W skipping one between stripes 3 and 4 (an edge
    inside stripe 4, its lowest confidence at its third pixel).  Stripe 4's far link holds, so its
    pixels right of that minimum keep its W and the rest are unlabelled; stripe 3, with no pixel
    under the operating point, stays dropped.  Nothing is split where nothing marks the edge, or
    where the stripe's far link is broken too, or at a level of 0."""
    p = np.array([0, 1, 2, 3, 5, 6, 7], np.int32)
    linked = np.ones(7, bool)
    linked[0] = False
    dropped = drop_broken_links(p, linked, cycle=8)
    labels = np.repeat(np.arange(7, dtype=np.int32), 10)[None, :]
    stripes = Stripes(
        labels,
        np.zeros(7, np.int32),
        np.arange(0, 70, 10, dtype=np.int32),
        np.arange(10, 80, 10, dtype=np.int32),
        linked,
    )
    conf = np.full((1, 70), 20.0, np.float32)
    conf[0, 40:45] = [4.0, 2.5, 1.0, 2.0, 5.0]
    split = dict(cycle=8, min_confidence=3.0)

    def parts(p, dropped, conf, **kw):
        return keep_straddler_parts(p, dropped, linked, stripes, conf, stripe_floor(conf, stripes), **kw)

    out, lab = parts(p, dropped, conf, **split)
    assert out.tolist() == [0, 1, 2, -1, 5, 6, 7]
    assert lab[0, 40:43].tolist() == [-1, -1, -1] and lab[0, 43:50].tolist() == [4] * 7
    assert np.array_equal(lab[0, :40], labels[0, :40]) and np.array_equal(lab[0, 50:], labels[0, 50:])
    assert np.array_equal(stripes.labels, labels)  # the input is left alone
    # the mirror image: the edge in stripe 3, whose left link holds - its left part kept
    conf[0, 40:45] = 20.0
    conf[0, 35:38] = [1.0, 2.0, 2.5]
    out, lab = parts(p, dropped, conf, **split)
    assert out.tolist() == [0, 1, 2, 3, -1, 6, 7]
    assert lab[0, 30:35].tolist() == [3] * 5 and lab[0, 35:40].tolist() == [-1] * 5
    # nothing under the operating point, a level of 0, a far link broken as well, or a far
    # neighbour under the operating point itself: nothing split
    conf[0, 35:38] = 20.0
    assert parts(p, dropped, conf, **split)[0].tolist() == dropped.tolist()
    conf[0, 42] = 1.0
    assert parts(p, dropped, conf, cycle=8, min_confidence=0.0)[0].tolist() == dropped.tolist()
    p3 = np.array([0, 1, 2, 3, 5, 7, 0], np.int32)  # stripe 4 between two broken links
    d3 = drop_broken_links(p3, linked, cycle=8)
    assert parts(p3, d3, conf, **split)[0].tolist() == d3.tolist()
    assert parts(p, dropped, conf, **split)[0].tolist() == [0, 1, 2, -1, 5, 6, 7]
    conf[0, 55] = 2.0  # stripe 5, beyond the holding link, is not clean
    assert parts(p, dropped, conf, **split)[0].tolist() == dropped.tolist()


@pytest.mark.parametrize("mode", ["reference", "calibrated"])
def test_result_does_not_depend_on_threads(mode, reference):
    img, _, _ = _tilted(20, depth=1.1)
    one = decode(img, rig=RIG, params=DecoderParams(mode=mode, threads=1), reference=reference)
    for threads in (2, 3):
        r = decode(img, rig=RIG, params=DecoderParams(mode=mode, threads=threads), reference=reference)
        assert np.array_equal(r.depth_m, one.depth_m, equal_nan=True)
        assert np.array_equal(r.stripe_index, one.stripe_index)
    labels = r.stages["stripe_label"]
    assert labels.shape == (960, 1280)
    # renumbered across bands: one label never spans two bands' rows
    rows_of = {}
    ys, xs = np.nonzero(labels >= 0)
    for y, lab in zip(ys[::97], labels[ys[::97], xs[::97]]):
        rows_of.setdefault(lab, set()).add(y)
    assert all(len(v) == 1 for v in rows_of.values())


def test_band_plan_is_one_band_per_thread_and_splitting_changes_no_bit(reference):
    """Bands cover the rows in order, one per thread (none thinner than 4 halos or 32 rows),
    whatever the image size; decoding in more bands changes no bit."""
    from simbench.decode.bands import row_bands

    for threads in (1, 2, 3, None):
        for h, w in ((960, 1280), (1080, 1920), (3000, 4000), (60, 1280), (5, 7)):
            bands, halo, workers = row_bands(h, w, DecoderParams(threads=threads), RIG)
            assert bands[0][0] == 0 and bands[-1][1] == h and all(a[1] == b[0] for a, b in zip(bands, bands[1:]))
            want = threads or os.cpu_count()
            assert workers == len(bands) == (min(want, h // max(4 * halo, 32)) or 1)
    img, _, _ = _tilted(15, depth=1.05)
    whole = decode(img, rig=RIG, params=DecoderParams(threads=2), reference=reference)
    assert len(row_bands(960, 1280, DecoderParams(threads=6), RIG)[0]) == 6
    split = decode(img, rig=RIG, params=DecoderParams(threads=6), reference=reference)
    assert np.array_equal(split.depth_m, whole.depth_m, equal_nan=True)
    assert np.array_equal(split.stages["stripe_label"], whole.stages["stripe_label"])


def _decode_in_child(img, reference, queue):
    queue.put(decode(img, rig=RIG, params=DecoderParams(threads=2), reference=reference).depth_m)


def test_band_threads_are_kept_and_a_forked_child_starts_its_own(reference):
    """The row bands run on threads kept per process: a second decode starts none, and a child
    forked after a decode (which inherits the pool but not its threads) decodes too, the same."""
    import multiprocessing as mp
    import threading

    img, _, _ = _tilted(10, depth=1.2)
    first = decode(img, rig=RIG, params=DecoderParams(threads=2), reference=reference)
    threads = set(threading.enumerate())
    again = decode(img, rig=RIG, params=DecoderParams(threads=2), reference=reference)
    assert set(threading.enumerate()) == threads and any(t.name.startswith("simbench-band") for t in threads)
    assert np.array_equal(again.depth_m, first.depth_m, equal_nan=True)
    ctx = mp.get_context("fork")
    queue = ctx.Queue()
    child = ctx.Process(target=_decode_in_child, args=(img, reference, queue))
    child.start()
    depth = queue.get(timeout=120)
    child.join(timeout=30)
    assert child.exitcode == 0 and np.array_equal(depth, first.depth_m, equal_nan=True)


def test_custom_sequence_pattern_decodes():
    """Any cyclic binary sequence with unique windows: here B(2, 4) reversed, and a
    12-stripe sequence whose windows of 4 are unique but which is not a De Bruijn sequence."""
    for seq in (tuple(int(c) for c in de_bruijn(4)[::-1]), (0, 0, 0, 1, 1, 0, 1, 0, 1, 1, 1, 1)):
        spec = PatternSpec(order=4, sequence=seq)
        drive = transfer_curve(quantize(fringe_pattern(spec)), transfer="linear")
        img, col, _ = synthetic_plane_capture(drive, RIG, point_m=(0, 0, 1.1))
        r = decode(img, rig=RIG, params=DecoderParams(pattern=spec, mode="calibrated"))
        # a 4-code window reaches two stripes right: the last, partial stripe of each row has
        # no window and only two voting neighbours (min_support 3), so about 1.4 % is lost there
        assert r.valid.mean() > 0.98
        assert np.mean(np.nonzero(~r.valid & np.isfinite(col))[1] > 1200) > 0.95
        err = r.column_px[r.valid] - col[r.valid]
        assert np.sqrt(np.mean(err**2)) < 0.02 and np.all(np.abs(err) < 10.5)


def test_sequence_with_repeated_windows_is_rejected():
    with pytest.raises(ValueError, match="repeats"):
        PatternSpec(order=2, sequence=(0, 1, 0, 1))
    with pytest.raises(ValueError, match="only 0 and 1"):
        DecoderParams(pattern={"sequence": (0, 2, 1)})


@pytest.mark.parametrize(
    "reflectance", [(0.8, 0.04, 0.04), (0.04, 0.8, 0.04), (0.8, 0.04, 0.8)], ids=["red", "green", "pink"]
)
def test_color_normalisation_decodes_coloured_planes(reflectance):
    """A board that absorbs a stripe colour defeats the plain Eq. 9/13 decoder (the red and green
    boards lose most pixels; the pink board's overlay is amplitude-modulated stripe by stripe,
    biasing the phase), while the normalised decoder recovers the column as on white."""
    img, col, _ = synthetic_plane_capture(DRIVE, RIG, point_m=(0, 0, 1.1), supersample=2, albedo=1.0)
    coloured = img * np.asarray(reflectance, np.float32)
    lit = np.isfinite(col)
    plain = decode(coloured, rig=RIG, params=DecoderParams(mode="calibrated"))
    fixed = decode(coloured, rig=RIG, params=DecoderParams(mode="calibrated", color_normalize=True))
    err = fixed.column_px[fixed.valid] - col[fixed.valid]
    assert fixed.valid[lit].mean() > 0.99
    assert np.all(np.abs(err) < 0.5 * 21)
    assert np.sqrt(np.mean(err**2)) < 0.05
    plain_err = plain.column_px[plain.valid] - col[plain.valid]
    plain_rms = np.sqrt(np.mean(plain_err**2)) if plain_err.size else np.inf
    assert plain.valid[lit].mean() < 0.5 or plain_rms > 5 * np.sqrt(np.mean(err**2))


@pytest.mark.parametrize("reflectance", [(0.0, 1.0, 1.0), (1.0, 0.0, 1.0)], ids=["cyan", "pink"])
def test_color_normalisation_reads_code_from_one_channel(reflectance):
    """The paper's-simulation boards that reflect nothing in one code channel (Table 1's cyan and
    pink as linear RGB material colour, 2 % ambient, 8 bits): the code is in the other channel
    alone (a red stripe on cyan is where green is dark), and the normalised decoder reads it
    (:func:`simbench.decode.color.normalized_color_code`).  Comparing with the empty channel's 0
    read nearly every stripe as one code and wrote wrong columns (cyan: 24 % decoded, half of it
    a stripe or more off)."""
    img, col, _ = synthetic_plane_capture(DRIVE, RIG, point_m=(0, 0, 1.1), supersample=2, albedo=1.0)
    rho = np.asarray(reflectance, np.float32)
    lit = np.isfinite(col)
    capture = np.rint(np.clip(0.9 * (img + 0.02) * rho, 0, 1) * 255).astype(np.uint8)
    r = decode(capture, rig=RIG, params=DecoderParams(mode="calibrated", color_normalize=True))
    err = r.column_px[r.valid] - col[r.valid]
    assert r.valid[lit].mean() > 0.99
    assert np.all(np.abs(err) < 0.5 * 21)


def test_normalized_color_code_falls_back_on_the_fringe():
    """Unit cases: both code channels present -> Eq. 13; one absent -> the other against half the
    fringe (or 0.25 without a fringe); neither -> 1 (Eq. 13's tie)."""
    from simbench.decode.color import normalized_color_code

    rgb = np.array([[[0.9, 0.1, 0.9], [0.0, 0.8, 0.9], [0.0, 0.2, 0.9], [0.6, 0.0, 0.0], [0.1, 0.0, 0.0], [0, 0, 0.5]]])
    span = np.array([[[1, 1, 1], [0, 1, 1], [0, 1, 1], [1, 0, 0], [1, 0, 0], [0, 0, 1]]], np.float32)
    assert normalized_color_code(rgb.astype(np.float32), span).tolist() == [[True, False, True, True, False, True]]


def test_without_checks_switches_exactly_the_named_checks_off():
    from simbench.decode import PAPER_ADDED_CHECKS, without_checks

    base = DecoderParams()
    assert without_checks(base, "none") == base
    for name, check in PAPER_ADDED_CHECKS.items():
        off = without_checks(base, name)
        changed = {f for f in check.off if getattr(off, f) != getattr(base, f)}
        assert changed == set(check.off), name  # each check is on by default, and only its fields move
    assert without_checks(base, "all") == without_checks(base, list(PAPER_ADDED_CHECKS))
    with pytest.raises(ValueError, match="unknown decoder check.*valid"):
        without_checks(base, ["lit_test", "voting"])


def test_the_residual_check_is_what_stands_between_a_red_board_and_wrong_depths():
    """The paper's decoder on a red paint board (0.8, 0.04, 0.04), noise-free: its Eq. 9 overlay is
    the fringe in the red stripes and 1/20 of it in the green ones, so a Gabor window over both
    fits badly.  The residual check (ours, PAPER_ADDED_CHECKS) rejects those fits (nothing
    decodes); switched off, the decoder writes depths from them: 81 % of the pixels, 40 % of
    those more than half a projector pixel off (up to 3.5 px; measured)."""
    from simbench.decode import without_checks

    img, col, _ = synthetic_plane_capture(DRIVE, RIG, point_m=(0, 0, 1.1), supersample=2, albedo=1.0)
    red = img * np.asarray((0.8, 0.04, 0.04), np.float32)
    lit = np.isfinite(col)
    base = DecoderParams(mode="calibrated")
    with_check = decode(red, rig=RIG, params=base)
    without = decode(red, rig=RIG, params=without_checks(base, "max_residual"))
    assert without.valid[lit].mean() > with_check.valid[lit].mean() + 0.5
    err = np.abs(without.column_px - col)[without.valid & ~with_check.valid]
    assert (err > 0.5).mean() > 0.3


def test_color_normalisation_keeps_white_plane_accuracy(reference):
    img, col, _ = synthetic_plane_capture(DRIVE, RIG, point_m=(0, 0, 1.1))
    ref = synthetic_plane_capture(DRIVE, RIG, point_m=(0, 0, 1.0))[0]
    p = DecoderParams(color_normalize=True)
    r = decode(img, rig=RIG, params=p, reference=decode_reference(ref, rig=RIG, params=p))
    err = r.column_px[r.valid] - col[r.valid]
    assert r.valid.mean() > 0.99 and np.sqrt(np.mean(err**2)) < 0.02


@pytest.mark.parametrize("channels", ["rbg", "gbr"])
def test_other_channel_assignments_decode(channels):
    """A pattern with the fringe in green or red decodes like the paper's once the decoder is
    told (exact tier, 0.02 px).  Told the paper's layout instead, the fringe-in-red pattern fails
    (R >= G everywhere: every code reads 1); the fringe-in-green one happens to survive in a
    noise-free image (its red stripes equal the green fringe, and Eq. 13 says R >= G)."""
    drive = transfer_curve(quantize(fringe_pattern(PatternSpec(channels=channels))), transfer="linear")
    img, col, _ = synthetic_plane_capture(drive, RIG, point_m=(0, 0, 1.1))
    r = decode(img, rig=RIG, params=DecoderParams(mode="calibrated", pattern=PatternSpec(channels=channels)))
    err = r.column_px[r.valid] - col[r.valid]
    assert r.valid.mean() > 0.99 and np.sqrt(np.mean(err**2)) < 0.02
    if channels == "gbr":
        wrong = decode(img, rig=RIG, params=DecoderParams(mode="calibrated"))
        assert (wrong.valid & (np.abs(wrong.column_px - col) < 0.5)).mean() < 0.5
    with pytest.raises(ValueError, match="permutation of 'rgb'"):
        DecoderParams(pattern={"channels": "rgx"})


def test_repeated_decodes_are_bit_identical(reference):
    """Same capture, same bits: across repeated runs (fresh buffers at other addresses) and
    whatever OpenCV's own thread count is."""
    import cv2

    img, _, _ = synthetic_plane_capture(DRIVE, RIG, point_m=(0, 0, 1.2), supersample=2)
    saved = cv2.getNumThreads()
    try:
        results = []
        for n in (1, 8, 8, 8, 8, 8):
            cv2.setNumThreads(n)
            results.append(decode(img, rig=RIG, params=DecoderParams(), reference=reference))
            assert cv2.getNumThreads() == n
    finally:
        cv2.setNumThreads(saved)
    a = results[0]
    for b in results[1:]:
        assert np.array_equal(a.confidence, b.confidence) and np.array_equal(a.depth_m, b.depth_m, equal_nan=True)
        assert np.array_equal(a.stages["fit_residual"], b.stages["fit_residual"])


def test_magnitude_does_not_depend_on_buffer_alignment():
    """cv2.magnitude (Intel IPP) changes its last bit with the buffers' alignment; the
    decoder's own magnitude must not (it decides which amplitude a pixel gets)."""
    from simbench.decode.phase import magnitude

    rng = np.random.default_rng(3)

    def shifted(a, off):
        buf = np.empty(a.size + 32, np.float32)
        start = (-(buf.ctypes.data // 4)) % 16 + off
        view = buf[start : start + a.size].reshape(a.shape)
        view[...] = a
        return view

    for shape in ((40, 1280), (37, 1280), (33, 1824)):
        re, im = rng.normal(size=(2, *shape)).astype(np.float32)
        want = np.sqrt(re.astype(np.float64) ** 2 + im.astype(np.float64) ** 2).astype(np.float32)
        first = magnitude(re, im)
        np.testing.assert_allclose(first, want, rtol=2e-7)
        for off in range(16):
            assert np.array_equal(magnitude(shifted(re, off), shifted(im, off)), first), (shape, off)


def test_a_dropped_result_frees_its_images_without_the_cyclic_collector(reference):
    """A decode makes no reference cycles, so its band images are freed as soon as its result
    is: a cycle (a stage closing over the stages holding it) kept ~40 MB a decode alive until
    the cyclic collector ran, and every decode then wrote into freshly faulted pages."""
    import gc

    from simbench.decode.pipeline import LazyStages

    img, _, _ = _tilted(10, depth=1.1)
    gc.collect()
    enabled = gc.isenabled()
    gc.disable()
    try:
        r = decode(img, rig=RIG, params=DecoderParams(threads=2), reference=reference)
        assert r.stages["triangulated"].shape == img.shape[:2]  # a stage made from another one
        del r
        gc.set_debug(gc.DEBUG_SAVEALL)
        found = gc.collect()
        kinds = sorted({type(o).__name__ for o in gc.garbage})
    finally:
        gc.set_debug(0)
        gc.garbage.clear()
        if enabled:
            gc.enable()
    assert found == 0, kinds
    st = LazyStages()
    st.put("a", np.ones(3))
    st.put("b", lambda s: 2 * s["a"], derived=True)
    assert st["b"].tolist() == [2.0, 2.0, 2.0]
    with pytest.raises(TypeError, match="derived stage needs a function"):
        st.put("c", np.ones(3), derived=True)


@pytest.mark.parametrize(("b", "sigma"), [(0.3, 0.01), (0.1, 0.02), (0.2, 0.06)])
def test_confidence_is_the_fringe_rms_over_the_noise_rms(b, sigma):
    """Statistical tier: for a cosine of amplitude B under white noise of standard deviation
    sigma, the fringe SNR (simbench.decode.phase.fringe_snr) is B / (sigma sqrt 2).  Tolerance
    5 %: the fit's three parameters absorb ~3 of the window's ~(4 pi sigma_x sigma_y) effective
    samples, which raises the SNR by ~2 % at the decoder's window (measured 2-3 %)."""
    from simbench.decode.phase import fringe_snr, gabor_phase

    rng = np.random.default_rng(7)
    h, w, t = 160, 320, 12.0
    x = np.arange(w)[None, :] * np.ones((h, 1))
    img = (0.4 + b * np.cos(2 * np.pi * x / t + 0.3) + rng.normal(0.0, sigma, (h, w))).astype(np.float32)
    fit = gabor_phase(
        img, certainty=np.ones((h, w), np.float32), period_px=t, sigma_x_px=0.25 * t, sigma_y_px=0.15 * t, offset=False
    )
    snr = np.median(fringe_snr(fit.residual)[20:-20, 20:-20])
    assert snr == pytest.approx(b / (sigma * np.sqrt(2.0)), rel=0.05)


def test_confidence_of_an_unfit_or_perfect_window():
    from simbench.decode.phase import MAX_FRINGE_SNR, fringe_snr

    got = fringe_snr(np.array([[np.nan, np.inf, 0.0, 0.5, -1.0]], np.float32))
    assert got.dtype == np.float32
    assert got.tolist() == [[0.0, 0.0, MAX_FRINGE_SNR, 2.0, 0.0]]


def test_the_operating_point_turns_doubtful_pixels_into_holes_and_keeps_their_confidence(reference):
    """min_confidence: the decode with no threshold, less the pixels whose confidence is below it
    (bit for bit); their confidence stays, the rest of the output is that of a hole."""
    rng = np.random.default_rng(3)
    img, _, _ = _tilted(25, 1.1)
    noisy = np.clip(img + rng.normal(0.0, 0.04, img.shape), 0.0, 1.0).astype(np.float32)
    base = DecoderParams(mode="calibrated")
    everything = decode(noisy, rig=RIG, params=base)
    threshold = float(np.quantile(everything.confidence[everything.valid], 0.3))
    kept = decode(noisy, rig=RIG, params=DecoderParams(mode="calibrated", min_confidence=threshold))
    doubtful = everything.valid & (everything.confidence < threshold)
    assert 0.2 < doubtful.sum() / everything.valid.sum() < 0.4
    assert np.array_equal(kept.valid, everything.valid & ~doubtful)
    assert np.array_equal(kept.confidence, everything.confidence)
    assert np.isnan(kept.depth_m[doubtful]).all() and np.isnan(kept.column_px[doubtful]).all()
    assert (kept.stripe_index[doubtful] == -1).all()
    same = kept.valid
    assert np.array_equal(kept.depth_m[same], everything.depth_m[same])
    assert np.array_equal(kept.column_px[same], everything.column_px[same])
    from simbench.decode.pipeline import apply_min_confidence

    after = apply_min_confidence(everything, threshold)
    for name in ("depth_m", "valid", "confidence", "column_px", "stripe_index"):
        assert np.array_equal(getattr(after, name), getattr(kept, name), equal_nan=True), name


def test_the_paper_decoder_has_no_operating_point_and_the_robust_one_has():
    from simbench.decode import ROBUST_MIN_CONFIDENCE, robust_params

    assert DecoderParams().min_confidence == 0.0
    assert robust_params().min_confidence == ROBUST_MIN_CONFIDENCE > 0.0
    with pytest.raises(ValueError, match="min_confidence"):
        DecoderParams(min_confidence=-1.0)


@pytest.mark.parametrize("dark", [0.05, 0.3])
def test_phase_stability_flags_the_pixels_an_albedo_step_biases(dark):
    """Exact tier: a noise-free fringe on a print whose albedo steps from 1 to ``dark`` across
    the stripes, fitted as it is (no albedo flattening).  Every pixel whose phase the window's
    straddling biases by more than 0.15 rad (0.5 projector px, ~2.4 mm at 1 m) scores below 3
    once the stability term is folded in; away from the step the confidence is the fringe SNR.
    On the milder step the fringe SNR alone lets such a pixel through (measured: x = 120,
    0.19 rad off at SNR 3.4, the phase moving 0.14 rad when the window is halved).  The
    colour-robust decoder's operating point is 3 (ROBUST_MIN_CONFIDENCE); it also flattens
    printed steps before the fit (``albedo_flatten``, tests/test_robust_decoder.py), so that
    its windows do not see them.  (At a threshold of 2, as it was for a while, such a raw step
    keeps pixels up to 0.26 rad (0.05) and 0.41 rad (0.3) off.)"""
    from simbench.decode import ROBUST_MIN_CONFIDENCE, STABILITY_KAPPA_RAD, STABILITY_WINDOW_SCALE
    from simbench.decode.phase import fringe_snr, gabor_phase
    from simbench.decode.pipeline import phase_change

    h, w, t = 80, 240, 12.4
    x = np.arange(w)[None, :] * np.ones((h, 1))
    true = np.angle(np.exp(1j * (2 * np.pi * (x + 0.5) / t - np.pi + 0.7)))
    img = (np.where(x < 120.3, 1.0, dark) * (0.5 + 0.5 * np.cos(true))).astype(np.float32)
    kw = dict(certainty=np.ones((h, w), np.float32), period_px=t, sigma_y_px=0.15 * t, offset=False)
    wide = gabor_phase(img, sigma_x_px=0.25 * t, **kw)
    narrow = gabor_phase(img, sigma_x_px=0.25 * t * STABILITY_WINDOW_SCALE, **kw)
    snr = fringe_snr(wide.residual)[40]
    with np.errstate(divide="ignore"):
        conf = np.fmin(snr, STABILITY_KAPPA_RAD / phase_change(wide.wrapped, narrow.wrapped)[40])
    biased = phase_change(wide.wrapped, true)[40] > 0.15
    assert 3 <= biased.sum() <= 12 and (np.abs(np.nonzero(biased)[0] - 121) <= 8).all()
    assert (conf[biased] < 3.0).all()
    if dark == 0.3:
        assert (snr[biased] >= 3.0).any()
    assert ROBUST_MIN_CONFIDENCE == 3.0
    assert (conf[phase_change(wide.wrapped, true)[40] > 0.42] < 2.0).all()
    far = slice(20, 100)
    assert np.array_equal(conf[far], snr[far]) and (conf[far] > 100).all()


@pytest.mark.parametrize("noise", [0.0, 0.03])
def test_the_narrow_windows_snr_admits_pixels_beside_a_phase_jump_not_on_it(noise):
    """A fringe whose phase jumps at x = 120.3 (a depth edge: the two surfaces' fringes; the far
    side equally bright or 0.6 as bright), fitted as the colour-robust decoder fits it.  Beside
    the jump the wide window's far-side share c raises its residual as sqrt(c) but biases its
    phase only as c: with ``narrow_snr`` the narrow window's SNR admits pixels the wide SNR held
    under 3 (>= 1 a row on the pi jump), each within 0.25 rad of the truth (0.8 projector px, no
    worse than what the wide SNR alone admits on the same rows: up to 0.24 rad on the milder
    jumps).  On the jump itself the narrow window is as mixed as the wide one and its fit can still
    look clean: taking its SNR everywhere admits pixels 0.5-1 rad off (measured), which
    ``off_discontinuity`` keeps out.  Noise 0.03 of full scale: SNR ~12 away from the jump."""
    from simbench.decode import STABILITY_KAPPA_RAD, STABILITY_WINDOW_SCALE
    from simbench.decode.phase import fringe_snr, gabor_phase, off_discontinuity
    from simbench.decode.pipeline import phase_change

    h, w, t = 80, 240, 12.4
    x = np.arange(w)[None, :] * np.ones((h, 1))
    rng = np.random.default_rng(7)
    unguarded_worst = 0.0
    for jump in (np.pi / 2, 2 * np.pi / 3, np.pi, -np.pi / 2):
        for far_side in (1.0, 0.6):
            true = np.angle(np.exp(1j * (2 * np.pi * (x + 0.5) / t - np.pi + 0.7 + np.where(x < 120.3, 0.0, jump))))
            img = np.where(x < 120.3, 1.0, far_side) * (0.5 + 0.5 * np.cos(true)) + rng.normal(0.0, noise, x.shape)
            kw = dict(certainty=np.ones((h, w), np.float32), period_px=t, sigma_y_px=0.15 * t, offset=False)
            wide = gabor_phase(img.astype(np.float32), sigma_x_px=0.25 * t, **kw)
            narrow = gabor_phase(img.astype(np.float32), sigma_x_px=0.25 * t * STABILITY_WINDOW_SCALE, **kw)
            snr, snr_n = fringe_snr(wide.residual), fringe_snr(narrow.residual)
            with np.errstate(divide="ignore"):
                stability = STABILITY_KAPPA_RAD / phase_change(wide.wrapped, narrow.wrapped)
            off = off_discontinuity(wide.residual, sigma_x_px=0.25 * t)
            old = np.fmin(snr, stability)
            new = np.fmin(np.where(off, np.fmax(snr, snr_n), snr), stability)
            unguarded = np.fmin(np.fmax(snr, snr_n), stability)
            err = phase_change(wide.wrapped, true)
            gained = (new >= 3) & (old < 3)
            assert (new >= old).all()
            assert not gained.any() or err[gained].max() <= 0.25, (jump, far_side, err[gained].max())
            if jump == np.pi:
                assert gained.sum() >= h, (far_side, gained.sum())
            unguarded_worst = max(unguarded_worst, float(err[(unguarded >= 3) & (old < 3)].max(initial=0.0)))
    assert unguarded_worst > 0.5


def test_the_robust_decoders_confidence_is_the_lower_of_its_two_terms(reference):
    """End to end: DecodeResult.confidence is, where a depth came out, the stage ``confidence``:
    fmin(fringe SNR, kappa / phase change) of the stages ``fit_residual`` and ``phase_change``,
    with ``narrow_snr`` the SNR the higher of the wide and the narrow fit's (``narrow_fit_residual``)
    off the discontinuities; the paper's decoder has no phase_change stage and its confidence is
    the fringe SNR."""
    from simbench.decode import STABILITY_KAPPA_RAD
    from simbench.decode.phase import fringe_snr, off_discontinuity

    rng = np.random.default_rng(5)
    img, _, _ = _tilted(20, 1.05)
    near, _, _ = synthetic_plane_capture(DRIVE, RIG, point_m=(0, 0, 0.98))
    img[:, 700:] = near[:, 700:]  # a depth edge: the narrow window's SNR has pixels beside it to count
    noisy = np.clip(img + rng.normal(0.0, 0.02, img.shape), 0.0, 1.0).astype(np.float32)
    for stability, narrow_snr in ((False, False), (True, False), (True, True)):
        p = DecoderParams(mode="calibrated", phase_stability=stability, narrow_snr=narrow_snr)
        r = decode(noisy, rig=RIG, params=p)
        snr = fringe_snr(r.stages["fit_residual"])
        if stability:
            if narrow_snr:
                off = off_discontinuity(r.stages["fit_residual"], sigma_x_px=p.sigma_periods * p.camera_period(RIG))
                snr = np.where(off, np.fmax(snr, fringe_snr(r.stages["narrow_fit_residual"])), snr)
                assert off.any() and (snr[r.valid] > fringe_snr(r.stages["fit_residual"])[r.valid]).any()
            with np.errstate(divide="ignore"):
                want = np.fmin(snr, np.float32(STABILITY_KAPPA_RAD) / r.stages["phase_change"])
            assert (want[r.valid] < snr[r.valid]).any()
        else:
            assert "phase_change" not in r.stages
            want = snr
        assert np.array_equal(r.confidence[r.valid], want[r.valid])
        assert np.array_equal(r.stages["confidence"], want)


def test_with_changes_is_the_one_way_from_names_to_decoder_settings():
    """The command line's --decoder name=value and an ablation's decoder.* axes both go through
    simbench.decode.with_changes: lists become tuples for tuple fields, ``without`` switches the
    added checks off, an unknown name lists the valid ones."""
    from simbench.decode import DecoderParams, with_changes, without_checks

    base = DecoderParams()
    got = with_changes(base, {"depth_range_m": [0.5, 2.0], "phase_method": "ftp", "without": ["link_check"]})
    assert got.depth_range_m == (0.5, 2.0) and got.phase_method == "ftp"
    assert got == without_checks(dataclasses.replace(base, depth_range_m=(0.5, 2.0), phase_method="ftp"), "link_check")
    assert with_changes(base, {}) == base
    with pytest.raises(ValueError, match=r"unknown decoder setting\(s\) \['sigma'\]; valid: .*sigma_periods"):
        with_changes(base, {"sigma": 1.0})


def test_decoder_assignments_take_without_repeated_and_any_other_name_once():
    """A user's audit (2026-11-30): ``--decoder without=lit_test without=max_residual`` switched
    off max_residual alone (the last value won), and ``voting=false voting=true`` decoded with
    voting.  ``without`` accumulates (repeated or a list); another name given twice is refused."""
    from simbench.decode import DecoderParams, with_assignments, without_checks

    both = without_checks(DecoderParams(), ["lit_test", "max_residual"])
    assert with_assignments(DecoderParams(), ["without=lit_test", "without=max_residual"]) == both
    assert with_assignments(DecoderParams(), ['without=["lit_test", "max_residual"]']) == both
    assert with_assignments(DecoderParams(), ["without=lit_test", "voting=false"]).voting is False
    with pytest.raises(ValueError, match=r"--decoder: voting is given twice \(False and True\): give it once"):
        with_assignments(DecoderParams(), ["voting=false", "voting=true"])


def test_the_narrow_snr_stands_only_where_the_wide_window_is_clean_enough_itself():
    """off_discontinuity: beside a residual peak, a pixel whose wide residual is low relative to
    the peak but whose wide SNR is under NARROW_SNR_MIN_WIDE_SNR (its far side large in absolute
    terms) is not off the discontinuity; one above it is; the peak itself never is."""
    from simbench.decode.phase import NARROW_SNR_MIN_WIDE_SNR, off_discontinuity

    floor = 1.0 / NARROW_SNR_MIN_WIDE_SNR
    r = np.full((1, 41), 0.05, np.float32)
    r[0, 20] = 2.0  # the discontinuity
    r[0, 23] = 1.2 * floor  # a third of the peak, but wide SNR under the floor
    r[0, 17] = 0.8 * floor  # wide SNR over the floor
    off = off_discontinuity(r, sigma_x_px=5.0)[0]
    assert not off[20] and not off[23] and off[17]


def test_crease_bias_is_the_concave_second_difference_and_nothing_else():
    """Closed form: a column map whose slope drops by k at x0 (concave for a rig whose column
    grows with depth) predicts ratio * k * (L - |x - x0|) within L of x0 and 0 beyond; the mirror
    (convex) break, a plane, and a break with a depth step or a hole within reach predict 0."""
    from simbench.decode.depth import crease_bias

    x = np.arange(200, dtype=np.float64)
    k, x0, reach, ratio = 0.25, 100, 22, 0.3  # slopes and values exact in float32
    concave = np.where(x < x0, x, x0 + (1.0 - k) * (x - x0))
    maps = np.stack([concave, 2 * x0 - concave[::-1], 0.5 * x + 3.0, concave, concave]).astype(np.float32)
    maps[3, 110:] += 5.0  # a depth edge 10 px from the crease
    maps[4, 85] = np.nan  # a hole 15 px from it
    got = crease_bias(maps, scale_px=reach, depth_sign=1.0, bias_ratio=ratio, max_step_px=3.0)
    want = ratio * k * np.clip(reach - np.abs(x - x0), 0.0, None)
    np.testing.assert_allclose(got[0], want, atol=2e-5)
    assert np.array_equal(got[1:3], np.zeros((2, 200), np.float32))
    assert np.all(got[3, 110 - reach : 110 + reach] == 0.0) and got[3, 80] > 0.0
    assert np.all(got[4, 85 - reach : 85 + reach + 1] == 0.0) and got[4, 115] > 0.0
    mirrored = crease_bias(maps[1:2], scale_px=reach, depth_sign=-1.0, bias_ratio=ratio, max_step_px=3.0)
    np.testing.assert_allclose(mirrored[0], want[::-1], atol=2e-5)  # the other rig: the other sign
    # down a crease the rows' mean: a crease with noise of 0.3 px and one of a single row's
    rng = np.random.default_rng(2)
    noisy = np.tile(concave, (41, 1)).astype(np.float32) + rng.normal(0.0, 0.3, (41, 200)).astype(np.float32)
    alone, averaged = (
        crease_bias(noisy, scale_px=reach, depth_sign=1.0, bias_ratio=ratio, max_step_px=3.0, rows_reach=r)
        for r in (0, 20)
    )
    far = np.abs(x - x0) > reach
    assert (alone[:, far] > 0.3).mean() > 10 * (averaged[:, far] > 0.3).mean()  # noise averaged away
    assert np.abs(averaged[20, x0] - want[x0]) < 0.2  # the crease kept
    short = np.zeros((41, 200), np.float32) + x.astype(np.float32)
    short[20] = concave
    got = crease_bias(short, scale_px=reach, depth_sign=1.0, bias_ratio=ratio, max_step_px=3.0, rows_reach=20)
    np.testing.assert_allclose(got[20], want / 41, atol=2e-6)  # one row's break over the mean's 41 rows


def test_the_crease_prediction_is_raised_at_a_folds_apex_and_not_at_a_prints_bend():
    """Closed form: a column map whose slope drops at x0 (a fold) gets crease_bias's prediction
    times apex_factor within apex_px of its apex, and as it was beyond; an S-shaped bend (a print's
    step: concave, then as deep convex) and a map with no bias are left as they are.  The
    90-degree corner kept 0.51 % of its decoded pixels 5-7 mm wrong at its crease's apex without
    this (2026-11-30)."""
    from simbench.decode.depth import crease_apex_bias, crease_bias

    x = np.arange(300, dtype=np.float64)
    k, x0, reach = 0.25, 150, 22
    fold = np.where(x < x0, x, x0 + (1.0 - k) * (x - x0))
    # an S: the slope drops by k at x0 and rises back by k 30 px on (concave, then convex)
    s_bend = fold + np.where(x > x0 + 30, k * (x - x0 - 30), 0.0)
    maps = np.tile(np.stack([fold, s_bend]).astype(np.float32)[:, None, :], (1, 41, 1)).reshape(82, 300)
    kw = dict(scale_px=reach, depth_sign=1.0)
    bias = crease_bias(maps, bias_ratio=0.3, max_step_px=3.0, rows_reach=reach, **kw)
    assert bias[20, x0] > 0.3 * k * reach * 0.9 and bias[61, x0] > 0.3 * k * reach * 0.9  # both predicted
    got = crease_apex_bias(bias, maps, peak_px=10, apex_px=8, apex_factor=0.55 / 0.3, lobe_share=0.3, **kw)
    near = np.abs(x - x0) <= 8
    np.testing.assert_allclose(got[20, near], 0.55 / 0.3 * bias[20, x0], rtol=1e-6)  # the apex's, raised
    assert np.array_equal(got[20, ~near], bias[20, ~near])
    assert np.array_equal(got[41:], bias[41:])  # the print's S: its convex lobe as deep as its concave one
    assert np.all(got >= bias)
    # an apex under min_px is not raised (a plane's fitted ripple): the prediction comes back as it was
    small = crease_apex_bias(
        bias, maps, peak_px=10, apex_px=8, apex_factor=0.55 / 0.3, lobe_share=0.3, min_px=10.0, **kw
    )
    assert small is bias
    flat = np.zeros((5, 300), np.float32)
    assert crease_apex_bias(flat, maps[:5], peak_px=10, apex_px=8, apex_factor=2.0, lobe_share=0.3, **kw) is flat


def test_edge_bend_bias_is_the_maps_distance_from_its_line_beside_an_edge_and_nothing_else():
    """Closed form: a plane's linear column map bent by ``b(k)`` at the ``k``-th pixel before a
    hole or a depth step reads ``|b(k)|`` within the reach of it and 0 beyond; the straight map
    beside the same edges, the row's own ends, and a run shorter than reach + fit read 0."""
    from simbench.decode.depth import edge_bend_bias

    reach, fit = 11, 22
    x = np.arange(200, dtype=np.float64)
    line = 0.5 * x + 300.0  # values exact in float32
    bend = np.zeros(200)
    bend[90:100] = -0.125 * np.arange(1, 11)  # towards the hole at 100: -0.125 .. -1.25 px
    ends = np.zeros(200)
    ends[:10] = 0.125 * np.arange(10, 0, -1)  # bent at both of the row's own ends, as before a hole
    ends[190:] = -0.125 * np.arange(1, 11)
    maps = np.stack([line, line + bend, line, line + bend, line, line + ends]).astype(np.float32)
    maps[:2, 100:108] = np.nan  # a hole
    maps[2:4, 100:] += 40.0  # a depth step, no hole
    maps[4, 30:] = np.nan  # a 30-px run from the row's start: shorter than reach + fit
    got = edge_bend_bias(maps, reach_px=reach, fit_px=fit, max_step_px=3.0)
    want = np.abs(bend).astype(np.float32)
    assert np.all(got[[0, 2, 4]] < 1e-4)  # the straight map: float32 rounding of 300-400 px only
    np.testing.assert_allclose(got[1, :100], want[:100], atol=1e-4)
    np.testing.assert_allclose(got[3], want, atol=1e-4)  # the far side of the step: straight
    assert np.all(got[1, 108:] < 1e-4)  # after the hole, straight
    assert np.all(got[:, :89] == 0.0) and np.all(got[5] == 0.0)  # the row's own ends are no edge
    # ... but a hole is: the same row with one undecoded pixel after its end reads the bend there
    holed = np.append(maps[5], np.float32(np.nan))[None, :]
    got = edge_bend_bias(holed, reach_px=reach, fit_px=fit, max_step_px=3.0)[0]
    np.testing.assert_allclose(got[189:200], np.abs(ends[189:200]), atol=1e-4)
    assert np.all(got[:189] == 0.0) and got[199] > 1.2
    with pytest.raises(ValueError, match="column_px"):
        edge_bend_bias(np.zeros(5, np.float32), reach_px=reach, fit_px=fit, max_step_px=3.0)
    # down the columns: the same maps turned a quarter read the same, turned back
    turned = np.ascontiguousarray(maps.T)
    alone = edge_bend_bias(turned, reach_px=0, fit_px=0, max_step_px=3.0, reach_y_px=reach, fit_y_px=fit)
    assert np.array_equal(alone, edge_bend_bias(maps, reach_px=reach, fit_px=fit, max_step_px=3.0).T)
    # both passes on one map with an edge of each kind: the larger of the two, each one's own
    plane = np.tile(line.astype(np.float32), (200, 1))
    plane[40:50, :] += bend[90:100, None].astype(np.float32)  # bent down the columns (-0.125 .. -1.25)
    plane[50:58, 60:160] = np.nan  # ... towards a hole across the rows
    plane[120:130, :] += bend.astype(np.float32)  # bent along the rows
    plane[120:130, 100:108] = np.nan  # ... towards a hole in them
    rows = edge_bend_bias(plane, reach_px=reach, fit_px=fit, max_step_px=3.0)
    cols = edge_bend_bias(plane, reach_px=0, fit_px=0, max_step_px=3.0, reach_y_px=reach, fit_y_px=fit)
    both = edge_bend_bias(plane, reach_px=reach, fit_px=fit, max_step_px=3.0, reach_y_px=reach, fit_y_px=fit)
    assert np.array_equal(both, np.maximum(rows, cols))
    assert rows[125, 99] > 1.2 and cols[125, 99] < 1e-4  # the hole in the rows: the rows' pass alone
    assert cols[49, 100] > 1.0 and rows[49, 100] < 1e-4  # the bend towards the hole below: the columns'


def _corner_capture(opening_deg: float, crease_m: float = 1.2):
    """A vertical crease at x = 0, z = crease_m, opening towards the camera (concave, < 180 deg)
    or away from it (a ridge, > 180 deg), noise-free: each pixel the nearer face (concave) or the
    farther (ridge)."""
    tilt = np.radians(90.0 - opening_deg / 2.0)
    faces = [
        synthetic_plane_capture(DRIVE, RIG, normal=(s * np.sin(tilt), 0.0, -np.cos(tilt)), point_m=(0, 0, crease_m))
        for s in (-1.0, 1.0)
    ]
    pick = np.nanargmin if opening_deg < 180 else np.nanargmax
    which = pick(np.stack([np.where(np.isfinite(f[2]), f[2], np.nan) for f in faces]), axis=0)
    img = np.where(which[..., None] == 0, faces[0][0], faces[1][0])
    col = np.where(which == 0, faces[0][1], faces[1][1])
    return img, col


def test_the_crease_term_doubts_pixels_beside_a_concave_crease_only():
    """End to end on noise-free corners of the paper rig: with ``crease_doubt`` the confidence is
    the lower of the other terms' and kappa T / (2 pi bias) of the stage ``crease_bias``; a 60-deg
    concave corner gets a bias over the operating point's 0.45 px beside its crease (so those
    pixels become holes at 3) and only the fit's ripple a period away; a ridge only that ripple;
    without the flag there is no crease stage and the confidence is the other terms'."""
    from simbench.decode import CREASE_APEX_SHARE, STABILITY_KAPPA_RAD

    base = DecoderParams(mode="calibrated", phase_stability=True, narrow_snr=True)
    img, col = _corner_capture(60.0)
    plain = decode(img, rig=RIG, params=base)
    assert "crease_bias" not in plain.stages
    r = decode(img, rig=RIG, params=dataclasses.replace(base, crease_doubt=True))
    bias = r.stages["crease_bias"]
    with np.errstate(divide="ignore"):
        cap = np.float32(STABILITY_KAPPA_RAD * 21 / (2 * np.pi)) / bias
    assert np.array_equal(r.confidence[r.valid], np.fmin(plain.confidence, cap)[r.valid])
    row = 480
    crease = int(np.nanargmin(np.diff(col[row], 2))) + 1  # the true map's sharpest concave break
    k = (col[row, crease - 1] - col[row, crease - 31]) / 30 - (col[row, crease + 31] - col[row, crease + 1]) / 30
    assert k > 0.15  # the slope's drop
    # the decoded map is the true one seen through the Gabor window (sigma_x = T_cam / 4): a
    # break blurred by a Gaussian of sigma has D2 = k (L - 2 sigma / sqrt(2 pi)) at its centre,
    # where (a fold's apex: crease_apex_bias) the prediction is the apex's share of it
    sigma = 0.25 * base.camera_period(RIG)
    assert bias[row, crease] == pytest.approx(CREASE_APEX_SHARE * k * (22 - 2 * sigma / np.sqrt(2 * np.pi)), rel=0.1)
    assert np.all(bias[row, crease - 5 : crease + 6] > 0.45)
    # a period away only the fit's ripple: a third of the operating point's level
    assert np.all(bias[row, crease + 25 : crease + 60] < 0.15) and np.all(bias[row, crease - 60 : crease - 25] < 0.15)
    assert (r.valid & (r.confidence < 3.0)).sum() > (plain.valid & (plain.confidence < 3.0)).sum()
    ridge, _ = _corner_capture(240.0)
    assert (
        decode(ridge, rig=RIG, params=dataclasses.replace(base, crease_doubt=True)).stages["crease_bias"].max() < 0.15
    )


@pytest.mark.parametrize(
    "name, normal, point, carrier",
    [
        # the box interior's faces, whole: a side wall (the fringe 1.41x the nominal frequency)
        # and a floor (fringes tilted 32 deg)
        ("side wall", (1.0, 0.0, 0.0), (-0.2, 0.0, 1.1), 1),
        ("floor", (0.0, -1.0, 0.0), (0.0, 0.15, 1.1), 2),
    ],
)
def test_the_carrier_bank_decodes_faces_seen_at_a_steep_angle(name, normal, point, carrier):
    """Exact tier, with noise: a face whose fringe the nominal window cannot fit (nothing valid
    without the bank) decodes wholly with it, every column within 0.15 px (noise 0.01 of full
    scale), each pixel with the bank's fit made for it (stage ``carrier``)."""
    img, col, z = synthetic_plane_capture(DRIVE, RIG, normal=normal, point_m=point)
    inside = np.isfinite(col) & (z > 0.8) & (z < 1.7)
    noisy = np.clip(img + np.random.default_rng(0).normal(0, 0.01, img.shape), 0, 1).astype(np.float32)
    base = DecoderParams(mode="calibrated", phase_stability=True)
    assert not decode(noisy, rig=RIG, params=base).valid[inside].any()
    r = decode(noisy, rig=RIG, params=dataclasses.replace(base, carrier_bank=True))
    assert r.valid[inside].mean() > 0.99
    assert np.abs(r.column_px - col)[r.valid & inside].max() < 0.15
    assert np.mean(r.stages["carrier"][r.valid & inside] == carrier) > 0.99
    # with the narrow window's SNR on, a bank fit's pixel keeps its own fit's SNR (no edge there
    # for the narrow window to see less of): the confidence is fmin(wide SNR, kappa / change)
    from simbench.decode import STABILITY_KAPPA_RAD
    from simbench.decode.phase import fringe_snr

    n = decode(noisy, rig=RIG, params=dataclasses.replace(base, carrier_bank=True, narrow_snr=True))
    banked = n.valid & (n.stages["carrier"] > 0)
    with np.errstate(divide="ignore"):
        want = np.fmin(fringe_snr(n.stages["fit_residual"]), np.float32(STABILITY_KAPPA_RAD) / n.stages["phase_change"])
    assert banked.sum() > 1000 and np.array_equal(n.confidence[banked], want[banked])


def test_bank_fit_keeps_the_nominal_fit_wherever_it_passes_and_reuses_a_choice():
    """A clean fringe of the nominal period: the nominal fit's very bits and no other choice.
    Beside it a fringe 1.4x as fast: there, away from the change and the image's ends, the bank's
    first entry wherever the nominal fit fails (its residual swings about the limit), with the
    bits of a whole-row fit of that carrier (the slice of columns it is fitted on does not change
    them) and the true phase; given that choice, a narrower call fits each pixel with its own
    carrier.  Beside the change of frequency (a discontinuity of the fit's model, a stretch of
    the nominal fit still clean within its reach) the bank is not tried."""
    from simbench.decode.phase import CARRIER_BANK, bank_fit, gabor_phase

    t, h, w = 21.8, 40, 560
    x = np.arange(w, dtype=np.float64)
    psi = np.where(x < 200, 2 * np.pi * x / t, 2 * np.pi * 200 / t + 1.4 * 2 * np.pi * (x - 200) / t)
    img = np.tile(0.5 + 0.4 * np.cos(psi), (h, 1)).astype(np.float32)
    cert = np.ones((h, w), np.float32)
    kw = dict(certainty=cert, period_px=t, sigma_y_px=0.15 * t)
    clean = np.tile(0.5 + 0.4 * np.cos(2 * np.pi * x / t), (h, 1)).astype(np.float32)
    got, choice = bank_fit(gabor_phase, clean, sigma_x_px=0.25 * t, max_residual=0.6, **kw)
    want = gabor_phase(clean, sigma_x_px=0.25 * t, offset=False, **kw)
    assert not choice.any() and np.array_equal(got.wrapped, want.wrapped)
    nominal = gabor_phase(img, sigma_x_px=0.25 * t, offset=False, **kw)
    got, choice = bank_fit(gabor_phase, img, sigma_x_px=0.25 * t, max_residual=0.6, **kw)
    fast = choice == 1
    inner = (x > 260) & (x < 500)
    assert np.array_equal(fast[:, inner], nominal.residual[:, inner] > 0.6) and fast[:, inner].mean() > 0.4
    assert not choice[:, 20:200].any() and np.array_equal(got.wrapped[~fast], nominal.wrapped[~fast])
    assert nominal.residual[:, 200:215].max() > 0.6 and not choice[:, 200:215].any()  # the change itself
    scale = CARRIER_BANK[0][0]
    full = gabor_phase(img, certainty=cert, period_px=t * scale, sigma_x_px=0.25 * t * scale, sigma_y_px=0.15 * t)
    assert np.array_equal(got.wrapped[fast], full.wrapped[fast]) and np.array_equal(
        got.residual[fast], full.residual[fast]
    )
    error = np.abs(np.angle(np.exp(1j * (got.wrapped - psi))))  # the fit's phase: I = A + B cos(psi)
    assert error[fast & inner].max() < 0.02
    narrow, again = bank_fit(gabor_phase, img, sigma_x_px=0.125 * t, max_residual=0.6, choice=choice, **kw)
    assert again is choice
    alone = gabor_phase(img, certainty=cert, period_px=t * scale, sigma_x_px=0.125 * t * scale, sigma_y_px=0.15 * t)
    assert np.array_equal(narrow.wrapped[fast], alone.wrapped[fast])


def test_the_carrier_bank_skips_a_carrier_past_the_sampling_limit():
    """A fringe of 2.5 camera px: the bank's faster carrier (2.5 / 1.4 = 1.8 px) cannot be in a
    sampled image and is not fitted (a pattern designer's audit, 2026-11-30: a 2.1-px camera period
    failed the colour-robust decode with "period_px must be > 2, got 1.48"); the other entry is."""
    from simbench.decode.phase import CARRIER_BANK, bank_fit, gabor_phase

    assert 2.5 * CARRIER_BANK[0][0] < 2 < 2.5 * CARRIER_BANK[1][0]
    t, h, w = 2.5, 24, 120
    x = np.arange(w, dtype=np.float64)
    rng = np.random.default_rng(0)
    img = np.tile(0.5 + 0.4 * np.cos(2 * np.pi * x / t), (h, 1)) + rng.normal(0, 0.05, (h, w))
    cert = np.ones((h, w), np.float32)
    kw = dict(certainty=cert, period_px=t, sigma_x_px=0.25 * t, sigma_y_px=0.15 * t)
    # max_residual 0: every pixel fails the nominal fit, so the bank is tried everywhere
    got, choice = bank_fit(gabor_phase, img.astype(np.float32), max_residual=0.0, **kw)
    assert not (choice == 1).any() and (choice == 2).any()
    assert np.isfinite(got.wrapped).mean() > 0.9


def test_the_channel_and_encoding_checks_do_not_read_a_fringe_too_fine_to_read(monkeypatch):
    """Under MIN_CAMERA_PERIOD_PX camera px the capture's spectrum at the fringe's period says
    nothing of its channels (a pattern designer's audit, 2026-11-30: a 3.1-px fringe in the blue
    channel was said to be in the green): the period warning alone, not the channel-order or
    encoding checks."""
    import dataclasses

    import simbench.decode.pipeline as pipeline
    from simbench.decode import DecoderParams
    from simbench.decode.params import MIN_CAMERA_PERIOD_PX
    from simbench.rig import paper_rig

    rig = paper_rig()
    capture = np.random.default_rng(0).uniform(0, 1, (*rig.camera.size_hw, 3)).astype(np.float32)
    asked = []
    monkeypatch.setattr(pipeline, "channel_order_doubt", lambda *a, **k: asked.append("channels") or "")
    monkeypatch.setattr(pipeline, "fringe_harmonic_ratio", lambda *a, **k: asked.append("encoding") or 1.0)
    fine = DecoderParams(camera_period_px=0.9 * MIN_CAMERA_PERIOD_PX)
    told = pipeline.capture_warnings(capture, rig=rig, params=fine)
    assert any("under the 4 the phase fit needs" in t for t in told) and asked == [], (told, asked)
    pipeline.reference_warnings(capture, rig=rig, params=fine)
    assert asked == []
    pipeline.capture_warnings(capture, rig=rig, params=dataclasses.replace(fine, camera_period_px=None))
    assert asked == ["channels", "encoding"]


def test_a_camera_period_set_by_hand_is_not_told_as_the_rigs_prediction():
    """--decoder camera_period_px=X against a fringe at the rig's period: the doubt names X as the
    setting and gives the rig's own prediction beside it (a pattern designer's audit, 2026-11-30:
    X was called the rig's prediction, beside a product of the rig's numbers that was not X)."""
    from simbench.decode import DecoderParams
    from simbench.decode.pipeline import fringe_period_doubt
    from simbench.systems import get_system

    capture, _, scene = get_system("proposed").bench_inputs()
    told = fringe_period_doubt(capture, rig=scene.rig, params=DecoderParams(camera_period_px=10.9))
    assert "but the decoder's camera_period_px (--decoder) is 10.9 (the rig predicts 21.8:" in told, told
    assert fringe_period_doubt(capture, rig=scene.rig, params=DecoderParams()) == ""


def test_the_carrier_bank_gives_the_same_bits_on_any_number_of_threads():
    """The bank refits slices of columns chosen per row band; with the carrier referred to the
    image's columns the result does not depend on the bands: a side wall seen in the upper half
    from one column and in the lower half from another decodes to the same bits on 1, 2 and 3
    threads (their bands need the bank on different spans of columns) - with the window-centroid
    correction too, whose narrow fit is corrected in a band-sized array and whose bank pixels keep
    their phase."""
    upper, col_u, _ = synthetic_plane_capture(DRIVE, RIG, normal=(1.0, 0.0, 0.0), point_m=(-0.2, 0.0, 1.1))
    lower, col_l, _ = synthetic_plane_capture(DRIVE, RIG, normal=(1.0, 0.0, 0.0), point_m=(-0.25, 0.0, 1.1))
    img = upper.copy()
    img[480:] = lower[480:]
    noisy = np.clip(img + np.random.default_rng(1).normal(0, 0.01, img.shape), 0, 1).astype(np.float32)
    base = DecoderParams(mode="calibrated", phase_stability=True, narrow_snr=True, carrier_bank=True)
    for params in (base, dataclasses.replace(base, centroid_correction=True)):
        runs = [decode(noisy, rig=RIG, params=dataclasses.replace(params, threads=n)) for n in (1, 2, 3)]
        assert (runs[0].stages["carrier"] > 0).mean() > 0.1
        for r in runs[1:]:
            for a, b in ((r.depth_m, runs[0].depth_m), (r.confidence, runs[0].confidence), (r.valid, runs[0].valid)):
                assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f")


@pytest.mark.parametrize("mode", ["reference", "calibrated"])
def test_a_projector_on_the_cameras_left_decodes_the_true_depth(mode):
    """A new user's audit: with the projector at x < 0 the reference mode's depths were mirrored
    about Z0 (1/Z = 2/Z0 - 1/Z_true: 319 mm MAE on a step, exit 0) - the disparity's sign was the
    baseline's length's.  The mirrored paper rig decodes planes off Z0 as the paper rig does."""
    left = dataclasses.replace(RIG, position_m=(-RIG.position_m[0], 0.0, 0.0))
    ref_img, _, _ = synthetic_plane_capture(DRIVE, left, point_m=(0, 0, 1.0))
    ref = decode_reference(ref_img, rig=left, params=DecoderParams())
    for depth in (0.9, 1.3):
        img, col, z = synthetic_plane_capture(DRIVE, left, point_m=(0, 0, depth))
        r = decode(img, rig=left, params=DecoderParams(mode=mode), reference=ref)
        assert r.valid[np.isfinite(col)].mean() > 0.99
        dz = r.depth_m[r.valid] - z[r.valid]
        assert np.sqrt(np.mean(dz**2)) < 0.02 * depth**2 / (left.projector.focal_px * left.baseline_m), depth


def test_the_pattern_on_the_rig_warns_of_undersampling_and_of_a_range_past_one_cycle():
    """A new user's audit of their own patterns: a period of 8 px (a 64 px cycle against the
    working range's 160 px of disparity) put half a step's pixels a whole cycle off - 380-430 mm
    - at 99 % completeness without a word; a period of 2.3 camera pixels decoded nothing, with
    hints of a wrong reference.  The paper's rig and pattern give neither warning (the range spans
    158 of the cycle's 168 px)."""
    from simbench.decode.params import pattern_on_rig_warnings

    assert pattern_on_rig_warnings(RIG, DecoderParams()) == []
    (told,) = pattern_on_rig_warnings(RIG, DecoderParams(pattern=PatternSpec(period_px=8)))
    assert "repeats every 64 projector px" in told and "spans 158 px" in told
    # the range it suggests is one cycle wide: no warning there
    for period in (8, 10, 12, 16):  # (a review: rounded up to 3 digits, 10, 12 and 16 warned again)
        (told,) = pattern_on_rig_warnings(RIG, DecoderParams(pattern=PatternSpec(period_px=period)))
        near, far = (float(x) for x in re.search(r"e\.g\. ([\d.]+)-([\d.]+) m", told).groups())
        narrow = DecoderParams(pattern=PatternSpec(period_px=period), depth_range_m=(near, far))
        assert pattern_on_rig_warnings(RIG, narrow) == [], period
    small = dataclasses.replace(RIG, camera=dataclasses.replace(RIG.camera, focal_px=RIG.projector.focal_px / 6))
    (told,) = pattern_on_rig_warnings(small, DecoderParams())
    assert "3.5 camera pixels" in told


def test_reference_mode_warns_of_a_rig_its_formula_does_not_fit():
    """A new user's audit: a projector 20 mm behind the camera gave the step scene 3.3 mm MAE and
    28 % of its pixels > 5 mm wrong in reference mode (paper Eq. 14-15, exact for a rectified rig),
    without a word; triangulation (calibrated mode) 0.48 mm.  reference_model_error predicts that
    error from the rig - a noise-free plane at 0.9 m decoded in reference mode is off by what it
    predicts (measured 1.11x at its worst pixel, 1.0 % of 0.9 m) - and reference mode warns above 0.1 % of the
    depth; turns about x, y and z (the reference plane absorbs them), the paper's rig and calibrated
    mode do not warn."""
    from simbench.decode.params import pattern_on_rig_warnings, reference_model_error

    behind = dataclasses.replace(RIG, position_m=(RIG.position_m[0], 0.0, -0.02))
    (told,) = pattern_on_rig_warnings(behind, DecoderParams())
    assert "--mode calibrated" in told and "projector at 93, 0, -20 mm" in told
    assert pattern_on_rig_warnings(behind, DecoderParams(mode="calibrated")) == []
    for turn in ((0.5, 0.0, 0.0), (0.0, 12.0, 0.0), (0.0, 0.0, 1.0)):
        assert pattern_on_rig_warnings(dataclasses.replace(RIG, rotation_deg=turn), DecoderParams()) == [], turn
    assert reference_model_error(RIG, DecoderParams()) < 1e-12
    # the prediction against the decoder, at one depth
    ref_img, _, _ = synthetic_plane_capture(DRIVE, behind, point_m=(0, 0, 1.0))
    reference = decode_reference(ref_img, rig=behind, params=DecoderParams())
    img, _, z = synthetic_plane_capture(DRIVE, behind, point_m=(0, 0, 0.9))
    r = decode(img, rig=behind, params=DecoderParams(), reference=reference)
    measured = np.nanmax(np.abs(r.depth_m[r.valid] - z[r.valid]) / z[r.valid])
    predicted = reference_model_error(behind, DecoderParams(depth_range_m=(0.8999, 0.9001)))
    assert 0.8 < measured / predicted < 1.25, (measured, predicted)


def test_a_reference_lit_in_part_by_a_lens_shifted_projector_decodes():
    """A new user's audit: a projector lens-shifted down (its principal point 440 px below the
    centre) lights 64 % of the view on the plane at Z0, all of which decoded, and the reference
    was refused as "decodes at only ... is it the reference-plane capture?" - the coverage is now
    asked of the lit part; a black reference is still refused, naming that part."""
    shifted = dataclasses.replace(RIG, projector=dataclasses.replace(RIG.projector, cy_px=RIG.projector.cy_px + 440))
    img, _, _ = synthetic_plane_capture(DRIVE, shifted, point_m=(0, 0, 1.0))
    assert 0.6 < (img.max(axis=2) > 0).mean() < 0.7
    ref = decode_reference(img, rig=shifted, params=DecoderParams())
    assert np.isfinite(ref.column_px).mean() > 0.6
    with pytest.raises(ValueError, match=r"at least 50 % of the 64\.2 % this rig's projector lights"):
        decode_reference(np.zeros_like(img), rig=shifted, params=DecoderParams())


def test_a_capture_with_its_channels_out_of_order_is_doubted():
    """A new user's audit: a capture saved BGR as RGB decoded with the colour-robust decoder to 2-9 %
    of its pixels 0.1-0.7 m wrong at full confidence, without a word.  channel_order_doubt finds the
    fringe in another channel than the pattern's; the capture as it is, the red and green swapped
    (code_order_doubt's case) and a scale change leave it quiet."""
    from simbench.decode.pipeline import channel_order_doubt

    img, _, _ = synthetic_plane_capture(DRIVE, RIG, point_m=(0, 0, 1.1))
    cap = np.clip(img / 1.21 * 255, 0, 255).astype(np.uint8)
    params = DecoderParams()
    assert channel_order_doubt(cap, rig=RIG, params=params) == ""
    assert channel_order_doubt(cap[..., [1, 0, 2]], rig=RIG, params=params) == ""
    assert channel_order_doubt((cap // 2).astype(np.uint8), rig=RIG, params=params) == ""
    told = channel_order_doubt(cap[..., ::-1], rig=RIG, params=params)
    assert "the fringe seems to be in the red channel, not in the blue" in told and "BGR saved as RGB" in told
    assert "in the green channel" in channel_order_doubt(cap[..., [0, 2, 1]], rig=RIG, params=params)
    # a pattern that puts the fringe in green reads that capture as it should
    gbr = DecoderParams(pattern=PatternSpec(channels="rbg"))
    assert channel_order_doubt(cap[..., [0, 2, 1]], rig=RIG, params=gbr) == ""


@pytest.mark.slow
def test_a_printed_charts_channels_out_of_order_are_doubted(tmp_path, variant):
    """A new user's audit (2026-11-30): the 20:1 chart (scenes/hard_chart_high.toml) saved BGR
    decoded with 871 pixels > 5 mm wrong and no warning - its printed edges lift every channel's
    code band, and the channel holding the fringe read 2.4 times the blue one's ratio, under the
    margin of 3 then.  Rendered here at the quick run's size: R/B and G/B swapped are doubted, the
    capture as it is and with red and green swapped (code_order_doubt's case) are not."""
    from simbench.decode.pipeline import channel_order_doubt
    from simbench.experiments.common import RunConfig, Session

    cfg = RunConfig.preset(quick=True)
    session = Session(cfg, out_dir=tmp_path, cache_dir=tmp_path / "cache", progress=lambda s: None, command="test")
    cap = session.capture(session.prepare(session.raw_scene("hard_chart_high")), "test/chart")[0]
    img, rig, params = np.asarray(cap.raw), cap.scene.rig, DecoderParams()
    assert channel_order_doubt(img, rig=rig, params=params) == ""
    assert channel_order_doubt(img[..., [1, 0, 2]], rig=rig, params=params) == ""
    assert "the fringe seems to be in the red channel" in channel_order_doubt(img[..., ::-1], rig=rig, params=params)
    assert "in the green channel" in channel_order_doubt(img[..., [0, 2, 1]], rig=rig, params=params)


def test_a_coherent_run_of_misread_codes_is_contested_and_scores_zero():
    """A run of stripes whose codes read like another stretch of the De Bruijn sequence (here
    stripes 0-3 of one cycle printed with the codes of stripes 4-7: JPEG's chroma subsampling of
    a dark board made such runs) predicts one other position coherently: without the check its
    stripes decode half a cycle off at full fringe SNR; with ``position_doubt`` every pixel off by
    a period or more scores 0 and pixels beyond the votes' reach keep their confidence bits."""
    spec = PatternSpec()
    t, n = spec.period_px, spec.codes().size
    drive = quantize(fringe_pattern(spec)).copy()
    first = 5 * n * t  # stripe 0 of the sixth cycle, near the middle of the view at 1 m
    for j in range(n // 2):
        a, b = first + j * t, first + (j + n // 2) * t
        drive[:, a : a + t, :2] = drive[:, b : b + t, :2]
    img, col, _ = synthetic_plane_capture(transfer_curve(drive, transfer="linear"), RIG, point_m=(0, 0, 1.0))
    params = DecoderParams(mode="calibrated")
    plain = decode(img, rig=RIG, params=params)
    doubt = decode(img, rig=RIG, params=dataclasses.replace(params, position_doubt=True))
    for same_in_both in ("position", "column"):  # the term moves no stripe
        assert np.array_equal(plain.stages[same_in_both], doubt.stages[same_in_both], equal_nan=True)
    off = plain.valid & (np.abs(plain.column_px - col) > t)
    assert off.sum() > 1000 and np.median(plain.confidence[off]) > 30  # silent: a clean fringe
    assert (doubt.confidence[off] == 0).all()
    assert doubt.stages["contested"][off].all()
    away = np.isfinite(col) & (np.abs(col - (first + n * t / 2)) > (n + 2 * params.neighbour_reach) * t)
    assert np.array_equal(plain.confidence[away], doubt.confidence[away])
    at_point = dataclasses.replace(params, position_doubt=True, min_confidence=3.0)
    kept = decode(img, rig=RIG, params=at_point)
    assert not (kept.valid & (np.abs(kept.column_px - col) > 0.5 * t)).any()


@pytest.mark.parametrize("scale", [1.0, 0.25])
def test_the_column_noise_at_a_fringe_snr_is_the_windows_closed_form(scale):
    """Statistical: a plane's capture with white noise (sigma 0.1 of a 0.8 white, no quantisation)
    decoded by the paper's decoder; over the pixels of fringe SNR 2-4 the decoded column's spread
    about the truth against :meth:`DecoderParams.column_noise_px` over each pixel's SNR (RMS):
    measured 1.22x at the paper's camera period (21.8 px, 0.074 px against 0.060) and 1.06x at a
    quarter of its resolution (5.4 px, 0.282 against 0.265) - so the same confidence means ~4x the
    noise there; above 1 by the fringe's own ripple (~0.05 px at full resolution, noise-free).
    Bounds 0.9-1.5x: the closed form neither misses the window's scaling nor overstates it."""
    from simbench.rig import scale_camera

    rig = scale_camera(RIG, scale)
    img, col, _ = synthetic_plane_capture(DRIVE, rig, point_m=(0, 0, 1.0), supersample=2, albedo=1.0)
    img = img / img.max() * np.float32(0.8)
    cap = np.clip(img + np.random.default_rng(1).normal(0, 0.1, img.shape).astype(np.float32), 0, 1)
    p = DecoderParams(mode="calibrated")
    r = decode(cap, rig=rig, params=p)
    h, w = col.shape
    inner = np.zeros((h, w), bool)
    inner[h // 8 : -h // 8, w // 8 : -w // 8] = True
    ok = r.valid & np.isfinite(col) & inner & (r.confidence >= 2) & (r.confidence < 4)
    assert ok.sum() > 10000
    err = (r.column_px - col)[ok]
    assert np.all(np.abs(err) < 0.5 * p.period_px)  # no stripe-order error inflates the spread
    predicted = p.column_noise_px(rig) * np.sqrt(np.mean(1.0 / r.confidence[ok] ** 2))
    assert 0.9 < np.std(err) / predicted < 1.5, (np.std(err), predicted)
    if scale == 1.0:
        assert p.column_noise_px(rig) == pytest.approx(0.223, abs=0.001)


def test_the_fringe_period_check_tells_a_projector_grid_from_a_print_that_repeats():
    """fringe_period_doubt: a plane's capture repeats at the rig's predicted camera period (to 1 %)
    and is not doubted; decoded with the projector's focal length halved (a projector written on a
    grid half the pattern's) it is, naming both periods; a print of squares a period wide (the 10 mm
    chart's kind: their square wave, of twice the period, repeats more strongly than the fringe)
    leaves the fringe's peak in place and is not doubted; a black capture has no peak (NaN, "")."""
    from simbench.decode.pipeline import fringe_period_doubt, fringe_period_px
    from simbench.rig import scale_camera

    rig = scale_camera(RIG, 0.25)
    img, _, _ = synthetic_plane_capture(DRIVE, rig, point_m=(0, 0, 1.0), supersample=2, albedo=1.0)
    cap = np.clip(img / img.max() * 0.8, 0, 1).astype(np.float32)
    p = DecoderParams()
    t_cam = p.camera_period(rig)
    assert fringe_period_px(cap, period_px=t_cam) == pytest.approx(t_cam, rel=0.01)
    assert fringe_period_doubt(cap, rig=rig, params=p) == ""
    half = dataclasses.replace(rig, projector=dataclasses.replace(rig.projector, focal_px=rig.projector.focal_px / 2))
    told = fringe_period_doubt(cap, rig=half, params=p)
    measured = float(re.search(r"repeats every ([0-9.]+) camera px", told).group(1))
    assert measured == pytest.approx(t_cam, abs=0.06) and f"but the rig predicts {2 * t_cam:.1f}" in told, told
    x = np.arange(cap.shape[1])
    squares = np.where(np.sin(2 * np.pi * x / (2.1 * t_cam)) > 0, 1.0, 0.1).astype(np.float32)
    printed = cap * squares[None, :, None]
    assert fringe_period_px(printed, period_px=t_cam) > 1.35 * t_cam  # the print repeats most strongly
    assert fringe_period_doubt(printed, rig=rig, params=p) == ""
    black = np.zeros_like(cap)
    assert np.isnan(fringe_period_px(black, period_px=t_cam)) and fringe_period_doubt(black, rig=rig, params=p) == ""
