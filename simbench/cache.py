"""Content-addressed cache of renders and ground truth.

A render is keyed by a SHA-256 of everything that affects it: the scene (rig, objects,
materials, the bytes of every mesh file, projector scale, ambient light), the projector drive
image, spp, seed, path length, the Mitsuba variant and version, and :data:`RENDER_VERSION`
(bumped when simbench's rendering code changes what it produces).  A decoder-only or
camera-only change therefore never re-renders.  Entries are ``.npz`` files written atomically,
so an interrupted run leaves no half-written entry, and each carries a SHA-256 of its arrays:
an entry damaged later (truncated, bit-flipped) fails the check and is re-made.  Processes may
share a cache: an entry two of them miss at once is made by one while the other waits
(:meth:`RenderCache.get_or_make`).

A cache grows with every scene, setting and code change that makes new keys (a full paper run
holds ~16 GB).  Each hit marks its entry's modification time as its last use, and the last use of
the entries it was made from (an entry made inside another's ``make`` is recorded as its source:
a warm run reads recordings, not the renders under them, and those must not look unused), so
:func:`cache_usage` tells what a cache holds and :func:`prune_cache` removes the entries used
least recently (``simbench cache info|prune``).  A disk that fills up does not stop a run: an
entry that cannot be stored for lack of space is logged once and the run goes on uncached.
A cache this process cannot write (a read-only mount, another user's folder: a cache shared read
only) is read: its hits are served, what a run makes is used and not stored (logged once), and no
lock is taken.

A cache folder carries a marker, :data:`MARKER_NAME` (a ``CACHEDIR.TAG`` of the Cache Directory
Tagging Specification, so that backup tools skip it, naming simbench and the cache's format).
A folder that holds other files and no marker is refused as a cache, and pruning touches only a
marked folder, and in it only the files whose names and contents are a cache's own: a user's
``my-data.npz`` or ``uv.lock`` in a folder given as ``--cache`` by mistake is never removed.
"""

from __future__ import annotations

import ast
import errno
import hashlib
import io
import json
import logging
import os
import re
import sys
import threading
import zipfile
import time
import weakref
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from simbench.io import DISK_FULL_ERRNOS, atomic_write_bytes, read_json_dict
from simbench import termination
from simbench.manifest import file_sha256

__all__ = [
    "CACHE_FORMAT",
    "MARKER_NAME",
    "PROGRESS_MIN_S",
    "RENDER_VERSION",
    "CacheEntry",
    "NotACacheError",
    "PruneResult",
    "RenderCache",
    "array_digest",
    "cache_entries",
    "cache_usage",
    "check_cache_folder",
    "check_cache_location",
    "CACHE_HINT",
    "claim_cache_folder",
    "prune_cache",
    "file_digest",
    "foreign_code_digest",
    "source_digest",
    "code_text",
    "user_cache_dir",
]

log = logging.getLogger(__name__)

RENDER_VERSION = 1

# a command's progress lines (``RenderCache.on_made``): the entries made in at least this long (a
# path-traced render, ground truth; not the many sub-second ones beside them)
PROGRESS_MIN_S = 1.0

# The cache folder's marker: a CACHEDIR.TAG (Cache Directory Tagging Specification, Bryan Ford
# 2004: its first line is this signature) whose second line names simbench and the format of the
# folder's files (entry names, lock and temporary files); bumped when that layout changes.
CACHE_FORMAT = 1
MARKER_NAME = "CACHEDIR.TAG"
_TAG_SIGNATURE = "Signature: 8a477f597d28d172789f06886806bc55"
_MARKER_LINE = "# simbench render cache, format "
_MARKER_TEXT = (
    f"{_TAG_SIGNATURE}\n{_MARKER_LINE}{CACHE_FORMAT}\n"
    "# This folder's entries are re-made when missing; `simbench cache info|prune` manages it.\n"
    "# Backup tools that follow the Cache Directory Tagging Specification skip it.\n"
)

# A cache's own files: entries ``KIND-KEY.npz``, locks ``KIND-KEY.lock`` and the temporary files of
# atomic writes ``.KIND-KEY.RANDOM.tmp`` (simbench.io's mkstemp), KEY 32 hex digits (RenderCache.key)
_KIND = r"[a-z][a-z0-9_]*"
_KEY = r"[0-9a-f]{32}"
_ENTRY_RE = re.compile(rf"({_KIND})-{_KEY}\.npz")
_LOCK_RE = re.compile(rf"{_KIND}-{_KEY}\.lock")
_TEMP_RE = re.compile(rf"\.(?:{_KIND}-{_KEY}|CACHEDIR)\.[A-Za-z0-9_]+\.tmp")
# The small per-user memos (:func:`user_cache_dir`: the code digests here, the spectral memo of
# simbench.sim.spectral.memo_path) and their atomic writes' temporary files.  They share the
# default folder ~/.cache/simbench with the render cache's default .cache/simbench when the working
# folder is the home folder, so a render cache tolerates them (and never prunes them).
_MEMO_RE = re.compile(
    r"(\.)?(?:code-digests-v\d+-python\d+\.\d+|spectral-colour[0-9A-Za-z.+_-]*-[0-9a-f]{16})"
    r"(?(1)\.[A-Za-z0-9_]+\.tmp|\.json)"
)


class NotACacheError(ValueError):
    """A folder given as a render cache is not one (no simbench marker, and other files in it),
    or is one of another format."""


def _marker_format(root: Path) -> int | None:
    """The format named by ``root``'s simbench marker; None when it has none (or another tool's
    CACHEDIR.TAG)."""
    try:
        lines = (root / MARKER_NAME).read_text(encoding="utf-8", errors="replace").splitlines()
    except (FileNotFoundError, NotADirectoryError, IsADirectoryError):
        return None
    if len(lines) < 2 or lines[0] != _TAG_SIGNATURE or not lines[1].startswith(_MARKER_LINE):
        return None
    try:
        return int(lines[1][len(_MARKER_LINE) :])
    except ValueError:
        return None


def _is_own_name(name: str) -> bool:
    return bool(
        _ENTRY_RE.fullmatch(name) or _LOCK_RE.fullmatch(name) or _TEMP_RE.fullmatch(name) or _MEMO_RE.fullmatch(name)
    )


def check_cache_folder(root: str | Path) -> Path:
    """``root`` as a cache folder of this format, or :class:`NotACacheError`.

    A marked folder of another format is refused; an unmarked one is refused when it holds
    anything but a cache's own files (an unmarked folder of those alone is a cache made before
    the marker existed).

    Raises
    ------
    FileNotFoundError
        ``root`` is not a folder.
    NotACacheError
        See above.
    """
    root = Path(root)
    if root.exists() and not root.is_dir():
        raise NotACacheError(f"{root} is a file, not a cache folder")
    if not root.is_dir():
        raise FileNotFoundError(f"{root}: no such cache folder")
    fmt = _marker_format(root)
    if fmt == CACHE_FORMAT:
        return root
    if fmt is not None:
        raise NotACacheError(
            f"{root}: a simbench render cache of format {fmt}, not {CACHE_FORMAT} (another simbench version's); "
            "use a new folder"
        )
    others = sorted(e.name for e in os.scandir(root) if not _is_own_name(e.name))
    if others == [MARKER_NAME] and _marker_format(root) == CACHE_FORMAT:
        # another process sharing a new folder marked it between our look and the listing (two
        # ablate workers starting on one new cache: one of them failed its run)
        return root
    if others:
        shown = ", ".join(others[:3]) + (f" and {len(others) - 3} more" if len(others) > 3 else "")
        # a marker damaged (emptied, overwritten) in a folder of cache entries locked the whole cache
        # out with advice that threw it away (an audit, 2026-11-30): say how to keep it
        damaged_marker = (
            f" - if this is a simbench cache whose {MARKER_NAME} was damaged, delete that file and it is "
            "marked again on the next run"
            if others == [MARKER_NAME]
            else ""
        )
        raise NotACacheError(
            f"{root}: not a simbench render cache (no {MARKER_NAME} of simbench's) and it holds other files "
            f"({shown}); give an empty or new folder as the cache{damaged_marker}"
        )
    return root


def check_cache_location(root: str | Path, *, what: str = "cache", hint: str = "") -> Path:
    """Check, before any work, that ``root`` can serve as a cache folder: a marked cache (read
    only where it cannot be written) or one that can be made there (not a file, not under a file,
    writable).  ``hint`` ends the
    message (the command line's: how to do without the default folder).

    Raises
    ------
    ValueError
        Naming the folder and what stands in the way (:class:`NotACacheError` for a folder of
        other files).
    """
    from simbench.io import check_output_folder

    try:
        try:
            root = check_output_folder(root, what=what)
        except ValueError:
            # a marked cache this process cannot write is read (module docstring); a folder that
            # is not one yet, or cannot be made, is the error
            if not (Path(root).is_dir() and _marker_format(Path(root)) == CACHE_FORMAT):
                raise
            root = Path(root)
        if root.exists():
            check_cache_folder(root)
    except ValueError as exc:
        if not hint:
            raise
        raise type(exc)(f"{exc}; {hint}") from None
    return root


# the errors of a write to a folder this process may not write: the cache is read only then
READ_ONLY_ERRNOS = (errno.EROFS, errno.EACCES, errno.EPERM)


def _can_write(root: Path) -> bool:
    """Whether this process can create a file in the folder ``root`` (a probe: ``os.access``
    passes for root on a read-only mount)."""
    from simbench.io import write_probe

    # the probe named as the cache's own temporaries (_TEMP_RE): another process checking a new,
    # still unmarked cache folder meanwhile must not take it for a user's file (a review)
    return os.access(root, os.W_OK | os.X_OK) and write_probe(root, prefix=".CACHEDIR.", suffix=".tmp") is None


# what the command line adds to a cache folder's error
CACHE_HINT = "pass --no-cache to store nothing, or --cache DIR for another folder"


def claim_cache_folder(root: str | Path) -> Path:
    """Make ``root`` a cache folder (created if missing, the marker written), or
    :class:`NotACacheError` when it holds other things (:func:`check_cache_folder`).  A
    folder that cannot be written keeps no marker (it is read: :class:`RenderCache`)."""
    root = Path(root)
    if not root.exists():
        try:
            root.mkdir(parents=True, exist_ok=True)
        except OSError:
            return root  # reported by the first store, with its file
    check_cache_folder(root)
    if _marker_format(root) is None:
        try:
            atomic_write_bytes(root / MARKER_NAME, _MARKER_TEXT.encode())
        except OSError as exc:
            log.debug("render cache %s: no marker written (%s)", root, exc)
        except ValueError:
            # another process sharing the folder marked it between our look and our write (the
            # writer refuses to replace a cache's marker): the folder is marked, as wanted
            if _marker_format(root) is None:
                raise
    return root


@lru_cache(maxsize=64)
def file_digest(path: str, mtime_ns: int, size: int) -> str:
    """:func:`simbench.manifest.file_sha256`, memoised by the file's time and size."""
    return file_sha256(path)


def source_digest(paths: Iterable[str | Path]) -> str:
    """SHA-256 over source files (name and code, in the order given): part of a cache key for
    results of code that may change between runs.

    A Python file counts by its syntax tree without docstrings (:func:`code_text`): an edit of
    its comments, docstrings or layout keeps the digest, as it keeps every result the code makes,
    while any change to what the code does changes it; other files (C) count by their bytes."""
    files = []
    for path in paths:
        st = Path(path).stat()
        files.append((str(path), st.st_mtime_ns, st.st_size))
    h = hashlib.sha256(f"python{sys.version_info[0]}.{sys.version_info[1]}/code{CODE_TEXT_VERSION}".encode())
    for (path, _, _), code in zip(files, _code_bytes(tuple(files))):
        h.update(Path(path).name.encode())
        h.update(code)
    return h.hexdigest()


_PACKAGE_ROOT = Path(__file__).resolve().parent


@lru_cache(maxsize=256)
def _own_file(file: str) -> bool:
    # (memoised: the decoder asks for its phase method on every call, ~40 us a time without)
    return Path(file).is_file() and Path(file).resolve().is_relative_to(_PACKAGE_ROOT)


def foreign_code_digest(*objects: object) -> str | None:
    """SHA-256 over the code of the callables in ``objects`` that are defined outside simbench's
    package - a user's own phase method or scene object kind, registered from their module - or
    None when every one is simbench's own (whose code the package's digests key already, so that
    their keys do not change).  Part of the cache keys of what such code makes, so that an edited
    extension, imported again, does not read what its earlier version made (an extender's audit,
    2026-11-30: a decoded reference plane, an ablation's finished runs and a render made by an
    older version came back, 4.9 mm off, without a word).

    A function counts by the source of the module that defines it (:func:`source_digest`: any
    change to what that module's code does) and its qualified name, read when this first sees the
    function object (so a file edited but not imported again keeps the key of the code that runs);
    one with no file (made in ``python -c`` or by ``exec``) by its bytecode and constants; a
    callable object by its class's module; a ``functools.partial`` by its function and arguments.
    Not seen: the modules the code imports, and what it reads at run time (a file, an environment
    variable, a global changed after import)."""
    import functools

    h = hashlib.sha256()
    foreign = False
    for obj in objects:
        args = ""
        while isinstance(obj, functools.partial):
            args += repr((obj.args, sorted(obj.keywords.items())))
            obj = obj.func
        digest = _callable_digest(obj)
        if digest is not None:
            foreign = True
            h.update(f"{digest}{args}".encode())
    return h.hexdigest() if foreign else None


_MISSING = object()
# callable -> its digest as first seen (None: simbench's own)
_FOREIGN_MEMO: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()
_FOREIGN_LOCK = threading.Lock()


def _callable_digest(obj: object) -> str | None:
    import inspect
    import marshal

    try:
        with _FOREIGN_LOCK:
            hit = _FOREIGN_MEMO.get(obj, _MISSING)
    except TypeError:  # (not weakly referable: read every time)
        hit = _MISSING
    if hit is not _MISSING:
        return hit
    code = getattr(obj, "__code__", None)
    owner = obj if code is not None or inspect.isclass(obj) or inspect.isroutine(obj) else type(obj)
    # the file the code was compiled from (a function made by exec or eval has none, whatever
    # module it lives in)
    file = code.co_filename if code is not None else getattr(inspect.getmodule(owner), "__file__", None)
    if file is not None and _own_file(file):
        digest = None
    else:
        h = hashlib.sha256(f"{getattr(owner, '__module__', '')}.{getattr(owner, '__qualname__', '')}".encode())
        if file is not None and Path(file).is_file():
            h.update(source_digest([file]).encode())
        elif code is not None:
            h.update(marshal.dumps(code, 2))  # (version 2: no reference flags, whose bytes vary with refcounts)
        else:
            h.update(type(obj).__qualname__.encode())
        digest = h.hexdigest()
    try:
        with _FOREIGN_LOCK:
            _FOREIGN_MEMO[obj] = digest
    except TypeError:
        pass
    return digest


_HEX64 = re.compile(r"[0-9a-f]{64}")
# bump when what code_text keeps of a module changes: it names the memo of file digests, whose
# entries are keyed by the files' bytes alone
CODE_TEXT_VERSION = 1


def user_cache_dir() -> Path | None:
    """The folder of simbench's small per-user memos (what the renders need from colour-science,
    the code digests of :func:`source_digest`): ``SIMBENCH_CACHE_DIR``, else
    ``$XDG_CACHE_HOME/simbench`` or ``~/.cache/simbench``; None when ``SIMBENCH_CACHE_DIR`` is set
    to an empty string (the memos off: their values computed every time)."""
    root = os.environ.get("SIMBENCH_CACHE_DIR")
    if root == "":
        return None
    if root is None:
        return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "simbench"
    return Path(root)


@lru_cache(maxsize=64)
def _code_bytes(files: tuple[tuple[str, int, int], ...]) -> tuple[bytes, ...]:
    """Each source file's bytes, or for a Python file the SHA-256 of its :func:`code_text`.
    Parsing the simulator's and the decoder's modules takes ~0.5 s, so those digests are kept in
    a memo in :func:`user_cache_dir`, keyed by the SHA-256 of the file's bytes (an entry that is
    not a digest is recomputed), written once for the files it lacked."""
    data = [Path(path).read_bytes() for path, _, _ in files]
    raw = [hashlib.sha256(d).hexdigest() for d in data]
    root = user_cache_dir()
    memo = (
        None
        if root is None
        else root / f"code-digests-v{CODE_TEXT_VERSION}-python{sys.version_info[0]}.{sys.version_info[1]}.json"
    )
    known = {} if memo is None else read_json_dict(memo)
    new = {}
    out = []
    for (path, _, _), d, r in zip(files, data, raw):
        if not path.endswith(".py"):
            out.append(d)
            continue
        hit = known.get(r)
        if not (isinstance(hit, str) and _HEX64.fullmatch(hit)):
            try:
                text = code_text(d).encode()
            except (SyntaxError, ValueError):  # not parsable here (a file being written, newer syntax)
                text = b"bytes:" + d
            hit = new[r] = hashlib.sha256(text).hexdigest()
        out.append(bytes.fromhex(hit))
    if new and memo is not None:
        try:  # merged with what other processes wrote meanwhile; replaced atomically
            memo.parent.mkdir(parents=True, exist_ok=True)
            atomic_write_bytes(memo, json.dumps({**read_json_dict(memo), **new}).encode())
        except OSError:
            pass  # an unwritable folder costs time, not results
    return tuple(out)


# CPython before 3.11.8 and 3.12.1 counts the AST constructor's depth in state the threads of an
# interpreter share (python/cpython#106905): two threads parsing at once raised "SystemError: AST
# constructor recursion depth mismatch" - the decoder's bands, each digesting a user's phase
# method on its first decode, did (a test run, 2026-12-01)
_AST_LOCK = threading.Lock()


def code_text(source: str | bytes) -> str:
    """What a Python module does, as text: its syntax tree (:func:`ast.dump`, without line
    numbers) with every module, class and function docstring removed - the same for two sources
    that differ only in comments, docstrings or layout.  Thread-safe (one parse at a time)."""
    with _AST_LOCK:
        tree = ast.parse(source)
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                if isinstance(body[0].value.value, str):
                    node.body = body[1:]
    return ast.dump(tree, annotate_fields=False, include_attributes=False)


def array_digest(a: np.ndarray) -> str:
    """SHA-256 of an array's dtype, shape and bytes."""
    a = np.ascontiguousarray(a)
    h = hashlib.sha256(f"{a.dtype.str}{a.shape}".encode())
    h.update(a.reshape(-1).view(np.uint8))  # the bytes tobytes() gives, without its copy (-40 %)
    return h.hexdigest()


def _digest(parts: dict) -> str:
    text = json.dumps(parts, sort_keys=True, default=str, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


class RenderCache:
    """A directory of cached arrays keyed by content; ``root=None`` disables caching.

    ``hits`` and ``misses`` count look-ups (for progress messages and tests), ``damaged`` the
    entries found unreadable or failing their checksum (removed and re-made), ``made`` the
    entries made per kind: ``{kind: (count, seconds)}``, the seconds spent in their ``make``
    with the entries made inside it (a recording's render) counted to their own kind.  That is
    where a cold run's time goes (:meth:`made_summary`).  ``unstored`` counts the entries made
    but not stored because the cache's disk was full or the cache is read only
    (:attr:`read_only`: a folder this process cannot write is read, its misses made and not
    stored; logged once per cache object).

    A folder holding other files than a cache's raises :class:`NotACacheError` here; the
    folder and its marker are written with the first entry (:func:`claim_cache_folder`), so a
    command that fails before storing anything leaves no folder behind.
    """

    def __init__(self, root: str | Path | None) -> None:
        self.root = None if root is None else Path(root)
        self.read_only = False
        if self.root is not None and self.root.exists():
            check_cache_folder(self.root)  # a wrong folder is refused before any work
            if self.root.is_dir() and not _can_write(self.root):
                self._go_read_only("this process cannot write in it")
        self._claimed = False
        self.hits = 0
        self.misses = 0
        self.damaged = 0
        self.unstored = 0
        self.made: dict[str, tuple[int, float]] = {}
        # called as on_made(kind, seconds) after each entry this process made (a command's progress)
        self.on_made: Callable[[str, float], None] | None = None
        self._lock = threading.Lock()
        # per thread, innermost last: the nested makes' seconds, and the keys each has used
        self._local = threading.local()

    @contextmanager
    def making(self, kind: str) -> Iterator[set[str]]:
        """Count the block as one entry of ``kind`` made (when it does not raise), with its
        time less that of the entries made inside it.  Yields the set of the keys of entries
        read or stored inside the block in this thread (and of their own sources): what the
        entry is made from, to pass to :meth:`store`."""
        stack = self._local.__dict__.setdefault("nested_s", [])
        frames = self._local.__dict__.setdefault("sources", [])
        stack.append(0.0)
        frames.append(set())
        t0 = time.perf_counter()
        ok = False
        try:
            yield frames[-1]
            ok = True
        finally:
            elapsed = time.perf_counter() - t0
            own = elapsed - stack.pop()
            frames.pop()
            if stack:
                stack[-1] += elapsed
            if ok:
                self.add_made({kind: (1, own)})
                if self.on_made is not None:
                    self.on_made(kind, own)

    def _used(self, path: Path, sources: Iterable[str]) -> None:
        """An entry was read: mark it and its sources used, and note them as sources of the
        entries being made around this read (in this thread)."""
        sources = list(sources)
        for p in (path, *(self.root / f"{k}.npz" for k in sources)):
            _mark_used(p)
        self._note_source(path.stem, sources)

    def _note_source(self, key: str, sources: Iterable[str]) -> None:
        """Record entry ``key`` and its own sources as sources of every entry being made in this
        thread around its read or store."""
        for frame in self._local.__dict__.get("sources", ()):
            frame.add(key)
            frame.update(sources)

    def add_made(self, made: dict[str, tuple[int, float]]) -> None:
        """Add another count of made entries (a worker process's) to :attr:`made`."""
        with self._lock:
            for kind, (n, s) in made.items():
                n0, s0 = self.made.get(kind, (0, 0.0))
                self.made[kind] = (n0 + n, s0 + s)

    def made_summary(self) -> str:
        """The entries made per kind, the costliest first: ``"radiance 12 (30.5 s), ..."``;
        "nothing" when every look-up was a hit."""
        with self._lock:
            items = sorted(self.made.items(), key=lambda kv: (-kv[1][1], kv[0]))
        return ", ".join(f"{kind} {n} ({s:.1f} s)" for kind, (n, s) in items) or "nothing"

    def key(self, kind: str, parts: dict) -> str:
        return f"{kind}-{_digest({'kind': kind, 'render_version': RENDER_VERSION, **parts})[:32]}"

    def get_or_make(
        self, kind: str, parts: dict, make: Callable[[], dict[str, np.ndarray]], *, wait: bool = True
    ) -> dict[str, np.ndarray] | None:
        """The arrays stored under ``(kind, parts)``, made by ``make()`` and stored on a miss.

        Processes sharing the cache (``simbench reproduce --workers``, ablation workers) make
        an entry once: a miss is made under an exclusive lock on the entry's key, and a process
        that waited for another's lock reads what that one stored (a hit, not a miss).
        ``wait=False``: None, at once, when another process is making the entry - for a caller
        with several entries to make, to make the others first (and come back for this one)."""
        out = self.lookup(kind, parts)
        if out is None and self.read_only:
            with self.making(kind) as sources:
                out = make()
            self.store(kind, parts, out, sources=sources)
        elif out is None:
            self._claim()
            lock = _KeyLock(None if self.read_only else self.root, self.key(kind, parts))
            try:  # not only `with lock`: a signal between acquire_now and entering must let it go too
                try:
                    got = lock.acquire_now()
                except OSError as exc:
                    if exc.errno not in READ_ONLY_ERRNOS:
                        raise
                    self._go_read_only(os.strerror(exc.errno))  # (the folder became unwritable)
                    lock = _KeyLock(None, "")
                    got = True
                if not wait and not got:
                    self.misses -= 1  # not looked up yet, as far as the counts go: the caller comes back
                    return None
                with lock:
                    # stored by another process since the lookup (it held the lock, or had just let it go)
                    if self.root is not None and (out := self._read(kind, parts)) is not None:
                        self.misses -= 1
                        self.hits += 1
                        return out
                    with self.making(kind) as sources:
                        out = make()
                    self.store(kind, parts, out, sources=sources)
            finally:
                lock.release()
        return out

    def _go_read_only(self, why: str) -> None:
        """Read the cache from here on: no entry stored, no lock taken (logged the first time)."""
        if not self.read_only:
            self.read_only = True
            log.warning(
                "render cache %s is read only (%s): its entries are read, and what this run makes is used and not "
                "stored",
                self.root,
                why,
            )

    def _claim(self) -> None:
        """Create the folder with its marker before the first lock or entry is written."""
        if self.root is not None and not self._claimed:
            claim_cache_folder(self.root)
            self._claimed = True

    def _read(self, kind: str, parts: dict) -> dict[str, np.ndarray] | None:
        path = self.root / f"{self.key(kind, parts)}.npz"
        out = _read_entry(path) if path.is_file() else None
        if out is not None:
            self._used(path, _pop_sources(out))
        return out

    def lookup(self, kind: str, parts: dict) -> dict[str, np.ndarray] | None:
        """The arrays stored under ``(kind, parts)``, or None (a miss; a damaged entry is
        removed and counts as one)."""
        if self.root is None:
            self.misses += 1
            return None
        path = self.root / f"{self.key(kind, parts)}.npz"
        if path.is_file():
            out = _read_entry(path)
            if out is not None:
                self._used(path, _pop_sources(out))
                self.hits += 1
                return out
            try:
                path.unlink(missing_ok=True)  # a damaged entry is re-made, never trusted
            except OSError as exc:  # (a read-only cache keeps it: it is never read as good)
                if exc.errno not in READ_ONLY_ERRNOS:
                    raise
            self.damaged += 1
        self.misses += 1
        return None

    def store(self, kind: str, parts: dict, arrays: dict[str, np.ndarray], *, sources: Iterable[str] = ()) -> None:
        """Store ``arrays`` under ``(kind, parts)`` (atomically, with their checksum), with the
        keys of the entries they were made from (``sources``, from :meth:`making`).

        A full disk (or quota) or a cache this process cannot write does not raise: the entry
        is not stored (``unstored``), the first time is logged, and the caller goes on with the
        arrays it has.  Any other error writing the cache raises."""
        if self.root is None:
            return
        if self.read_only:
            with self._lock:
                self.unstored += 1
            return
        self._claim()
        sources = sorted(sources)
        if sources:
            arrays = {**arrays, _SOURCES_KEY: np.frombuffer("\n".join(sources).encode("ascii"), np.uint8)}
        path = self.root / f"{self.key(kind, parts)}.npz"
        arrays = {**arrays, _NAME_KEY: np.frombuffer(path.stem.encode("ascii"), np.uint8)}
        buf = io.BytesIO()
        np.savez(buf, **arrays, **{_DIGEST_KEY: np.frombuffer(bytes.fromhex(_arrays_digest(arrays)), np.uint8)})
        try:
            atomic_write_bytes(path, buf.getvalue())
            self._note_source(path.stem, sources)
        except OSError as exc:
            if exc.errno in READ_ONLY_ERRNOS:
                self._go_read_only(os.strerror(exc.errno))
                with self._lock:
                    self.unstored += 1
                return
            if exc.errno not in DISK_FULL_ERRNOS:
                raise
            with self._lock:
                self.unstored += 1
                first = self.unstored == 1
            if first:
                log.warning(
                    "render cache %s: no space left on its disk (%s); the run goes on, storing no entry that does not "
                    "fit (`simbench cache info --cache %s` shows what it holds, `simbench cache prune` frees space)",
                    self.root,
                    os.strerror(exc.errno),
                    self.root,
                )


_DIGEST_KEY = "__sha256__"
_SOURCES_KEY = "__sources__"  # the keys of the entries an entry was made from, newline-separated ASCII
# the entry's own key, under the checksum: a file renamed or copied under another entry's name (by
# hand, or a sync tool) is damaged, not another key's arrays - an audit (2026-11-30) swapped two
# recordings' file names and `render` sealed the other capture, exit 0.  Entries written before
# it have none and are read as before.
_NAME_KEY = "__key__"


def _pop_sources(arrays: dict[str, np.ndarray]) -> list[str]:
    raw = arrays.pop(_SOURCES_KEY, None)
    return [] if raw is None or raw.size == 0 else raw.tobytes().decode("ascii").split("\n")


def _mark_used(path: Path) -> None:
    """Set an entry's modification time to now: its last use, which :func:`prune_cache` orders
    by (access times are not kept on ``noatime``/``relatime`` mounts).  A read-only cache
    keeps its times."""
    try:
        os.utime(path)
    except OSError:
        pass


# How long a process waits for another's lock on one entry before making the entry itself (the
# longest single entry, a full-resolution calibration view's renders, takes ~1 min on 2 cores).
# A backstop only: a process holding one key and waiting for a second while another holds the
# second and waits for the first would need each entry to be made from the other, and then one
# process alone would never finish either.
LOCK_WAIT_S = 1800.0


class _KeyLock:
    """An exclusive lock (``flock``) on one cache key among processes, held while the entry is
    made; entering waits for another holder to let it go.  No root: no lock.  The lock file is
    removed after the entry is stored; whoever takes the lock next finds the entry there
    (:meth:`RenderCache.get_or_make` reads it).  After ``LOCK_WAIT_S`` a waiter goes on
    without the lock (a warning): the entry may then be made twice, never wrongly (entries are
    written atomically)."""

    def __init__(self, root: Path | None, key: str) -> None:
        self.path = None if root is None else root / f"{key}.lock"
        self.fd: int | None = None

    def acquire_now(self) -> bool:
        """Take the lock if no other holder has it (entering then goes straight on); False if
        one has.  No root: True.  The command line's SIGTERM exception is held back while the
        lock file is made and taken (:func:`simbench.termination.held`: raised between the two,
        it left the file behind; CI saw it, rarely, under load) and, raised once the lock is held,
        lets it go with its file.  A signal mask would not do: the kernel gives the signal to a
        thread that does not block it (Dr.Jit's, the decoder's) and Python runs the handler in
        the main thread at once."""
        if self.path is None or self.fd is not None:
            return True
        import fcntl

        self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            with termination.held():
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
                try:
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                except BlockingIOError:
                    os.close(fd)
                    return False
                self.fd = fd
        except BaseException:
            self.release()
            raise
        return True

    def __enter__(self) -> None:
        import warnings

        deadline = time.monotonic() + LOCK_WAIT_S
        while not self.acquire_now():
            if time.monotonic() > deadline:
                warnings.warn(
                    f"cache entry {self.path.stem}: another process held it {LOCK_WAIT_S:.0f} s; making it here too"
                )
                return
            time.sleep(0.05)

    def __exit__(self, *exc) -> None:
        self.release()

    def release(self) -> None:
        """Remove the lock file and let the lock go (nothing if not held); SIGTERM's exception
        meanwhile waits until both are done (:func:`simbench.termination.held`)."""
        if self.fd is not None:
            with termination.held():
                self.path.unlink(missing_ok=True)
                os.close(self.fd)  # closing releases the lock
                self.fd = None


def _arrays_digest(arrays: dict[str, np.ndarray]) -> str:
    """SHA-256 over every array's name, dtype, shape and bytes, in name order."""
    h = hashlib.sha256()
    for name in sorted(arrays):
        h.update(name.encode())
        h.update(array_digest(np.asarray(arrays[name])).encode())
    return h.hexdigest()


def _read_entry(path: Path) -> dict[str, np.ndarray] | None:
    """A cache entry's arrays, or None if it cannot be read or its checksum does not match
    (truncated, bit-flipped, written by an older simbench without a checksum)."""
    try:
        # our own handle: np.load leaves its file open when the zip directory is unreadable
        with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as z:
            out = {k: z[k] for k in z.files}
    except Exception:  # noqa: BLE001 - zip, zlib, format and OS errors alike mean "damaged"
        return None
    stored = out.pop(_DIGEST_KEY, None)
    if stored is None or stored.dtype != np.uint8 or stored.tobytes().hex() != _arrays_digest(out):
        return None
    name = out.pop(_NAME_KEY, None)
    if name is not None and name.tobytes() != path.stem.encode("ascii"):
        return None
    return out


# ---------------------------------------------------------------------------------------
# What a cache holds, and pruning it.


@dataclass(frozen=True)
class CacheEntry:
    """One stored entry: its file, kind (``radiance``, ``recording``, ...), size and last use
    (the time of its last hit or, never hit, of its writing; seconds since the epoch)."""

    path: Path
    kind: str
    size_bytes: int
    last_used_s: float


# How old a writer's temporary file must be to count as left by a killed process: writing one
# entry (at most ~60 MB) takes seconds, so an hour leaves any live writer alone.
STALE_TEMP_S = 3600.0


def _is_entry_file(path: str) -> bool:
    """Whether the file is an entry this cache wrote: a zip whose members include the arrays'
    checksum (read from the zip's directory alone, not the arrays)."""
    try:
        with zipfile.ZipFile(path) as z:
            return f"{_DIGEST_KEY}.npy" in z.namelist()
    except (OSError, zipfile.BadZipFile, ValueError):
        return False


def cache_entries(root: str | Path) -> list[CacheEntry]:
    """Every entry in the cache folder ``root``, least recently used first (ties by name).

    Only the cache's own entries: a file named as one (``KIND-KEY.npz``) that is a zip holding
    the checksum an entry carries.  A damaged entry (its zip directory unreadable) is not listed;
    a look-up removes it.

    Raises
    ------
    FileNotFoundError
        ``root`` is not a folder.
    NotACacheError
        ``root`` is not a simbench render cache (:func:`check_cache_folder`).
    """
    root = check_cache_folder(root)
    out = []
    with os.scandir(root) as it:
        for e in it:
            m = _ENTRY_RE.fullmatch(e.name)
            if m is None or not e.is_file(follow_symlinks=False) or not _is_entry_file(e.path):
                continue
            try:
                st = e.stat(follow_symlinks=False)
            except FileNotFoundError:  # removed meanwhile by another process
                continue
            out.append(CacheEntry(Path(e.path), m.group(1), st.st_size, st.st_mtime))
    out.sort(key=lambda c: (c.last_used_s, c.path.name))
    return out


def cache_usage(root: str | Path) -> dict[str, tuple[int, int]]:
    """``{kind: (entries, bytes)}`` of the cache folder ``root``, the largest kind first."""
    usage: dict[str, tuple[int, int]] = {}
    for c in cache_entries(root):
        n, b = usage.get(c.kind, (0, 0))
        usage[c.kind] = (n + 1, b + c.size_bytes)
    return dict(sorted(usage.items(), key=lambda kv: (-kv[1][1], kv[0])))


@dataclass(frozen=True)
class PruneResult:
    """What :func:`prune_cache` removed (or, in a dry run, would remove): ``entries``, least
    recently used first, and ``leftovers``, the temporary files of killed writers and the lock
    files no process holds."""

    entries: list[CacheEntry]
    leftovers: list[Path]

    @property
    def paths(self) -> list[Path]:
        """Every file removed (or to be), entries first."""
        return [c.path for c in self.entries] + list(self.leftovers)


def prune_cache(
    root: str | Path,
    *,
    max_bytes: int | None = None,
    unused_for_s: float | None = None,
    dry_run: bool = False,
    now_s: float | None = None,
) -> PruneResult:
    """Remove the cache's least recently used entries; returns what was removed (or, with
    ``dry_run``, all that would be).

    Removed are every entry not used for ``unused_for_s`` seconds, then the least recently
    used of the rest until they hold at most ``max_bytes``.  Temporary files of writers killed
    mid-write (older than :data:`STALE_TEMP_S`) and lock files no process holds go too.  Safe
    beside a running simbench: an entry removed under it is a miss, made again.  Only a marked
    cache folder is pruned, and only its own files (:func:`cache_entries`): nothing else in it
    is touched.

    Parameters
    ----------
    root : str or Path
        The cache folder.
    max_bytes : int, optional
        The most the kept entries may hold, bytes (>= 0).
    unused_for_s : float, optional
        Entries last used longer ago than this are removed, seconds (>= 0).
    dry_run : bool
        Only list what would be removed.
    now_s : float, optional
        The present, seconds since the epoch (default: now).

    Raises
    ------
    ValueError
        Neither bound is given, or one is negative.
    FileNotFoundError
        ``root`` is not a folder.
    NotACacheError
        ``root`` is not a simbench render cache, or is unmarked (made before caches were
        marked: a run with it marks it).
    """
    if max_bytes is None and unused_for_s is None:
        raise ValueError("prune_cache needs max_bytes or unused_for_s (or both)")
    if max_bytes is not None and max_bytes < 0:
        raise ValueError(f"max_bytes must be >= 0, got {max_bytes}")
    if unused_for_s is not None and not unused_for_s >= 0:
        raise ValueError(f"unused_for_s must be >= 0, got {unused_for_s}")
    root = check_cache_folder(root)
    if _marker_format(root) is None:  # pruning asks for proof, not a guess from the names
        raise NotACacheError(
            f"{root}: no {MARKER_NAME} of simbench's, so it is not pruned (a render with --cache {root} marks a "
            "folder that holds only cache entries)"
        )
    now_s = time.time() if now_s is None else now_s
    entries = cache_entries(root)
    total = sum(c.size_bytes for c in entries)
    removed = []
    for c in entries:  # least recently used first
        too_old = unused_for_s is not None and now_s - c.last_used_s > unused_for_s
        too_big = max_bytes is not None and total > max_bytes
        if not (too_old or too_big):
            continue
        removed.append(c)
        total -= c.size_bytes
        if not dry_run:
            c.path.unlink(missing_ok=True)
    return PruneResult(removed, _leftovers(root, now_s=now_s, remove=not dry_run))


def damaged_entries(root: str | Path) -> list[Path]:
    """The damaged entries of the cache folder ``root``, by name: files named as entries
    (``KIND-KEY.npz``) that begin as an entry does (a zip's local header) but whose zip directory
    is unreadable or lacks the entry's checksum - truncated, overwritten (:func:`cache_entries`
    leaves them out; a look-up removes and re-makes them).  One damaged inside its arrays (a
    flipped byte) is found by a look-up's checksum only (reading every entry's arrays here would
    take minutes).  A file of an entry's name that is no zip at all is not taken for one (a
    user's, :func:`prune_cache` never touches it).  Entries are written whole under a temporary
    name and renamed, so a file of an entry's name is never one being written."""
    root = check_cache_folder(root)

    def zip_begun(path: str) -> bool:
        try:
            with open(path, "rb") as fh:
                return fh.read(4) == b"PK\x03\x04"
        except OSError:
            return False

    with os.scandir(root) as it:
        return sorted(
            Path(e.path)
            for e in it
            if _ENTRY_RE.fullmatch(e.name)
            and e.is_file(follow_symlinks=False)
            and zip_begun(e.path)
            and not _is_entry_file(e.path)
        )


def _leftovers(root: Path, *, now_s: float, remove: bool) -> list[Path]:
    """Temporary files of killed writers, lock files no process holds and damaged entries
    (:func:`damaged_entries`; removed if ``remove``); only files named as the cache's own, and no
    lock with content (ours are empty)."""
    import fcntl

    out = []
    damaged = set(damaged_entries(root))
    for e in os.scandir(root):
        if not e.is_file(follow_symlinks=False):
            continue
        p = Path(e.path)
        try:
            st = e.stat(follow_symlinks=False)
        except FileNotFoundError:
            continue
        if p in damaged:  # (as a look-up removes one)
            out.append(p)
            if remove:
                p.unlink(missing_ok=True)
        elif _TEMP_RE.fullmatch(e.name):
            if now_s - st.st_mtime > STALE_TEMP_S:
                out.append(p)
                if remove:
                    p.unlink(missing_ok=True)
        elif _LOCK_RE.fullmatch(e.name) and st.st_size == 0:
            try:
                fd = os.open(p, os.O_RDWR)
            except FileNotFoundError:
                continue
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:  # a process is making this entry
                os.close(fd)
                continue
            out.append(p)
            if remove:
                p.unlink(missing_ok=True)  # as the holder does when it has stored its entry
            os.close(fd)
    return sorted(out)
