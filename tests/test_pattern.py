import itertools

import numpy as np
import pytest

from simbench.pattern import (
    PatternSpec,
    column_from_phase,
    de_bruijn,
    fringe_pattern,
    phase_from_column,
    quantize,
    window_positions,
)


def test_paper_sequence():
    # paper Sec. 4.2: B(2,3) = 00,010,111
    assert "".join(map(str, de_bruijn(3))) == "00010111"


def test_sequences_are_the_lexicographically_smallest():
    """The Fredricksen-Kessler-Maiorana (Lyndon word) sequences of the published tables."""
    assert "".join(map(str, de_bruijn(4))) == "0000100110101111"
    assert "".join(map(str, de_bruijn(2, alphabet=3))) == "001021122"
    assert "".join(map(str, de_bruijn(2, alphabet=4))) == "0010203112132233"


@pytest.mark.parametrize("order", range(2, 9))
@pytest.mark.parametrize("alphabet", [2, 3])
def test_every_cyclic_window_occurs_exactly_once(order, alphabet):
    if alphabet**order > 5000:
        pytest.skip("large")
    seq = de_bruijn(order, alphabet=alphabet)
    assert seq.size == alphabet**order
    ext = np.concatenate([seq, seq[: order - 1]])
    windows = {tuple(ext[i : i + order]) for i in range(seq.size)}
    assert windows == set(itertools.product(range(alphabet), repeat=order))


def test_window_table_locates_each_window():
    seq = de_bruijn(4)
    table = window_positions(seq, order=4)
    assert sorted(table.tolist()) == list(range(16))
    for q in range(16):
        code = 0
        for j in range(4):
            code = code * 2 + int(seq[(q + j) % 16])
        assert table[code] == q


def test_window_table_rejects_repeats():
    with pytest.raises(ValueError, match="repeats"):
        window_positions(np.array([0, 0, 1, 0, 0, 1]), order=2)


@pytest.mark.parametrize(
    "bad",
    [
        {"order": 1},
        {"period_px": 2},
        {"dc": 0.3, "amplitude": 0.5},
        {"size_hw": (0, 10)},
        {"channels": "rgr"},
        {"channels": "rg"},
    ],
)
def test_invalid_specs_raise(bad):
    with pytest.raises(ValueError):
        PatternSpec(**bad)


@pytest.mark.parametrize("period", [11, 21, 32])
def test_wrapped_phase_jumps_exactly_at_stripe_borders(period):
    u = np.arange(0, 10 * period) - 0.5  # pixel edges
    wrapped = np.angle(np.exp(1j * phase_from_column(u, period_px=period)))
    at_border = (np.arange(u.size) % period) == 0
    # at each border the phase is -pi (== +pi): it wraps there and nowhere else
    assert np.allclose(np.abs(wrapped[at_border]), np.pi, atol=1e-9)
    assert np.all(np.abs(wrapped[~at_border]) < np.pi - 1e-6)
    assert np.allclose(column_from_phase(phase_from_column(u, period_px=period), period_px=period), u)


def test_eq8_channels_and_stripe_colours():
    spec = PatternSpec(size_hw=(4, 21 * 16), period_px=21, order=3)
    p = fringe_pattern(spec)
    r, g, b = p[0, :, 0], p[0, :, 1], p[0, :, 2]
    assert np.allclose(r + g, b)  # the code splits the fringe between R and G (Eq. 8)
    assert np.all((r == 0) | (g == 0))
    seq = de_bruijn(3)
    for s in range(16):
        cols = slice(21 * s, 21 * (s + 1))
        assert (r[cols].sum() > 0) == bool(seq[s % 8])  # C = 1 is red
    # brightest at stripe centres, darkest at borders
    assert np.argmax(b[:21]) == 10 and np.argmin(b[:21]) in (0, 20)
    assert np.all(p == p[:1])
    # row-major, as OpenCV and every pixel loop after it read images (a broadcast row's astype
    # kept numpy's K order: column-major, which made each pass over a projector drive strided)
    assert p.flags.c_contiguous and quantize(p).flags.c_contiguous


@pytest.mark.parametrize("channels", ["rbg", "gbr", "brg"])
def test_channel_assignment_permutes_eq8(channels):
    """``channels`` names the colours of code 1, code 0 and the fringe: the paper's pattern with its channels moved."""
    spec = PatternSpec(size_hw=(2, 21 * 8))
    paper = fringe_pattern(spec)
    moved = fringe_pattern(PatternSpec(size_hw=(2, 21 * 8), channels=channels))
    idx = ["rgb".index(c) for c in channels]
    for k in range(3):
        assert np.array_equal(moved[..., idx[k]], paper[..., k])


def test_quantize():
    q = quantize(np.array([[0.0, 0.5, 1.0, 1.2]]))
    assert q.dtype == np.uint8 and q.tolist() == [[0, 128, 255, 255]]
    with pytest.raises(ValueError):
        quantize(np.array([np.nan]))


@pytest.mark.parametrize("bits", [8, 10])
def test_grey_drive_is_the_quantised_grey_in_three_channels(bits):
    """grey_drive quantises each pixel once: the same as quantising the frames copied into
    three channels (values outside [0, 1] clipped, uint8 up to 8 bits, uint16 above)."""
    from simbench.pattern import grey_drive, quantize

    grey = np.random.default_rng(1).uniform(-0.2, 1.2, (2, 5, 7)).astype(np.float32)
    got = grey_drive(grey, bits=bits)
    want = quantize(np.repeat(grey[..., None], 3, axis=-1), bits=bits)
    assert got.dtype == want.dtype and got.shape == (2, 5, 7, 3) and np.array_equal(got, want)
    assert got.flags.c_contiguous


def test_a_sequence_longer_than_its_windows_can_tell_apart_names_the_order_it_needs():
    """A new user's audit: `pattern --sequence 0000100110101111` without `--order 4` failed with
    "window at position 1 repeats the one at 0", no word of the window length it defaulted to."""
    from simbench.pattern import window_positions

    with pytest.raises(ValueError, match=r"\(windows of 3 codes\).*needs windows of at least 4 \(--order\)"):
        window_positions(np.array([int(c) for c in "0000100110101111"]), order=3)
    assert window_positions(np.array([int(c) for c in "0000100110101111"]), order=4).min() >= 0
