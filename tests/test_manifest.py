"""Recording folders decode with what they were recorded with, or refuse (issue 33).

A folder is sealed by :mod:`simbench.manifest`: every file's SHA-256 and the manifest's own.
These tests alter one thing at a time - a field of the manifest, one file, an option on the
command line - and require a refusal with one line, never a decode with other inputs."""

from __future__ import annotations

import re

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from simbench.cli import main
from simbench.manifest import ManifestError, read_manifest, seal_manifest

from .test_bad_inputs import TINY_RIG, render_folder


def _run(argv, capsys) -> tuple[int, str, str]:
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def _folder_with_pattern(d: Path, **pattern) -> Path:
    """A sealed render folder of the tiny rig whose capture and reference were made with the
    pattern ``PatternSpec(**pattern)`` (synthetic planes at 1.1 m and 1.0 m)."""
    import tomllib

    from simbench.io import save_json, save_npy, save_png
    from simbench.pattern import PatternSpec, fringe_pattern, quantize
    from simbench.rig import rig_from_dict
    from simbench.sim.synthetic import synthetic_plane_capture
    from simbench.systems.proposed import pattern_record

    rig = rig_from_dict(tomllib.loads(TINY_RIG))
    spec = PatternSpec(size_hw=rig.projector.size_hw, **pattern)
    drive = quantize(fringe_pattern(spec)).astype(np.float32) / 255
    r = d / "r"
    r.mkdir()
    (r / "rig.toml").write_text(TINY_RIG)
    for name, z in (("capture.png", 1.1), ("reference.png", 1.0)):
        img = synthetic_plane_capture(drive, rig, point_m=(0, 0, z))[0]
        save_png(r / name, np.round(np.clip(img, 0, 1) * 255).astype(np.uint8))
    save_npy(r / "gt_depth.npy", np.full((120, 160), 1.1, np.float32))
    names = {"capture": "capture.png", "reference": "reference.png", "rig": "rig.toml", "gt_depth": "gt_depth.npy"}
    meta = {"system": "proposed", "pattern": pattern_record(spec), "reference_depth_m": 1.0}
    save_json(r / "meta.json", seal_manifest(r, meta, names))
    return r


def test_a_folder_decodes_with_its_recorded_pattern(tmp_path, capsys):
    """A render made with another window length (order 4, 16 stripes a cycle) decoded with no
    pattern option: as recorded (it decoded at the defaults before, 66 % and 5.9 mm RMSE, exit 0).
    An option that contradicts the recording is an error; one that agrees is accepted."""
    r = _folder_with_pattern(tmp_path, order=4)
    rc, out, err = _run(["decode", r, "--out", tmp_path / "d.npy"], capsys)
    assert rc == 0, err
    depth = np.load(tmp_path / "d.npy")
    ok = np.isfinite(depth)
    # 160x120 synthetic planes: ~94 % at ~1.1 mm (decoded with the defaults: see below)
    assert ok.mean() > 0.9 and np.abs(depth[ok] - 1.1).mean() < 2e-3, (ok.mean(), np.nanmean(np.abs(depth - 1.1)))
    # the same images outside the folder, decoded with the default pattern (what happened before)
    for name in ("capture.png", "reference.png", "rig.toml"):
        (tmp_path / name).write_bytes((r / name).read_bytes())
    argv = [
        "decode",
        tmp_path / "capture.png",
        "--rig",
        tmp_path / "rig.toml",
        "--reference",
        tmp_path / "reference.png",
    ]
    rc, _, err = _run([*argv, "--out", tmp_path / "wrong.npy"], capsys)
    # the reference, decoded with the wrong pattern, reads its windows out of succession
    # (code_succession_doubt; before it, it failed to triangulate to Z0)
    assert rc == 2 and "neighbouring stripes of the reference capture read successive" in err, err
    assert not (tmp_path / "wrong.npy").exists()
    for option, value in (("--order", "3"), ("--period", "25"), ("--channels", "grb"), ("--sequence", "00010111")):
        rc, _, err = _run(["decode", r, "--out", tmp_path / "x.npy", option, value], capsys)
        assert rc == 2 and f"{option} {value} contradicts the recording" in err and "order 4" in err, err
    rc, _, err = _run(["decode", r, "--out", tmp_path / "y.npy", "--order", "4", "--period", "21"], capsys)
    assert rc == 0, err
    assert not (tmp_path / "x.npy").exists()


def test_a_contradicting_z0_is_an_error_and_an_explicit_rig_is_announced(tmp_path, capsys):
    r = render_folder(tmp_path)
    rc, _, err = _run(["decode", r, "--out", tmp_path / "d.npy", "--z0", "1.2"], capsys)
    assert rc == 2 and "--z0 1.2 contradicts" in err and "Z0 = 1.0 m" in err
    rc, _, err = _run(["decode", r, "--out", tmp_path / "d.npy", "--decoder", "z0_m=1.2"], capsys)
    assert rc == 2 and "--decoder z0_m=1.2 contradicts" in err and "Z0 = 1.0 m" in err, err
    (tmp_path / "calibrated.toml").write_text(TINY_RIG)
    rc, out, err = _run(["decode", r, "--out", tmp_path / "d.npy", "--rig", tmp_path / "calibrated.toml"], capsys)
    assert rc == 0 and "overriding the recording: rig" in out and "calibrated.toml" in out, (out, err)


def test_outputs_never_overwrite_a_recordings_files(tmp_path, capsys):
    """``decode --out FOLDER/gt_depth.npy`` overwrote the ground truth; later decode and score
    did not notice."""
    r = render_folder(tmp_path)
    before = {p.name: p.read_bytes() for p in r.iterdir()}
    for args in (
        ["--out", r / "gt_depth.npy"],
        ["--out", r / "gt_depth.npy", "--ply", tmp_path / "p.ply"],
        ["--out", r / "capture.png.npy", "--debug-dir", r],
    ):
        rc, _, err = _run(["decode", r, *args], capsys)
        assert rc == 2 and ("a file of the recording" in err or "a recording's folder" in err), err
    assert {p.name: p.read_bytes() for p in r.iterdir()} == before
    rc, _, err = _run(["decode", r, "--out", r / "depth2.npy"], capsys)  # a new file in the folder is fine
    assert rc == 0, err


def test_a_reference_of_another_rig_is_refused(tmp_path, capsys):
    """A reference plane captured with a 0.120 m baseline decoded against a 0.093 m rig's
    capture: 100 % decoded at 389 mm MAE before."""
    from .test_bad_inputs import _rig_text, _seal

    a = render_folder(tmp_path / "a" if (tmp_path / "a").mkdir() is None else None)
    b = render_folder(tmp_path / "b" if (tmp_path / "b").mkdir() is None else None)
    (b / "rig.toml").write_text(_rig_text(**{"pose.position_m": "[0.120, 0.0, 0.0]"}))
    _seal(b, reference_depth_m=1.0)
    rc, _, err = _run(["decode", a, "--reference", b / "reference.png", "--out", tmp_path / "d.npy"], capsys)
    assert rc == 2 and "recorded with another rig" in err, err


def test_a_recorded_capture_refuses_another_rigs_file(tmp_path, capsys):
    """A new user's audit (2026-11-29): a capture recorded with a 150 mm baseline decoded in
    calibrated mode with a 93 mm rig, bare or as a folder: exit 0, 268 mm MAE.  Another device's rig
    is refused (simbench.rig.rig_differences); a close calibration of the recorded rig decodes,
    and so does the image copied out of its recording folder, with any rig.  (Here the recording
    is 93 mm and the other device 150 mm: the folder's images are the 93 mm rig's, and since
    2026-11-30 a capture given alone is also checked against its folder's reference plane.)"""
    import shutil

    from simbench.rig import load_rig, rig_differences

    from .test_bad_inputs import _rig_text

    r = render_folder(tmp_path)  # recorded with the 93 mm rig
    other = tmp_path / "wide.toml"
    other.write_text(_rig_text(**{"pose.position_m": "[0.150, 0.0, 0.0]"}))
    for capture in (r / "capture.png", r):
        rc, _, err = _run(
            ["decode", capture, "--rig", other, "--mode", "calibrated", "--out", tmp_path / "d.npy"], capsys
        )
        assert rc == 2 and "another rig than" in err and "baseline 150.0 mm against 93.0" in err, err
        assert not (tmp_path / "d.npy").exists()
    # a close calibration of the recorded rig (0.2 mm, 0.1 % of the focal length, 0.01 deg off:
    # its reference plane within the 0.5 % that passes without a word)
    near = tmp_path / "calibrated.toml"
    near.write_text(
        _rig_text(
            **{
                "pose.position_m": "[0.0932, 0.0, 0.0]",
                "pose.rotation_deg": "[0.0, 0.01, 0.0]",
                "camera.focal_px": "289.3",
            }
        )
    )
    assert rig_differences(load_rig(near), load_rig(r / "rig.toml")) == []
    rc, _, err = _run(
        ["decode", r / "capture.png", "--rig", near, "--mode", "calibrated", "--out", tmp_path / "d.npy"], capsys
    )
    assert rc == 0 and "triangulates" not in err, err
    loose = tmp_path / "loose.png"
    shutil.copyfile(r / "capture.png", loose)
    rc, _, err = _run(["decode", loose, "--rig", other, "--mode", "calibrated", "--out", tmp_path / "e.npy"], capsys)
    assert rc == 0, err


def test_rig_differences_names_each_kind_of_other_device():
    from simbench.rig import Intrinsics, Rig, rig_differences

    cam, proj = Intrinsics.centred(160, 120, 289.0), Intrinsics.centred(456, 285, 557.0)
    base = Rig(cam, proj, (0.093, 0.0, 0.0))
    assert rig_differences(base, base) == []
    cases = {
        "camera focal length": Rig(Intrinsics.centred(160, 120, 310.0), proj, (0.093, 0.0, 0.0)),
        "projector principal point": Rig(cam, Intrinsics(456, 285, 557.0, 260.0, 142.0), (0.093, 0.0, 0.0)),
        "camera 320x240": Rig(Intrinsics.centred(320, 240, 289.0), proj, (0.093, 0.0, 0.0)),
        "baseline": Rig(cam, proj, (0.093, 0.0, 0.006)),
        "turned": Rig(cam, proj, (0.093, 0.0, 0.0), (0.0, 6.0, 0.0)),
    }
    for phrase, rig in cases.items():
        found = rig_differences(rig, base)
        assert len(found) == 1 and phrase in found[0], (phrase, found)
    # within the bounds: a calibration's error, not another device
    near = Rig(Intrinsics.centred(160, 120, 292.0), proj, (0.095, 0.0, 0.001), (0.5, 0.5, 0.0))
    assert rig_differences(near, base) == []


def _truth(shape_hw):
    """A ground truth of a plane at 1 m, every pixel lit, one object."""
    from types import SimpleNamespace

    return SimpleNamespace(
        depth_m=np.ones(shape_hw, np.float32), lit=np.ones(shape_hw, bool), object_id=np.zeros(shape_hw, np.int16)
    )


def test_every_systems_folder_is_sealed(tmp_path):
    """A ToF folder had no manifest: a shifted taps.npy or a doubled modulation_hz decoded."""
    from simbench.systems.recording import read_device_info, write_device_recording
    from simbench.systems.tof import ToFModel

    model = ToFModel()
    taps = np.arange(48, dtype=np.float32).reshape(4, 3, 4)
    write_device_recording(
        tmp_path / "rec",
        "tof",
        model,
        {"taps": lambda d: (np.save(d / "taps.npy", taps), d / "taps.npy")[1]},
        gt=_truth((4, 3)),
        info={"modulation_note": "x"},
    )
    read_device_info(tmp_path / "rec", "tof", ToFModel)
    manifest = tmp_path / "rec" / "device.json"
    data = json.loads(manifest.read_text())
    field = next(k for k in data if k.endswith("_hz"))
    data[field] *= 2
    manifest.write_text(json.dumps(data))
    with pytest.raises(ManifestError, match="edited after it was written"):
        read_device_info(tmp_path / "rec", "tof", ToFModel)
    data[field] /= 2
    manifest.write_text(json.dumps(data))
    read_device_info(tmp_path / "rec", "tof", ToFModel)
    np.save(tmp_path / "rec" / "taps.npy", np.roll(taps, 1, axis=1))
    with pytest.raises(ManifestError, match="taps.npy is not the file recorded"):
        read_device_info(tmp_path / "rec", "tof", ToFModel)


# What Hypothesis alters in a sealed folder: one field of meta.json (changed, removed, or a
# table replaced by another type), or one file's bytes (a byte flipped, the file cut short or
# removed, a PNG shifted by some pixels).
_FIELDS = ["reference_depth_m", "pattern", "sha256", "files", "system", "manifest_format", "manifest_sha256"]
_FILES = ["capture.png", "reference.png", "rig.toml", "gt_depth.npy"]


@settings(max_examples=40, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(
    what=st.sampled_from(["field", "file"]),
    field=st.sampled_from(_FIELDS),
    change=st.sampled_from(["remove", "list", "number", "string", "nested"]),
    name=st.sampled_from(_FILES),
    damage=st.sampled_from(["flip", "truncate", "remove", "append"]),
    where=st.floats(0.0, 1.0),
)
def test_any_single_alteration_of_a_folder_is_refused(tmp_path_factory, what, field, change, name, damage, where):
    d = tmp_path_factory.mktemp("alter")
    r = render_folder(d)
    read_manifest(r / "meta.json")  # as written: accepted
    if what == "field":
        data = json.loads((r / "meta.json").read_text())
        if change == "remove":
            data.pop(field)
        elif change == "list":
            data[field] = [data[field]]
        elif change == "number":
            data[field] = 1.25 if data[field] != 1.25 else 2.5
        elif change == "string":
            data[field] = "x"
        else:
            data[field] = {"a": data[field]}
        (r / "meta.json").write_text(json.dumps(data))
    else:
        p = r / name
        raw = bytearray(p.read_bytes())
        if damage == "flip":
            raw[min(int(where * len(raw)), len(raw) - 1)] ^= 0x01
            p.write_bytes(bytes(raw))
        elif damage == "truncate":
            p.write_bytes(bytes(raw[: int(where * (len(raw) - 1))]))
        elif damage == "remove":
            p.unlink()
        else:
            p.write_bytes(bytes(raw) + b"\n")
    rc = main(["decode", str(r), "--out", str(d / "d.npy")])
    assert rc == 2 and not (d / "d.npy").exists()


def test_the_seal_covers_its_own_content(tmp_path):
    (tmp_path / "a.txt").write_text("a")
    sealed = seal_manifest(tmp_path, {"x": 1, "nested": {"y": [1, 2]}}, {"a": "a.txt"})
    (tmp_path / "m.json").write_text(json.dumps(sealed))
    assert read_manifest(tmp_path / "m.json")["x"] == 1
    for edit in ({"x": 2}, {"nested": {"y": [1, 3]}}, {"files": {"a": "../a.txt"}}):
        (tmp_path / "m.json").write_text(json.dumps({**sealed, **edit}))
        with pytest.raises(ManifestError):
            read_manifest(tmp_path / "m.json")
    bad = seal_manifest(tmp_path, {}, {"a": "a.txt"})
    bad["files"] = {"a": "../a.txt"}
    from simbench.manifest import _content_sha256

    bad["manifest_sha256"] = _content_sha256(bad)  # even re-sealed: a name outside the folder
    (tmp_path / "m.json").write_text(json.dumps(bad))
    with pytest.raises(ManifestError, match="not a file name in the folder"):
        read_manifest(tmp_path / "m.json")


def _tiny_plane_png(path: Path, rig_text: str, z_m: float) -> None:
    import tomllib

    from simbench.io import save_png
    from simbench.pattern import PatternSpec, fringe_pattern, quantize
    from simbench.rig import rig_from_dict
    from simbench.sim.synthetic import synthetic_plane_capture

    rig = rig_from_dict(tomllib.loads(rig_text))
    drive = quantize(fringe_pattern(PatternSpec(size_hw=rig.projector.size_hw))).astype(np.float32) / 255
    img = synthetic_plane_capture(drive, rig, point_m=(0, 0, z_m))[0]
    save_png(path, np.round(np.clip(img, 0, 1) * 255).astype(np.uint8))


def test_reference_plane_offset_against_its_closed_form(tmp_path):
    """A synthetic reference at Z decoded as if at Z0 = 1 m lies at (Z - Z0) / Z0: triangulated
    exactly (a first-order form read 1.168 m for a plane at 1.2 m)."""
    import tomllib

    from simbench.decode import DecoderParams, decode_reference, reference_plane_offset
    from simbench.io import load_image
    from simbench.pattern import PatternSpec
    from simbench.rig import rig_from_dict

    rig = rig_from_dict(tomllib.loads(TINY_RIG))
    params = DecoderParams(pattern=PatternSpec(size_hw=rig.projector.size_hw), z0_m=1.0)
    for z, tol in ((1.0, 5e-4), (1.02, 5e-4), (0.98, 5e-4), (1.1, 1e-3), (1.2, 1e-3)):
        _tiny_plane_png(tmp_path / "ref.png", TINY_RIG, z)
        ref = decode_reference(load_image(tmp_path / "ref.png"), rig=rig, params=params)
        assert reference_plane_offset(ref, rig) == pytest.approx(z - 1.0, abs=tol)


def test_a_bare_reference_of_another_rig_or_depth_is_refused(tmp_path, capsys):
    """No recording to compare rigs by: the reference is triangulated with the rig instead.  A
    0.120 m-baseline reference against the 0.093 m rig, and a --z0 that is not the plane's."""
    from .test_bad_inputs import _rig_text

    other = _rig_text(**{"pose.position_m": "[0.120, 0.0, 0.0]"})
    (tmp_path / "rig.toml").write_text(TINY_RIG)
    _tiny_plane_png(tmp_path / "cap.png", TINY_RIG, 1.1)
    _tiny_plane_png(tmp_path / "ref.png", TINY_RIG, 1.0)
    _tiny_plane_png(tmp_path / "ref_other.png", other, 1.0)
    base = ["decode", tmp_path / "cap.png", "--rig", tmp_path / "rig.toml", "--out", tmp_path / "d.npy", "--no-cache"]
    assert _run([*base, "--reference", tmp_path / "ref.png"], capsys)[0] == 0
    rc, _, err = _run([*base, "--reference", tmp_path / "ref_other.png"], capsys)
    assert rc == 2 and "not its Z0 = 1 m" in err and "captured with this rig" in err, err
    rc, _, err = _run([*base, "--reference", tmp_path / "ref.png", "--z0", "1.1"], capsys)
    assert rc == 2 and "not its Z0 = 1.1 m" in err, err
    # the projector on the other side: no ray meets its column in front of the camera (the exact
    # triangulation gives no depth there; the check said nothing of it at first)
    (tmp_path / "left.toml").write_text(_rig_text(**{"pose.position_m": "[-0.093, 0.0, 0.0]"}))
    rc, _, err = _run(
        [*base[:2], "--rig", tmp_path / "left.toml", *base[4:], "--reference", tmp_path / "ref.png"], capsys
    )
    assert rc == 2 and ("captured with this rig" in err or "decodes at only" in err), err


def test_reference_plane_offset_is_inf_when_no_ray_meets_its_column_in_front():
    """A map whose columns no ray of the rig meets in front of the camera (a projector on the
    other side) gives inf, which the check refuses, not NaN, which it reads as nothing decoded."""
    import tomllib

    from simbench.decode import ReferenceMap, reference_plane_offset
    from simbench.rig import projector_column_at_depth, rig_from_dict

    rig = rig_from_dict(tomllib.loads(TINY_RIG))
    col = projector_column_at_depth(1.0, rig).astype(np.float32)
    ref = ReferenceMap(column_px=col, expected_px=col, inverse=np.zeros((1, 1), np.float32), z0_m=1.0)
    assert reference_plane_offset(ref, rig) == pytest.approx(0.0, abs=1e-6)
    left = rig_from_dict(tomllib.loads(TINY_RIG.replace("[0.093, 0.0, 0.0]", "[-0.093, 0.0, 0.0]")))
    assert reference_plane_offset(ref, left) == float("inf")
    empty = ReferenceMap(column_px=np.full_like(col, np.nan), expected_px=col, inverse=ref.inverse, z0_m=1.0)
    assert np.isnan(reference_plane_offset(empty, rig))


def test_a_reference_a_little_off_its_z0_is_decoded_with_a_warning(tmp_path, capsys, caplog):
    """A Z0 2 % off (20 mm at 1 m) passed the 3 % check without a word and every depth was 20 mm
    off; now a warning names the plane's triangulated depth and the Z0 to give, and a Z0 that no
    option gave is called assumed."""
    (tmp_path / "rig.toml").write_text(TINY_RIG)
    _tiny_plane_png(tmp_path / "cap.png", TINY_RIG, 1.1)
    _tiny_plane_png(tmp_path / "ref.png", TINY_RIG, 1.0)
    _tiny_plane_png(tmp_path / "ref_102.png", TINY_RIG, 1.02)
    base = ["decode", tmp_path / "cap.png", "--rig", tmp_path / "rig.toml", "--out", tmp_path / "d.npy", "--no-cache"]
    rc, out, _ = _run([*base, "--reference", tmp_path / "ref.png", "--z0", "1.0"], capsys)
    assert rc == 0 and "triangulates" not in caplog.text and "Z0 = 1.0 m (assumed" not in out
    rc, out, _ = _run([*base, "--reference", tmp_path / "ref.png", "--z0", "1.02"], capsys)
    z = float(re.search(r"to Z = (\d\.\d{4}) m, not its Z0 = 1.02 m \(-\d", caplog.text).group(1))
    assert rc == 0 and z == pytest.approx(1.0, abs=1e-3), caplog.text
    assert f"give --z0 {z:.4f}" in caplog.text and "~20 mm at Z0" in caplog.text
    caplog.clear()
    rc, out, _ = _run([*base, "--reference", tmp_path / "ref_102.png"], capsys)
    assert rc == 0 and "Z0 = 1.0 m (assumed: no --z0 given)" in out, out
    z = float(
        re.search(r"to Z = (\d\.\d{4}) m, not its Z0 = 1 m \(assumed: no --z0 given\) \(\+", caplog.text).group(1)
    )
    assert z == pytest.approx(1.02, abs=1e-3), caplog.text


def test_a_reference_captured_with_another_pattern_is_refused(tmp_path, capsys):
    """A new user's audit (2026-11-30): the reference of a recording made with a 24-px period given
    to a 21-px capture was refused only because its plane happened to triangulate 13 % off Z0 (at
    24 px 3.6 %: a little less and it would have decoded with a warning).  The reference's
    recorded pattern is compared now, in both modes, for a folder's capture and a bare image."""
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    a = _folder_with_pattern(tmp_path / "a")
    b = _folder_with_pattern(tmp_path / "b", period_px=24)
    (tmp_path / "cap.png").write_bytes((a / "capture.png").read_bytes())
    for capture in (a, tmp_path / "cap.png"):
        for mode in ("reference", "calibrated"):
            argv = ["decode", capture, "--reference", b / "reference.png", "--mode", mode, "--rig", a / "rig.toml"]
            rc, _, err = _run([*argv, "--out", tmp_path / "d.npy", "--no-cache"], capsys)
            assert rc == 2 and "was captured with the pattern period 24 px" in err, err
            assert "the capture is decoded with period 21 px" in err and not (tmp_path / "d.npy").exists(), err
    # its own folder's reference, given explicitly: accepted
    argv = ["decode", a, "--reference", a / "reference.png", "--out", tmp_path / "d.npy", "--no-cache"]
    assert _run(argv, capsys)[0] == 0


def test_calibration_frames_dropped_into_a_recording_are_refused(tmp_path, capsys):
    """A new user's audit (2026-11-30): another recording's calibration frames copied into a folder
    rendered without them were used by `--robust`, without a word (given with --calibration, the
    same frames were refused for their rig).  A frame in a recording folder must be one of its
    files; copied to a folder of their own they are judged as frames given with --calibration."""
    from simbench.io import save_png
    from simbench.pattern import CALIBRATION_FRAMES

    r = _folder_with_pattern(tmp_path)
    frame = np.full((120, 160, 3), 40, np.uint8)
    for name in CALIBRATION_FRAMES:
        save_png(r / f"calibration_{name}.png", frame)
    rc, _, err = _run(["decode", r, "--robust", "--out", tmp_path / "d.npy", "--no-cache"], capsys)
    assert rc == 2 and "calibration_dark.png lies in a recording folder whose manifest does not list it" in err, err
    assert not (tmp_path / "d.npy").exists()


def test_a_rig_whose_camera_tilts_the_reference_plane_is_refused_or_warned(tmp_path, capsys, caplog):
    """A new user's audit (2026-11-30): a rig whose camera focal length was 3.8 % off left the
    reference plane's median at Z0 (the only thing checked) but tilted it -9.5 / +11.6 % across the
    image, and a chart decoded at 54 mm MAE in calibrated mode, exit 0, without a word.  The plane's
    2nd and 98th percentiles are checked against its median now: the true rig passes in silence, a
    focal length 1 % off warns (the spread named), 3.8 % off is refused (both modes)."""
    import tomllib

    from simbench.decode import DecoderParams, decode_reference, reference_plane_extent
    from simbench.io import load_image
    from simbench.pattern import PatternSpec
    from simbench.rig import rig_from_dict

    from .test_bad_inputs import _rig_text

    (tmp_path / "rig.toml").write_text(TINY_RIG)
    _tiny_plane_png(tmp_path / "cap.png", TINY_RIG, 1.1)
    _tiny_plane_png(tmp_path / "ref.png", TINY_RIG, 1.0)
    rig = rig_from_dict(tomllib.loads(TINY_RIG))
    ref = decode_reference(
        load_image(tmp_path / "ref.png"),
        rig=rig,
        params=DecoderParams(pattern=PatternSpec(size_hw=rig.projector.size_hw)),
    )
    low, med, high = reference_plane_extent(ref, rig)
    assert max(abs(low - med), abs(high - med)) < 0.004 and abs(med) < 5e-4  # (0.23 %: under the 0.5 % warning)
    spreads = {}
    for factor in (1.01, 1.038):
        text = _rig_text(**{"camera.focal_px": f"{289.0 * factor:.4f}"})
        (tmp_path / f"f{factor}.toml").write_text(text)
        low, med, high = reference_plane_extent(ref, rig_from_dict(tomllib.loads(text)))
        spreads[factor] = max(abs(low - med), abs(high - med))
    assert 0.005 < spreads[1.01] < 0.03 < spreads[1.038], spreads
    for mode in ("reference", "calibrated"):
        base = ["decode", tmp_path / "cap.png", "--reference", tmp_path / "ref.png", "--mode", mode, "--z0", "1.0"]
        base += ["--out", tmp_path / "d.npy", "--no-cache"]
        caplog.clear()
        rc, _, err = _run([*base, "--rig", tmp_path / "rig.toml"], capsys)
        assert rc == 0 and "tilted" not in caplog.text and "tilted" not in err, (caplog.text, err)
        rc, _, err = _run([*base, "--rig", tmp_path / "f1.01.toml"], capsys)
        assert rc == 0 and "tilted or bent more than 0.5 %" in caplog.text, caplog.text
        assert "(2nd - 98th percentile" in caplog.text, caplog.text
        # (a second audit: reference mode takes the camera's geometry from the reference - its depths
        # carry far less of the tilt than calibrated mode's; the warning said the same for both)
        carried = (
            "calibrated-mode depths carry that error"
            if mode == "calibrated"
            else "reference-mode depths carry far less"
        )
        assert carried in caplog.text, caplog.text
        rc, _, err = _run([*base, "--rig", tmp_path / "f1.038.toml"], capsys)
        assert rc == 2 and "tilted or bent more than 3 %" in err and "focal length" in err, err


def test_a_tof_folder_with_read_noise_below_zero_decodes(tmp_path):
    """Issue 33 audit: read noise makes dim taps negative (render scenes/sphere.toml --system tof);
    a check for non-negative taps refused every such folder."""
    from simbench.systems.recording import write_device_recording
    from simbench.systems.tof import ToFModel
    from simbench.systems import get_system

    model = ToFModel()
    rng = np.random.default_rng(0)
    taps = rng.normal(100.0, 60.0, (model.height_px, model.width_px, 4)).astype(np.float32)
    assert (taps < 0).any()
    write_device_recording(
        tmp_path / "rec",
        "tof",
        model,
        {"taps": lambda d: (np.save(d / "taps.npy", taps), d / "taps.npy")[1]},
        gt=_truth((model.height_px, model.width_px)),
        info={},
    )
    raw, _, _ = get_system("tof").read_recording(tmp_path / "rec")
    assert np.array_equal(raw, taps)


def test_a_phase_shift_recording_refuses_another_rigs_file(tmp_path, capsys):
    """The same for a system decoding with the scene's rig (phase shifting): `decode FOLDER --rig`
    of another device refused, a calibration of the recorded rig announced and decoded."""
    import dataclasses
    from types import SimpleNamespace

    from simbench.rig import save_rig
    from simbench.systems import get_system

    system = get_system("phase_shift")
    raw, cal, scene = system.bench_inputs()
    hw = scene.rig.camera.size_hw
    gt = SimpleNamespace(depth_m=np.full(hw, 1.0, np.float32), lit=np.ones(hw, bool), object_id=np.zeros(hw, np.int16))
    system.write_recording(tmp_path / "ps", raw, cal, scene=scene, gt=gt, meta={"seed": 1})
    wide = dataclasses.replace(scene.rig, position_m=(0.150, 0.0, 0.0))
    near = dataclasses.replace(scene.rig, position_m=(scene.rig.position_m[0] + 0.0005, 0.0, 0.0))
    save_rig(wide, tmp_path / "wide.toml")
    save_rig(near, tmp_path / "near.toml")
    rc, _, err = _run(["decode", tmp_path / "ps", "--rig", tmp_path / "wide.toml", "--out", tmp_path / "d.npy"], capsys)
    assert rc == 2 and "another rig than" in err and "baseline 150.0 mm" in err, err
    rc, out, err = _run(
        ["decode", tmp_path / "ps", "--rig", tmp_path / "near.toml", "--out", tmp_path / "d.npy"], capsys
    )
    assert rc == 0 and "overriding the recording: rig" in out, (out, err)


def test_calibration_frames_of_another_rig_are_refused(tmp_path, capsys):
    """`--robust --calibration FOLDER` of another rig's recording (a new user's audit, 2026-11-29:
    accepted unchallenged) is refused as another rig's --reference is; the same rig's frames pass
    this check."""
    import shutil

    from simbench.io import save_json
    from simbench.pattern import PatternSpec
    from simbench.systems.proposed import pattern_record

    from .test_bad_inputs import _rig_text

    a = render_folder(tmp_path / "a" if (tmp_path / "a").mkdir() is None else None)
    b = render_folder(tmp_path / "b" if (tmp_path / "b").mkdir() is None else None)
    frames = {f"calibration_{k}": f"calibration_{k}.png" for k in ("dark", "red", "green", "blue")}
    names = {"capture": "capture.png", "reference": "reference.png", "rig": "rig.toml", "gt_depth": "gt_depth.npy"}
    for folder, rig_text in ((a, _rig_text()), (b, _rig_text(**{"pose.position_m": "[0.120, 0.0, 0.0]"}))):
        (folder / "rig.toml").write_text(rig_text)
        for name in frames.values():
            shutil.copyfile(folder / "reference.png", folder / name)
        (folder / "meta.json").unlink()
        record = {
            "system": "proposed",
            "pattern": pattern_record(PatternSpec(size_hw=(285, 456))),
            "reference_depth_m": 1.0,
        }
        save_json(folder / "meta.json", seal_manifest(folder, record, {**names, **frames}))
    argv = ["decode", a, "--robust", "--mode", "calibrated", "--out", tmp_path / "d.npy"]
    rc, _, err = _run([*argv, "--calibration", b], capsys)
    assert rc == 2 and "calibration frame" in err and "another rig than the reference" in err, err
    rc, _, err = _run(argv, capsys)  # its own frames: past this check (what the frames hold is the decoder's affair)
    assert "another rig" not in err, err


def test_a_rig_whose_reference_plane_lands_off_its_z0_warns_in_the_words_of_the_mode(tmp_path, capsys, caplog):
    """A reference plane that triangulates with the rig 0.5-3 % off its Z0 warns; which depths
    carry the error depends on what is off - a third audit (2026-11-30) got "reference-mode depths
    carry that error" in calibrated mode, where a baseline 2.7 % long gave 26.6 mm MAE and reference
    mode 2.4 mm: each mode now names its own case."""
    from .test_bad_inputs import _rig_text

    (tmp_path / "rig.toml").write_text(TINY_RIG)
    _tiny_plane_png(tmp_path / "cap.png", TINY_RIG, 1.1)
    _tiny_plane_png(tmp_path / "ref.png", TINY_RIG, 1.0)
    (tmp_path / "long.toml").write_text(_rig_text(**{"pose.position_m": "[0.0949, 0, 0]"}))  # +2 % baseline
    for mode, carried in (
        ("calibrated", "calibrated-mode depths carry that error"),
        ("reference", "reference-mode depths carry that error"),
    ):
        caplog.clear()
        argv = ["decode", tmp_path / "cap.png", "--reference", tmp_path / "ref.png", "--mode", mode, "--z0", "1.0"]
        rc, _, err = _run([*argv, "--out", tmp_path / "d.npy", "--no-cache", "--rig", tmp_path / "long.toml"], capsys)
        assert rc == 0 and "triangulates with the rig" in caplog.text and carried in caplog.text, (caplog.text, err)
        assert ("far less" in caplog.text) == (mode == "reference")
