"""Calibration targets: printed checkerboards, read from TOML files like
``simbench/presets/targets/checkerboard.toml``.

A target file::

    name = "checkerboard"
    kind = "checkerboard"          # the only kind so far
    squares = [11, 8]              # squares along the board's x and y
    square_m = 0.030               # printed square side
    margin_squares = 1             # white margin around the squares, in squares
    paper_rgb = [0.8, 0.8, 0.8]    # linear diffuse reflectance of the paper
    ink_rgb = [0.04, 0.04, 0.04]   # ... and of the dark squares

    [flatness]                     # form error of the board (simbench.sim.scene.board_form_m)
    bow_m_per_m = 0.0
    waviness_m = 0.0

The board frame: origin at the board's centre, x along its columns of squares, y along its
rows, z = 0 on the printed surface (the scene object ``type = "target"``).  The inner corners
are OpenCV's ``pattern_size = (squares[0] - 1, squares[1] - 1)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from simbench import validate
from simbench.io import read_toml
from simbench.sim.scene import MAX_FORM_M, target_size_m

__all__ = ["CalibrationTarget", "TARGET_KINDS", "TARGET_PRESETS", "get_target", "load_target", "target_from_dict"]

TARGETS_DIR = Path(__file__).resolve().parent.parent / "presets" / "targets"
TARGET_PRESETS = ("checkerboard",)
TARGET_KINDS = ("checkerboard",)
_KEYS = ("name", "description", "kind", "squares", "square_m", "margin_squares", "paper_rgb", "ink_rgb", "flatness")
_FLATNESS_KEYS = ("bow_m_per_m", "waviness_m")


@dataclass(frozen=True)
class CalibrationTarget:
    """A printed checkerboard (module docstring); lengths in metres, reflectances linear."""

    name: str = "checkerboard"
    squares: tuple[int, int] = (11, 8)
    square_m: float = 0.030
    margin_squares: int = 1
    paper_rgb: tuple[float, float, float] = (0.8, 0.8, 0.8)
    ink_rgb: tuple[float, float, float] = (0.04, 0.04, 0.04)
    bow_m_per_m: float = 0.0
    waviness_m: float = 0.0
    kind: str = "checkerboard"
    description: str = ""

    def __post_init__(self) -> None:
        v = validate
        try:
            squares = v.numbers(self.squares, "squares", 2, lo=3, hi=64)
        except ValueError as exc:
            raise ValueError(f"{exc} (squares = [columns, rows])") from None
        if any(int(n) != n for n in squares):
            raise ValueError(f"squares must be 2 whole numbers [columns, rows], got {self.squares!r}")
        values = {
            "kind": v.choice(self.kind, "target kind", TARGET_KINDS),
            "squares": tuple(int(n) for n in squares),
            # assumption: printed squares of 2 mm - 0.2 m
            "square_m": v.number(self.square_m, "square_m", lo=0.002, hi=0.2),
            "margin_squares": v.integer(self.margin_squares, "margin_squares", lo=0, hi=10),
            "paper_rgb": v.numbers(self.paper_rgb, "paper_rgb", 3, lo=0.0, hi=1.0),
            "ink_rgb": v.numbers(self.ink_rgb, "ink_rgb", 3, lo=0.0, hi=1.0),
            "bow_m_per_m": v.number(self.bow_m_per_m, "flatness.bow_m_per_m", lo=-MAX_FORM_M, hi=MAX_FORM_M),
            "waviness_m": v.number(self.waviness_m, "flatness.waviness_m", lo=0.0, hi=MAX_FORM_M),
        }
        if min(values["paper_rgb"]) <= max(values["ink_rgb"]):
            raise ValueError(f"the paper ({values['paper_rgb']}) must reflect more than the ink ({values['ink_rgb']})")
        for name, value in values.items():
            object.__setattr__(self, name, value)

    @property
    def pattern_size(self) -> tuple[int, int]:
        """Inner corners per row and per column: OpenCV's ``patternSize``."""
        return (self.squares[0] - 1, self.squares[1] - 1)

    @property
    def size_m(self) -> tuple[float, float]:
        """Printed size (x, y) with the margin, metres."""
        return target_size_m(self.squares, self.square_m, self.margin_squares)

    def object_points(self) -> np.ndarray:
        """The inner corners in the board frame, row by row (x fastest), shape (N, 3) float32,
        metres: OpenCV's ``objectPoints`` for one view."""
        nx, ny = self.pattern_size
        s = self.square_m
        j, i = np.mgrid[0:ny, 0:nx]
        x = (i + 1 - self.squares[0] / 2.0) * s
        y = (j + 1 - self.squares[1] / 2.0) * s
        return np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1).astype(np.float32)

    def scene_object(self, *, center_m: tuple[float, float, float], rotation_deg: tuple[float, float, float]) -> dict:
        """The target at a pose as a scene-file object table (``type = "target"``)."""
        obj = {
            "type": "target",
            "name": "target",
            "center_m": [float(c) for c in center_m],
            "rotation_deg": [float(a) for a in rotation_deg],
            "squares": list(self.squares),
            "square_m": self.square_m,
            "margin_squares": self.margin_squares,
            "rgb": list(self.paper_rgb),
            "ink_rgb": list(self.ink_rgb),
        }
        if self.bow_m_per_m:
            obj["bow_m_per_m"] = self.bow_m_per_m
        if self.waviness_m:
            obj["waviness_m"] = self.waviness_m
        return obj

    def to_dict(self) -> dict:
        """The TOML layout :func:`target_from_dict` reads (everything that affects a render)."""
        return {
            "name": self.name,
            "description": self.description,
            "kind": self.kind,
            "squares": list(self.squares),
            "square_m": self.square_m,
            "margin_squares": self.margin_squares,
            "paper_rgb": list(self.paper_rgb),
            "ink_rgb": list(self.ink_rgb),
            "flatness": {"bow_m_per_m": self.bow_m_per_m, "waviness_m": self.waviness_m},
        }


def target_from_dict(data: dict, *, where: str = "target") -> CalibrationTarget:
    """Validate a target table (module docstring); errors name ``where`` and the field."""
    if not isinstance(data, dict):
        raise ValueError(f"{where}: expected a table")
    unknown = sorted(set(data) - set(_KEYS))
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {unknown}; valid keys: {list(_KEYS)}")
    missing = [k for k in ("squares", "square_m") if k not in data]
    if missing:
        raise ValueError(f"{where}: missing key(s) {missing}")
    flat = data.get("flatness", {})
    if not isinstance(flat, dict) or sorted(set(flat) - set(_FLATNESS_KEYS)):
        raise ValueError(f"{where}: [flatness] takes only {list(_FLATNESS_KEYS)}")
    defaults = CalibrationTarget()
    try:
        return CalibrationTarget(
            name=str(data.get("name", "target")),
            description=str(data.get("description", "")),
            kind=data.get("kind", "checkerboard"),
            squares=data["squares"],
            square_m=data["square_m"],
            margin_squares=data.get("margin_squares", defaults.margin_squares),
            paper_rgb=data.get("paper_rgb", defaults.paper_rgb),
            ink_rgb=data.get("ink_rgb", defaults.ink_rgb),
            bow_m_per_m=flat.get("bow_m_per_m", 0.0),
            waviness_m=flat.get("waviness_m", 0.0),
        )
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {exc}") from None


def load_target(path: str | Path) -> CalibrationTarget:
    """Read a target TOML file."""
    return target_from_dict(read_toml(path, what="calibration target"), where=str(path))


def get_target(name_or_path: str | Path) -> CalibrationTarget:
    """A preset by name (:data:`TARGET_PRESETS`) or a target TOML file."""
    key = str(name_or_path)
    if key in TARGET_PRESETS:
        return load_target(TARGETS_DIR / f"{key}.toml")
    if Path(key).suffix.lower() != ".toml":
        raise ValueError(f"unknown target {key!r}: give a preset ({', '.join(TARGET_PRESETS)}) or a .toml file")
    return load_target(key)
