"""What the commands share: argument types with their ranges, the help formatter, the render,
cache and pattern options."""

from __future__ import annotations

import argparse

from collections.abc import Callable
from typing import TYPE_CHECKING, NoReturn

from simbench import api

if TYPE_CHECKING:
    from simbench.cache import RenderCache
    from simbench.pattern import PatternSpec


class Parser(argparse.ArgumentParser):
    """argparse with the CLI's error convention: one line on stderr, exit status 2; options only
    by their whole names (argparse's prefix matching took ``decode --debug DIR`` for
    ``--debug-dir DIR`` and wrote stage images where a traceback was asked for: a new user's
    audit, 2026-11-29)."""

    def __init__(self, *args, **kwargs) -> None:
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> NoReturn:  # noqa: D102 - argparse's hook
        where = self.prog.split(" ", 1)[1] + ": " if " " in self.prog else ""
        self.exit(2, f"simbench: error: {where}{message} (see {self.prog} --help)\n")

    def parse_args(self, args=None, namespace=None) -> argparse.Namespace:  # noqa: D102 - argparse's
        # an option the command does not take is the command's error, pointing at its own help
        # (argparse reports it from the top parser: "see simbench --help", which lists no options)
        ns, extras = self.parse_known_args(args, namespace)
        if extras:
            self._chosen(ns).error(f"unrecognized arguments: {' '.join(extras)}")
        return ns

    def _chosen(self, ns: argparse.Namespace) -> Parser:
        """The (sub)command parser that ``ns`` was parsed by: this one, or a command's below it."""
        for action in self._actions:
            if isinstance(action, argparse._SubParsersAction):
                sub = action.choices.get(getattr(ns, action.dest, None) or "")
                if isinstance(sub, Parser):
                    return sub._chosen(ns)
        return self


class Formatter(argparse.HelpFormatter):
    """Every option's help ends with its default (unless it has none or says it already)."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if (
            action.default is None
            or action.default is False
            or action.default == argparse.SUPPRESS
            or "default" in text
            or action.required
            or not action.option_strings
        ):
            return text
        return f"{text} (default: %(default)s)"


def checked(convert: Callable[[str], object], check: str, what: str, **limits: object) -> Callable[[str], object]:
    """An argparse type: ``convert(text)`` checked by ``simbench.validate.<check>``."""

    def parse(text: str):
        from simbench import validate

        try:
            value = convert(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        try:
            return getattr(validate, check)(value, "value", **limits)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc).replace("value must", "must")) from None

    parse.__name__ = check
    return parse


def encoding(text: str) -> str:
    """An argparse type: an image encoding (:func:`simbench.io.check_encoding`)."""
    from simbench.io import check_encoding

    try:
        return check_encoding(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def int_in(lo: int | None = None, hi: int | None = None) -> Callable[[str], object]:
    """An argparse type: an integer checked by :func:`simbench.validate.integer`."""
    return checked(int, "integer", "an integer", lo=lo, hi=hi)


def float_in(**limits: object) -> Callable[[str], object]:
    """An argparse type: a number checked by :func:`simbench.validate.number`."""
    return checked(float, "number", "a number", **limits)


# seeds: SeedSequence takes any non-negative integer; 63 bits keep them exact in JSON and NumPy
SEED = int_in(*api.SEED_RANGE)


SPP = int_in(*api.SPP_RANGE)

CAMERA_SCALE = float_in(lo=api.CAMERA_SCALE_RANGE[0], lo_open=True, hi=api.CAMERA_SCALE_RANGE[1])


# the render cache's folder, relative to the working folder (every command that renders or reads it)
DEFAULT_CACHE = api.DEFAULT_CACHE  # the render cache folder of the Python API and the command line


SIZE_UNITS = {"": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}


def size_bytes(text: str) -> int:
    """An argparse type: a size in bytes, ``du``'s way (``500M``, ``10G``, ``1.5GiB``; K, M,
    G, T are powers of 1024)."""
    import re

    m = re.fullmatch(r"\s*(\d+(?:\.\d*)?|\.\d+)\s*([KMGT]?)(?:i?B)?\s*", text, flags=re.IGNORECASE)
    if m is None:
        raise argparse.ArgumentTypeError(f"expected a size such as 500M, 10G or 1.5GiB, got {text!r}")
    return int(float(m.group(1)) * SIZE_UNITS[m.group(2).upper()])


def human_bytes(n: float) -> str:
    """``n`` bytes in the largest binary unit it reaches, as ``du -h`` writes sizes."""
    for unit in ("B", "KiB", "MiB", "GiB"):
        if abs(n) < 1024:
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} TiB"


def add_render_options(s, *, quick_spp: int | None = None) -> None:
    """--spp and --sampler, one definition for every subcommand that renders."""
    from simbench.sim.mitsuba_dict import DEFAULT_SAMPLER, DEFAULT_SPP, SAMPLERS

    quick = f", {quick_spp} with --quick" if quick_spp else ""
    s.add_argument(
        "--spp",
        type=SPP,
        default=None,
        help=f"path-tracing samples per pixel (default: {DEFAULT_SPP}{quick}); the stratified, multijitter and "
        "ldsampler samplers take a square count (4, 9, 16, 25, 36 ...; ldsampler a power of two's square), the "
        "orthogonal sampler a prime's square (4, 9, 25, 49 ...)",
    )
    s.add_argument(
        "--sampler",
        choices=SAMPLERS,
        default=DEFAULT_SAMPLER,
        help="Mitsuba sample generator (results/render_noise.md compares them)",
    )


def add_cache_options(
    s,
    cache_help: str = "render cache folder (renders and ground truth keyed by everything that affects them)",
    no_cache_help: str = "render everything, store nothing",
) -> None:
    """``--cache DIR`` and ``--no-cache``, which exclude each other (given both, the folder was
    ignored without a word, even one that could not serve as a cache)."""
    g = s.add_mutually_exclusive_group()
    g.add_argument(
        "--cache",
        default=DEFAULT_CACHE,
        help=f"{cache_help} (default: {DEFAULT_CACHE}; ${api.RENDER_CACHE_VARIABLE} sets another)",
    )
    g.add_argument("--no-cache", action="store_true", help=no_cache_help)


def cache_of(args: argparse.Namespace) -> RenderCache:
    from simbench.cache import RenderCache

    return RenderCache(None if args.no_cache else args.cache)


def render_settings(args) -> tuple[int, str]:
    """(spp, sampler) of the parsed options, checked together before anything renders."""
    from simbench.sim.mitsuba_dict import DEFAULT_SPP, check_sampler

    spp = args.spp if args.spp is not None else DEFAULT_SPP
    check_sampler(args.sampler, spp)
    return spp, args.sampler


# Mitsuba's path length: 1 sees only the emitters, so the projector's light needs >= 2
MAX_DEPTH = int_in(*api.MAX_DEPTH_RANGE)


def calibration_defaults() -> dict:
    """The defaults of `simbench calibrate`: those the experiments' calibrated rig uses, so
    that both share their cached observations."""
    from simbench.calibration import procedure as p

    return {
        "poses": p.DEFAULT_POSES,
        "spp": p.CALIBRATION_SPP,
        "corner_spp": p.CALIBRATION_CORNER_SPP,
        "sampler": p.CALIBRATION_SAMPLER,
        "max_depth": p.CALIBRATION_MAX_DEPTH,
    }


def distortion_models() -> list[str]:
    from simbench.calibration.procedure import DISTORTION_MODELS

    return list(DISTORTION_MODELS)


def samplers() -> tuple[str, ...]:
    from simbench.sim.mitsuba_dict import SAMPLERS

    return SAMPLERS


def registered_systems() -> list[str]:
    from simbench.systems import system_names

    return system_names()


def add_pattern_options(s: argparse.ArgumentParser) -> None:
    """The pattern's options, shared by every command that makes or reads the pattern."""
    # None = not given: a recording folder is decoded with the pattern it records, and an option
    # given explicitly that contradicts it is an error
    s.add_argument("--period", type=int_in(4, 16384), help="fringe period T in projector pixels (default: 21)")
    s.add_argument(
        "--order",
        type=int_in(2, 16),
        help=(
            "window length n (the De Bruijn cycle: 2**n stripes, or the --sequence's length, whose windows of n "
            "codes must all differ; default: 3)"
        ),
    )
    s.add_argument("--sequence", help="stripe codes of one cycle, e.g. 00010111 (default: B(2, order))")
    s.add_argument(
        "--channels",
        help="colour channels of code 1, code 0 and the fringe (rgb: the paper's red/green stripes, blue fringe; "
        "default: rgb)",
    )


def pattern_spec(args: argparse.Namespace, size_hw: tuple[int, int]) -> PatternSpec:
    """The PatternSpec of the pattern options (:func:`add_pattern_options`) at ``size_hw``."""
    from simbench.pattern import pattern_from_options

    return pattern_from_options(
        size_hw, period_px=args.period, order=args.order, sequence=args.sequence, channels=args.channels
    )
