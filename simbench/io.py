"""File I/O: atomic writes and the formats users expect (PNG, NPY, EXR, PLY, JSON).

Every writer goes through a temporary file in the destination directory and ``os.replace``,
so an interrupted run never leaves a half-written result behind.
"""

from __future__ import annotations

import io
import errno
import hashlib
import json
import functools
import os
import re
import tempfile
import warnings
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from simbench import termination, validate
from simbench.warn import SimbenchWarning

__all__ = [
    "check_not_protected",
    "claim_output",
    "check_own_folder",
    "check_output_directory",
    "recorded_files",
    "not_recorded",
    "file_sha256",
    "atomic_write_bytes",
    "atomic_write_text",
    "json_bytes",
    "save_json",
    "npy_bytes",
    "save_npy",
    "load_npy",
    "write_files",
    "output_directory",
    "png_bytes",
    "ply_bytes",
    "save_png",
    "load_image",
    "adc_full_scale",
    "camera_full_scale",
    "ENCODINGS",
    "check_encoding",
    "linearize",
    "narrow_uint16_hint",
    "save_exr",
    "stored_adc_bits",
    "load_depth_map",
    "save_ply",
    "read_toml",
    "read_json_dict",
]


def _file_mode() -> int:
    """Permissions a plain ``open()`` would give (mkstemp's are 0600)."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def _raise_with_filename(exc: BaseException, path: Path) -> None:
    """A failed write or fsync does not say which file ("[Errno 28] No space left on device"),
    and a failed temporary file names itself (".depth.k2j4.ply: Permission denied"): raise it
    again naming ``path``, so the message and the free-space hint point at the file asked for.
    Other exceptions are left to the caller's ``raise``."""
    if not isinstance(exc, OSError) or exc.errno is None:
        return
    named = exc.filename
    temporary = named is not None and Path(os.fsdecode(named)).name.startswith(f".{path.stem}.")
    if named is None or temporary:
        raise OSError(exc.errno, exc.strerror, str(path)) from exc


# Files simbench writes to mark what a folder is: a recording's manifests (simbench.manifest) and
# the render cache's marker (simbench.cache).  No output may replace one, or a file a manifest
# lists: a recording would no longer decode, a cache would be refused.
_MANIFEST_NAMES = ("meta.json", "device.json")
_CACHE_MARKER = "CACHEDIR.TAG"


def check_not_protected(path: str | Path) -> None:
    """ValueError when ``path`` is an existing recording manifest, a file its folder's
    manifest lists, or a render cache's marker (new files beside them are fine)."""
    path = Path(path)
    if not path.is_file():
        return
    if path.name == _CACHE_MARKER and "simbench render cache" in path.read_text(errors="replace")[:200]:
        raise ValueError(f"{path} is a simbench render cache's marker; choose another output path")
    for name in _MANIFEST_NAMES:
        m = path.parent / name
        if not m.is_file():
            continue
        try:
            files = json.loads(m.read_text(encoding="utf-8")).get("files", {})
        except (ValueError, UnicodeDecodeError, AttributeError, OSError):
            continue
        listed = set(files.values()) if isinstance(files, dict) else set()
        if path.name == name or path.name in listed:
            raise ValueError(
                f"{path} belongs to the recording in {path.parent} (listed in its {name}): writing it would break the "
                "recording; choose another output path"
            )


@contextmanager
def _atomic_target(path: Path, suffix: str) -> Iterator[str]:
    """A temporary file beside ``path`` that replaces it when the block succeeds."""
    check_not_protected(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=suffix, dir=path.parent)
    except OSError as exc:  # a folder this process may not write to
        _raise_with_filename(exc, path)
        raise
    os.close(fd)
    try:
        os.chmod(tmp, _file_mode())
        yield tmp
        os.replace(tmp, path)
    except BaseException as exc:
        if os.path.exists(tmp):
            os.unlink(tmp)
        _raise_with_filename(exc, path)
        raise


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _remove_stale_siblings(folder: Path) -> None:
    """Remove temporary siblings of ``folder`` left by a process that was killed while
    building or replacing it (their names carry the dead process's id)."""
    import re
    import shutil

    pattern = re.compile(re.escape(f".{folder.name}.") + r"(tmp|old)-(\d+)-")
    for entry in folder.parent.glob(f".{folder.name}.*"):
        m = pattern.match(entry.name)
        if m and entry.is_dir() and not _pid_alive(int(m.group(2))):
            shutil.rmtree(entry, ignore_errors=True)


def _exchange(a: Path, b: Path) -> bool:
    """Swap two paths atomically (Linux ``renameat2(RENAME_EXCHANGE)``); False if unsupported."""
    import ctypes

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        fn = libc.renameat2
    except (OSError, AttributeError):
        return False
    at_fdcwd, rename_exchange = -100, 2
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    return fn(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange) == 0


def file_sha256(path: str | Path) -> str:
    """SHA-256 of a file's bytes, read in 1 MiB blocks."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def recorded_files(folder: Path, manifest: str | Sequence[str]) -> tuple[set[str], dict[str, str]] | None:
    """What the first readable ``manifest`` (a name, or several tried in order) in ``folder``
    lists: the names it lists (itself included) and the SHA-256 it records of each (name ->
    hex); None where there is none.  Read as plain JSON (no seal checked): what a command
    wrote there, for deciding what replacing the folder would remove."""
    names = (manifest,) if isinstance(manifest, str) else tuple(manifest)
    for name in names:
        m = folder / name
        if not m.is_file():
            continue
        try:
            data = json.loads(m.read_text(encoding="utf-8"))
            files = data.get("files", {})
            listed = {str(v) for v in (files.values() if isinstance(files, dict) else files)} | {name}
            sha = data.get("sha256")
            digests = {}
            if isinstance(files, dict) and isinstance(sha, dict):
                digests = {str(files[k]): sha[k] for k in files if k in sha}
            return listed, digests
        except (ValueError, AttributeError, UnicodeDecodeError, TypeError):
            continue
    return None


def not_recorded(folder: Path, manifest: str | Sequence[str]) -> tuple[list[str], list[str]]:
    """The entries of ``folder`` its manifest (:func:`recorded_files`) does not list, and the
    listed files whose bytes are no longer those it recorded (both sorted): the user's work
    that replacing the folder would remove.  Both empty where it has no manifest."""
    rec = recorded_files(folder, manifest)
    if rec is None:
        return [], []
    listed, digests = rec
    entries = sorted(e.name for e in folder.iterdir())
    extra = [e for e in entries if e not in listed]
    changed = [n for n, d in sorted(digests.items()) if (folder / n).is_file() and file_sha256(folder / n) != d]
    return extra, changed


def _check_replaceable(folder: Path, manifest: str | Sequence[str], overwrite: bool) -> None:
    """May ``folder`` be replaced by a new output?  Yes if empty; if it is an output of the
    same kind (a ``manifest`` - or one of several names - lists every file in it); or, with
    ``overwrite``, if it is such an output holding other files too.  A folder simbench did not
    write is never replaced, ``overwrite`` or not."""
    names = (manifest,) if isinstance(manifest, str) else tuple(manifest)
    if not any(folder.iterdir()):
        return
    if recorded_files(folder, names) is None:
        raise ValueError(
            f"{folder} exists, is not empty and was not written by this command (no {' or '.join(names)}); simbench "
            f"never replaces such a folder, --overwrite or not: choose another output folder"
        )
    extra, changed = not_recorded(folder, names)
    # a listed file changed since the command wrote it (a rig.toml edited by hand: an audit,
    # 2026-11-30, saw calibrate replace it without --overwrite) is the user's work now
    if changed and not overwrite:
        raise ValueError(
            f"{folder}: {', '.join(changed)} changed since this command wrote it (edited by hand?); pass "
            "--overwrite to replace the folder whole, or choose another output folder"
        )
    if extra and not overwrite:
        shown = ", ".join(extra[:4]) + (", ..." if len(extra) > 4 else "")
        raise ValueError(
            f"{folder} holds files this command did not write ({shown}); pass --overwrite to replace the folder whole, "
            f"or choose another output folder"
        )


def check_output_directory(path: str | Path, *, manifest: str | Sequence[str], overwrite: bool = False) -> None:
    """ValueError unless :func:`output_directory` could write ``path`` (call it before long
    work, so that a wrong ``--out`` fails at once)."""
    path = Path(path)
    if path.is_symlink():  # the swap would replace the link, not the folder it names
        raise ValueError(f"{path} is a symbolic link (to {os.readlink(path)}): give the folder itself as the output")
    if path.exists() and not path.is_dir():
        raise ValueError(f"{path} exists and is not a folder")
    if path.is_dir():
        _check_replaceable(path, manifest, overwrite)
        _check_removable(path)
    check_output_folder(path.parent, what=str(path))  # the new folder is built beside it, then swapped in


def _check_removable(folder: Path) -> None:
    """ValueError unless the files of ``folder`` (an output to be replaced) can be removed: every
    folder in it writable and searchable.  (Without the check, a read-only old output was swapped
    out and its removal failed after the new one had taken its place: the command reported a
    failure that had replaced the folder, and left the old one as a hidden sibling.)"""
    for d, _, _ in os.walk(folder):
        if not os.access(d, os.W_OK | os.X_OK):
            raise ValueError(
                f"{folder} cannot be replaced: its files cannot be removed ({d} is not writable); make it writable "
                "or choose another output folder"
            )


@contextmanager
def output_directory(path: str | Path, *, manifest: str | Sequence[str], overwrite: bool = False) -> Iterator[Path]:
    """A result folder written whole or not at all.

    Yields a temporary sibling folder to fill; when the block succeeds it takes ``path``'s
    place in one atomic step (an existing output is swapped out and removed), so a reader sees
    the old folder or the new one, never a mix.  If the block fails, or the process is killed,
    ``path`` is untouched; a killed run's temporary sibling is removed by the next run.  An old
    output whose files cannot be removed (a read-only folder) is refused before any work; should
    its removal still fail after the swap, the new output stands and a
    :class:`simbench.SimbenchWarning` names where the old one was left.

    Parameters
    ----------
    path : the output folder
    manifest : name of the JSON file in the folder that lists its files under ``"files"``
        (what makes an existing folder recognisable as a replaceable output), or several such
        names (any of them: a recording folder of any depth system may take another's place)
    overwrite : replace an existing output even when it holds files it did not write

    Raises
    ------
    ValueError
        ``path`` is a file, or an existing folder that may not be replaced.
    """
    import shutil

    check_output_directory(path, manifest=manifest, overwrite=overwrite)
    # the folder the path names (a new user's "x/../out", x missing, failed on a raw errno after
    # making x: the kernel resolves "x/.." only once x exists)
    path = Path(os.path.realpath(path))
    created = _make_parents(path)
    _remove_stale_siblings(path)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.tmp-{os.getpid()}-", dir=path.parent))
    try:
        yield tmp
        os.chmod(tmp, 0o777 & ~_umask())
        if not path.exists():
            os.rename(tmp, path)
            return
        if _exchange(tmp, path):
            old = tmp  # now the old folder
        else:
            old = Path(tempfile.mkdtemp(prefix=f".{path.name}.old-{os.getpid()}-", dir=path.parent))
            os.rmdir(old)
            os.rename(path, old)
            os.rename(tmp, path)
    except BaseException as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        for c in reversed(created):  # innermost first
            try:
                c.rmdir()
            except OSError:
                break
        _raise_with_filename(exc, path)
        raise
    # the new output is in place: what is left is the old one's removal, which cannot undo it
    try:
        shutil.rmtree(old)
    except OSError as exc:
        warnings.warn(
            f"{path} was written, but the output it replaced could not be removed ({exc.strerror or exc}): "
            f"it is left as {old}",
            SimbenchWarning,
            stacklevel=3,
        )


@contextmanager
def claim_output(path: str | Path, *, what: str = "--out") -> Iterator[None]:
    """Hold, for the block, an exclusive claim among this host's processes on writing the output
    ``path`` (a ``flock`` on a lock file named by a hash of its real absolute path, in a folder of
    the system's temporary directory - the same file however the path is spelled and whatever
    folders the work creates): a second command writing the same output fails at once, before
    its work, instead of both running for minutes and the later silently replacing the earlier
    (an audit, 2026-11-30: two ``calibrate`` runs into one --out both reported success).  Where
    no lock file can be made, nothing is claimed (logged).

    Raises
    ------
    ValueError
        Another process holds the claim.
    """
    import fcntl
    import logging

    target = Path(os.path.realpath(os.path.abspath(path)))
    folder = Path(tempfile.gettempdir()) / f"simbench-outputs-{os.getuid()}"
    lock = folder / f"{hashlib.sha256(os.fsencode(target)).hexdigest()[:32]}.lock"
    fd = None
    while fd is None:
        try:
            folder.mkdir(mode=0o700, exist_ok=True)
            fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o600)
        except OSError as exc:
            logging.getLogger("simbench").debug("no claim on %s: %s", path, exc)
            break
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise ValueError(
                f"{what} {path}: another process is writing it now (another simbench command with the same {what}?): "
                "wait for it to finish, or choose another folder"
            ) from None
        try:
            same = os.stat(lock).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            same = False
        if not same:  # the holder removed the file between our open and our lock: again
            os.close(fd)
            fd = None
    try:
        yield
    finally:
        if fd is not None:
            lock.unlink(missing_ok=True)
            os.close(fd)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


# the errors of a write that found no room: a full disk, or a full quota
DISK_FULL_ERRNOS = (errno.ENOSPC, errno.EDQUOT)


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (temporary file + rename); returns the path."""
    path = Path(path)
    with _atomic_target(path, ".tmp") as tmp:
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
    return path


def atomic_write_text(path: str | Path, text: str) -> Path:
    return atomic_write_bytes(path, text.encode("utf-8"))


def json_bytes(obj: object) -> bytes:
    """``obj`` as indented, key-sorted JSON (NumPy scalars and arrays, paths allowed)."""
    return (json.dumps(obj, indent=2, sort_keys=True, default=_json_default) + "\n").encode("utf-8")


def save_json(path: str | Path, obj: object) -> Path:
    return atomic_write_bytes(path, json_bytes(obj))


def _json_default(o: object):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"cannot store {type(o).__name__} in JSON")


def npy_bytes(array: np.ndarray) -> bytes:
    """An array encoded as an .npy file (no pickles)."""
    buf = io.BytesIO()
    np.save(buf, np.asarray(array), allow_pickle=False)
    return buf.getvalue()


def save_npy(path: str | Path, array: np.ndarray) -> Path:
    return atomic_write_bytes(path, npy_bytes(array))


def _make_parents(path: Path) -> list[Path]:
    """Create ``path``'s missing parent folders (of its real path: ``x/../out`` is ``out``);
    returns them, outermost first."""
    missing = []
    d = Path(os.path.realpath(path)).parent
    while not d.exists():
        missing.append(d)
        d = d.parent
    missing.reverse()
    for m in missing:
        m.mkdir()
    return missing


def check_output_file(path: str | Path, *, what: str = "output") -> Path:
    """Check, before any work, that ``path`` can be written as a file: not an existing folder
    (or device), not under a file, in a folder this process may write.  Returns the path.

    Raises
    ------
    ValueError
        Naming the path and what stands in the way.
    """
    path = Path(path)
    if str(path) == "":
        raise ValueError(f"{what}: an empty path")
    if path.exists() and not path.is_file():
        kind = "a folder" if path.is_dir() else "not a regular file"
        raise ValueError(f"{what} {path} is {kind}; give a file path")
    check_not_protected(path)
    check_output_folder(path.parent, what=what)
    return path


def check_output_folder(path: str | Path, *, what: str = "output") -> Path:
    """Check that ``path`` is, or can be created as, a folder this process may write in."""
    path = Path(path) if str(path) else Path(".")
    if path.exists() and not path.is_dir():
        raise ValueError(f"{what}: {path} is a file, not a folder")
    d = path
    while not d.exists():
        d = d.parent
    if not d.is_dir():
        raise ValueError(f"{what}: {d} is a file, so {path} cannot be created")
    if not os.access(d, os.W_OK | os.X_OK):
        raise ValueError(f"{what}: cannot write in {d} (permission denied or a read-only file system)")
    exc = write_probe(d)
    if exc is not None:
        # (a new user's audit: "--ply /proc/nope/c.ply" read "cannot write in /proc" - the folder to
        # be made is what fails, named now)
        target = d if d == path else f"{path}: cannot create it in {d}"
        raise ValueError(f"{what}: cannot write in {target} ({exc.strerror or exc})") from None
    return path


def write_probe(folder: str | Path, *, prefix: str = ".simbench-probe-", suffix: str = "") -> OSError | None:
    """None if this process can create a file in ``folder`` (a probe file made there and
    removed: ``os.access`` passes for root where a write still fails - /proc, /sys, a read-only
    mount), else the error."""
    try:
        fd, probe = tempfile.mkstemp(dir=folder, prefix=prefix, suffix=suffix)
    except OSError as exc:
        return exc
    os.close(fd)
    os.unlink(probe)
    return None


def check_own_folder(path: str | Path, *, marker: str, written_by: str, what: str) -> Path:
    """A folder a command fills file by file (not swapped in whole) may be new, empty, or one it
    filled before - recognised by its ``marker`` file, a JSON object whose ``"command"`` starts
    with ``written_by``.  Any other non-empty folder is refused: its files are a user's, and
    same-named outputs would replace them.

    Raises
    ------
    ValueError
        Naming the folder and how to proceed.
    """
    path = Path(path)
    check_output_folder(path, what=what)
    if not path.is_dir() or not any(path.iterdir()):
        return path
    try:
        record = json.loads((path / marker).read_text(encoding="utf-8"))
        ours = isinstance(record, dict) and str(record.get("command", "")).startswith(written_by)
    except (OSError, ValueError, UnicodeDecodeError):
        ours = False
    if not ours:
        raise ValueError(
            f"{what} {path} holds files that `{written_by}` did not write (no {marker} of its own): its outputs would "
            "replace files of the same name; give a new or empty folder"
        )
    return path


def write_files(files: dict[str | Path, bytes]) -> list[Path]:
    """Write several files all or nothing.

    Every file is first written to a temporary file beside its destination (creating missing
    folders); only when all of them are written are they renamed into place (a Ctrl-C or
    SIGTERM meanwhile takes effect after the last rename under the command line's signal
    handlers, :func:`simbench.termination.held`; Python's own Ctrl-C handler does not wait).  If any write
    fails (an unwritable folder, a full disk), the temporary files and the folders this call
    created are removed and the error is raised: no destination is touched.

    Returns
    -------
    list of Path, the destinations in the order given
    """
    for path in files:
        check_output_file(path)  # a folder in the way fails before anything is written
    staged: list[tuple[str, Path]] = []
    created: list[Path] = []
    try:
        for path, data in files.items():
            path = Path(path)
            created += _make_parents(path)
            real_dir = Path(os.path.realpath(path)).parent  # (x/../d.npy with x missing: d.npy)
            fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=".tmp", dir=real_dir)
            staged.append((tmp, path))
            with os.fdopen(fd, "wb") as fh:
                fh.write(data)
                fh.flush()
                os.fsync(fh.fileno())
            os.chmod(tmp, _file_mode())
    except BaseException as exc:
        for tmp, _ in staged:
            if os.path.exists(tmp):
                os.unlink(tmp)
        for m in reversed(created):
            try:
                m.rmdir()
            except OSError:
                pass
        _raise_with_filename(exc, path)
        raise
    try:
        with termination.held():  # Ctrl-C or SIGTERM between two renames would leave a mixed set
            for tmp, path in staged:
                os.replace(tmp, Path(tmp).parent / path.name)
    finally:  # a rename that failed leaves no temporary file behind
        for tmp, _ in staged:
            if os.path.exists(tmp):
                os.unlink(tmp)
    return [path for _, path in staged]


# The largest array simbench reads from a file: an RGB image of the largest supported size in
# float64 (validate.MAX_PIXELS x 3 x 8 bytes = 1.5 GiB); a header announcing more (a sparse
# 64 GiB file, say) is refused before memory is asked for.
MAX_ARRAY_BYTES = validate.MAX_PIXELS * 3 * 8


def _check_npy_size(fh, path: Path) -> None:
    """Refuse an .npy whose header announces more than :data:`MAX_ARRAY_BYTES` (``fh`` just
    past the magic string)."""
    fh.seek(0)
    try:
        fmt = np.lib.format
        version = fmt.read_magic(fh)
        read = fmt.read_array_header_1_0 if version == (1, 0) else fmt.read_array_header_2_0
        shape, _, dtype = read(fh)
    except (ValueError, OSError, EOFError):
        return  # np.load reports a damaged header with its own message
    nbytes = int(np.prod(shape, dtype=object)) * dtype.itemsize
    if nbytes > MAX_ARRAY_BYTES:
        raise ValueError(
            f"{path}: the array is {'x'.join(map(str, shape))} {dtype} ({nbytes / 2**30:.1f} GiB), more than the "
            f"{MAX_ARRAY_BYTES / 2**30:.1f} GiB of the largest image simbench reads"
        )


def load_npy(path: str | Path, *, expected_shape: tuple[int, ...] | None = None) -> np.ndarray:
    """Load an .npy array (no pickles); errors name the file and what is wrong."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"file not found: {path}")
    with open(path, "rb") as fh:
        magic = fh.read(6)
        if magic == b"\x93NUMPY":
            _check_npy_size(fh, path)
    if magic != b"\x93NUMPY":
        what = "an empty file" if not magic else "not a NumPy .npy file"
        raise ValueError(f"{path}: {what} (expected an array saved with numpy.save)")
    try:
        arr = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise ValueError(f"{path}: not a readable .npy array ({exc or 'truncated'})") from None
    if expected_shape is not None and arr.shape != tuple(expected_shape):
        raise ValueError(f"{path}: shape {arr.shape}, expected {tuple(expected_shape)}")
    return arr


# image files a depth map is sometimes saved as, which hold no metres
IMAGE_SUFFIXES = frozenset({".png", ".tif", ".tiff", ".jpg", ".jpeg", ".bmp", ".pgm"})


def _float_tiff(path: Path) -> np.ndarray | None:
    """A one-channel floating-point TIFF's values (read by OpenCV), or None where the file holds
    integers (refused by the caller as any integer image).  Other TIFFs are refused here."""
    import cv2

    if not path.is_file():
        raise FileNotFoundError(f"file not found: {path}")
    try:
        arr = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    except cv2.error:
        arr = None
    if arr is None:
        raise ValueError(f"{path}: not a TIFF file OpenCV can read")
    if arr.dtype.kind != "f":
        return None
    if arr.ndim != 2:
        raise ValueError(f"{path}: {arr.shape[2]} channels; a depth map has one")
    return arr


def load_depth_map(path: str | Path, *, expected_shape: tuple[int, ...] | None = None) -> np.ndarray:
    """A depth map from an .npy file (:func:`load_npy`), a one-channel OpenEXR file (``render``
    writes ``gt_depth`` as both, the same values; read with Mitsuba's ``Bitmap``) or a
    one-channel floating-point TIFF (read with OpenCV; an audit, 2026-12-05: a float32 TIFF in
    metres was refused as an image of integers); errors name the file and what is wrong.  Its
    dtype and shape as stored (the caller checks them)."""
    path = Path(path)
    if path.suffix.lower() in (".tif", ".tiff"):
        arr = _float_tiff(path)
        if arr is not None:
            if expected_shape is not None and arr.shape != tuple(expected_shape):
                raise ValueError(f"{path}: shape {arr.shape}, expected {tuple(expected_shape)}")
            return arr
    if path.suffix.lower() in IMAGE_SUFFIXES:
        # (a new user's audit: a 16-bit PNG depth read "not a NumPy .npy file", naming no way on)
        raise ValueError(
            f"{path}: a depth map is read from .npy, .exr or a floating-point .tif, float metres with NaN holes; this "
            "image file holds integers in units of its own (e.g. millimetres in a 16-bit PNG): convert it, e.g. "
            "numpy.save('depth.npy', png.astype(numpy.float32) / 1000) with 0 set to NaN"
        )
    if path.suffix.lower() != ".exr":
        return load_npy(path, expected_shape=expected_shape)
    if not path.is_file():
        raise FileNotFoundError(f"file not found: {path}")
    import mitsuba as mi

    try:
        arr = np.array(mi.Bitmap(str(path)))
    except RuntimeError as exc:
        raise ValueError(f"{path}: not a readable OpenEXR file ({str(exc).splitlines()[0]})") from None
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[..., 0]
    if arr.ndim != 2:
        raise ValueError(f"{path}: {arr.shape[2]} channels; a depth map has one")
    if expected_shape is not None and arr.shape != tuple(expected_shape):
        raise ValueError(f"{path}: shape {arr.shape}, expected {tuple(expected_shape)}")
    return arr


def save_png(path: str | Path, image: np.ndarray) -> Path:
    """Save an RGB (H, W, 3) or grey (H, W) uint8/uint16 image as PNG (RGB order in memory).

    Raises
    ------
    ValueError
        When ``path`` does not end in ``.png``: PNG bytes under another name (a ``.jpg``, say)
        would be read as that format by other tools, or not at all."""
    check_not_protected(path)  # that error first: it names what the path is
    if Path(path).suffix.lower() != ".png":
        raise ValueError(f"{path}: a PNG file's name must end in .png")
    return atomic_write_bytes(path, png_bytes(image, name=str(path)))


def png_bytes(image: np.ndarray, *, name: str = "image") -> bytes:
    """An RGB (H, W, 3) or grey (H, W) uint8/uint16 image encoded as PNG."""
    import cv2

    path = name
    img = np.asarray(image)
    if img.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"PNG needs uint8 or uint16 pixels, got {img.dtype}")
    if img.ndim == 3:
        if img.shape[2] != 3:
            raise ValueError(f"PNG needs 1 or 3 channels, got shape {img.shape}")
        img = img[..., ::-1]
    ok, enc = cv2.imencode(".png", np.ascontiguousarray(img))
    if not ok:
        raise ValueError(f"could not encode {path} as PNG")
    return enc.tobytes()


def load_image(
    path: str | Path, *, expected_size_hw: tuple[int, int] | None = None, channels: int = 3, bits: int | None = None
) -> np.ndarray:
    """Load a capture (PNG/TIFF/...; .npy for float captures) as RGB, shape (H, W, 3), or with
    ``channels=1`` as a grey image, shape (H, W).  ``bits``: the camera's ADC bits the caller was
    told (``--bits``), for the advice on a float image beyond full scale.

    Raises
    ------
    FileNotFoundError, ValueError
        Missing file, undecodable image, wrong channel count or wrong size.
    """
    import cv2

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"image not found: {path}")
    if path.suffix.lower() == ".npy":
        img = load_npy(path)
    else:
        data = np.fromfile(path, dtype=np.uint8)
        if data.size == 0:
            raise ValueError(f"{path}: an empty file, not an image")
        # a PNG's IHDR colour type (byte 25): OpenCV expands grey+alpha to BGRA, which would pass as RGB
        if channels == 3 and data.size > 25 and data[:8].tobytes() == b"\x89PNG\r\n\x1a\n" and data[25] in (0, 4):
            kind = "grey+alpha" if data[25] == 4 else "grey"
            raise ValueError(f"{path}: a {kind} PNG, expected an RGB image (a colour capture)")
        with _captured_stderr() as messages:
            try:
                img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
            except cv2.error:
                img = None
        if img is None:
            # OpenCV's log lines carry "[ WARN:0@0.03] global grfmt_png.cpp:793 function" first
            lines = [re.sub(r"^\[[^\]]*\]\s*global\s+\S+\s+\S+\s+", "", ln.strip()) for ln in messages().splitlines()]
            detail = "; ".join(ln for ln in lines if ln)
            raise ValueError(f"{path}: not a readable image" + (f" ({detail[:200]})" if detail else ""))
        if img.ndim == 3 and img.shape[2] == 4:
            img = img[..., :3]
        if img.ndim == 3:
            img = img[..., ::-1]
    if img.dtype.kind == "f":  # .npy or a float TIFF/EXR
        finite = img[np.isfinite(img)]
        if finite.size != img.size:
            raise ValueError(f"{path}: {img.size - finite.size} pixel values are NaN or inf; a capture is finite")
        if finite.size and (finite.min() < 0.0 or finite.max() > 1.0):
            lo, hi = float(finite.min()), float(finite.max())
            if lo < 0.0:
                hint = "no camera records negative light: an image after background subtraction or other processing?"
            elif bits is not None and bits > 8 and hi <= (1 << bits) - 1:
                full = (1 << bits) - 1
                hint = f"{bits}-bit digital numbers? divide by {full}, or save them as uint16 with --bits {bits}"
            elif hi <= 255.0:
                hint = "8-bit values? divide by 255, or save it as uint8"
            else:
                hint = "16-bit values? divide by 65535, or save it as uint16"
            raise ValueError(
                f"{path}: a float capture holds values in [0, 1] of full scale, this one spans "
                f"[{lo:g}, {hi:g}] ({hint})"
            )
    elif img.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"{path}: {img.dtype} pixels; a capture is uint8, uint16 or float in [0, 1]")
    if channels == 1:
        if img.ndim != 2:
            raise ValueError(f"{path}: expected a single-channel image, got shape {img.shape}")
    elif img.ndim != 3 or img.shape[2] != 3:
        raise ValueError(f"{path}: expected an RGB image, got shape {img.shape}")
    if expected_size_hw is not None and img.shape[:2] != tuple(expected_size_hw):
        h, w = expected_size_hw
        raise ValueError(f"{path}: image is {img.shape[1]}x{img.shape[0]} (WxH) but the camera is {w}x{h}")
    return np.ascontiguousarray(img)


# the ADC depths a camera may have (simbench.sim.camera, simbench.sim.sensor)
ADC_BITS = (8, 10, 12, 14, 16)


def stored_adc_bits(bits: int) -> int | None:
    """The bits a reader of a ``bits``-bit camera's images must be told (:func:`adc_full_scale`):
    a 10-, 12- or 14-bit camera's, whose digital numbers fill only part of their uint16; None for an
    8- or 16-bit camera's, read by their dtype's range."""
    return bits if bits in (10, 12, 14) else None


def adc_full_scale(img: np.ndarray, *, bits: int | None, where: str) -> np.ndarray:
    """A capture as the decoder reads it, given the bits of the camera's ADC that recorded it.

    The decoder takes uint8 / 255 and uint16 / 65535 as full scale.  A 10-, 12- or 14-bit camera's
    image is stored in uint16 as its digital numbers, 0 to ``2**bits - 1`` (as the simulated
    camera records them, and as most machine-vision software saves such frames unscaled), so it
    is returned as float32 ``DN / (2**bits - 1)``; an 8- or 16-bit camera's image (or ``bits``
    None: the container's range) and float images are returned as they are.

    Raises
    ------
    ValueError
        An image whose values or dtype cannot come from a ``bits``-bit camera.
    """
    if bits is None or img.dtype.kind == "f":
        return img
    bits = validate.choice(validate.integer(bits, "bits"), "bits", ADC_BITS)
    if img.dtype == np.uint8:
        if bits != 8:
            raise ValueError(f"{where}: an 8-bit image, not the {bits}-bit camera's digital numbers (uint16)")
        return img
    if img.dtype != np.uint16 or bits == 16:
        return img
    if bits == 8:
        raise ValueError(f"{where}: a 16-bit image, not an 8-bit camera's digital numbers (uint8)")
    full = (1 << bits) - 1
    top = int(img.max(initial=0))
    if top > full:
        raise ValueError(
            f"{where}: values up to {top}, above a {bits}-bit camera's largest digital number {full}: "
            f"not that camera's image as recorded (scaled to 16 bits? then it is read as it is, without the bits)"
        )
    return np.multiply(img, np.float32(1.0 / full), dtype=np.float32)


# How an image's values encode light: linear (a machine-vision camera's raw digital numbers, the
# simulated camera's), sRGB's transfer function (IEC 61966-2-1: most consumer cameras' and image
# tools' 8-bit output), or a pure power law ``gamma=G`` (value = light ** (1 / G): a camera's
# "gamma" setting, e.g. 2.2).
ENCODINGS = ("linear", "srgb", "gamma=G")
GAMMA_RANGE = (1.0, 4.0)


def check_encoding(text: str) -> str:
    """``text`` as an encoding name (:data:`ENCODINGS`), normalised ("sRGB" -> "srgb",
    "gamma=2.20" -> "gamma=2.2"); ValueError naming the valid ones otherwise."""
    t = str(text).strip().lower()
    if t in ("linear", "srgb"):
        return t
    if t.startswith("gamma="):
        try:
            g = float(t[6:])
        except ValueError:
            g = float("nan")
        if GAMMA_RANGE[0] <= g <= GAMMA_RANGE[1]:
            return f"gamma={g:g}"
        raise ValueError(
            f"encoding {text!r}: the gamma must be a number from {GAMMA_RANGE[0]:g} to {GAMMA_RANGE[1]:g} "
            "(e.g. gamma=2.2)"
        )
    raise ValueError(f"encoding {text!r} is not one of {', '.join(ENCODINGS)}")


def linearize(img: np.ndarray, *, encoding: str) -> np.ndarray:
    """An image's values as linear light, float32 in [0, 1] of its full scale (an integer image's
    by its dtype's range, a float image's as it is); a ``linear`` image is returned unchanged.

    A camera's encoded output fed to the decoder as if linear bends the fringe: a step captured
    through gamma 1/2.2 (every frame, reference and calibration frames too) decoded by the
    colour-robust decoder 64 % complete with 0.17 % of its pixels > 5 mm wrong (94 % and 0.04 %
    linearised first).
    """
    name = check_encoding(encoding)
    if name == "linear":
        return img
    a = np.asarray(img)
    if a.dtype in (np.uint8, np.uint16):
        # through a table of every value the dtype holds: the same bits, ~10x faster on a capture
        return _decoding_table(name, a.dtype.str)[a]
    scale = 1.0 / float(np.iinfo(a.dtype).max) if a.dtype.kind in "ui" else 1.0
    return _decoded(np.clip(a.astype(np.float32) * np.float32(scale), 0.0, 1.0), name)


@functools.lru_cache(maxsize=8)
def _decoding_table(name: str, dtype: str) -> np.ndarray:
    values = np.arange(np.iinfo(np.dtype(dtype)).max + 1, dtype=np.dtype(dtype))
    table = linearize(values.astype(np.float32) * np.float32(1.0 / float(values[-1])), encoding=name)
    table.setflags(write=False)
    return table


def _decoded(v: np.ndarray, name: str) -> np.ndarray:
    """``v`` (float32 in [0, 1]) decoded by the encoding ``name`` (not linear)."""
    if name == "srgb":
        # IEC 61966-2-1 (the sRGB standard's decoding function)
        return np.where(
            v <= 0.04045, v / np.float32(12.92), ((v + np.float32(0.055)) / np.float32(1.055)) ** 2.4
        ).astype(np.float32)
    return (v ** np.float32(float(name[6:]))).astype(np.float32)


def camera_full_scale(img: np.ndarray, *, bits: int) -> np.ndarray:
    """A simulated camera's recording (``bits``: its ADC's) as every reader takes it: a 10- or
    12-bit camera's uint16 digital numbers as float32 of its full scale
    (:func:`adc_full_scale`), any other camera's image as it is (read by its dtype's range)."""
    return adc_full_scale(img, bits=stored_adc_bits(bits), where="the camera's recording")


def narrow_uint16_hint(img: np.ndarray) -> str:
    """A hint for a uint16 image read at the full 16-bit range whose values all fit in 14, 12 or
    10 bits (a 10-, 12- or 14-bit camera's digital numbers, which would then read 4, 16 or 64 times
    too dark); "" otherwise."""
    if img.dtype != np.uint16:
        return ""
    top = int(img.max(initial=0))
    for bits in (10, 12, 14):
        if 0 < top <= (1 << bits) - 1:
            return (
                f"a 16-bit image whose largest value is {top}, within {bits} bits: if it holds a {bits}-bit camera's "
                f"digital numbers, give --bits {bits} (read now as 16-bit, {1 << (16 - bits)} times darker)"
            )
    return ""


@contextmanager
def _captured_stderr() -> Iterator:
    """Collect what C libraries write to file descriptor 2 (libpng's "libpng error: ..."
    lines) instead of letting it reach the terminal; yields a function returning the text."""
    import sys

    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):
        yield lambda: ""
        return
    text = ""
    with tempfile.TemporaryFile() as sink:
        os.dup2(sink.fileno(), 2)
        try:
            yield lambda: text
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            sink.seek(0)
            text = sink.read().decode("utf-8", "replace")


def save_exr(path: str | Path, image: np.ndarray) -> Path:
    """Save a float32 (H, W) or (H, W, C) array as OpenEXR (via Mitsuba's Bitmap)."""
    import mitsuba as mi

    arr = np.asarray(image, dtype=np.float32)
    if arr.ndim == 2:
        arr = arr[..., None]
    path = Path(path)
    with _atomic_target(path, ".exr") as tmp:
        mi.Bitmap(np.ascontiguousarray(arr)).write(tmp)
    return path


def read_toml(path: str | Path, *, what: str) -> dict:
    """Parse a TOML file; a missing file or a syntax error names the file (``what``: its kind)."""
    import tomllib

    path = Path(path)
    if path.is_dir():  # e.g. calibrate's --out folder given as the rig
        inside = path / f"{what}.toml"
        hint = f" (give {inside}, the {what} file in it)" if inside.is_file() else ""
        raise ValueError(f"{path}: a folder, not a {what} file{hint}")
    if not path.is_file():
        raise FileNotFoundError(f"{what} file not found: {path}")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path}: not a UTF-8 text file (byte {exc.start}), so not TOML") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: not valid TOML ({exc})") from None


def save_ply(path: str | Path, points_m: np.ndarray, colors: np.ndarray | None = None) -> Path:
    """Save a point cloud as binary little-endian PLY.

    Parameters
    ----------
    points_m : ndarray, shape (N, 3)
    colors : ndarray, shape (N, 3), uint8, optional
    """
    return atomic_write_bytes(path, ply_bytes(points_m, colors))


def ply_bytes(points_m: np.ndarray, colors: np.ndarray | None = None) -> bytes:
    """A point cloud encoded as binary little-endian PLY (see :func:`save_ply`)."""
    pts = np.asarray(points_m, dtype=np.float32).reshape(-1, 3)
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    if colors is not None:
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
    rec = np.empty(len(pts), dtype=fields)
    rec["x"], rec["y"], rec["z"] = pts[:, 0], pts[:, 1], pts[:, 2]
    props = "property float x\nproperty float y\nproperty float z\n"
    if colors is not None:
        c = np.asarray(colors, dtype=np.uint8).reshape(-1, 3)
        rec["red"], rec["green"], rec["blue"] = c[:, 0], c[:, 1], c[:, 2]
        props += "property uchar red\nproperty uchar green\nproperty uchar blue\n"
    header = f"ply\nformat binary_little_endian 1.0\nelement vertex {len(pts)}\n{props}end_header\n"
    return header.encode("ascii") + rec.tobytes()


def read_json_dict(path: str | Path) -> dict:
    """A JSON object kept as a memo: its dict, or an empty one where the file is missing,
    unreadable, damaged or not an object (the caller recomputes, and rewrites, what it needs)."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}
