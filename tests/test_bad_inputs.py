"""Bad input, table-driven: every case exits with status 2, prints exactly one line on stderr
that names the problem, and leaves nothing behind in the working folder.

The cases run the real command line (``simbench.cli.main``) in-process, in a fresh temporary
folder each; a sample also runs in a fresh interpreter (``test_a_sample_in_fresh_processes``),
where import order is what a user's shell gives.  Files the case itself prepares are inputs;
anything else appearing in the folder afterwards is a partial output and fails the case.
"""

from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import pytest

from simbench.cli import main
from simbench.io import save_exr

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / "scenes"

TINY_RIG = """\
name = "tiny"
[camera]
width_px = 160
height_px = 120
focal_px = 289.0
[projector]
width_px = 456
height_px = 285
focal_px = 557.0
[pose]
position_m = [0.093, 0.0, 0.0]
"""


def _rig_text(**changes) -> str:
    """TINY_RIG with ``section.key = value`` lines replaced or added (value as TOML text)."""
    lines = TINY_RIG.splitlines()
    for dotted, value in changes.items():
        section, key = dotted.split(".")
        start = lines.index(f"[{section}]")
        end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("[")), len(lines))
        hit = [i for i in range(start + 1, end) if lines[i].split("=")[0].strip() == key]
        if value is None:
            for i in hit:
                lines.pop(i)
        elif hit:
            lines[hit[0]] = f"{key} = {value}"
        else:
            lines.insert(end, f"{key} = {value}")
    return "\n".join(lines) + "\n"


def _tiny_images() -> tuple[np.ndarray, np.ndarray]:
    from simbench.pattern import PatternSpec, fringe_pattern, quantize
    from simbench.rig import rig_from_dict
    from simbench.sim.synthetic import synthetic_plane_capture
    import tomllib

    rig = rig_from_dict(tomllib.loads(TINY_RIG))
    drive = quantize(fringe_pattern(PatternSpec(size_hw=rig.projector.size_hw))).astype(np.float32) / 255
    cap = synthetic_plane_capture(drive, rig, point_m=(0, 0, 1.1))[0]
    ref = synthetic_plane_capture(drive, rig, point_m=(0, 0, 1.0))[0]
    return np.round(np.clip(cap, 0, 1) * 255).astype(np.uint8), np.round(np.clip(ref, 0, 1) * 255).astype(np.uint8)


_IMAGES: list = []


def render_folder(d: Path) -> Path:
    """A small, valid render folder (synthetic plane at 1.1 m, reference at 1.0 m) in ``d/r``."""

    from simbench.io import save_npy, save_png

    if not _IMAGES:
        _IMAGES.extend(_tiny_images())
    cap, ref = _IMAGES
    r = d / "r"
    r.mkdir()
    (r / "rig.toml").write_text(TINY_RIG)
    save_png(r / "capture.png", cap)
    save_png(r / "reference.png", ref)
    gt = np.full((120, 160), 1.1, np.float32)
    save_npy(r / "gt_depth.npy", gt)
    save_npy(r / "gt_lit.npy", np.ones((120, 160), bool))
    save_npy(r / "gt_column.npy", np.zeros((120, 160), np.float32))
    save_npy(r / "depth.npy", gt)
    _seal(r, reference_depth_m=1.0)
    return r


def _relist(r: Path, key: str, name: str, array) -> None:
    """Add ``array`` to the sealed folder ``r`` as ``name``, then replace it after the seal."""
    import json

    np.save(r / name, np.ones_like(array))
    data = json.loads((r / "meta.json").read_text())
    from simbench.io import save_json
    from simbench.manifest import seal_manifest

    files = {**data["files"], key: name}
    (r / "meta.json").unlink()
    save_json(r / "meta.json", seal_manifest(r, {k: v for k, v in data.items()}, files))
    (r / name).unlink()
    np.save(r / name, array)


def _seal(r: Path, **meta) -> None:
    """``r/meta.json`` as ``simbench render`` writes it (simbench.manifest), with ``meta``."""
    from simbench.io import save_json
    from simbench.manifest import seal_manifest
    from simbench.pattern import PatternSpec
    from simbench.systems.proposed import pattern_record

    names = {"capture": "capture.png", "reference": "reference.png", "rig": "rig.toml", "gt_depth": "gt_depth.npy"}
    pattern = pattern_record(PatternSpec(size_hw=(285, 456)))
    (r / "meta.json").unlink(missing_ok=True)  # a written manifest is protected: sealed anew
    save_json(r / "meta.json", seal_manifest(r, {"system": "proposed", "pattern": pattern, **meta}, names))


@dataclass
class Case:
    """``argv(d)`` builds the command line after ``setup(d)`` has made its input files."""

    id: str
    argv: object
    expect: str | tuple[str, ...]
    setup: object = None
    files: dict = field(default_factory=dict)


CASES: list[Case] = []


def case(id: str, argv, expect, *, setup=None, files=None) -> None:
    CASES.append(Case(id, argv, expect, setup, files or {}))


def _w(path: str, content: str | bytes):
    return {path: content}


# --------------------------------------------------------------------------------- pattern
for opt, bad, msg in [
    ("--width", "0", "--width"),
    ("--width", "-1", "--width"),
    ("--width", "10000000", "--width"),
    ("--width", "abc", "--width"),
    ("--width", "1.5", "--width"),
    ("--width", "", "--width"),
    ("--height", "0", "--height"),
    ("--height", "100000", "--height"),
    ("--height", "x", "--height"),
    ("--height", "-7", "--height"),
    ("--period", "0", "--period"),
    ("--period", "2", "--period"),
    ("--period", "3", "--period"),
    ("--period", "-5", "--period"),
    ("--period", "x", "--period"),
    ("--period", "1e9", "--period"),
    ("--order", "0", "--order"),
    ("--order", "1", "--order"),
    ("--order", "17", "--order"),
    ("--order", "x", "--order"),
    ("--sequence", "0101", "repeats"),
    ("--sequence", "01x", "0 and 1"),
    ("--sequence", "", "0 and 1"),
    ("--sequence", "2", "0 and 1"),
    ("--channels", "rgg", "permutation"),
    ("--channels", "rgba", "permutation"),
    ("--channels", "", "permutation"),
    ("--channels", "xyz", "permutation"),
    ("--period", "1000", "fewer than one De Bruijn window"),  # 1.8 stripes over 1824 px (an audit)
]:
    case(f"pattern{opt}={bad!r}", lambda d, o=opt, b=bad: ["pattern", "--out", str(d / "p.png"), o, b], msg)
case(
    "pattern-width-x-height-too-many-pixels",
    lambda d: ["pattern", "--out", str(d / "p.png"), "--width", "16384", "--height", "16384"],
    "Mpx",
)
case("pattern-out-under-a-file", lambda d: ["pattern", "--out", str(d / "f" / "p.png")], "f", files=_w("f", "x"))
case(
    "pattern-out-is-a-folder",
    lambda d: ["pattern", "--out", str(d / "dir")],
    "dir is a folder; give a file path",  # checked before the pattern is made (it said "[Errno 21]")
    setup=lambda d: (d / "dir").mkdir(),
)
case(
    "pattern-sequence-for-other-order",
    lambda d: ["pattern", "--out", str(d / "p.png"), "--order", "2", "--sequence", "00010111"],
    "--sequence: window at position 1 repeats",  # the option named (a user's audit, 2026-11-30)
)


# ---------------------------------------------------------------------------------- render
def _scene(body: str, rig: str | None = None) -> dict:
    files = {"s.toml": body}
    if rig is not None:
        files["rig.toml"] = rig
    return files


PLANE = '[[object]]\ntype = "plane"\nname = "wall"\ncenter_m = [0.0, 0.0, 1.0]\nsize_m = [1.5, 1.2]\n'
for cid, body, msg in [
    ("empty", "", "object"),
    ("bad-toml", "name = \n", "not valid TOML"),
    ("unknown-key", "colour = 1\n" + PLANE, "unknown key"),
    ("no-objects", 'name = "x"\n', "object"),
    ("object-unknown-type", '[[object]]\ntype = "cone"\n', "unknown type"),
    ("object-not-table", "object = [1]\n", "expected a table"),
    ("center-string", PLANE.replace("[0.0, 0.0, 1.0]", '"here"'), "center_m"),
    ("center-nan", PLANE.replace("[0.0, 0.0, 1.0]", "[0.0, nan, 1.0]"), "center_m"),
    ("center-inf", PLANE.replace("[0.0, 0.0, 1.0]", "[0.0, 0.0, inf]"), "center_m"),
    ("center-two", PLANE.replace("[0.0, 0.0, 1.0]", "[0.0, 1.0]"), "center_m"),
    ("center-bool", PLANE.replace("[0.0, 0.0, 1.0]", "[true, 0.0, 1.0]"), "center_m"),
    ("size-negative", PLANE.replace("[1.5, 1.2]", "[-1.5, 1.2]"), "size_m"),
    ("size-zero", PLANE.replace("[1.5, 1.2]", "[0, 1.2]"), "size_m"),
    ("size-missing", PLANE.replace("size_m = [1.5, 1.2]\n", ""), "size_m"),
    ("rgb-above-one", PLANE + "rgb = [1.5, 0.5, 0.5]\n", "rgb"),
    ("rgb-negative", PLANE + "rgb = [-0.1, 0.5, 0.5]\n", "rgb"),
    ("rgb-string", PLANE + 'rgb = "red"\n', "rgb"),
    ("srgb8-above-255", PLANE + "srgb8 = [300, 0, 0]\n", "srgb8"),
    ("srgb8-bool", PLANE + "srgb8 = [true, false, true]\n", "srgb8"),
    ("rgb-and-srgb8", PLANE + "rgb = [0.5, 0.5, 0.5]\nsrgb8 = [255, 0, 0]\n", "not rgb and srgb8"),
    ("material-unknown", PLANE + 'material = "glass"\n', "material"),
    ("metal-unknown", PLANE + 'material = "metal"\nmetal = "unobtainium"\n', "metal"),
    ("roughness-without-plastic", PLANE + "roughness = 0.2\n", "roughness"),
    ("roughness-zero", PLANE + 'material = "plastic"\nroughness = 0\n', "roughness"),
    ("rig-unknown-preset", 'rig = "kinect2"\n' + PLANE, "kinect2"),
    ("rig-file-missing", 'rig = "nope.toml"\n' + PLANE, "nope.toml"),
    ("z0-zero", "reference_depth_m = 0\n" + PLANE, "reference_depth_m"),
    ("z0-negative", "reference_depth_m = -1.0\n" + PLANE, "reference_depth_m"),
    ("z0-inf", "reference_depth_m = inf\n" + PLANE, "reference_depth_m"),
    ("z0-nan", "reference_depth_m = nan\n" + PLANE, "reference_depth_m"),
    ("z0-string", 'reference_depth_m = "1"\n' + PLANE, "reference_depth_m"),
    ("ambient-negative", "[ambient]\nrgb = [-1.0, 0.0, 0.0]\n" + PLANE, "ambient"),
    ("ambient-unknown-key", "[ambient]\nlux = 3\n" + PLANE, "ambient"),
    ("projector-scale-zero", "[projector]\nscale = 0\n" + PLANE, "projector.scale"),
    ("projector-scale-inf", "[projector]\nscale = inf\n" + PLANE, "projector.scale"),
    ("sphere-radius-zero", '[[object]]\ntype = "sphere"\nradius_m = 0\n', "radius_m"),
    ("sphere-radius-missing", '[[object]]\ntype = "sphere"\n', "radius_m"),
    ("mesh-missing", '[[object]]\ntype = "mesh"\nfile = "nope.ply"\n', "nope.ply"),
    ("mesh-not-ply", '[[object]]\ntype = "mesh"\nfile = "s.toml"\n', ".ply or .obj"),
    (
        "mesh-scale-negative",
        f'[[object]]\ntype = "mesh"\nfile = "{SCENES / "meshes" / "pear.ply"}"\nscale = -1\n',
        "scale",
    ),
    ("duplicate-names", PLANE + PLANE, "unique"),
    # issue 33: values that validated and rendered nothing (exit 0); bounds in simbench.sim.scene
    ("center-1e308", PLANE.replace("[0.0, 0.0, 1.0]", "[0.0, 0.0, 1e308]"), "center_m"),
    ("center-beyond-100m", PLANE.replace("[0.0, 0.0, 1.0]", "[0.0, 0.0, 150.0]"), "center_m"),
    ("sphere-radius-1e30", '[[object]]\ntype = "sphere"\nradius_m = 1e30\n', "radius_m"),
    ("rotation-1e308", PLANE + "rotation_deg = [0.0, 1e308, 0.0]\n", "rotation_deg"),
    ("rotation-beyond-a-turn", PLANE + "rotation_deg = [400.0, 0.0, 0.0]\n", "rotation_deg"),
    ("srgb8-fraction", PLANE + "srgb8 = [0.5, 0.5, 0.5]\n", "8-bit integers"),
    ("name-table", '[[object]]\ntype = "sphere"\nradius_m = 0.1\nname = {x = 1}\n', "name must be a non-empty string"),
    ("scene-name-table", "name = {x = 1}\n" + PLANE, "name must be a string"),
    ("projector-scale-1e300", "[projector]\nscale = 1e300\n" + PLANE, "projector.scale"),
    (
        "mesh-scale-huge",
        f'[[object]]\ntype = "mesh"\nfile = "{SCENES / "meshes" / "pear.ply"}"\nscale = 1e30\n',
        "scale",
    ),
]:
    case(
        f"render-scene-{cid}", lambda d: ["render", str(d / "s.toml"), "--out", str(d / "out")], msg, files=_scene(body)
    )
case(  # issue 33: a folder of black images, exit 0 (the tiny rig, 1 spp: a render of ~1 s)
    "render-scene-behind-the-camera",
    lambda d: ["render", str(d / "s.toml"), "--out", str(d / "out"), "--spp", "1", "--no-cache", "--sensor", "ideal"],
    "no object is visible",
    files=_scene('rig = "rig.toml"\n' + PLANE.replace("[0.0, 0.0, 1.0]", "[0.0, 0.0, -1.0]"), TINY_RIG),
)
case(
    "render-scene-missing", lambda d: ["render", str(d / "nope.toml"), "--out", str(d / "out")], "scene file not found"
)
case(
    "render-scene-is-folder",
    lambda d: ["render", str(d / "sd"), "--out", str(d / "out")],
    "sd",
    setup=lambda d: (d / "sd").mkdir(),
)
case(
    "render-scene-not-utf8",
    lambda d: ["render", str(d / "s.toml"), "--out", str(d / "out")],
    "s.toml",
    files={"s.toml": b'name = "\xff\xfe"\n'},
)

for cid, changes, msg in [
    ("width-zero", {"camera.width_px": "0"}, "width_px"),
    ("width-fraction", {"camera.width_px": "10.5"}, "width_px"),
    ("width-huge", {"camera.width_px": "100000", "camera.height_px": "100000"}, "width_px"),
    ("too-many-pixels", {"camera.width_px": "16000", "camera.height_px": "16000"}, "Mpx"),
    ("width-string", {"camera.width_px": '"160"'}, "width_px"),
    ("width-bool", {"camera.width_px": "true"}, "width_px"),
    ("focal-zero", {"camera.focal_px": "0"}, "focal_px"),
    ("focal-negative", {"camera.focal_px": "-1.0"}, "focal_px"),
    ("focal-nan", {"camera.focal_px": "nan"}, "focal_px"),
    ("focal-missing", {"camera.focal_px": None}, "focal_px"),
    ("cx-huge", {"camera.cx_px": "1e9"}, "cx_px"),
    ("cy-minus-huge", {"camera.cy_px": "-1e9"}, "cy_px"),
    ("distortion-four", {"camera.distortion": "[0.1, 0.0, 0.0, 0.0]"}, "distortion"),
    ("distortion-string", {"camera.distortion": '"barrel"'}, "distortion"),
    ("distortion-huge", {"camera.distortion": "[1e6, 0.0, 0.0, 0.0, 0.0]"}, "distortion"),
    ("projector-height-negative", {"projector.height_px": "-285"}, "height_px"),
    ("unknown-key", {"camera.skew": "0.0"}, "unknown key"),
    ("no-baseline", {"pose.position_m": "[0.0, 0.0, 0.0]"}, "baseline"),
    ("position-nan", {"pose.position_m": "[nan, 0.0, 0.0]"}, "position_m"),
    ("position-far", {"pose.position_m": "[1000.0, 0.0, 0.0]"}, "position_m"),
    ("rotation-inf", {"pose.rotation_deg": "[0.0, inf, 0.0]"}, "rotation_deg"),
    ("rotation-two", {"pose.rotation_deg": "[0.0, 0.0]"}, "rotation_deg"),
    # a new user's audit of their own rigs: each rendered, then decoded nothing with misleading hints
    ("vertical-baseline", {"pose.position_m": "[0.0, 0.093, 0.0]"}, "0.0 mm along the camera's x axis of 93.0 mm"),
    ("off-centre-principal-point-under-the-thin-lens", {"camera.cx_px": "85.0"}, "principal point (85, 59.5) is off"),
]:
    case(
        f"render-rig-{cid}",
        lambda d: ["render", str(d / "s.toml"), "--out", str(d / "out")],
        msg,
        files=_scene('rig = "rig.toml"\n' + PLANE, _rig_text(**changes)),
    )
case(
    "render-rig-missing-camera",
    lambda d: ["render", str(d / "s.toml"), "--out", str(d / "out")],
    "camera",
    files=_scene('rig = "rig.toml"\n' + PLANE, "[projector]\nwidth_px=10\nheight_px=10\nfocal_px=5\n"),
)
case(
    "render-rig-missing-pose",
    lambda d: ["render", str(d / "s.toml"), "--out", str(d / "out")],
    "missing key(s) ['pose']",
    files=_scene('rig = "rig.toml"\n' + PLANE, TINY_RIG.split("[pose]")[0]),
)
case(
    "render-rig-missing-position",
    lambda d: ["render", str(d / "s.toml"), "--out", str(d / "out")],
    "missing key(s) ['position_m']",
    files=_scene('rig = "rig.toml"\n' + PLANE, TINY_RIG.replace("position_m = [0.093, 0.0, 0.0]", "")),
)
case(
    "render-rig-pose-not-table",
    lambda d: ["render", str(d / "s.toml"), "--out", str(d / "out")],
    "pose",
    files=_scene('rig = "rig.toml"\n' + PLANE, TINY_RIG.replace("[pose]\nposition_m", "pose = 3\n[x]\nposition_m")),
)

for opt, bad, msg in [
    ("--spp", "0", "--spp"),
    ("--spp", "-1", "--spp"),
    ("--spp", "x", "--spp"),
    ("--spp", "1000000", "--spp"),
    ("--seed", "-1", "--seed"),
    ("--seed", "x", "--seed"),
    ("--seed", str(2**64), "--seed"),
    ("--max-depth", "0", "--max-depth"),
    ("--max-depth", "1", "--max-depth"),
    ("--max-depth", "x", "--max-depth"),
    ("--period", "2", "--period"),
    ("--order", "1", "--order"),
    ("--channels", "rrb", "permutation"),
    ("--sequence", "0101", "repeats"),
]:
    case(
        f"render{opt}={bad}",
        lambda d, o=opt, b=bad: ["render", str(SCENES / "white_plane.toml"), "--out", str(d / "out"), o, b],
        msg,
    )

SENSOR_OK = (ROOT / "simbench" / "presets" / "minimal.toml").read_text()
PAPER = (ROOT / "simbench" / "presets" / "paper.toml").read_text()


def _sensor(text: str, old: str, new: str) -> str:
    assert old in text, old
    return text.replace(old, new, 1)


for cid, text, msg in [
    ("noise-string", _sensor(PAPER, "noise = true", 'noise = "false"'), "noise"),
    ("noise-int", _sensor(PAPER, "noise = true", "noise = 0"), "noise"),
    ("gamma-inf", _sensor(PAPER, "gamma = 2.2", "gamma = inf"), "gamma"),
    ("gamma-zero", _sensor(PAPER, "gamma = 2.2", "gamma = 0.0"), "gamma"),
    ("gamma-negative", _sensor(PAPER, "gamma = 2.2", "gamma = -2.2"), "gamma"),
    ("qe-four", _sensor(PAPER, "qe = [0.45, 0.50, 0.45]", "qe = [0.45, 0.50, 0.45, 0.4]"), "qe"),
    ("qe-zero", _sensor(PAPER, "qe = [0.45, 0.50, 0.45]", "qe = [0.0, 0.50, 0.45]"), "qe"),
    ("qe-string", _sensor(PAPER, "qe = [0.45, 0.50, 0.45]", 'qe = "high"'), "qe"),
    ("full-well-zero", _sensor(PAPER, "full_well_e = 10000.0", "full_well_e = 0.0"), "full_well_e"),
    ("full-well-nan", _sensor(PAPER, "full_well_e = 10000.0", "full_well_e = nan"), "full_well_e"),
    ("dark-noise-negative", _sensor(PAPER, "dark_noise_e = 20.0", "dark_noise_e = -1.0"), "dark_noise_e"),
    ("dark-noise-inf", _sensor(PAPER, "dark_noise_e = 20.0", "dark_noise_e = inf"), "dark_noise_e"),
    ("bits-9", _sensor(PAPER, "bits = 8", "bits = 9"), "bits"),
    # issue 33: validated and made every capture 255 (exit 0); bounds argued in simbench.sim.sensor
    ("offset-1e30", _sensor(PAPER, "offset_dn = 0.0", "offset_dn = 1e30"), "offset_dn"),
    ("offset-above-half-range", _sensor(PAPER, "offset_dn = 0.0", "offset_dn = 200.0"), "offset_dn"),
    ("dark-current-1e30", _sensor(PAPER, "dark_current_e_s = 0.0", "dark_current_e_s = 1e30"), "dark_current_e_s"),
    ("dsnu-1e30", _sensor(PAPER, "dsnu_e = 5.0", "dsnu_e = 1e30"), "dsnu_e"),
    ("focus-1e20", _sensor(PAPER, "focus_m = 1.0", "focus_m = 1e20"), "focus_m"),
    ("full-well-1e30", _sensor(PAPER, "full_well_e = 10000.0", "full_well_e = 1e30"), "full_well_e"),
    ("bits-string", _sensor(PAPER, "bits = 8", 'bits = "8"'), "bits"),
    ("cfa-unknown", _sensor(PAPER, 'cfa = "RGGB"', 'cfa = "RGBW"'), "cfa"),
    ("demosaic-unknown", _sensor(PAPER, 'demosaic = "bilinear"', 'demosaic = "ai"'), "demosaic"),
    ("prnu-above-one", _sensor(PAPER, "prnu = 0.01", "prnu = 2.0"), "prnu"),
    ("exposure-negative", _sensor(PAPER, 'exposure_s = "auto"', "exposure_s = -0.01"), "exposure_s"),
    ("exposure-word", _sensor(PAPER, 'exposure_s = "auto"', 'exposure_s = "manual"'), "auto"),
    (
        "auto-fraction-zero",
        _sensor(PAPER, "auto_exposure_fraction = 0.7", "auto_exposure_fraction = 0.0"),
        "auto_exposure_fraction",
    ),
    ("camera-unknown-key", _sensor(PAPER, "pixel_pitch_um = 5.3", "pixel_pitch_um = 5.3\niso = 100"), "unknown key"),
    ("camera-missing-pitch", _sensor(PAPER, "pixel_pitch_um = 5.3", ""), "pixel_pitch_um"),
    ("camera-model-unknown", _sensor(PAPER, 'model = "emva"', 'model = "ccd"'), "model"),
    ("lens-f-number-zero", _sensor(PAPER, "f_number = 4.0", "f_number = 0.0"), "f_number"),
    ("lens-transmission-two", _sensor(PAPER, "transmission = 0.9", "transmission = 2.0"), "transmission"),
    ("lens-defocus-string", _sensor(PAPER, "defocus = true", 'defocus = "yes"'), "defocus"),
    ("lens-focus-inf", _sensor(PAPER, "focus_m = 1.0", "focus_m = inf"), "focus_m"),
    ("lumens-zero", _sensor(PAPER, "lumens = 150.0", "lumens = 0.0"), "lumens"),
    ("contrast-below-one", _sensor(PAPER, "contrast_ratio = 1000.0", "contrast_ratio = 0.5"), "contrast_ratio"),
    ("contrast-word", _sensor(PAPER, "contrast_ratio = 1000.0", 'contrast_ratio = "high"'), "contrast_ratio"),
    ("dmd-unknown", _sensor(PAPER, 'dmd = "diamond"', 'dmd = "hexagon"'), "dmd"),
    ("transfer-unknown", _sensor(PAPER, 'transfer = "linear"', 'transfer = "log"'), "transfer"),
    ("crosstalk-string", _sensor(PAPER, "crosstalk = true", 'crosstalk = "true"'), "crosstalk"),
    ("ambient-negative", _sensor(PAPER, "ratio = 0.02", "ratio = -0.02"), "ratio"),
    ("ambient-nan", _sensor(PAPER, "ratio = 0.02", "ratio = nan"), "ratio"),
    ("unknown-table", PAPER + "\n[thermal]\ndrift = 1\n", "unknown key"),
    ("not-toml", "camera = [", "not valid TOML"),
]:
    case(
        f"render-sensor-{cid}",
        lambda d: [
            "render",
            str(SCENES / "white_plane.toml"),
            "--out",
            str(d / "out"),
            "--sensor",
            str(d / "sensor.toml"),
        ],
        msg,
        files={"sensor.toml": text},
    )
case(
    "render-sensor-unknown-preset",
    lambda d: ["render", str(SCENES / "white_plane.toml"), "--out", str(d / "out"), "--sensor", "flea4"],
    "unknown sensor",
)
case(
    "render-sensor-file-missing",
    lambda d: ["render", str(SCENES / "white_plane.toml"), "--out", str(d / "out"), "--sensor", str(d / "nope.toml")],
    "nope.toml",
)
case(
    "render-sensor-minimal-crosstalk",
    lambda d: ["render", str(SCENES / "white_plane.toml"), "--out", str(d / "out"), "--sensor", str(d / "sensor.toml")],
    "crosstalk",
    files={"sensor.toml": SENSOR_OK + "\n[spectral]\ncrosstalk = true\n"},
)
case(
    "render-out-foreign-folder",
    lambda d: ["render", str(SCENES / "white_plane.toml"), "--out", str(d / "mine")],
    "mine",
    files={"mine/notes.txt": "my notes"},
)
case(
    "render-out-is-a-file",
    lambda d: ["render", str(SCENES / "white_plane.toml"), "--out", str(d / "f")],
    "not a folder",
    files={"f": "x"},
)

# ---------------------------------------------------------------------------------- decode


def _decode(
    d: Path, *extra: str, capture: str = "capture.png", reference: str | None = "reference.png", rig: str = "rig.toml"
) -> list[str]:
    r = d / "r"
    argv = ["decode", str(r / capture), "--rig", str(r / rig), "--out", str(d / "depth.npy")]
    if reference is not None:
        argv += ["--reference", str(r / reference)]
    return argv + list(extra)


def _grey_alpha_png(h: int, w: int) -> bytes:
    """A valid 8-bit grey+alpha PNG (colour type 4) of a mid-grey, opaque image."""
    import struct
    import zlib

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)

    rows = b"".join(b"\x00" + bytes([128, 255]) * w for _ in range(h))
    ihdr = struct.pack(">IIBBBBB", w, h, 8, 4, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(rows)) + chunk(b"IEND", b"")


def _image_file(name: str, content) -> object:
    def setup(d: Path) -> None:
        render_folder(d)
        p = d / "r" / name
        if isinstance(content, bytes):
            p.write_bytes(content)
        else:
            from simbench.io import save_npy, save_png

            (save_npy if name.endswith(".npy") else save_png)(p, content)

    return setup


RNG = np.random.default_rng(7)
for cid, name, content, msg in [
    ("capture-empty", "c.png", b"", "empty"),
    ("capture-random-bytes", "c.png", RNG.integers(0, 256, 4000, dtype=np.uint8).tobytes(), "not a readable image"),
    ("capture-text", "c.png", b"this is not a png\n", "not a readable image"),
    ("capture-truncated-png", "c.png", None, "not a readable image"),
    ("capture-crc-error", "c.png", "flip", "CRC error"),
    ("capture-grey", "c.png", np.zeros((120, 160), np.uint8), "RGB"),
    ("capture-wrong-size", "c.png", np.zeros((240, 320, 3), np.uint8), "320x240"),
    ("capture-npy-nan", "c.npy", np.full((120, 160, 3), np.nan, np.float32), ("c.npy: 57600 pixel values", "NaN")),
    ("capture-npy-2d", "c.npy", np.zeros((120, 160), np.float32), "RGB"),
    ("capture-npy-int64", "c.npy", np.zeros((120, 160, 3), np.int64), ("c.npy: int64 pixels", "uint8, uint16")),
    ("capture-npy-empty", "c.npy", b"", "empty"),
    ("capture-npy-not-npy", "c.npy", b"PK\x03\x04 not numpy", "not a NumPy"),
    # issue 33: read as RGB and decoded to 0 % with exit 0; floats on the 8-bit scale accepted
    ("capture-grey-alpha-png", "c.png", b"GA", "grey+alpha PNG"),
    ("capture-npy-0-255", "c.npy", np.full((120, 160, 3), 200.0, np.float32), "8-bit values"),
    ("capture-npy-negative", "c.npy", np.full((120, 160, 3), -0.5, np.float32), ("spans [-0.5", "negative light")),
    ("capture-npy-0-65535", "c.npy", np.full((120, 160, 3), 4000.0, np.float32), "16-bit values? divide by 65535"),
]:

    def _setup(d, name=name, content=content):
        if isinstance(content, bytes) and content == b"GA":  # OpenCV cannot write grey+alpha: a PNG by hand
            render_folder(d)
            (d / "r" / name).write_bytes(_grey_alpha_png(120, 160))
        elif content is None:  # a real PNG cut in half
            render_folder(d)
            data = (d / "r" / "capture.png").read_bytes()
            (d / "r" / name).write_bytes(data[: len(data) // 2])
        elif isinstance(content, str):  # a real PNG with one byte of its image data flipped
            render_folder(d)
            data = bytearray((d / "r" / "capture.png").read_bytes())
            data[len(data) // 2] ^= 0xFF
            (d / "r" / name).write_bytes(bytes(data))
        else:
            _image_file(name, content)(d)

    case(f"decode-{cid}", lambda d, n=name: _decode(d, capture=n), msg, setup=_setup)


def _sparse_npy(path: Path) -> None:
    """A 9.6 GiB .npy that takes a few kB of disk (its data never written)."""
    from numpy.lib.format import open_memmap

    del_ = open_memmap(path, mode="w+", dtype=np.float64, shape=(20000, 20000, 3))
    del del_


case(  # issue 33: "out of memory" without the file
    "decode-capture-npy-sparse-huge",
    lambda d: _decode(d, capture="huge.npy"),
    ("huge.npy", "GiB", "more than"),
    setup=lambda d: _sparse_npy(render_folder(d) / "huge.npy"),
)
case("decode-capture-missing", lambda d: _decode(d, capture="nope.png"), "nope.png", setup=render_folder)
case(
    "decode-capture-is-folder",
    lambda d: _decode(d, capture="sub"),
    "sub",
    setup=lambda d: (render_folder(d) / "sub").mkdir(),
)
for cid, content, msg in [
    ("reference-black", np.zeros((120, 160, 3), np.uint8), "reference capture decodes at only"),
    (
        "reference-saturated",
        np.full((120, 160, 3), 255, np.uint8),
        ("reference capture decodes at only", "(100 % of it is clipped: expose shorter)"),
    ),
    ("reference-noise", RNG.integers(0, 256, (120, 160, 3), dtype=np.uint8), "reference capture decodes at only"),
    ("reference-wrong-size", np.zeros((60, 80, 3), np.uint8), "80x60"),
    ("reference-empty", b"", "empty"),
]:
    case(f"decode-{cid}", lambda d: _decode(d, reference="ref2.png"), msg, setup=_image_file("ref2.png", content))
case("decode-reference-missing", lambda d: _decode(d, reference="nope.png"), "nope.png", setup=render_folder)
case(
    "decode-reference-mode-without-reference", lambda d: _decode(d, reference=None), "--reference", setup=render_folder
)
case(  # a third audit: NumPy bytes written under a .png name, exit 0
    "decode-confidence-not-npy",
    lambda d: [*_decode(d), "--confidence", str(d / "c.png")],
    "--confidence must name a .npy file",
    setup=render_folder,
)
case("decode-rig-missing", lambda d: _decode(d, rig="nope.toml"), "nope.toml", setup=render_folder)
# a second audit: calibrate's --out folder given as the rig read "rig file not found"
case(
    "decode-rig-a-folder",
    lambda d: _decode(d, rig="."),
    ("a folder, not a rig file", "rig.toml, the rig file in it"),
    setup=render_folder,
)
case(
    "decode-rig-invalid",
    lambda d: _decode(d, rig="bad.toml"),
    "focal_px",
    setup=lambda d: (render_folder(d) / "bad.toml").write_text(_rig_text(**{"camera.focal_px": "0"})),
)
case(
    "decode-rig-not-utf8",
    lambda d: _decode(d, rig="bad.toml"),
    "UTF-8",
    setup=lambda d: (render_folder(d) / "bad.toml").write_bytes(b"\xff\xfe\x00"),
)
case(
    "decode-rig-other-camera",
    lambda d: _decode(d, rig="big.toml"),
    "camera is 320x240",
    setup=lambda d: (render_folder(d) / "big.toml").write_text(
        _rig_text(**{"camera.width_px": "320", "camera.height_px": "240"})
    ),
)
for opt, bad in [
    ("--z0", "0"),
    ("--z0", "-1"),
    ("--z0", "inf"),
    ("--z0", "nan"),
    ("--z0", "x"),
    ("--near", "0"),
    ("--near", "-1"),
    ("--far", "nan"),
    ("--far", "1e9"),
]:
    case(f"decode{opt}={bad}", lambda d, o=opt, b=bad: _decode(d, o, b), opt, setup=render_folder)
case(
    "decode-near-beyond-far",
    lambda d: _decode(d, "--near", "2.0", "--far", "1.0"),
    "--near 2 must be less than --far 1",
    setup=render_folder,
)
case("decode-mode-unknown", lambda d: _decode(d, "--mode", "stereo"), "--mode", setup=render_folder)
for item, msg in [
    ("voting=maybe", "voting"),
    ("voting=1", "voting"),
    ("voting='true'", "voting"),
    ("neighbour_reach=[1,2]", "neighbour_reach"),
    ("neighbour_reach=-1", "neighbour_reach"),
    ("neighbour_reach=2.5", "neighbour_reach"),
    ("sigma_periods=0", "sigma_periods"),
    ("sigma_periods=inf", "sigma_periods"),
    ("sigma_periods=nan", "sigma_periods"),
    ("dark_level=2", "dark_level"),
    ("phase_method=nope", "phase_method"),
    ("phase_method=1", "phase_method"),
    ("unknown=1", "name one of"),
    ("voting", "name=value"),
    ("mode=stereo", "mode"),
    ("depth_range_m=[2.0,1.0]", "depth_range_m"),
    ("depth_range_m=3", "depth_range_m"),
    ("min_support=0", "min_support"),
    ("threads=0", "threads"),
    ("z0_m=-1", "z0_m"),
    ("saturation_level=0", "saturation_level"),
    ("max_residual=0", "max_residual"),
    ("sequence=[0,2,1]", "sequence"),
    ("sequence='0101'", "sequence"),
    ("intensity_mode=3", "intensity_mode"),
    ("camera_period_px=1", "camera_period_px"),
    ("min_amplitude=-0.1", "min_amplitude"),
    ("min_reference_coverage=1.5", "min_reference_coverage"),
    ("color_normalize=yes", "color_normalize"),
    ("link_check=0", "link_check"),
    ("without=colour", "unknown decoder check"),
    ("without=[1]", "unknown decoder check"),
    ("stripe_step_ratio=[3.0,0.3]", "stripe_step_ratio"),
    ("stripe_step_ratio=[-1.0,3.0]", "stripe_step_ratio"),
]:
    case(f"decode--decoder-{item}", lambda d, i=item: _decode(d, "--decoder", i), msg, setup=render_folder)
case(
    "decode-out-not-npy",
    lambda d: _decode(d)[:-5] + [str(d / "depth.png")] + _decode(d)[-2:],
    "--out",
    setup=render_folder,
)
case(
    "decode-ply-unwritable",
    lambda d: _decode(d, "--ply", str(d / "f" / "c.ply")),
    "f",
    setup=lambda d: (render_folder(d), (d / "f").write_text("x")),
)
case("decode-ply-not-ply", lambda d: _decode(d, "--ply", str(d / "c.txt")), "--ply", setup=render_folder)
case(
    "decode-debug-dir-unwritable",
    lambda d: _decode(d, "--debug-dir", str(d / "f" / "stages")),
    "f",
    setup=lambda d: (render_folder(d), (d / "f").write_text("x")),
)
case(
    "decode-debug-dir-is-a-file",
    lambda d: _decode(d, "--debug-dir", str(d / "f")),
    "not a folder",
    setup=lambda d: (render_folder(d), (d / "f").write_text("x")),
)
case(
    "decode-out-under-a-file",
    lambda d: _decode(d)[:-5] + [str(d / "f" / "depth.npy")] + _decode(d)[-2:],
    "f",
    setup=lambda d: (render_folder(d), (d / "f").write_text("x")),
)


# issue 33: partial outputs - each was exit 2 with depth.npy (or a .tmp) already written
case(
    "decode-cache-is-a-file",
    lambda d: _decode(d, "--cache", str(d / "f")),
    ("is a file, not a folder", "pass --no-cache to store nothing, or --cache DIR for another folder"),
    setup=lambda d: (render_folder(d), (d / "f").write_text("x")),
)
case(
    "decode-cache-under-a-file",
    lambda d: _decode(d, "--cache", str(d / "f" / "cache")),
    "is a file, so",
    setup=lambda d: (render_folder(d), (d / "f").write_text("x")),
)
case(
    "decode-cache-of-other-files",
    lambda d: _decode(d, "--cache", str(d / "mine")),
    ("not a simbench render cache", "; pass --no-cache to store nothing"),
    setup=lambda d: (render_folder(d), (d / "mine").mkdir(), (d / "mine" / "notes.txt").write_text("x")),
)
case(
    "decode-ply-is-a-folder",
    lambda d: _decode(d, "--ply", str(d / "p.ply")),
    "is a folder",
    setup=lambda d: (render_folder(d), (d / "p.ply").mkdir()),
)
# a fourth audit: --decoder pattern= and min_confidence= won over the options that say the same
# a third new user's audit: a --cache that is a file failed every run of the sweep - a table of n/a, exit 0
case(
    "ablate-cache-is-a-file",
    lambda d: ["ablate", "period", "--out", str(d / "o"), "--cache", str(d / "f")],
    "is a file, not a cache folder",
    setup=lambda d: (d / "f").write_text("x"),
)
case(
    "decode-decoder-pattern-against-the-recording",
    lambda d: _decode(d, "--decoder", "pattern={period_px=30}"),
    # (a new user's audit: the message named both patterns whole, not the field that differs)
    ("--decoder pattern=", "contradicts the recording", "they differ in period (30 px against 21 px recorded)"),
    setup=lambda d: render_folder(d),
)
case(
    "decode-period-and-decoder-pattern",
    lambda d: _decode(d, "--period", "25", "--decoder", "pattern={period_px=21}"),
    ("--period", "--decoder pattern=", "disagree"),
    setup=lambda d: (render_folder(d), (d / "r" / "meta.json").unlink()),
)
case(
    "decode-min-confidence-twice",
    lambda d: _decode(d, "--min-confidence", "2", "--decoder", "min_confidence=5"),
    "--min-confidence 2 and --decoder min_confidence=5 disagree",
    setup=lambda d: render_folder(d),
)
if Path("/proc/self").is_dir():  # Linux: os.access lets root "write" in /proc, where no file can be made
    case(
        "decode-ply-in-proc",
        lambda d: _decode(d, "--ply", "/proc/x.ply"),
        "--ply: cannot write in /proc",
        setup=lambda d: render_folder(d),
    )
    case(  # a new user's audit (2026-11-30): the folder that cannot be made is the one named
        "decode-ply-in-a-new-folder-in-proc",
        lambda d: _decode(d, "--ply", "/proc/nope/x.ply"),
        "--ply: cannot write in /proc/nope: cannot create it in /proc",
        setup=lambda d: render_folder(d),
    )
for bad, msg in (
    ("gamma", "is not one of linear, srgb, gamma=G"),
    ("gamma=9", "from 1 to 4"),
    ("gamma=x", "from 1 to 4"),
):
    case(f"decode-encoding-{bad}", lambda d, b=bad: _decode(d, "--encoding", b), msg, setup=lambda d: render_folder(d))
case(  # a simbench recording's images are linear: no encoding to undo
    "decode-encoding-of-a-recording",
    lambda d: ["decode", str(d / "r"), "--out", str(d / "o.npy"), "--encoding", "srgb"],
    "is a simbench recording's image, whose camera records linear digital numbers",
    setup=lambda d: render_folder(d),
)
case(
    "decode-out-is-a-folder",
    lambda d: ["decode", str(d / "r"), "--out", str(d / "o.npy")],
    "is a folder",
    setup=lambda d: (render_folder(d), (d / "o.npy").mkdir()),
)
case(
    "decode-debug-dir-is-out",
    lambda d: _decode(d, "--debug-dir", str(d / "depth.npy")),
    "is --out",
    setup=render_folder,
)
case(
    "decode-out-over-the-ground-truth",
    lambda d: ["decode", str(d / "r"), "--out", str(d / "r" / "gt_depth.npy")],
    "a file of the recording",
    setup=render_folder,
)
case(
    "decode-out-empty",
    lambda d: ["decode", str(d / "r"), "--out", ""],
    "--out",
    setup=render_folder,
)
case(
    "system-decode-out-over-its-ground-truth",
    lambda d: ["decode", str(d / "rec"), "--out", str(d / "rec" / "gt_depth.npy")],
    "a file of the recording",
    setup=lambda d: _recording(d, {"device": "tof"}, {"gt_depth.npy": b"x"}),
)
# issue 33 audit: other commands wrote over a recording's files and the cache's marker (exit 0)
case(
    "decode-out-over-another-recordings-truth",
    lambda d: ["decode", str(d / "r"), "--out", str(d / "rec" / "gt_depth.npy")],
    "belongs to the recording",
    setup=lambda d: (render_folder(d), _recording(d, {"device": "tof"}, {"gt_depth.npy": _npy(np.ones((2, 2)))})),
)
case(
    "pattern-out-over-a-recordings-capture",
    lambda d: ["pattern", "--out", str(d / "r" / "capture.png")],
    "belongs to the recording",
    setup=render_folder,
)
case(
    "crosstalk-out-over-a-manifest",
    lambda d: ["crosstalk", "--out", str(d / "r" / "meta.json")],
    "belongs to the recording",
    setup=render_folder,
)
case(
    "pattern-out-over-the-cache-marker",
    lambda d: ["pattern", "--out", str(d / "c" / "CACHEDIR.TAG")],
    "render cache's marker",
    setup=lambda d: __import__("simbench.cache", fromlist=["claim_cache_folder"]).claim_cache_folder(d / "c"),
)
case(  # issue 33 audit: the proposed sensor's options were ignored for other systems' folders
    "system-decode-proposed-options",
    lambda d: ["decode", str(d / "rec"), "--out", str(d / "x.npy"), "--z0", "1.1", "--order", "4"],
    "apply to the proposed sensor's folders only",
    setup=lambda d: _recording(d, {"device": "tof"}),
)
case(
    "decode-capture-float-tiff-0-255",
    lambda d: _decode(d, capture="c.tiff"),
    "8-bit values",
    setup=lambda d: (
        render_folder(d),
        __import__("cv2").imwrite(str(d / "r" / "c.tiff"), np.full((120, 160, 3), 200.0, np.float32)),
    ),
)
case(  # issue 33 audit: demo and --debug-dir replaced a user's same-named files
    "demo-out-a-users-folder",
    lambda d: ["demo", "--out", str(d / "mine"), "--scenes", "sphere"],
    "did not write",
    files={"mine/sphere.png": b"my picture", "mine/notes.txt": "x"},
)
case(
    "decode-debug-dir-a-users-folder",
    lambda d: _decode(d, "--debug-dir", str(d / "mine")),
    "did not write",
    setup=lambda d: (render_folder(d), (d / "mine").mkdir(), (d / "mine" / "depth.png").write_bytes(b"mine")),
)
case(
    "render-cache-is-out",
    lambda d: ["render", str(SCENES / "white_plane.toml"), "--out", str(d / "x"), "--cache", str(d / "x")],
    "overlap",
)
case(
    "render-cache-under-a-file",
    lambda d: ["render", str(SCENES / "white_plane.toml"), "--out", str(d / "x"), "--cache", str(d / "f" / "c")],
    ("is a file, so", "; pass --no-cache to store nothing, or --cache DIR for another folder"),
    files=_w("f", "x"),
)
# a third audit (2026-11-30): calibrate did not check its cache first - "[Errno 20] Not a directory"
case(
    "calibrate-cache-under-a-file",
    lambda d: ["calibrate", "--poses", "3", "--out", str(d / "cal"), "--cache", str(d / "f" / "c")],
    ("is a file, so", "; pass --no-cache to store nothing, or --cache DIR for another folder"),
    files=_w("f", "x"),
)
case(
    "render-cache-inside-out",
    lambda d: ["render", str(SCENES / "white_plane.toml"), "--out", str(d / "x"), "--cache", str(d / "x" / "c")],
    "overlap",
)


def _mixed(d: Path) -> None:
    """capture.png replaced after meta.json was written (what a killed older version left)."""
    from simbench.io import save_png

    r = render_folder(d)
    (r / "capture.png").unlink()  # simbench itself refuses to write over a recorded file
    save_png(r / "capture.png", np.roll(_IMAGES[0], 3, axis=1))


case("decode-mixed-render-folder", lambda d: _decode(d), "mixes files of two renders", setup=_mixed)
case(
    "decode-meta-not-json",
    lambda d: _decode(d),
    "meta.json",
    setup=lambda d: (render_folder(d) / "meta.json").write_text("{not json"),
)


def _unsealed(d: Path) -> None:
    import json

    r = render_folder(d)
    data = json.loads((r / "meta.json").read_text())
    del data["manifest_sha256"]
    (r / "meta.json").write_text(json.dumps(data))


case(  # a new user's audit: "no sealed manifest of format 2 (found 2)"
    "decode-meta-seal-removed",
    lambda d: _decode(d),
    ("meta.json: its seal (manifest_sha256) is missing", "render it again"),
    setup=_unsealed,
)
case(
    "decode-meta-z0-negative",
    lambda d: _decode(d),
    "reference_depth_m",
    setup=lambda d: _seal(render_folder(d), reference_depth_m=-1),
)
case(
    "decode-meta-z0-overflow",  # issue 33: an OverflowError, exit 1 (sealed, so only the value is wrong)
    lambda d: _decode(d),
    "reference_depth_m",
    setup=lambda d: _seal(render_folder(d), reference_depth_m=10**400),
)
case(
    "render-variant-cuda-without-gpu",
    lambda d: ["render", str(SCENES / "white_plane.toml"), "--out", str(d / "o"), "--variant", "cuda_ad_rgb"],
    "cuda_ad_rgb",
)


def _scene_with_rig(d: Path, rig_text: str) -> None:
    (d / "rig.toml").write_text(rig_text)
    (d / "s.toml").write_text('rig = "rig.toml"\n[[object]]\ntype = "plane"\ncenter_m = [0, 0, 1]\nsize_m = [2, 2]\n')


# the fresh-clone audit: a rig's lens distortion was dropped for the sensor model's without a word
case(
    "calibrate-rig-distortion-not-the-sensors",
    lambda d: ["calibrate", "--poses", "3", "--rig", str(d / "rig.toml"), "--out", str(d / "cal")],
    "the rig's camera distortion [-0.2, 0.0, 0.0, 0.0, 0.0] is not the lens of sensor model 'paper'",
    setup=lambda d: (d / "rig.toml").write_text(_rig_text(**{"camera.distortion": "[-0.2, 0, 0, 0, 0]"})),
)
case(
    "render-scene-rig-distortion-not-the-sensors",
    lambda d: ["render", str(d / "s.toml"), "--sensor", "ideal", "--out", str(d / "o")],
    "the rig's projector distortion [0.1, 0.0, 0.0, 0.0, 0.0] is not the lens of sensor model 'ideal'",
    setup=lambda d: _scene_with_rig(d, _rig_text(**{"projector.distortion": "[0.1, 0, 0, 0, 0]"})),
)

for cid, extra, msg in [
    ("kinect-sensor", ["--system", "kinect", "--sensor", "ideal"], "sensor (--sensor) does not apply to the kinect"),
    ("tof-period", ["--system", "tof", "--period", "25"], "pattern (--period, --order, --sequence, --channels) does"),
    ("phase-shift-order", ["--system", "phase_shift", "--order", "4"], "does not apply to the phase_shift system"),
    ("kinect-calibration-frames", ["--system", "kinect", "--calibration-frames"], "calibration_frames (--calib"),
    ("tof-camera-scale", ["--system", "tof", "--camera-scale", "0.5"], "camera_scale (--camera-scale) does not apply"),
    ("camera-scale-not-whole", ["--camera-scale", "0.33"], "camera scale 0.33 gives a 422.4x316.8 image: it must"),
    ("camera-scale-period", ["--camera-scale", "0.1"], "to 2.18 camera pixels, under the 4 its decoding needs"),
    ("kinect-camera-scale-not-whole", ["--system", "kinect", "--camera-scale", "0.33"], "does not apply to the kinect"),
    ("camera-scale-zero", ["--camera-scale", "0"], "argument --camera-scale: must be a finite number in (0, 4]"),
]:
    case(
        f"render-{cid}",
        lambda d, extra=extra: ["render", str(SCENES / "white_plane.toml"), "--out", str(d / "o"), *extra],
        msg,
    )

case(
    "calibrate-target-symmetric",  # the audit: 10 x 8 squares were accepted (9 x 7 corners: symmetric)
    lambda d: ["calibrate", "--poses", "3", "--target", str(d / "t.toml"), "--out", str(d / "cal")],
    "squares [10, 8] - give one count even and the other odd",
    setup=lambda d: (d / "t.toml").write_text("squares = [10, 8]\nsquare_m = 0.03\n"),
)


def _bare_copies(d: Path) -> None:
    """The render folder's capture and reference copied out of it (no manifest: a user's own
    images), and a rig of another baseline."""
    import shutil

    render_folder(d)
    (d / "bare").mkdir()
    for name in ("capture.png", "reference.png"):
        shutil.copyfile(d / "r" / name, d / "bare" / name)
    (d / "other.toml").write_text(_rig_text(**{"pose.position_m": "[0.12, 0, 0]"}))


# images of no recording with a rig of another baseline: their reference plane tells (its Z0)
case(
    "decode-calibrated-bare-images-rig-of-another-baseline",
    # (tmp_path has no spaces)
    lambda d: (
        f"decode {d}/bare/capture.png --reference {d}/bare/reference.png --mode calibrated --rig {d}/other.toml "
        f"--out {d}/x.npy".split()
    ),
    "triangulates with the rig",
    setup=_bare_copies,
)
# a docs audit (2026-12-05): bare images decoded in reference mode with a rig whose baseline is
# mostly vertical were blamed on the reference, Z0 or pattern; the baseline is named first now
case(
    "decode-reference-bare-images-rig-of-a-vertical-baseline",
    lambda d: (
        f"decode {d}/bare/capture.png --reference {d}/bare/reference.png --rig {d}/up.toml --out {d}/x.npy".split()
    ),
    "along the camera's x axis",
    setup=lambda d: (
        _bare_copies(d),
        (d / "up.toml").write_text(_rig_text(**{"pose.position_m": "[0.005, 0.093, 0]"})),
    ),
)
# the fresh-clone audit: a rig of another baseline decoded 95 % at 77 mm MAE in calibrated mode
# (refused since by its reference plane's Z0, and since 2026-11-29 first by the recorded rig.toml,
# which also covers the folder's capture given alone: tests/test_manifest.py)
case(
    "decode-calibrated-rig-of-another-baseline",
    lambda d: [
        "decode",
        str(d / "r"),
        "--mode",
        "calibrated",
        "--rig",
        str(d / "other.toml"),
        "--out",
        str(d / "x.npy"),
    ],
    ("another rig than", "baseline 120.0 mm against 93.0"),
    setup=lambda d: (render_folder(d), (d / "other.toml").write_text(_rig_text(**{"pose.position_m": "[0.12, 0, 0]"}))),
)

# a docs audit (2026-11-30): a rig within the recorded rig's tolerances (baseline +4 %) but off
# by more than the reference plane allows decoded a recording's capture given alone at 40 mm MAE,
# exit 0, where the folder form refused it by its reference plane: both forms check it now
for form in ("folder", "capture"):
    case(
        f"decode-calibrated-{form}-rig-4-percent-off",
        lambda d, form=form: [
            "decode",
            str(d / "r") if form == "folder" else str(d / "r" / "capture.png"),
            "--mode",
            "calibrated",
            "--rig",
            str(d / "near.toml"),
            "--out",
            str(d / "x.npy"),
        ],
        ("reference.png triangulates with the rig", "more than 3 %"),
        setup=lambda d: (
            render_folder(d),
            (d / "near.toml").write_text(_rig_text(**{"pose.position_m": "[0.0967, 0, 0]"})),
        ),
    )

# ----------------------------------------------------------------------------------- score
for cid, argv, msg, setup in [
    (
        "depth-missing",
        lambda d: ["score", str(d / "nope.npy"), "--gt", str(d / "r" / "gt_depth.npy")],
        "nope.npy",
        render_folder,
    ),
    (
        "depth-empty",
        lambda d: ["score", str(d / "e.npy"), "--gt", str(d / "r" / "gt_depth.npy")],
        "empty",
        lambda d: (render_folder(d), (d / "e.npy").write_bytes(b"")),
    ),
    (
        "depth-png",
        lambda d: ["score", str(d / "r" / "capture.png"), "--gt", str(d / "r" / "gt_depth.npy")],
        ("capture.png", "float metres with NaN holes"),
        render_folder,
    ),
    (
        "depth-truncated",
        lambda d: ["score", str(d / "t.npy"), "--gt", str(d / "r" / "gt_depth.npy")],
        "t.npy",
        lambda d: (render_folder(d), (d / "t.npy").write_bytes((d / "r" / "gt_depth.npy").read_bytes()[:200])),
    ),
    (
        "depth-wrong-shape",
        lambda d: ["score", str(d / "w.npy"), "--gt", str(d / "r" / "gt_depth.npy")],
        "shape",
        lambda d: (render_folder(d), np.save(d / "w.npy", np.zeros((10, 10), np.float32))),
    ),
    (
        "gt-missing",
        lambda d: ["score", str(d / "r" / "depth.npy"), "--gt", str(d / "nope.npy")],
        "nope.npy",
        render_folder,
    ),
    (  # a second audit: .exr was read as .npy ("not a NumPy .npy file")
        "gt-exr-not-exr",
        lambda d: ["score", str(d / "r" / "depth.npy"), "--gt", str(d / "g.exr")],
        ("g.exr", "not a readable OpenEXR file"),
        lambda d: (render_folder(d), (d / "g.exr").write_text("depth\n")),
    ),
    (  # a new user's audit (2026-11-30): a 16-bit PNG depth read "not a NumPy .npy file"
        "depth-png16",
        lambda d: ["score", str(d / "d.png"), "--gt", str(d / "r" / "gt_depth.npy")],
        ("d.png", "float metres with NaN holes", "millimetres in a 16-bit PNG"),
        lambda d: (render_folder(d), cv2.imwrite(str(d / "d.png"), np.full((120, 160), 1000, np.uint16))),
    ),
    (
        "gt-exr-three-channels",
        lambda d: ["score", str(d / "r" / "depth.npy"), "--gt", str(d / "g.exr")],
        ("g.exr", "3 channels; a depth map has one"),
        lambda d: (render_folder(d), save_exr(d / "g.exr", np.ones((120, 160, 3), np.float32))),
    ),
    (
        "gt-3d",
        lambda d: ["score", str(d / "r" / "depth.npy"), "--gt", str(d / "g.npy")],
        "2-D",
        lambda d: (render_folder(d), np.save(d / "g.npy", np.zeros((2, 3, 4), np.float32))),
    ),
    # issue 33: exit 0 with "completeness nan % of 0 pixels"; a complex map with a warning; a
    # structured dtype as an internal error; a ground truth overwritten in its recording folder
    (
        "gt-all-nan",
        lambda d: ["score", str(d / "r" / "depth.npy"), "--gt", str(d / "g.npy")],
        "no finite depth",
        lambda d: (render_folder(d), np.save(d / "g.npy", np.full((120, 160), np.nan, np.float32))),
    ),
    (
        "depth-complex",
        lambda d: ["score", str(d / "c.npy"), "--gt", str(d / "r" / "gt_depth.npy")],
        "real numbers",
        lambda d: (render_folder(d), np.save(d / "c.npy", np.ones((120, 160), np.complex64))),
    ),
    (
        "depth-structured",
        lambda d: ["score", str(d / "c.npy"), "--gt", str(d / "r" / "gt_depth.npy")],
        "real numbers",
        lambda d: (render_folder(d), np.save(d / "c.npy", np.zeros((120, 160), [("a", "f4"), ("b", "i2")]))),
    ),
    (
        "gt-replaced-in-its-folder",
        lambda d: ["score", str(d / "r" / "depth.npy"), "--gt", str(d / "r" / "gt_depth.npy")],
        "mixes files of two renders",
        lambda d: (render_folder(d), np.save(d / "r" / "gt_depth.npy", np.full((120, 160), 1.2, np.float32))),
    ),
    (  # issue 33 audit: only gt_depth.npy was checked, and only in proposed folders
        "lit-replaced-in-its-folder",
        lambda d: ["score", str(d / "r" / "depth.npy"), "--gt", str(d / "r" / "gt_depth.npy")],
        "mixes files of two renders",
        lambda d: (render_folder(d), _relist(d / "r", "gt_lit", "gt_lit.npy", np.zeros((120, 160), bool))),
    ),
    (
        "competitor-truth-replaced",
        lambda d: ["score", str(d / "r" / "depth.npy"), "--gt", str(d / "rec" / "gt_depth.npy")],
        "mixes files of two renders",
        lambda d: (
            render_folder(d),
            _recording(d, {"device": "tof"}, {"gt_depth.npy": _npy(np.ones((120, 160), np.float32))}),
            (d / "rec" / "gt_depth.npy").unlink(),
            np.save(d / "rec" / "gt_depth.npy", np.full((120, 160), 2.0, np.float32)),
        ),
    ),
    (
        "lit-region-empty",
        lambda d: ["score", str(d / "r" / "depth.npy"), "--gt", str(d / "r" / "gt_depth.npy")],
        "no pixel to score",
        lambda d: (render_folder(d), np.save(d / "r" / "gt_lit.npy", np.zeros((120, 160), bool))),
    ),
    (
        "period-zero",
        lambda d: ["score", str(d / "r" / "depth.npy"), "--gt", str(d / "r" / "gt_depth.npy"), "--period", "0"],
        "--period",
        render_folder,
    ),
    (
        "period-negative",
        lambda d: ["score", str(d / "r" / "depth.npy"), "--gt", str(d / "r" / "gt_depth.npy"), "--period", "-21"],
        "--period",
        render_folder,
    ),
    (
        "period-nan",
        lambda d: ["score", str(d / "r" / "depth.npy"), "--gt", str(d / "r" / "gt_depth.npy"), "--period", "nan"],
        "--period",
        render_folder,
    ),
    (
        "edge-band-negative",
        lambda d: ["score", str(d / "r" / "depth.npy"), "--gt", str(d / "r" / "gt_depth.npy"), "--edge-band", "-3"],
        "--edge-band",
        render_folder,
    ),
    (
        "lit-wrong-shape",
        lambda d: [
            "score",
            str(d / "r" / "depth.npy"),
            "--gt",
            str(d / "r" / "gt_depth.npy"),
            "--lit",
            str(d / "w.npy"),
        ],
        "shape",
        lambda d: (render_folder(d), np.save(d / "w.npy", np.ones((5, 5), bool))),
    ),
    (
        "column-wrong-shape",
        lambda d: [
            "score",
            str(d / "r" / "depth.npy"),
            "--gt",
            str(d / "r" / "gt_depth.npy"),
            "--column",
            str(d / "w.npy"),
        ],
        "shape",
        lambda d: (render_folder(d), np.save(d / "w.npy", np.ones((5, 5), np.float32))),
    ),
    (
        "pickled-object-array",
        lambda d: ["score", str(d / "o.npy"), "--gt", str(d / "r" / "gt_depth.npy")],
        "o.npy",
        lambda d: (render_folder(d), np.save(d / "o.npy", np.array([{"a": 1}], dtype=object), allow_pickle=True)),
    ),
]:
    case(f"score-{cid}", argv, msg, setup=setup)

# ------------------------------------------------------------------------------ competitor


def _recording(d: Path, device: dict, files: dict | None = None) -> None:
    from simbench.io import save_json
    from simbench.manifest import seal_manifest

    rec = d / "rec"
    rec.mkdir()
    for name, content in (files or {}).items():
        (rec / name).write_bytes(content)
    save_json(rec / "device.json", seal_manifest(rec, device, {Path(n).stem: n for n in files or {}}))


for cid, argv, msg in [
    (
        "render-unknown-system",
        lambda d: ["render", "--system", "kinect2", str(SCENES / "white_plane.toml"), "--out", str(d / "o")],
        ("kinect2", "'proposed', 'kinect', 'tof'"),
    ),
    (
        "render-scene-missing",
        lambda d: ["render", "--system", "kinect", str(d / "nope.toml"), "--out", str(d / "o")],
        "nope.toml",
    ),
    (
        "render-spp-zero",
        lambda d: ["render", "--system", "tof", str(SCENES / "white_plane.toml"), "--out", str(d / "o"), "--spp", "0"],
        "--spp",
    ),
    (
        "render-seed-negative",
        lambda d: [
            "render",
            "--system",
            "tof",
            str(SCENES / "white_plane.toml"),
            "--out",
            str(d / "o"),
            "--seed",
            "-1",
        ],
        "--seed",
    ),
    ("decode-folder-missing", lambda d: ["decode", str(d / "nope"), "--out", str(d / "x.npy")], "nope"),
    ("decode-out-not-npy", lambda d: ["decode", str(d / "rec"), "--out", str(d / "x.png")], "--out"),
]:
    case(
        f"system-{cid}",
        argv,
        msg,
        setup=(lambda d: _recording(d, {"device": "tof"})) if "rec" in cid or "not-npy" in cid else None,
    )
case(  # a new user's audit: the rig was announced as an override and changed only the point cloud
    "system-decode-rig-for-a-factory-calibrated-device",
    lambda d: ["decode", str(d / "rec"), "--rig", str(d / "r.toml"), "--out", str(d / "x.npy")],
    ("--rig applies to systems decoding with the scene's rig", "tof", "factory calibration"),
    setup=lambda d: (_recording(d, {"device": "tof"}), (d / "r.toml").write_text(TINY_RIG)),
)
case(
    "system-decode-device-json-invalid",
    lambda d: ["decode", str(d / "rec"), "--out", str(d / "x.npy")],
    "device.json",
    setup=lambda d: ((d / "rec").mkdir(), (d / "rec" / "device.json").write_text("{")),
)
case(
    "system-decode-device-unknown",
    lambda d: ["decode", str(d / "rec"), "--out", str(d / "x.npy")],
    ("unknown depth system", "lidar"),
    setup=lambda d: _recording(d, {"device": "lidar"}),
)
case(
    "system-decode-ir-empty",
    lambda d: ["decode", str(d / "rec"), "--out", str(d / "x.npy")],
    "empty",
    setup=lambda d: _recording(d, {"device": "kinect"}, {"ir.png": b"", "reference.png": b""}),
)
case(
    "system-decode-taps-missing",
    lambda d: ["decode", str(d / "rec"), "--out", str(d / "x.npy")],
    "taps.npy",
    setup=lambda d: _recording(d, {"device": "tof"}),
)
case(
    "system-decode-taps-wrong-shape",
    lambda d: ["decode", str(d / "rec"), "--out", str(d / "x.npy")],
    "shape",
    setup=lambda d: (
        _recording(d, {"device": "tof"}),
        np.save(d / "rec" / "taps.npy", np.zeros((4, 4, 4), np.float32)),
    ),
)


def _npy(a: np.ndarray) -> bytes:
    import io

    buf = io.BytesIO()
    np.save(buf, a)
    return buf.getvalue()


case(  # sealed, so the writer itself wrote them (read noise makes dim taps negative: legal; NaN is not)
    "system-decode-taps-nan",
    lambda d: ["decode", str(d / "rec"), "--out", str(d / "x.npy")],
    "finite electron counts",
    setup=lambda d: _recording(d, {"device": "tof"}, {"taps.npy": _npy(np.full((144, 176, 4), np.nan, np.float32))}),
)
case(
    "system-decode-taps-shifted-after-recording",
    lambda d: ["decode", str(d / "rec"), "--out", str(d / "x.npy")],
    "not the file recorded",
    setup=lambda d: (
        _recording(
            d, {"device": "tof"}, {"taps.npy": _npy(np.arange(144 * 176 * 4, dtype=np.float32).reshape(144, 176, 4))}
        ),
        np.save(d / "rec" / "taps.npy", np.roll(np.load(d / "rec" / "taps.npy"), 5, axis=1)),
    ),
)

# ------------------------------------------------------------------- bench, reproduce, ablate, demo, crosstalk
for cid, argv, msg in [
    ("bench-repeats-zero", ["bench", "--repeats", "0"], "--repeats"),
    ("bench-max-ms-zero", ["bench", "--repeats", "1", "--max-ms", "0"], "--max-ms"),
    ("bench-device-unknown", ["bench", "--device", "lidar"], "--device"),
    ("bench-scene-unknown", ["bench", "--scene", "bust"], "--scene"),
    ("bench-competitor-shadow", ["bench", "--device", "tof", "--scene", "shadow", "--repeats", "1"], "only the plane"),
    ("reproduce-unknown-target", ["reproduce", "table2"], "table2"),
    ("reproduce-spp-zero", ["reproduce", "--spp", "0"], "--spp"),
    ("reproduce-seed-negative", ["reproduce", "--seed", "-1"], "--seed"),
    ("reproduce-repeats-zero", ["reproduce", "--repeats", "0"], "--repeats"),
    ("reproduce-margin-negative", ["reproduce", "--margin", "-1"], "--margin"),
    # a second audit: ignored without a word
    (
        "reproduce-margin-without-write",
        ["reproduce", "table1", "--margin", "0.5"],
        "--margin applies to --write-thresholds",
    ),
    ("reproduce-sensor-unknown", ["reproduce", "table1", "--sensor", "flea4"], "unknown sensor"),
    ("reproduce-decoder-bad", ["reproduce", "table1", "--decoder", "voting=maybe"], "voting"),
    ("reproduce-check-missing", ["reproduce", "table1", "--check", "nope.toml"], "nope.toml"),
    ("ablate-file-missing", ["ablate", "nope.toml"], "nope.toml"),
    ("ablate-unknown-study", ["ablate", "periods"], "built-in"),
    ("ablate-workers-zero", ["ablate", "period", "--workers", "0"], "--workers"),
    # a new user's audit: two studies of one name wrote one csv, md, png and run log
    ("ablate-one-name-twice", ["ablate", "period", "period"], ("are both the study 'period'", "overwrite")),
    # a second audit: 'builtin' beside a study read as a file named builtin; --scheduler took --workers
    ("ablate-builtin-and-its-study", ["ablate", "builtin", "period"], ("'builtin' runs every built-in", "period")),
    ("ablate-builtin-twice", ["ablate", "builtin", "builtin"], "'builtin' runs every built-in"),
    (
        "ablate-workers-and-scheduler",
        ["ablate", "period", "--workers", "2", "--scheduler", "tcp://127.0.0.1:9"],
        "--workers and --scheduler",
    ),
    ("demo-spp-zero", ["demo", "--spp", "0"], "--spp"),
    ("demo-seed-word", ["demo", "--seed", "x"], "--seed"),
    ("demo-unknown-scene", ["demo", "--out", "demo", "--scenes", "white_plane", "no_such_scene"], "no_such_scene"),
    ("demo-sensor-unknown", ["demo", "--out", "demo", "--sensor", "flea4"], "unknown sensor"),
    # issue 33: a scene name read ../../x.toml and wrote x.png outside --out
    ("demo-scene-traversal", ["demo", "--out", "demo", "--scenes", "../../../elsewhere/evil"], "not a name of scenes/"),
    ("demo-scene-absolute", ["demo", "--out", "demo", "--scenes", "/etc/passwd"], "not a name of scenes/"),
    ("demo-scene-dotdot", ["demo", "--out", "demo", "--scenes", ".."], "not a name of scenes/"),
    ("demo-scene-empty", ["demo", "--out", "demo", "--scenes", ""], "not a name of scenes/"),
    # the second audit: --scenes with no names ran the four default scenes
    ("demo-scenes-none", ["demo", "--out", "demo", "--scenes"], "--scenes: expected at least one argument"),
    ("no-command", [], "required"),
    ("unknown-command", ["calibrate2"], "calibrate2"),
]:
    case(cid, lambda d, a=argv: list(a), msg)
case(
    "reproduce-check-invalid",
    lambda d: ["reproduce", "table1", "--check", str(d / "t.toml")],
    "max or min",
    files={"t.toml": '["a/b"]\nmeasured = 1\n'},
)
case(
    "reproduce-check-unknown-target",  # issue 33: reported only after the run
    lambda d: ["reproduce", "table1", "--quick", "--check", str(d / "t.toml")],
    "'table2/white/gt_mae_mm' is not made by the targets",
    files={"t.toml": '["table2/white/gt_mae_mm"]\nmax = 1\n'},
)
case(
    "reproduce-check-metric-of-another-target",
    lambda d: ["reproduce", "table1", "--quick", "--check", str(d / "t.toml")],
    "not made by the targets",
    files={"t.toml": '["fig9/x/rmse_mm"]\nmax = 1\n'},
)
case(  # a second audit: failed only after printing every table
    "crosstalk-out-a-folder",
    lambda d: ["crosstalk", "--out", str(d / "dir")],
    "is a folder",
    setup=lambda d: (d / "dir").mkdir(),
)
case(
    "reproduce-write-thresholds-a-folder",  # issue 33: wrote every result, then failed
    lambda d: ["reproduce", "table1", "--quick", "--write-thresholds", str(d / "dir")],
    "is a folder",
    setup=lambda d: (d / "dir").mkdir(),
)
# issue 33: an empty --out was the working folder to demo, reproduce and ablate (files written there)
for cid, argv in [
    ("pattern", ["pattern", "--out", ""]),
    ("render", ["render", str(SCENES / "white_plane.toml"), "--out", ""]),
    ("demo", ["demo", "--out", ""]),
    ("reproduce", ["reproduce", "table1", "--quick", "--out", ""]),
    ("ablate", ["ablate", "period", "--out", ""]),
    ("crosstalk", ["crosstalk", "--out", ""]),
    ("reproduce-check", ["reproduce", "table1", "--quick", "--check", ""]),
    ("calibrate", ["calibrate", "--out", ""]),
    ("render-cache", ["render", str(SCENES / "white_plane.toml"), "--out", "o", "--cache", ""]),
]:
    case(f"{cid}-empty-path", lambda d, a=argv: list(a), "an empty path")
case("crosstalk-out-under-a-file", lambda d: ["crosstalk", "--out", str(d / "f" / "c.md")], "f", files={"f": "x"})
for cid, body, msg in [
    ("unknown-parameter", 'name = "s"\n[[axis]]\nname = "decoder.votes"\nvalues = [1]\n', "unknown sweep parameter"),
    ("axis-without-values", 'name = "s"\n[[axis]]\nname = "decoder.voting"\n', "axis 1"),
    ("no-axis", 'name = "s"\n', "at least one"),
    (
        "combine-unknown",
        'name = "s"\ncombine = "cartesian"\n[[axis]]\nname = "decoder.voting"\nvalues = [true]\n',
        "combine",
    ),
    ("repeats-zero", 'name = "s"\nrepeats = 0\n[[axis]]\nname = "decoder.voting"\nvalues = [true]\n', "repeats"),
    ("repeats-bool", 'name = "s"\nrepeats = true\n[[axis]]\nname = "decoder.voting"\nvalues = [true]\n', "repeats"),
    ("seed-negative", 'name = "s"\nseed = -1\n[[axis]]\nname = "decoder.voting"\nvalues = [true]\n', "seed"),
    ("seed-string", 'name = "s"\nseed = "x"\n[[axis]]\nname = "decoder.voting"\nvalues = [true]\n', "seed"),
    (
        "plot-metric-unknown",
        'name = "s"\nplot_metric = "beauty"\n[[axis]]\nname = "decoder.voting"\nvalues = [true]\n',
        "plot_metric",
    ),
    ("name-with-spaces", 'name = "my sweep"\n[[axis]]\nname = "decoder.voting"\nvalues = [true]\n', "sweep name"),
    (
        "axis-twice",
        'name = "s"\n[[axis]]\nname = "decoder.voting"\nvalues = [true]\n[[axis]]\nname = "decoder.voting"\nvalues = '
        "[false]\n",
        "twice",
    ),
    ("not-toml", "name = [", "not valid TOML"),
    (  # a fourth audit: the base value was dropped without a word
        "base-and-axis",
        'name = "s"\n[base]\n"decoder.voting" = false\n[[axis]]\nname = "decoder.voting"\nvalues = [true]\n',
        "both in [base] and as an [[axis]]",
    ),
    # issue 33: values that validate nowhere but in the run gave exit 0 and "1 runs (1 failed)"
    ("voting-maybe", 'name = "s"\n[[axis]]\nname = "decoder.voting"\nvalues = [true, "maybe"]\n', "voting"),
    ("spp-zero", 'name = "s"\n[[axis]]\nname = "run.spp"\nvalues = [4, 0]\n', "run.spp"),
    ("spp-nan", 'name = "s"\n[[axis]]\nname = "run.spp"\nvalues = [4, nan]\n', "run.spp"),
    ("spp-float", 'name = "s"\n[[axis]]\nname = "run.spp"\nvalues = [4.5]\n', "run.spp"),
    ("scene-depth-1e308", 'name = "s"\n[[axis]]\nname = "scene.depth_m"\nvalues = [1e308]\n', "scene.depth_m"),
    ("scene-tilt-nan", 'name = "s"\n[[axis]]\nname = "scene.tilt_deg"\nvalues = [nan]\n', "scene.tilt_deg"),
    ("sensor-dev-zero", 'name = "s"\n[[axis]]\nname = "sensor.preset"\nvalues = ["/dev/zero"]\n', "unknown sensor"),
    ("sensor-toml-missing", 'name = "s"\n[[axis]]\nname = "sensor.preset"\nvalues = ["x.toml"]\n', "x.toml"),
    ("camera-scale-zero", 'name = "s"\n[[axis]]\nname = "run.camera_scale"\nvalues = [0.0]\n', "run.camera_scale"),
    ("rig-unknown", 'name = "s"\n[[axis]]\nname = "run.rig"\nvalues = ["guessed"]\n', "rig"),
    (  # a path is a scene file of one's own since 2026-11-30 (a new user's audit), read where the user
        # points and naming no output; one that is not there is refused by its name
        "scene-traversal",
        'name = "s"\n[[axis]]\nname = "scene.name"\nvalues = ["plane_white", "../../tmp/evil"]\n',
        "no scene file '../../tmp/evil'",
    ),
    (
        "scene-not-a-name",
        'name = "s"\n[[axis]]\nname = "scene.name"\nvalues = ["white plane"]\n',
        "not a name of scenes/",
    ),
]:
    case(
        f"ablate-sweep-{cid}",
        lambda d: ["ablate", str(d / "s.toml"), "--out", str(d / "abl")],
        msg,
        files={"s.toml": body},
    )


case(  # a fourth audit: a raw "[Errno 17] File exists"
    "ablate-out-is-a-file",
    lambda d: ["ablate", str(d / "s.toml"), "--out", str(d / "s.toml")],
    "is a file, not a folder",
    files={"s.toml": 'name = "s"\n[[axis]]\nname = "decoder.voting"\nvalues = [true]\n'},
)


# ---------------------------------------------------------------------------------- runner


def _snapshot(d: Path) -> set[str]:
    return {str(p.relative_to(d)) for p in d.rglob("*")}


def test_the_table_has_the_cases_the_issue_asked_for():
    assert len(CASES) >= 200
    assert len({c.id for c in CASES}) == len(CASES), "case ids must be unique"


@pytest.mark.parametrize("c", CASES, ids=[c.id for c in CASES])
def test_bad_input_gives_one_line_exit_2_and_no_output(c: Case, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    for name, content in c.files.items():
        p = tmp_path / name
        p.parent.mkdir(parents=True, exist_ok=True)
        (p.write_bytes if isinstance(content, bytes) else p.write_text)(content)
    if c.setup is not None:
        c.setup(tmp_path)
    argv = c.argv(tmp_path)
    before = _snapshot(tmp_path)
    rc = main(argv)
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert rc == 2, f"exit {rc}; stderr: {err!r}; stdout: {out[-500:]!r}"
    assert len(lines) == 1 and lines[0].startswith("simbench: error:"), err
    expects = (c.expect,) if isinstance(c.expect, str) else c.expect
    assert all(e in lines[0] for e in expects), f"{expects} not in {lines[0]!r}"
    assert "Traceback" not in err
    assert _snapshot(tmp_path) == before, f"left behind: {sorted(_snapshot(tmp_path) - before)}"


SAMPLE = [
    "decode-capture-empty",
    "decode-capture-truncated-png",
    "decode-capture-crc-error",
    "decode-capture-random-bytes",
    "decode--decoder-voting=maybe",
    "render-sensor-noise-string",
    "render-rig-cx-huge",
    "score-depth-png",
    "pattern--width='10000000'",
    # issue 33's process-level cases: a sparse 9.6 GiB file, an unusable Mitsuba variant, numbers
    # beyond a float, paths out of their folder, a render of nothing
    "decode-capture-npy-sparse-huge",
    "render-variant-cuda-without-gpu",
    "decode-meta-z0-overflow",
    "demo-scene-traversal",
    "ablate-sweep-sensor-dev-zero",
    "score-gt-all-nan",
    "decode-out-over-the-ground-truth",
    "render-scene-projector-scale-1e300",
    "render-scene-behind-the-camera",
    "system-decode-taps-nan",
]


def test_a_sample_in_fresh_processes(tmp_path):
    """The same cases through the installed `simbench` script: one line, exit 2, no traceback."""
    exe = Path(sys.executable).parent / "simbench"
    assert set(SAMPLE) <= {c.id for c in CASES}, "a sampled case id is not in the table"
    for c in [c for c in CASES if c.id in SAMPLE]:
        d = tmp_path / c.id.replace("/", "_")
        d.mkdir()
        for name, content in c.files.items():
            (d / name).parent.mkdir(parents=True, exist_ok=True)
            ((d / name).write_bytes if isinstance(content, bytes) else (d / name).write_text)(content)
        if c.setup is not None:
            c.setup(d)
        res = subprocess.run(
            [str(exe), *c.argv(d)],
            cwd=d,
            capture_output=True,
            text=True,
            timeout=300,
            env={**os.environ, "PYTHONWARNINGS": "default"},
        )
        lines = res.stderr.strip().splitlines()
        assert res.returncode == 2 and len(lines) == 1 and lines[0].startswith("simbench: error:"), (c.id, res.stderr)
    assert len([c for c in CASES if c.id in SAMPLE]) == len(SAMPLE)


def test_a_projector_on_another_pixel_grid_is_named_and_not_blamed_on_the_channels(tmp_path, capsys, caplog):
    """A lab user's audit (2026-11-30): a projector written on a grid half the pattern's (its focal
    length and size halved, as a DLP4500 calibrated on its 912-px native grid for an 1824-px
    pattern) was told its capture's channels were out of order, then its reference decoded 0 %.
    The capture's and the reference's fringe repeat at half the period that rig predicts: said so,
    with the rig's numbers, and not the channels; the right rig says nothing of it."""
    from simbench.cli import main

    lab = _lab_copies(render_folder(tmp_path))
    half = tmp_path / "half.toml"
    half.write_text(_rig_text(**{"projector.width_px": "228", "projector.focal_px": "278.5"}))
    argv = ["decode", str(lab / "capture.png"), "--reference", str(lab / "reference.png"), "--z0", "1.0"]
    main([*argv, "--rig", str(half), "--out", str(tmp_path / "h.npy")])
    err = capsys.readouterr().err + caplog.text
    assert (
        "capture.png: the capture's fringe repeats every 10.9 camera px along the rows, but the rig predicts 21.8"
        in err
    )
    assert "reference capture's fringe repeats every 10.9" in err and "the projector's 278.5" in err, err
    assert "channel" not in err, err
    caplog.clear()
    assert main([*argv, "--rig", str(lab / "rig.toml"), "--out", str(tmp_path / "d.npy")]) == 0
    assert "repeats every" not in capsys.readouterr().err + caplog.text


def test_calibrated_mode_with_no_reference_plane_says_nothing_checks_the_rig(tmp_path, capsys, caplog):
    """A lab user's audit (2026-11-30): rigs converted wrongly from OpenCV's stereo calibration (T's
    sign flipped, R inverted, cx and cy swapped) each decoded a lone capture 92-96 % complete and
    57-360 mm off in calibrated mode, exit 0, without a word.  Nothing in one capture can check a
    rig, so the decode says so; with a reference plane it checks (and refused each of them)."""
    from simbench.cli import main

    lab = _lab_copies(render_folder(tmp_path))
    argv = ["decode", str(lab / "capture.png"), "--rig", str(lab / "rig.toml"), "--mode", "calibrated"]
    assert main([*argv, "--out", str(tmp_path / "a.npy")]) == 0
    err = capsys.readouterr().err + caplog.text
    assert "calibrated mode with no reference plane: nothing checks the rig" in err and "--reference" in err, err
    # ... and the decode's record keeps it, beside the depth
    import json

    record = json.loads((tmp_path / "a_decode.json").read_text())
    assert any("nothing checks the rig" in w for w in record["warnings"]), record["warnings"]
    # an image records no pattern (a pattern designer's audit, 2026-11-30: a period-30 capture read as
    # period 21 decoded 88 % of its pixels 244 mm off, told only of the rig): the default is named as
    # assumed, in the warning, the decode's line and its record
    assumed = "nor the pattern, taken as the default (period 21 px, order 3, sequence 00010111, channels rgb"
    assert assumed in err, err
    assert "pattern period 21 px, order 3, sequence 00010111, channels rgb (assumed" in record["decoded"], record
    assert record["settings"]["pattern_assumed"] is True
    caplog.clear()
    assert main([*argv, "--period", "21", "--out", str(tmp_path / "p.npy")]) == 0
    err = capsys.readouterr().err + caplog.text
    assert "nothing checks the rig" in err and "nor the pattern" not in err, err
    assert json.loads((tmp_path / "p_decode.json").read_text())["settings"]["pattern_assumed"] is False
    caplog.clear()
    argv += ["--reference", str(lab / "reference.png"), "--z0", "1.0"]
    assert main([*argv, "--out", str(tmp_path / "b.npy")]) == 0
    assert "nothing checks the rig" not in capsys.readouterr().err + caplog.text
    record = json.loads((tmp_path / "b_decode.json").read_text())
    assert record["warnings"] == [] and record["settings"]["pattern_assumed"] is True
    # a recording's own capture: its folder's reference plane checks the rig (nothing to say)
    r = tmp_path / "r"
    assert (
        main(
            [
                "decode",
                str(r / "capture.png"),
                "--rig",
                str(r / "rig.toml"),
                "--mode",
                "calibrated",
                "--out",
                str(tmp_path / "c.npy"),
            ]
        )
        == 0
    )
    assert "nothing checks the rig" not in capsys.readouterr().err + caplog.text


def _lab_copies(r: Path) -> Path:
    """A render folder's capture, reference and rig copied out of it, as a lab's own files."""
    import shutil

    lab = r.parent / "lab"
    lab.mkdir()
    for name in ("capture.png", "reference.png", "rig.toml"):
        shutil.copy(r / name, lab / name)
    return lab
