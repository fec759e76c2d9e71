"""One validation layer for the values users give: numbers, booleans, choices, image sizes.

Every configuration path (rig, scene, sensor and sweep TOML files, ``--decoder NAME=VALUE``,
command-line options, the frozen dataclasses' ``__post_init__``) checks its values here, so the
rules are the same everywhere:

* a number is an ``int`` or ``float`` (never a ``bool``, never a string), finite unless a
  field allows infinity, and inside its stated range;
* a boolean comes only from a boolean (``"false"`` or ``1`` is an error, not a truthy value);
* a choice is one of a listed set, and the error lists them;
* an image side is a whole number of pixels no larger than :data:`MAX_SIDE_PX`, an image no
  larger than :data:`MAX_PIXELS`.

Errors are :class:`ValueError` whose message names the field, what it must be, and what it got.
"""

from __future__ import annotations

import math
import numbers as _numbers
from collections.abc import Callable, Iterable

import numpy as np

__all__ = ["MAX_SIDE_PX", "MAX_PIXELS", "number", "integer", "boolean", "choice", "numbers", "image_size", "optional"]

# Assumption: no structured-light camera or DMD in use exceeds 16K pixels on a side or 64 Mpx
# (the largest DMDs are 4K UHD, machine-vision cameras ~50 Mpx); a float32 RGB image of that
# size is already 0.8 GB, and renders hold several.
MAX_SIDE_PX = 16384
MAX_PIXELS = 64 * 1024 * 1024


def _is_real(value: object) -> bool:
    """A real number: Python or NumPy int/float, never a bool (which Python counts as an int)."""
    return isinstance(value, _numbers.Real) and not isinstance(value, (bool, np.bool_))


def _shown(value: object) -> str:
    """``repr(value)``, cut to 40 characters (an integer of 400 digits is one line's worth)."""
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _bound_text(x) -> str:
    """A range's bound as written: an integer exactly (a seed's 2**63 - 1, not 9.22337e+18)."""
    return str(x) if isinstance(x, _numbers.Integral) else f"{x:g}"


def _range_text(lo, hi, lo_open: bool, hi_open: bool) -> str:
    if lo is not None and hi is not None:
        return f"in {'(' if lo_open else '['}{_bound_text(lo)}, {_bound_text(hi)}{')' if hi_open else ']'}"
    if lo is not None:
        return f"{'>' if lo_open else '>='} {_bound_text(lo)}"
    if hi is not None:
        return f"{'<' if hi_open else '<='} {_bound_text(hi)}"
    return ""


def number(
    value: object,
    name: str,
    *,
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
    hi_open: bool = False,
    allow_inf: bool = False,
) -> float:
    """``value`` as a float, checked: a real number (not bool/str), finite unless
    ``allow_inf``, within ``[lo, hi]`` (``lo_open``/``hi_open`` exclude the bound).

    Raises
    ------
    ValueError
        ``"<name> must be a finite number > 0, got 'x'"`` and the like.
    """
    rng = _range_text(lo, hi, lo_open, hi_open)
    what = f"a {'' if allow_inf else 'finite '}number{' ' + rng if rng else ''}"
    if not _is_real(value):
        raise ValueError(f"{name} must be {what}, got {_shown(value)}")
    try:
        v = float(value)
    except OverflowError:  # an integer beyond a float's range (10**400)
        v = math.inf if value > 0 else -math.inf
    if math.isnan(v) or (math.isinf(v) and not allow_inf):
        raise ValueError(f"{name} must be {what}, got {_shown(value)}")
    if lo is not None and (v < lo or (lo_open and v == lo)):
        raise ValueError(f"{name} must be {what}, got {_shown(value)}")
    if hi is not None and (v > hi or (hi_open and v == hi)):
        raise ValueError(f"{name} must be {what}, got {_shown(value)}")
    return v


def integer(value: object, name: str, *, lo: int | None = None, hi: int | None = None) -> int:
    """``value`` as an int: an ``int`` (or a float with an integral value), not a bool, in
    ``[lo, hi]``."""
    rng = _range_text(lo, hi, False, False)
    what = f"an integer{' ' + rng if rng else ''}"
    ok = _is_real(value) and (
        isinstance(value, _numbers.Integral) or (math.isfinite(float(value)) and float(value) == int(value))
    )
    if not ok:
        raise ValueError(f"{name} must be {what}, got {value!r}")
    v = int(value)
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        raise ValueError(f"{name} must be {what}, got {value!r}")
    return v


def boolean(value: object, name: str) -> bool:
    """``value`` if it is a bool; anything else (``"false"``, ``0``, ``"maybe"``) is an error."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be true or false, got {value!r}")
    return bool(value)


def choice(value: object, name: str, options: Iterable) -> str:
    """``value`` if it is one of ``options`` (of the same type: a string for string options),
    else an error listing them."""
    opts = list(options)
    same_type = all(isinstance(value, str) == isinstance(o, str) for o in opts)
    if isinstance(value, bool) or not same_type or value not in opts:
        raise ValueError(f"{name} must be one of {opts}, got {value!r}")
    return value


def numbers(value: object, name: str, n: int, **limits: object) -> tuple[float, ...]:
    """A list or tuple of ``n`` numbers, each checked by :func:`number` with ``limits``."""
    if isinstance(value, (str, bytes)) or not isinstance(value, (list, tuple)) or len(value) != n:
        raise ValueError(f"{name} must be a list of {n} numbers, got {value!r}")
    return tuple(number(x, f"{name}[{i}]", **limits) for i, x in enumerate(value))


def image_size(
    width: object, height: object, name: str, *, names: tuple[str, str] = ("width_px", "height_px")
) -> tuple[int, int]:
    """A (width, height) in pixels: integers in [1, MAX_SIDE_PX], at most MAX_PIXELS in all;
    ``names`` are the two fields' names in messages, ``name`` the image's."""
    w = integer(width, names[0], lo=1, hi=MAX_SIDE_PX)
    h = integer(height, names[1], lo=1, hi=MAX_SIDE_PX)
    if w * h > MAX_PIXELS:
        raise ValueError(f"{name} is {w}x{h} = {w * h / 1e6:.0f} Mpx; at most {MAX_PIXELS / 1e6:.0f} Mpx are supported")
    return w, h


def optional(check: Callable[..., object], value: object, name: str, **kw: object) -> object:
    """``None`` stays ``None``; anything else goes through ``check(value, name, **kw)``."""
    return None if value is None else check(value, name, **kw)
