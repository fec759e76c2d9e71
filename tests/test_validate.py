"""The one validation layer (simbench.validate): its rules, as the module docstring states them."""

from __future__ import annotations

import math

import numpy as np
import pytest

from simbench import validate


@pytest.mark.parametrize("value", [1, 2.5, np.float32(0.5), np.int64(3), 10**400])
def test_a_number_is_an_int_or_float_of_any_kind(value):
    if isinstance(value, int) and value > 10**300:  # beyond a float: infinite, refused unless allowed
        with pytest.raises(ValueError, match="finite number"):
            validate.number(value, "x")
        assert validate.number(value, "x", allow_inf=True) == math.inf
    else:
        assert validate.number(value, "x") == pytest.approx(float(value))


@pytest.mark.parametrize("value", [True, np.bool_(False), "1.0", None, [1.0], math.nan, math.inf, -math.inf])
def test_a_number_is_never_a_bool_a_string_or_not_finite(value):
    with pytest.raises(ValueError, match=r"^x must be a finite number, got "):
        validate.number(value, "x")


def test_ranges_and_open_bounds_are_stated_in_the_message():
    assert validate.number(0.0, "z", lo=0.0) == 0.0
    with pytest.raises(ValueError, match=r"z must be a finite number > 0, got 0\.0"):
        validate.number(0.0, "z", lo=0.0, lo_open=True)
    with pytest.raises(ValueError, match=r"z must be a finite number in \[1, 2\), got 2"):
        validate.number(2, "z", lo=1, hi=2, hi_open=True)
    with pytest.raises(ValueError, match=r"z must be a finite number <= 5, got 6"):
        validate.number(6, "z", hi=5)
    assert validate.number(math.inf, "z", lo=0, allow_inf=True) == math.inf
    # an integer bound exactly as it is (a seed's range read "[0, 9.22337e+18]"), a float one in %g
    with pytest.raises(ValueError, match=r"seed must be an integer in \[0, 9223372036854775807\], got -1"):
        validate.integer(-1, "seed", lo=0, hi=2**63 - 1)
    with pytest.raises(ValueError, match=r"z must be a finite number <= 1e\+06, got "):
        validate.number(2e6, "z", hi=1e6)


def test_an_integer_may_be_an_integral_float_and_a_long_value_is_shown_cut():
    assert validate.integer(3.0, "n") == 3 and isinstance(validate.integer(np.int32(4), "n"), int)
    for bad in (3.5, True, "3", math.nan, math.inf):
        with pytest.raises(ValueError, match="n must be an integer"):
            validate.integer(bad, "n")
    with pytest.raises(ValueError, match=r"n must be an integer in \[1, 9\], got 10"):
        validate.integer(10, "n", lo=1, hi=9)
    with pytest.raises(ValueError) as exc:
        validate.number("x" * 400, "s")
    assert len(str(exc.value)) < 100  # the value cut to 40 characters


def test_booleans_and_choices_come_only_from_their_own_kind():
    assert validate.boolean(np.bool_(True), "b") is True
    for bad in ("false", 0, 1, None):
        with pytest.raises(ValueError, match="b must be true or false"):
            validate.boolean(bad, "b")
    assert validate.choice("ftp", "m", ("gabor", "ftp")) == "ftp"
    with pytest.raises(ValueError, match=r"m must be one of \['gabor', 'ftp'\], got 'nope'"):
        validate.choice("nope", "m", ("gabor", "ftp"))
    with pytest.raises(ValueError, match="must be one of"):
        validate.choice(1, "k", ("1", "2"))  # an int among strings is another type
    with pytest.raises(ValueError, match="must be one of"):
        validate.choice(True, "k", (1, 2))  # a bool is not the integer 1


def test_lists_of_numbers_and_image_sizes():
    assert validate.numbers([1, 2.0, 3], "v", 3, lo=0) == (1.0, 2.0, 3.0)
    for bad in ("abc", (1, 2), [1, 2, 3, 4], {1, 2, 3}):
        with pytest.raises(ValueError, match="v must be a list of 3 numbers"):
            validate.numbers(bad, "v", 3)
    with pytest.raises(ValueError, match=r"v\[1\] must be a finite number >= 0, got -1"):
        validate.numbers([1, -1, 2], "v", 3, lo=0)
    assert validate.image_size(1280, 960, "camera") == (1280, 960)
    with pytest.raises(ValueError, match=r"width_px must be an integer in \[1, 16384\], got 0"):
        validate.image_size(0, 960, "camera")
    with pytest.raises(ValueError, match="camera is 16384x16384 = 268 Mpx; at most 67 Mpx"):
        validate.image_size(16384, 16384, "camera")
    assert validate.optional(validate.number, None, "o") is None
    assert validate.optional(validate.number, 2, "o", lo=0) == 2.0
