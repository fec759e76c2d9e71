"""File I/O: atomic writes and the formats users expect (PNG, NPY, EXR, PLY, JSON).

Every writer goes through a temporary file in the destination directory and ``os.replace``,
so an interrupted run never leaves a half-written result behind.
"""

from __future__ import annotations

import io
import json
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

__all__ = [
    "atomic_write_bytes",
    "atomic_write_text",
    "save_json",
    "save_npy",
    "load_npy",
    "save_png",
    "load_image",
    "save_exr",
    "save_ply",
    "read_toml",
]


def _file_mode() -> int:
    """Permissions a plain ``open()`` would give (mkstemp's are 0600)."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


@contextmanager
def _atomic_target(path: Path, suffix: str) -> Iterator[str]:
    """A temporary file beside ``path`` that replaces it when the block succeeds."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=suffix, dir=path.parent)
    os.close(fd)
    try:
        os.chmod(tmp, _file_mode())
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


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


def save_json(path: str | Path, obj: object) -> Path:
    return atomic_write_text(path, json.dumps(obj, indent=2, sort_keys=True, default=_json_default) + "\n")


def _json_default(o: object):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"cannot store {type(o).__name__} in JSON")


def save_npy(path: str | Path, array: np.ndarray) -> Path:
    buf = io.BytesIO()
    np.save(buf, np.asarray(array), allow_pickle=False)
    return atomic_write_bytes(path, buf.getvalue())


def load_npy(path: str | Path, *, expected_shape: tuple[int, ...] | None = None) -> np.ndarray:
    """Load an .npy array (no pickles); errors name the file and what is wrong."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"file not found: {path}")
    try:
        arr = np.load(path, allow_pickle=False)
    except (ValueError, OSError) as exc:
        raise ValueError(f"{path}: not a readable .npy array ({exc})") from None
    if expected_shape is not None and arr.shape != tuple(expected_shape):
        raise ValueError(f"{path}: shape {arr.shape}, expected {tuple(expected_shape)}")
    return arr


def save_png(path: str | Path, image: np.ndarray) -> Path:
    """Save an RGB (H, W, 3) or grey (H, W) uint8/uint16 image as PNG (RGB order in memory)."""
    import cv2

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
    return atomic_write_bytes(path, enc.tobytes())


def load_image(path: str | Path, *, expected_size_hw: tuple[int, int] | None = None) -> np.ndarray:
    """Load a capture (PNG/TIFF/...; .npy for float captures) as RGB, shape (H, W, 3).

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
        img = cv2.imdecode(np.fromfile(path, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
        if img is None:
            raise ValueError(f"{path}: not a readable image")
        if img.ndim == 3 and img.shape[2] == 4:
            img = img[..., :3]
        if img.ndim == 3:
            img = img[..., ::-1]
    if img.ndim != 3 or img.shape[2] != 3:
        raise ValueError(f"{path}: expected an RGB image, got shape {img.shape}")
    if expected_size_hw is not None and img.shape[:2] != tuple(expected_size_hw):
        h, w = expected_size_hw
        raise ValueError(
            f"{path}: image is {img.shape[1]}x{img.shape[0]} (WxH) but the rig's camera is {w}x{h}"
        )
    return np.ascontiguousarray(img)


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
    if not path.is_file():
        raise FileNotFoundError(f"{what} file not found: {path}")
    try:
        return tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: not valid TOML ({exc})") from None


def save_ply(path: str | Path, points_m: np.ndarray, colors: np.ndarray | None = None) -> Path:
    """Save a point cloud as binary little-endian PLY.

    Parameters
    ----------
    points_m : ndarray, shape (N, 3)
    colors : ndarray, shape (N, 3), uint8, optional
    """
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
    return atomic_write_bytes(path, header.encode("ascii") + rec.tobytes())
