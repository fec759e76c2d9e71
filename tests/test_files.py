"""Decoding from files to files (simbench.systems.files, simbench.systems.proposed_files), called
as a library: what `simbench decode` runs, for an image of the paper's sensor and for a folder of
a system without a decoder of its own."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from simbench.systems import register_system, unregister_system
from simbench.systems.files import DecodeRequest, confidence_path, decode_files

from .test_systems import IdealDepthCamera


def _float_image(path: str) -> np.ndarray:
    from simbench.io import load_image

    return load_image(path).astype(np.float32) / 255


def _plane_images(tmp_path: Path) -> dict:
    """A synthetic capture of a plane at 1.1 m, its reference plane at 1.0 m and the rig."""
    from simbench.io import save_png
    from simbench.pattern import PatternSpec, fringe_pattern, quantize
    from simbench.rig import paper_rig, save_rig
    from simbench.sim.projector import transfer_curve
    from simbench.sim.synthetic import synthetic_plane_capture

    rig = paper_rig()
    drive = transfer_curve(quantize(fringe_pattern(PatternSpec())), transfer="linear")
    for name, depth in (("capture", 1.1), ("reference", 1.0)):
        img = synthetic_plane_capture(drive, rig, point_m=(0, 0, depth))[0]
        save_png(tmp_path / f"{name}.png", np.round(np.clip(img, 0, 1) * 255).astype(np.uint8))
    save_rig(rig, tmp_path / "rig.toml")
    return {
        "capture": str(tmp_path / "capture.png"),
        "reference": str(tmp_path / "reference.png"),
        "rig": str(tmp_path / "rig.toml"),
    }


def test_an_image_decodes_as_the_paper_sensor_with_its_stages(tmp_path):
    """An image file is the paper's sensor's capture: with a rig and a reference plane, the
    plane at 1.1 m decodes at 1.1 m; the confidence goes beside the depth, the stage folder
    holds the decoder's stages and names the image; nothing is cached without a cache."""
    inputs = _plane_images(tmp_path)
    request = DecodeRequest(out=str(tmp_path / "d.npy"), debug_dir=str(tmp_path / "stages"), **inputs)
    msg = decode_files(request)
    assert msg.startswith("decoded ")
    assert (
        f"reference mode, Z0 = 1.0 m (assumed: no --z0 given), reference decoded, rig {tmp_path / 'rig.toml'}, "
        "pattern period 21 px, order 3, sequence 00010111, channels rgb (assumed: no pattern option given))" in msg
    )
    depth = np.load(tmp_path / "d.npy")
    assert np.nanmedian(depth) == pytest.approx(1.1, abs=1e-3) and np.isfinite(depth).mean() > 0.95
    assert confidence_path(request) == tmp_path / "d_confidence.npy"
    assert np.load(confidence_path(request)).shape == depth.shape
    stages = json.loads((tmp_path / "stages" / "stages.json").read_text())
    assert stages["capture"] == inputs["capture"]
    assert {"column.npy", "valid.npy", "confidence.npy", "wrapped_phase.png", "depth.png"} <= set(stages["files"])


def test_an_image_without_a_rig_or_reference_is_refused_before_anything_is_written(tmp_path):
    inputs = _plane_images(tmp_path)
    with pytest.raises(ValueError, match="--rig is required"):
        decode_files(DecodeRequest(capture=inputs["capture"], out=str(tmp_path / "d.npy")))
    with pytest.raises(ValueError, match="--reference is required in reference mode"):
        decode_files(DecodeRequest(capture=inputs["capture"], rig=inputs["rig"], out=str(tmp_path / "d.npy")))
    with pytest.raises(ValueError, match="--out must name a .npy file"):
        decode_files(DecodeRequest(out=str(tmp_path / "d.png"), **inputs))
    with pytest.raises(ValueError, match="--confidence must name a .npy file"):  # an input: refused, untouched
        decode_files(DecodeRequest(out=str(tmp_path / "d.npy"), confidence=inputs["reference"], **inputs))
    np.save(tmp_path / "capture.npy", _float_image(inputs["capture"]))
    float_inputs = {**inputs, "capture": str(tmp_path / "capture.npy")}
    with pytest.raises(ValueError, match="is a file of the recording being decoded \\(or an input\\)"):
        decode_files(DecodeRequest(out=str(tmp_path / "d.npy"), confidence=float_inputs["capture"], **float_inputs))
    assert [p.name for p in tmp_path.glob("*.npy")] == ["capture.npy"]


def test_calibrated_mode_needs_no_reference(tmp_path):
    inputs = _plane_images(tmp_path)
    decode_files(
        DecodeRequest(capture=inputs["capture"], rig=inputs["rig"], mode="calibrated", out=str(tmp_path / "d.npy"))
    )
    assert np.nanmedian(np.load(tmp_path / "d.npy")) == pytest.approx(1.1, abs=2e-3)


def test_the_summary_names_the_mode_the_decoder_ran_in(tmp_path):
    """``--decoder mode=calibrated`` is the decoder's mode as much as ``--mode calibrated``: the
    summary line says the mode and Z0 the decoder ran with (it once printed ``--mode``'s
    default), no reference is asked for, and a ``--mode`` that says otherwise is refused."""
    inputs = _plane_images(tmp_path)
    out = str(tmp_path / "d.npy")
    msg = decode_files(
        DecodeRequest(capture=inputs["capture"], rig=inputs["rig"], decoder=("mode=calibrated",), out=out)
    )
    assert "calibrated mode" in msg and "reference mode" not in msg
    assert np.nanmedian(np.load(out)) == pytest.approx(1.1, abs=2e-3)
    msg = decode_files(DecodeRequest(decoder=("z0_m=1.0",), out=out, **inputs))
    assert "reference mode, Z0 = 1.0 m" in msg
    with pytest.raises(ValueError, match="--mode reference and --decoder mode=calibrated disagree"):
        decode_files(DecodeRequest(mode="reference", decoder=("mode=calibrated",), out=out, **inputs))
    # likewise Z0: --decoder z0_m= is --z0 (it decoded at 1.02 m and put the plane at 1.124 m)
    with pytest.raises(ValueError, match="--z0 1.0 and --decoder z0_m=1.02 disagree"):
        decode_files(DecodeRequest(z0_m=1.0, decoder=("z0_m=1.02",), out=out, **inputs))
    msg = decode_files(DecodeRequest(decoder=("z0_m=1.02",), out=out, **inputs))
    assert "reference mode, Z0 = 1.02 m" in msg  # an image's reference has no recorded Z0: taken as given


@pytest.fixture
def ideal_folder(tmp_path):
    """A recording folder of a system with no decode_files of its own (a test's toy system)."""
    from simbench.sim.truth import GroundTruth

    register_system("ideal_depth", IdealDepthCamera)
    system = IdealDepthCamera()
    h, w = system.model.camera.size_hw
    depth = np.full((h, w), 1.2, np.float32)
    depth[:10] = np.nan
    gt = GroundTruth(
        depth_m=depth,
        column_px=np.zeros((h, w), np.float32),
        object_id=np.zeros((h, w), np.int32),
        lit=np.isfinite(depth),
    )
    system.write_recording(tmp_path / "rec", depth, None, scene=None, gt=gt, meta={"scene": "flat"})
    yield tmp_path / "rec"
    unregister_system("ideal_depth")


def test_a_folder_decodes_its_system_way_and_refuses_the_colour_fringe_options(ideal_folder, tmp_path):
    msg = decode_files(DecodeRequest(capture=str(ideal_folder), out=str(tmp_path / "d.npy")))
    assert "; ideal depth camera)" in msg
    depth = np.load(tmp_path / "d.npy")
    assert np.isnan(depth[:10]).all() and (depth[10:] == np.float32(1.2)).all()
    # no confidence map: no file (a fourth audit: an all-zero one read as "zero confidence everywhere")
    assert not (tmp_path / "d_confidence.npy").exists() and "no confidence map (the ideal_depth system" in msg
    # ... and an earlier decode's confidence map there is removed, not left to read as this one's
    depth = np.load(tmp_path / "d.npy")
    np.save(tmp_path / "d_confidence.npy", np.ones(depth.shape, np.float32))
    np.save(tmp_path / "other_confidence.npy", np.ones((3, 3), np.float32))
    msg = decode_files(DecodeRequest(capture=str(ideal_folder), out=str(tmp_path / "d.npy")))
    assert not (tmp_path / "d_confidence.npy").exists() and "removed " in msg and "an earlier decode's" in msg
    msg = decode_files(DecodeRequest(capture=str(ideal_folder), out=str(tmp_path / "other.npy")))
    assert (tmp_path / "other_confidence.npy").exists() and "removed" not in msg  # not a map of this image
    with pytest.raises(ValueError, match="--confidence c.npy: the ideal_depth system gives no confidence map"):
        decode_files(DecodeRequest(capture=str(ideal_folder), out=str(tmp_path / "e.npy"), confidence="c.npy"))
    for given, flags in (
        ({"z0_m": 1.0, "robust": True}, "--z0, --robust apply"),
        ({"period_px": 30}, "--period applies"),
        ({"mode": "calibrated", "decoder": ("voting=false",)}, "--mode, --decoder apply"),
    ):
        with pytest.raises(ValueError, match=f"is a ideal_depth recording: {flags} to the proposed"):
            decode_files(DecodeRequest(capture=str(ideal_folder), out=str(tmp_path / "x.npy"), **given))
    # what the system cannot give is refused, not skipped
    with pytest.raises(ValueError, match="gives no confidence map"):
        decode_files(DecodeRequest(capture=str(ideal_folder), out=str(tmp_path / "x.npy"), min_confidence=1.0))
    with pytest.raises(ValueError, match="has no stage images"):
        decode_files(
            DecodeRequest(capture=str(ideal_folder), out=str(tmp_path / "x.npy"), debug_dir=str(tmp_path / "s"))
        )
    assert not (tmp_path / "x.npy").exists()
    # the recording's own files are never an output
    with pytest.raises(ValueError, match="is a file of the recording being decoded"):
        decode_files(DecodeRequest(capture=str(ideal_folder), out=str(ideal_folder / "depth.npy")))
