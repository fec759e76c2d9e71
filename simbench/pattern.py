"""The colour sequence coded fringe pattern (paper Sec. 2 and 4, Eq. 7-8).

Conventions (stated once, used everywhere)
-----------------------------------------
* Projector pixel coordinates follow OpenCV: pixel ``i`` has its centre at ``u = i`` and
  spans ``[i - 0.5, i + 0.5)``.
* Stripe ``s`` covers projector pixels ``s*T .. s*T + T - 1``; its borders lie at
  ``u = s*T - 0.5``.  The fringe (paper Eq. 7) is

      I(u) = A + B * cos(psi(u)),   psi(u) = 2*pi*(u + 0.5)/T - pi,

  so the *wrapped* phase ``psi`` runs from ``-pi`` at a stripe's left border to ``+pi`` at its
  right border and wraps exactly at stripe borders (paper Sec. 4.1 and 5.3 ask for this; the
  paper's ``phi_0 = pi/2`` is the same statement in its own, unstated, arctan convention).
  The fringe is darkest at stripe borders, so colour switches happen where there is least light.
* Code values follow Eq. 8 and Eq. 13: ``C = 1`` is a red stripe, ``C = 0`` a green one.
  (The paper's prose says the opposite once; the equations are consistent with each other.)
* The unwrapped phase (Eq. 12) is ``Phi = psi + 2*pi*n`` with ``n`` the stripe index, and
  ``u = T * (n + (psi + pi) / (2*pi)) - 0.5`` (:func:`column_from_phase`).
"""

from __future__ import annotations

import dataclasses

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from simbench import validate
from simbench.literature import PAPER_DEBRUIJN_ORDER, PAPER_PERIOD_PX

__all__ = [
    "pattern_from_options",
    "PatternSpec",
    "CALIBRATION_FRAMES",
    "calibration_frames",
    "check_channels",
    "de_bruijn",
    "window_positions",
    "check_sequence",
    "parse_sequence",
    "code_sequence",
    "fringe_pattern",
    "quantize",
    "grey_drive",
    "column_from_phase",
    "phase_from_column",
]


def de_bruijn(order: int, *, alphabet: int = 2) -> np.ndarray:
    """Lexicographically smallest cyclic De Bruijn sequence B(alphabet, order).

    Built by concatenating Lyndon words (Fredricksen-Kessler-Maiorana algorithm).

    Parameters
    ----------
    order : int
        Window length n >= 2 (the paper uses 3).
    alphabet : int
        Number of symbols k >= 2 (the paper uses 2: red and green).

    Returns
    -------
    ndarray, shape (alphabet**order,), uint8
        Every window of ``order`` consecutive symbols (cyclically) occurs exactly once.
        ``de_bruijn(3)`` is ``00010111``, the paper's sequence (Sec. 4.2).

    References
    ----------
    .. [1] H. Fredricksen, "A survey of full length nonlinear shift register cycle algorithms",
       SIAM Review 24(2), 195-221, 1982.

    Examples
    --------
    >>> de_bruijn(3)
    array([0, 0, 0, 1, 0, 1, 1, 1], dtype=uint8)
    >>> len(de_bruijn(4, alphabet=3))
    81
    """
    if int(order) != order or order < 2:
        raise ValueError(f"De Bruijn order must be an integer >= 2, got {order!r}")
    if int(alphabet) != alphabet or alphabet < 2:
        raise ValueError(f"De Bruijn alphabet must be an integer >= 2, got {alphabet!r}")
    if alphabet**order > 1 << 20:
        raise ValueError(f"B({alphabet},{order}) would have {alphabet**order} symbols; too long")
    k, n = int(alphabet), int(order)
    # the Lyndon words over the alphabet whose length divides n, in lexicographic order, made
    # one from the last (iteratively: a recursive closure would be a reference cycle per call)
    out: list[int] = []
    word = [-1]
    while word:
        word[-1] += 1
        m = len(word)
        if n % m == 0:
            out.extend(word)
        while len(word) < n:
            word.append(word[len(word) - m])
        while word and word[-1] == k - 1:
            word.pop()
    return np.asarray(out, dtype=np.uint8)


def window_positions(sequence: np.ndarray, *, order: int, alphabet: int = 2) -> np.ndarray:
    """Lookup table from a window's code to the position of the window's start.

    The window starting at position ``q`` is ``sequence[q], ..., sequence[q + order - 1]``
    (cyclic) and its code is ``sum(symbol_j * alphabet**(order - 1 - j))``.

    Returns
    -------
    ndarray, shape (alphabet**order,), int32
        ``table[code]`` is the start position, or -1 for a window that does not occur.

    Raises
    ------
    ValueError
        If some window occurs twice (the sequence is not a De Bruijn-like sequence).
    """
    seq = np.asarray(sequence, dtype=np.int64)
    length = seq.size
    if length < order:
        raise ValueError(f"sequence of length {length} is shorter than the window {order}")
    table = np.full(alphabet**order, -1, dtype=np.int32)
    for q in range(length):
        code = 0
        for j in range(order):
            code = code * alphabet + int(seq[(q + j) % length])
        if table[code] != -1:
            raise ValueError(
                f"window at position {q} repeats the one at {table[code]} (windows of {order} codes): the sequence "
                f"cannot locate stripes uniquely - a sequence of {length} codes needs windows of at least "
                f"{max(order + 1, int(np.ceil(np.log(max(length, 2)) / np.log(alphabet))))} (--order)"
            )
        table[code] = q
    return table


@dataclass(frozen=True)
class PatternSpec:
    """The colour sequence coded fringe.

    Attributes
    ----------
    size_hw : tuple of int
        Pattern size (height, width) in projector pixels.
    period_px : int
        Fringe period T = stripe width, in projector pixels (paper: 21).
    order : int
        Window length n: how many successive stripe codes identify a stripe (paper: 3).
    sequence : tuple of int, optional
        The binary stripe codes of one cycle.  Default: the De Bruijn sequence B(2, order)
        (paper: 00010111, 8 stripes).  Any cyclic binary sequence whose windows of ``order``
        codes are all different works.
    dc : float
        Fringe offset A of Eq. 7, in [0, 1] of full projector drive.
    amplitude : float
        Fringe amplitude B of Eq. 7; ``dc + amplitude <= 1`` and ``dc - amplitude >= 0``.
    channels : str
        Which colour channel carries code 1, code 0 and the fringe, in that order: a permutation
        of ``"rgb"``.  The paper's pattern is ``"rgb"`` (red stripes = 1, green = 0, fringe in
        blue); ``"rbg"`` puts the fringe in green, ``"gbr"`` in red.
    """

    size_hw: tuple[int, int] = (1140, 1824)
    period_px: int = PAPER_PERIOD_PX
    order: int = PAPER_DEBRUIJN_ORDER
    dc: float = 0.5
    amplitude: float = 0.5
    sequence: tuple[int, ...] | None = None
    channels: str = "rgb"

    def __post_init__(self) -> None:
        check_channels(self.channels)
        (h, w), period = checked_size_and_period(self.size_hw, self.period_px)
        object.__setattr__(self, "size_hw", (h, w))
        object.__setattr__(self, "period_px", period)
        object.__setattr__(self, "order", validate.integer(self.order, "order", lo=2, hi=16))
        if w < self.order * self.period_px:  # (a new user's audit: `pattern --period 1000` passed)
            raise ValueError(
                f"period {self.period_px} px over a {w} px wide pattern: {w / self.period_px:.1f} stripes, fewer than "
                f"one De Bruijn window of {self.order}: no stripe could be decoded"
            )
        object.__setattr__(self, "dc", validate.number(self.dc, "dc", lo=0.0, hi=1.0))
        object.__setattr__(
            self, "amplitude", validate.number(self.amplitude, "amplitude", lo=0.0, hi=0.5, lo_open=True)
        )
        if not (0.0 <= self.dc - self.amplitude and self.dc + self.amplitude <= 1.0):
            raise ValueError(
                f"dc={self.dc} and amplitude={self.amplitude} leave [0, 1]: "
                "need 0 <= dc - amplitude and dc + amplitude <= 1"
            )
        if self.amplitude <= 0:
            raise ValueError(f"amplitude must be > 0, got {self.amplitude}")
        if self.sequence is not None:
            object.__setattr__(self, "sequence", check_sequence(self.sequence, order=self.order))

    def codes(self) -> np.ndarray:
        """The stripe codes of one cycle, shape (L,), uint8."""
        return code_sequence(self.sequence, order=self.order)

    def projects_as(self, other: "PatternSpec") -> bool:
        """Whether ``other`` projects the same pattern (its sequence compared as the codes it
        projects: the default De Bruijn sequence given explicitly and left unset are one)."""
        return dataclasses.replace(self, sequence=tuple(int(c) for c in self.codes())) == dataclasses.replace(
            other, sequence=tuple(int(c) for c in other.codes())
        )

    @property
    def cycle_stripes(self) -> int:
        """Number of stripes L in one cycle (paper: 8)."""
        return 2**self.order if self.sequence is None else len(self.sequence)


def checked_size_and_period(size_hw, period_px) -> tuple[tuple[int, int], int]:
    """A projector pattern's (height, width) and fringe period in pixels, checked (the coded
    pattern's and the phase-shift sequence's alike)."""
    if isinstance(size_hw, (str, bytes)) or len(size_hw) != 2:
        raise ValueError(f"pattern size_hw must be (height, width), got {size_hw!r}")
    w, h = validate.image_size(size_hw[1], size_hw[0], "pattern", names=("pattern width", "pattern height"))
    return (h, w), validate.integer(period_px, "period_px", lo=4, hi=validate.MAX_SIDE_PX)


def check_channels(channels: str) -> tuple[int, int, int]:
    """Indices (R = 0, G = 1, B = 2) of the channels carrying code 1, code 0 and the fringe.

    Raises
    ------
    ValueError
        Unless ``channels`` is a permutation of ``"rgb"``.
    """
    if not isinstance(channels, str) or sorted(channels) != ["b", "g", "r"]:
        raise ValueError(f"channels must be a permutation of 'rgb' (code 1, code 0, fringe), got {channels!r}")
    return tuple("rgb".index(c) for c in channels)


def parse_sequence(text: str) -> tuple[int, ...]:
    """A code sequence written as a string of 0 and 1 (``"00010111"``, the CLI's and sweep
    files' form) as a tuple; its windows are checked by :class:`PatternSpec`."""
    if not isinstance(text, str) or not text or set(text) - {"0", "1"}:
        raise ValueError(f"a code sequence is a string of 0 and 1, got {text!r}")
    return tuple(int(c) for c in text)


def check_sequence(sequence: Sequence[int], *, order: int) -> tuple[int, ...]:
    """Validate a cyclic binary code sequence: 0/1 values, every window of ``order`` unique.

    Raises
    ------
    ValueError
        Naming what is wrong.
    """
    if isinstance(sequence, (str, bytes)):
        raise ValueError(f"sequence must be a list of 0 and 1, got {sequence!r}")
    try:
        items = list(sequence)
    except TypeError:
        raise ValueError(f"sequence must be a list of 0 and 1, got {sequence!r}") from None
    if any(isinstance(c, (bool, np.bool_)) or not isinstance(c, (int, np.integer)) or c not in (0, 1) for c in items):
        raise ValueError(f"sequence must hold only 0 and 1 (integers), got {sequence!r}")
    seq = tuple(int(c) for c in items)
    window_positions(np.asarray(seq), order=order)
    return seq


def code_sequence(sequence: Sequence[int] | None, *, order: int) -> np.ndarray:
    """``sequence`` as an array, or B(2, order) when it is None."""
    return de_bruijn(order) if sequence is None else np.asarray(sequence, dtype=np.uint8)


def phase_from_column(u: np.ndarray, *, period_px: float) -> np.ndarray:
    """Unwrapped phase Phi(u) of the fringe at projector column ``u`` (OpenCV coordinates).

    Examples
    --------
    The phase runs from -pi at a stripe's left border to +pi at its right border (the border of
    the first stripe is column -0.5, pixel centres at integers):

    >>> phase_from_column(np.array([-0.5, 10.0, 20.5]), period_px=21)
    array([-3.14159265,  0.        ,  3.14159265])
    >>> column_from_phase(phase_from_column(np.array([7.25]), period_px=21), period_px=21)
    array([7.25])
    """
    return 2.0 * np.pi * (np.asarray(u, dtype=np.float64) + 0.5) / period_px - np.pi


def column_from_phase(unwrapped: np.ndarray, *, period_px: float) -> np.ndarray:
    """Projector column (OpenCV coordinates, px) of an unwrapped phase; inverse of
    :func:`phase_from_column`."""
    return (np.asarray(unwrapped) + np.pi) * (period_px / (2.0 * np.pi)) - 0.5


def fringe_pattern(spec: PatternSpec) -> np.ndarray:
    """The colour sequence coded fringe of paper Eq. 7-8, sampled at projector pixel centres.

    Returns
    -------
    ndarray, shape (H, W, 3), float32 in [0, 1]
        Linear projector drive per channel (R, G, B): ``R = C*I``, ``G = (1-C)*I``, ``B = I``
        for the paper's ``channels = "rgb"``, permuted accordingly otherwise.

    References
    ----------
    .. [1] F. Li et al., "Single-Shot Dense Depth Sensing with Color Sequence Coded Fringe
       Pattern", Sensors 17(11), 2558, 2017, Eq. 7-8.
    """
    h, w = spec.size_hw
    u = np.arange(w, dtype=np.float64)
    intensity = spec.dc + spec.amplitude * np.cos(phase_from_column(u, period_px=spec.period_px))
    seq = spec.codes()
    code = seq[(np.arange(w) // spec.period_px) % seq.size].astype(np.float64)
    row = np.empty((w, 3))
    row[:, list(check_channels(spec.channels))] = np.stack(
        [code * intensity, (1.0 - code) * intensity, intensity], axis=-1
    )
    return np.broadcast_to(row[None, :, :], (h, w, 3)).astype(np.float32, order="C")  # K order: column-major


def quantize(pattern: np.ndarray, *, bits: int = 8) -> np.ndarray:
    """Quantise a [0, 1] pattern to the projector's input bit depth.

    Returns
    -------
    ndarray, same shape, uint8 (bits <= 8) or uint16
    """
    if not 1 <= bits <= 16:
        raise ValueError(f"bits must be in 1..16, got {bits}")
    if not np.all(np.isfinite(pattern)):
        raise ValueError("pattern contains NaN or inf")
    levels = (1 << bits) - 1
    q = np.rint(np.clip(pattern, 0.0, 1.0) * levels)
    return q.astype(np.uint8 if bits <= 8 else np.uint16)


def grey_drive(grey: np.ndarray, *, bits: int = 8) -> np.ndarray:
    """Grey [0, 1] frames (..., H, W) as the projector's RGB input (..., H, W, 3): each pixel
    quantised once (:func:`quantize`), the same value in the three channels."""
    q = quantize(grey, bits=bits)
    out = np.empty((*q.shape, 3), q.dtype)
    out[...] = q[..., None]
    return out


# the projector frames of the colour-robust decoder's calibration (Caspi, Kiryati and Shamir
# 1998): the reference plane under black and under each primary at full drive
CALIBRATION_FRAMES = ("dark", "red", "green", "blue")


def calibration_frames(pattern_u8: np.ndarray) -> dict[str, np.ndarray]:
    """The :data:`CALIBRATION_FRAMES` for a projector showing ``pattern_u8`` (same size and
    dtype): black, and each primary at full drive."""
    full = np.iinfo(pattern_u8.dtype).max
    out = {"dark": np.zeros_like(pattern_u8)}
    for p, name in enumerate(CALIBRATION_FRAMES[1:]):
        f = np.zeros_like(pattern_u8)
        f[..., p] = full
        out[name] = f
    return out


def pattern_from_options(
    size_hw: tuple[int, int],
    *,
    period_px: int | None = None,
    order: int | None = None,
    sequence: str | None = None,
    channels: str | None = None,
) -> PatternSpec:
    """The :class:`PatternSpec` at ``size_hw`` that the command line's pattern options give
    (``sequence`` as text, e.g. ``"00010111"``); an option left None keeps the default."""
    try:
        codes = None if sequence is None else parse_sequence(sequence)
        if codes is not None:  # its windows at the order it is given with (PatternSpec's check, named)
            check_sequence(codes, order=PatternSpec.order if order is None else order)
    except ValueError as exc:
        raise ValueError(f"--sequence: {exc}") from None
    given = {"period_px": period_px, "order": order, "channels": channels}
    return PatternSpec(size_hw=size_hw, sequence=codes, **{k: v for k, v in given.items() if v is not None})
