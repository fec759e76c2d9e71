"""Content-addressed cache of renders and ground truth.

A render is keyed by a SHA-256 of everything that affects it: the scene (rig, objects,
materials, the bytes of every mesh file, projector scale, ambient light), the projector drive
image, spp, seed, path length, the Mitsuba variant and version, and :data:`RENDER_VERSION`
(bumped when simbench's rendering code changes what it produces).  A decoder-only or
camera-only change therefore never re-renders.  Entries are ``.npz`` files written atomically,
so an interrupted run leaves no half-written entry, and each carries a SHA-256 of its arrays:
an entry damaged later (truncated, bit-flipped) fails the check and is re-made; delete the
directory to clear the cache.  Processes may share a cache: an entry two of them miss at once is
made by one while the other waits (:meth:`RenderCache.get_or_make`).
"""

from __future__ import annotations

import hashlib
import io
import json
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from functools import lru_cache
from pathlib import Path

import numpy as np

from simbench.io import atomic_write_bytes
from simbench.rig import rig_to_dict
from simbench.scene import SceneSpec

__all__ = ["RENDER_VERSION", "RenderCache", "scene_fingerprint", "array_digest", "source_digest"]

RENDER_VERSION = 1


@lru_cache(maxsize=64)
def _file_digest(path: str, mtime_ns: int, size: int) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def source_digest(paths: Iterable[str | Path]) -> str:
    """SHA-256 over source files (name and bytes, in the order given): part of a cache key
    for results of code that may change between runs."""
    h = hashlib.sha256()
    for path in paths:
        path = Path(path)
        h.update(path.name.encode())
        h.update(path.read_bytes())
    return h.hexdigest()


def array_digest(a: np.ndarray) -> str:
    """SHA-256 of an array's dtype, shape and bytes."""
    a = np.ascontiguousarray(a)
    h = hashlib.sha256(f"{a.dtype.str}{a.shape}".encode())
    h.update(a.reshape(-1).view(np.uint8))  # the bytes tobytes() gives, without its copy (-40 %)
    return h.hexdigest()


def scene_fingerprint(scene: SceneSpec) -> dict:
    """Everything about a scene that affects a render, as plain JSON-able data."""
    objects = []
    for o in scene.objects:
        params = dict(o.params)
        if o.kind == "mesh":
            p = Path(params["file"])
            st = p.stat()
            params["file"] = {"name": p.name, "sha256": _file_digest(str(p), st.st_mtime_ns, st.st_size)}
        material = [o.material.kind, list(o.material.rgb), o.material.roughness]
        if o.material.specular_rgb != (1.0, 1.0, 1.0):
            material.append(list(o.material.specular_rgb))
        if o.material.spectrum is not None:
            material.append({"spectrum": o.material.spectrum})
        objects.append({"kind": o.kind, "name": o.name, "params": params, "material": material})
    return {
        "rig": rig_to_dict(scene.rig),
        "objects": objects,
        "projector_scale": scene.projector_scale,
        "ambient_rgb": list(scene.ambient_rgb),
        # only when set, so that pinhole scenes keep their cache keys
        **({"camera_lens": list(scene.camera_lens)} if scene.camera_lens is not None else {}),
    }


def _digest(parts: dict) -> str:
    text = json.dumps(parts, sort_keys=True, default=str, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


class RenderCache:
    """A directory of cached arrays keyed by content; ``root=None`` disables caching.

    ``hits`` and ``misses`` count look-ups (for progress messages and tests), ``damaged`` the
    entries found unreadable or failing their checksum (removed and re-made), ``made`` the
    entries made per kind: ``{kind: (count, seconds)}``, the seconds spent in their ``make``
    with the entries made inside it (a recording's render) counted to their own kind.  That is
    where a cold run's time goes (:meth:`made_summary`).
    """

    def __init__(self, root: str | Path | None) -> None:
        self.root = None if root is None else Path(root)
        self.hits = 0
        self.misses = 0
        self.damaged = 0
        self.made: dict[str, tuple[int, float]] = {}
        self._lock = threading.Lock()
        self._local = threading.local()  # per thread: the nested makes' seconds, innermost last

    @contextmanager
    def making(self, kind: str) -> Iterator[None]:
        """Count the block as one entry of ``kind`` made (when it does not raise), with its
        time less that of the entries made inside it."""
        stack = self._local.__dict__.setdefault("nested_s", [])
        stack.append(0.0)
        t0 = time.perf_counter()
        ok = False
        try:
            yield
            ok = True
        finally:
            elapsed = time.perf_counter() - t0
            own = elapsed - stack.pop()
            if stack:
                stack[-1] += elapsed
            if ok:
                self.add_made({kind: (1, own)})

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

    def get_or_make(self, kind: str, parts: dict, make: Callable[[], dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
        """The arrays stored under ``(kind, parts)``, made by ``make()`` and stored on a miss.

        Processes sharing the cache (``simbench reproduce --workers``, ablation workers) make
        an entry once: a miss is made under an exclusive lock on the entry's key, and a process
        that waited for another's lock reads what that one stored (a hit, not a miss)."""
        out = self.lookup(kind, parts)
        if out is None:
            with _KeyLock(self.root, self.key(kind, parts)) as waited:
                if waited and (out := self._read(kind, parts)) is not None:
                    self.misses -= 1
                    self.hits += 1
                    return out
                with self.making(kind):
                    out = make()
                self.store(kind, parts, out)
        return out

    def _read(self, kind: str, parts: dict) -> dict[str, np.ndarray] | None:
        path = self.root / f"{self.key(kind, parts)}.npz"
        return _read_entry(path) if path.is_file() else None

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
                self.hits += 1
                return out
            path.unlink(missing_ok=True)  # a damaged entry is re-made, never trusted
            self.damaged += 1
        self.misses += 1
        return None

    def store(self, kind: str, parts: dict, arrays: dict[str, np.ndarray]) -> None:
        """Store ``arrays`` under ``(kind, parts)`` (atomically, with their checksum)."""
        if self.root is None:
            return
        buf = io.BytesIO()
        np.savez(buf, **arrays, **{_DIGEST_KEY: np.frombuffer(bytes.fromhex(_arrays_digest(arrays)), np.uint8)})
        atomic_write_bytes(self.root / f"{self.key(kind, parts)}.npz", buf.getvalue())


_DIGEST_KEY = "__sha256__"

# How long a process waits for another's lock on one entry before making the entry itself (the
# longest single entry, a full-resolution calibration view's renders, takes ~1 min on 2 cores).
# A backstop only: a process holding one key and waiting for a second while another holds the
# second and waits for the first would need each entry to be made from the other, and then one
# process alone would never finish either.
LOCK_WAIT_S = 1800.0


class _KeyLock:
    """An exclusive lock (``flock``) on one cache key among processes, held while the entry is
    made; entering says whether it had to wait for another holder.  No root: no lock.  The lock
    file is removed after the entry is stored; a process that opened it before only finds the
    entry there.  After ``LOCK_WAIT_S`` a waiter goes on without the lock (a warning): the
    entry may then be made twice, never wrongly (entries are written atomically)."""

    def __init__(self, root: Path | None, key: str) -> None:
        self.path = None if root is None else root / f"{key}.lock"
        self.fd: int | None = None

    def __enter__(self) -> bool:
        if self.path is None:
            return False
        import fcntl
        import os
        import time
        import warnings

        self.path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        waited, deadline = False, time.monotonic() + LOCK_WAIT_S
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                self.fd = fd
                return waited
            except BlockingIOError:
                if time.monotonic() > deadline:
                    os.close(fd)
                    warnings.warn(
                        f"cache entry {self.path.stem}: another process held it {LOCK_WAIT_S:.0f} s; making it here too"
                    )
                    return True
                waited = True
                time.sleep(0.05)

    def __exit__(self, *exc) -> None:
        if self.fd is not None:
            import os

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
    return out
