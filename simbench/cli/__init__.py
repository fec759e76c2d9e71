"""Command line: each subcommand parses its arguments and calls one library function.

Errors are one line on stderr and exit status 2 (``--debug`` shows the traceback).

One module per command group (:mod:`~simbench.cli.render`, :mod:`~simbench.cli.calibrate`,
:mod:`~simbench.cli.decode`, :mod:`~simbench.cli.experiments`, :mod:`~simbench.cli.cache`), each
adding its commands to the parser; the options they share are in :mod:`~simbench.cli.options`.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import re
import sys
from pathlib import Path

from simbench.cli import cache, calibrate, decode, experiments, render
from simbench.cli.options import DEFAULT_CACHE, Formatter, Parser, human_bytes

__all__ = ["main"]


def _parser() -> argparse.ArgumentParser:

    kw = {"formatter_class": Formatter}
    p = Parser(
        prog="simbench",
        description="Simulation testbed for single-shot structured-light depth sensing (Li et al., Sensors 2017).",
        **kw,
    )
    p.add_argument("--debug", action="store_true", help="show tracebacks")
    sub = p.add_subparsers(dest="command", required=True, parser_class=Parser)

    render.add_parsers(sub, kw)
    calibrate.add_parsers(sub, kw)
    decode.add_parsers(sub, kw)
    experiments.add_parsers(sub, kw)
    cache.add_parsers(sub, kw)
    _debug_after_the_command(sub)
    return p


def _debug_after_the_command(sub: argparse._SubParsersAction) -> None:
    """``--debug`` taken after a command too (``simbench decode ... --debug``), as users type it;
    the command's own default leaves the one given before the command standing."""
    for parser in sub.choices.values():
        parser.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help="show tracebacks")
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                _debug_after_the_command(action)


class _LevelFormatter(logging.Formatter):
    """``simbench: warning: ...`` for a warning, as the commands' own warnings read (``score``,
    ``calibrate``); ``simbench: error: ...`` for an error; other records ``simbench: ...``."""

    def format(self, record: logging.LogRecord) -> str:
        level = {logging.WARNING: "warning: ", logging.ERROR: "error: "}.get(record.levelno, "")
        return f"simbench: {level}{super().format(record)}"


class _StderrHandler(logging.StreamHandler):
    """Library messages (``logging``, logger ``simbench``) as ``simbench: warning: ...`` lines
    (:class:`_LevelFormatter`) on the current ``sys.stderr`` (looked up per record, so redirected
    streams see them)."""

    def __init__(self) -> None:
        super().__init__()
        self.setFormatter(_LevelFormatter())

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, value) -> None:
        pass


def _report_library_messages() -> None:
    logger = logging.getLogger("simbench")
    if not any(isinstance(h, _StderrHandler) for h in logger.handlers):
        logger.addHandler(_StderrHandler())
    logger.setLevel(logging.WARNING)


# options that name files or folders (an empty value is refused for every one)
_PATH_OPTIONS = (
    "out",
    "confidence",
    "ply",
    "debug_dir",
    "write_thresholds",
    "check",
    "cache",
    "calibration",
    "reference",
    "rig",
    "gt",
    "lit",
    "column",
    "gt_column",
)


def main(argv: list[str] | None = None) -> int:
    """Run one command; returns the exit status (0 ok, 1 a bug or a failed check, 2 bad input)."""
    from simbench.threads import (
        THREADS_VARIABLE,
        apply_threads,
        limit_malloc_arenas,
        process_threads,
        single_thread_blas,
    )

    single_thread_blas()
    limit_malloc_arenas()
    _report_library_messages()
    if os.environ.get(THREADS_VARIABLE, "").strip():  # the user's share of the machine for every pool
        try:
            apply_threads(process_threads())
        except ValueError as exc:
            print(f"simbench: error: {exc}", file=sys.stderr)
            return 2
    try:
        args = _parser().parse_args(_negative_values_attached(sys.argv[1:] if argv is None else list(argv)))
    except SystemExit as exc:  # --help, or a usage error already printed as one line
        return exc.code if isinstance(exc.code, int) else 2
    empty = [name for name in _PATH_OPTIONS if getattr(args, name, None) == ""]
    if empty:  # "" would mean the working folder to some writers (demo, reproduce wrote into it)
        print(f"simbench: error: --{empty[0].replace('_', '-')}: an empty path; give a file or folder", file=sys.stderr)
        return 2
    previous = _on_sigterm_raise()
    try:
        with _warnings_as_lines():
            return args.fn(args)
    except KeyboardInterrupt:
        print("simbench: interrupted", file=sys.stderr)
        return 130
    except _Terminated:
        print(_TERMINATED_LINE, file=sys.stderr)
        _quiet_finalizers(args)
        return 143
    except BrokenPipeError:  # `simbench ... | head`: the reader has gone; stop quietly, as `yes | head` does
        try:
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # the exit's flush is not a 2nd error
        except (OSError, ValueError, AttributeError):  # a stdout without a descriptor (a test's buffer)
            pass
        return 141
    except MemoryError as exc:
        _traceback_if_asked(exc, args)
        print("simbench: error: out of memory (the inputs ask for more than this machine has)", file=sys.stderr)
        return 2
    except Exception as exc:  # noqa: BLE001 - SIGTERM re-wrapped by a render (simbench.termination)
        from simbench import termination

        if not termination.requested():
            return _report_error(exc, args)
        if termination.requested_signal() == 2:  # Ctrl-C, re-wrapped by a render
            print("simbench: interrupted", file=sys.stderr)
            return 130
        print(_TERMINATED_LINE, file=sys.stderr)
        _quiet_finalizers(args)
        return 143
    finally:
        if previous is not None:
            import signal

            signal.signal(signal.SIGTERM, previous[0])
            signal.signal(signal.SIGINT, previous[1])


@contextlib.contextmanager
def _warnings_as_lines():
    """The library's :class:`simbench.SimbenchWarning` (what the Python API warns of) printed as
    the command line's other messages are, one ``simbench: ...`` line each, every time (not as
    Python's ``file:line: SimbenchWarning: ...`` with the source line, once per place)."""
    import warnings

    from simbench import SimbenchWarning

    shown = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, SimbenchWarning):
            logging.getLogger("simbench").warning("%s", message)
        else:
            shown(message, category, filename, lineno, file, line)

    with warnings.catch_warnings():
        warnings.simplefilter("always", SimbenchWarning)
        warnings.showwarning = show
        yield


# a value that argparse would take for an option, since it begins with "-": "-1G", "-1e3", "-inf"
# (argparse reads only "-1" and "-0.5" as numbers); no simbench option name begins so
_NEGATIVE_VALUE = re.compile(r"-(\d|\.\d|inf\b|nan\b)", re.IGNORECASE)


def _negative_values_attached(argv: list[str]) -> list[str]:
    """``--max-size -1G`` as ``--max-size=-1G``: argparse said "expected one argument" of a value
    that it took for an option; attached, the option's own check names the value."""
    out: list[str] = []
    for token in argv:
        previous = out[-1] if out else ""
        if _NEGATIVE_VALUE.match(token) and previous.startswith("--") and "=" not in previous and previous != "--":
            out[-1] = f"{previous}={token}"
        else:
            out.append(token)
    return out


def _traceback_if_asked(exc: BaseException, args) -> None:
    if getattr(args, "debug", False):
        import traceback

        traceback.print_exception(exc, file=sys.stderr)


def _report_error(exc: Exception, args) -> int:
    """One line for a failed command: exit 2 for bad input (missing or unreadable files,
    invalid values), 1 for anything else, a bug (``--debug``: the traceback first, the same exit
    status: a script's handling of bad input does not change with it)."""
    _traceback_if_asked(exc, args)
    if isinstance(exc, (ValueError, OSError)):
        print(f"simbench: error: {_one_line(exc)}{_disk_full_hint(exc, args)}", file=sys.stderr)
        return 2
    from simbench.systems import plugin_in_traceback

    plugin = plugin_in_traceback(exc)
    if plugin is not None:  # another package's bug, not simbench's
        print(
            f"simbench: error in the {plugin} ({type(exc).__name__}: {_one_line(exc)}); rerun with --debug for the "
            "traceback and report it to the plugin's authors",
            file=sys.stderr,
        )
        return 1
    print(
        f"simbench: internal error ({type(exc).__name__}: {_one_line(exc)}); rerun with --debug for the traceback "
        f"and please report it",
        file=sys.stderr,
    )
    return 1


_TERMINATED_LINE = "simbench: terminated (SIGTERM); partial outputs and cache locks removed"


def _quiet_finalizers(args) -> None:
    """After SIGTERM, objects the signal interrupted half-built may fail in their finalizers at
    exit (a ``ZipFile`` whose ``__init__`` it cut short: "Exception ignored in ZipFile.__del__",
    seen in CI), which printed tracebacks after the one-line message: those are dropped (kept
    with ``--debug``).  Their files are the temporaries the unwinding already removed."""
    if not getattr(args, "debug", False):
        sys.unraisablehook = lambda unraisable: None


class _Terminated(BaseException):
    """SIGTERM (``kill``, a job scheduler's stop) raised in the main thread, as Ctrl-C raises
    KeyboardInterrupt: the ``with`` blocks unwind, so temporary folders go and cache locks are
    released and removed, and the exit says so."""


def _on_sigterm_raise():
    """Turn SIGTERM into :class:`_Terminated` while a command runs, and note Ctrl-C before its
    KeyboardInterrupt (:mod:`simbench.termination`); returns the SIGTERM and SIGINT handlers to
    restore (None off the main thread, where signals cannot be handled)."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return None

    def handler(signum, frame):
        f = frame
        while f is not None:
            # an exception raised inside an import breaks a C extension's initialisation (Mitsuba's
            # aborts the interpreter at exit): ask again once the import is done
            if f.f_code.co_filename.startswith("<frozen importlib"):
                threading.Timer(0.05, os.kill, (os.getpid(), signal.SIGTERM)).start()
                return
            f = f.f_back
        from simbench import termination

        termination.request()
        termination.run_or_hold(_raise_terminated)  # not inside a cache lock's taking or letting go

    def interrupted(signum, frame):
        # Ctrl-C raises KeyboardInterrupt as ever; noted first, so that code which records a failed
        # task and goes on (an ablation run) sees it through a render's re-wrapping RuntimeError
        from simbench import termination

        termination.request(signal.SIGINT)
        # not between a cache lock's taking and its file, nor between two renames of a file set
        termination.run_or_hold(lambda: signal.default_int_handler(signum, frame))

    previous_int = signal.getsignal(signal.SIGINT)
    if previous_int is signal.default_int_handler:  # (not where a caller set its own)
        signal.signal(signal.SIGINT, interrupted)
    return signal.signal(signal.SIGTERM, handler), previous_int


def _raise_terminated() -> None:
    raise _Terminated()


def _disk_full_hint(exc: BaseException, args) -> str:
    """For a full disk: how much is free where the write failed, and how to free the cache."""
    import shutil

    from simbench.io import DISK_FULL_ERRNOS

    if not isinstance(exc, OSError) or exc.errno not in DISK_FULL_ERRNOS:
        return ""
    where = Path(exc.filename) if exc.filename else Path(".")
    while not where.exists() and where != where.parent:
        where = where.parent
    try:
        free = f"{human_bytes(shutil.disk_usage(where).free)} free there now; "
    except OSError:
        free = ""
    # the cache the command used; without one (--no-cache, a command that keeps none) the default
    # cache where there is one - a cache the command did not use was named (an audit, 2026-11-30)
    cache = None if getattr(args, "no_cache", False) else getattr(args, "cache", None)
    if cache is None and Path(DEFAULT_CACHE).is_dir():
        cache = DEFAULT_CACHE
    if cache is None:
        return f" ({free.removesuffix('; ')})" if free else ""
    return (
        f" ({free}`simbench cache info --cache {cache}` shows what the render cache holds, "
        f"`simbench cache prune --cache {cache} --max-size SIZE` frees it)"
    )


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text or type(exc).__name__
