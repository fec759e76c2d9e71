import json
import re
from pathlib import Path

import numpy as np
import pytest

from simbench.cli import main
from simbench.cli.options import DEFAULT_CACHE
from simbench.io import load_image
from simbench.sim.mitsuba_dict import DEFAULT_SAMPLER, DEFAULT_SPP

from .conftest import SCENES


def test_pattern_command(tmp_path, capsys):
    assert main(["pattern", "--out", str(tmp_path / "p.png")]) == 0
    img = load_image(tmp_path / "p.png")
    assert img.shape == (1140, 1824, 3)
    out = capsys.readouterr().out
    # the pattern made, not the options given (None where left to their defaults: the audit's find)
    assert "p.png" in out and "period 21 px" in out and "(window 3)" in out, out
    assert main(["pattern", "--out", str(tmp_path / "q.png"), "--order", "4", "--period", "24"]) == 0
    assert "period 24 px, codes 0000100110101111 (window 4)" in capsys.readouterr().out
    # a long window's cycle is shortened (order 12: 4096 codes printed whole before)
    assert main(["pattern", "--out", str(tmp_path / "r.png"), "--order", "12"]) == 0
    out = capsys.readouterr().out
    assert "...11111111 (4096 codes) (window 12)" in out and not re.search(r"[01]{100}", out), out


@pytest.mark.parametrize(
    "argv, match",
    [
        (["decode", "missing.png", "--rig", "missing.toml", "--out", "d.npy"], "rig file not found"),
        (["render", "missing.toml", "--out", "x"], "scene file not found"),
        (["score", "nope.npy", "--gt", "gt.npy"], "file not found"),
        (["pattern", "--out", "p.png", "--period", "2"], "--period"),
        (["pattern", "--out", "p.png", "--sequence", "0101"], "repeats"),
        (["pattern", "--out", "p.png", "--sequence", "01x"], "0 and 1"),
        (["pattern", "--out", "p.png", "--channels", "rgg"], "permutation of 'rgb'"),
        (["pattern", "--out", "p.jpg"], "must end in .png"),
        (["bench", "--device", "tof", "--scene", "shadow", "--repeats", "1"], "only the plane"),
        (["bench", "--rig", "missing.toml", "--repeats", "1"], "rig file not found"),
        (["bench", "--device", "tof", "--mode", "calibrated", "--repeats", "1"], "proposed decoder"),
    ],
)
def test_errors_are_one_line_and_nonzero(tmp_path, monkeypatch, capsys, argv, match):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("simbench: error:") and match in err and "\n" not in err


def test_pattern_channels(tmp_path):
    """`--channels gbr`: code 1 green, code 0 blue, the fringe in red (OpenCV reads BGR; load_image gives RGB)."""
    assert main(["pattern", "--out", str(tmp_path / "p.png"), "--channels", "gbr"]) == 0
    import numpy as np

    img = load_image(tmp_path / "p.png").astype(int)
    assert np.abs(img[..., 1] + img[..., 2] - img[..., 0]).max() <= 1 and (img[..., 1] * img[..., 2] == 0).all()


def test_invalid_rig_field(tmp_path, capsys):
    (tmp_path / "r.toml").write_text(
        "[camera]\nwidth_px=1280\nheight_px=960\nfocal_px=0\n[projector]\nwidth_px=10\nheight_px=10\nfocal_px=5\n"
        "[pose]\nposition_m=[0.093, 0.0, 0.0]\n"
    )
    assert (
        main(["decode", str(tmp_path / "c.png"), "--rig", str(tmp_path / "r.toml"), "--out", str(tmp_path / "d.npy")])
        == 2
    )
    assert "focal_px" in capsys.readouterr().err


def _score_json(capsys, depth: Path, *, gt: Path, column: Path) -> dict:
    """`simbench score DEPTH --gt GT --column COLUMN --json`, parsed."""
    capsys.readouterr()
    assert main(["score", str(depth), "--gt", str(gt), "--column", str(column), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def _decode_render_folder(out: Path, depth: Path, *extra: str) -> int:
    """`simbench decode` of a render folder's capture with its reference and rig."""
    argv = [
        "decode",
        str(out / "capture.png"),
        "--reference",
        str(out / "reference.png"),
        "--rig",
        str(out / "rig.toml"),
    ]
    return main([*argv, "--out", str(depth), *extra])


@pytest.mark.slow
@pytest.mark.parametrize("sensor, max_mae_mm", [("minimal", 0.3), ("paper", 1.0)])
def test_render_decode_score_end_to_end(tmp_path, capsys, monkeypatch, variant, sensor, max_mae_mm):
    """The pipeline issue's bound with the minimal camera; with the physical paper model
    (distortion in rig.toml, undistorted by decode) the error grows but stays sub-millimetre."""
    import simbench.cache

    monkeypatch.setattr(simbench.cache, "PROGRESS_MIN_S", 0.0)  # every entry, on any machine
    out = tmp_path / "wp"
    assert main(["render", str(SCENES / "white_plane.toml"), "--out", str(out), "--seed", "3", "--sensor", sensor]) == 0
    # progress on the way (a cold render is silent for a minute otherwise): each costly entry made
    assert re.search(r"simbench: radiance made in \d+\.\d s \(\d+ s so far\)", capsys.readouterr().err)
    for f in (
        "capture.png",
        "reference.png",
        "gt_depth.npy",
        "gt_depth.exr",
        "gt_column.npy",
        "gt_lit.npy",
        "rig.toml",
        "meta.json",
    ):
        assert (out / f).is_file(), f
    meta = json.loads((out / "meta.json").read_text())
    assert (
        meta["seed"] == 3
        and meta["spp"] == DEFAULT_SPP
        and meta["sampler"] == DEFAULT_SAMPLER
        and meta["variant"] == variant
    )
    assert (
        _decode_render_folder(
            out, tmp_path / "d.npy", "--ply", str(tmp_path / "c.ply"), "--debug-dir", str(tmp_path / "dbg")
        )
        == 0
    )
    assert (tmp_path / "c.ply").is_file() and (tmp_path / "dbg" / "wrapped_phase.npy").is_file()
    # the cloud's colours on the ideal grid its points are on (the paper camera's lens undistorted)
    import trimesh

    from simbench.io import load_image
    from simbench.optics import undistort_image
    from simbench.rig import load_rig

    cloud = trimesh.load(tmp_path / "c.ply")
    valid = np.isfinite(np.load(tmp_path / "d.npy"))
    camera = load_rig(out / "rig.toml").camera
    assert camera.has_distortion == (sensor == "paper")
    want = undistort_image(load_image(out / "capture.png"), camera)[valid]
    assert np.array_equal(np.asarray(cloud.colors)[:, :3], want)
    m = _score_json(capsys, tmp_path / "d.npy", gt=out / "gt_depth.npy", column=tmp_path / "dbg" / "column.npy")
    assert m["mae_mm"] < max_mae_mm and m["completeness"] > 0.99 and m["stripe_order_errors"] == 0
    assert meta["sensor"]["name"] == sensor
    # the same seed gives the same capture, bit for bit: the rerun reads the render cache, whose
    # recordings are pinned to fresh ones by tests/test_cache.py, and a fresh render of a seed is
    # the same bits (tests/test_render.py; an uncached rerun here cost 18-60 s)
    argv = ["render", str(SCENES / "white_plane.toml"), "--out", str(tmp_path / "wp2"), "--seed", "3"]
    assert main([*argv, "--sensor", sensor]) == 0
    assert (out / "capture.png").read_bytes() == (tmp_path / "wp2" / "capture.png").read_bytes()


def _synthetic_recording(tmp_path):
    import numpy as np

    from simbench.pattern import PatternSpec, fringe_pattern, quantize
    from simbench.sim.projector import transfer_curve
    from simbench.rig import paper_rig
    from simbench.sim.synthetic import synthetic_plane_capture

    from .conftest import bare_files

    rig = paper_rig()
    drive = transfer_curve(quantize(fringe_pattern(PatternSpec())), transfer="linear")
    cap, ref = (synthetic_plane_capture(drive, rig, point_m=(0, 0, depth))[0] for depth in (1.1, 1.0))
    return bare_files(tmp_path, *(np.round(np.clip(img, 0, 1) * 255).astype(np.uint8) for img in (cap, ref)), rig)


def test_decode_takes_decoder_parameters(tmp_path, capsys):
    """`--decoder phase_method=ftp` reaches the decoder (a plane at 1.1 m comes out at 1.1 m);
    an unknown method is one clear line listing the valid ones."""
    import numpy as np

    args = _synthetic_recording(tmp_path)
    for method in ("ftp", "wfr"):
        out = tmp_path / f"{method}.npy"
        assert main(["decode", *args, "--out", str(out), "--decoder", f"phase_method={method}", "voting=false"]) == 0
        depth = np.load(out)
        assert np.nanmedian(depth) == pytest.approx(1.1, abs=1e-3) and np.isfinite(depth).mean() > 0.95
    assert main(["decode", *args, "--out", str(tmp_path / "x.npy"), "--decoder", "phase_method=nope"]) == 2
    err = capsys.readouterr().err
    assert "phase_method must be one of" in err and "'nope'" in err and "'ftp'" in err and "'wfr'" in err


def test_decode_writes_the_confidence_beside_the_depth_and_applies_the_operating_point(tmp_path, capsys):
    """The confidence (fringe SNR) goes beside --out (or to --confidence); --min-confidence
    turns the decoded pixels below it into holes and leaves the confidence map as it was."""
    import numpy as np

    args = _synthetic_recording(tmp_path)
    assert main(["decode", *args, "--out", str(tmp_path / "d.npy")]) == 0
    out = capsys.readouterr().out
    assert "d_confidence.npy" in out and "fringe SNR" in out and "no threshold" in out
    depth, conf = np.load(tmp_path / "d.npy"), np.load(tmp_path / "d_confidence.npy")
    assert conf.dtype == np.float32 and conf.shape == depth.shape
    assert (conf[np.isfinite(depth)] > 0).all() and (conf[~np.isfinite(depth)] == 0).all()
    cut = float(np.quantile(conf[np.isfinite(depth)], 0.5))
    argv = ["decode", *args, "--out", str(tmp_path / "e.npy"), "--confidence", str(tmp_path / "c.npy")]
    assert main([*argv, "--min-confidence", str(cut)]) == 0
    assert f"holes below {cut:g}" in capsys.readouterr().out
    kept = np.isfinite(np.load(tmp_path / "e.npy"))
    assert np.array_equal(kept, np.isfinite(depth) & (conf >= np.float32(cut)))
    assert np.array_equal(np.load(tmp_path / "c.npy"), conf)
    assert not (tmp_path / "e_confidence.npy").exists()
    for bad, match in (
        (["--confidence", str(tmp_path / "e.npy")], "--confidence"),
        (["--min-confidence", "-1"], "--min-confidence"),
        (["--confidence", args[0]], "--confidence must name a .npy file"),  # the capture: refused, untouched
        (["--confidence", str(tmp_path / "c.png")], "--confidence must name a .npy file"),
    ):
        assert main([*argv[:-2], *bad]) == 2
        assert match in capsys.readouterr().err


TINY_SCENE = """\
name = "tiny"
rig = "rig.toml"
[[object]]
type = "plane"
name = "wall"
center_m = [0.0, 0.0, 1.1]
size_m = [2.0, 2.0]
"""


def _folder_is_whole(out) -> bool:
    """Every file meta.json lists is there with the SHA-256 it records, and nothing else."""
    import hashlib

    meta = json.loads((out / "meta.json").read_text())
    listed = set(meta["files"].values()) | {"meta.json"}
    present = {p.name for p in out.iterdir()}
    return present == listed and all(
        hashlib.sha256((out / n).read_bytes()).hexdigest() == meta["sha256"][k] for k, n in meta["files"].items()
    )


@pytest.mark.slow
def test_render_killed_at_any_moment_leaves_a_whole_folder(tmp_path):
    """kill -9 of `simbench render` over an earlier render, at moments spread over its run
    (start-up, rendering, writing): the folder is always one whole render, old or new; the next
    run removes what the killed ones left beside it."""
    import signal
    import subprocess
    import sys
    import time
    from pathlib import Path

    from tests.test_bad_inputs import TINY_RIG

    (tmp_path / "rig.toml").write_text(TINY_RIG)
    (tmp_path / "s.toml").write_text(TINY_SCENE)
    exe = str(Path(sys.executable).parent / "simbench")
    out = tmp_path / "out"

    def render(seed):
        return subprocess.Popen(
            [
                exe,
                "render",
                str(tmp_path / "s.toml"),
                "--out",
                str(out),
                "--sensor",
                "ideal",
                "--spp",
                "4",
                "--seed",
                str(seed),
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )

    first = render(1)
    assert first.wait(timeout=300) == 0
    t0 = time.monotonic()
    full = render(99)
    assert full.wait(timeout=300) == 0
    duration = time.monotonic() - t0
    seeds_seen = set()
    for k, frac in enumerate((0.3, 0.5, 0.65, 0.75, 0.8, 0.85, 0.9, 0.95, 0.98)):
        p = render(100 + k)
        time.sleep(frac * duration)
        p.send_signal(signal.SIGKILL)
        p.wait(timeout=60)
        assert _folder_is_whole(out), f"killed at {frac:.2f} of a run: {sorted(x.name for x in out.iterdir())}"
        seeds_seen.add(json.loads((out / "meta.json").read_text())["seed"])
    last = render(7)
    assert last.wait(timeout=300) == 0
    assert _folder_is_whole(out) and json.loads((out / "meta.json").read_text())["seed"] == 7
    # (.cache: the render cache, the working folder's own)
    assert sorted(p.name for p in tmp_path.iterdir()) == [".cache", "out", "rig.toml", "s.toml"], (
        "a killed run's temporary folder was left"
    )


def _all_parsers():
    import argparse

    from simbench.cli import _parser

    todo, out = [_parser()], []
    while todo:
        p = todo.pop()
        out.append(p)
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction):
                todo.extend(a.choices.values())
    return out


def test_every_option_has_help_and_shows_its_default():
    import argparse

    parsers = _all_parsers()
    assert len(parsers) >= 10
    for p in parsers:
        text = p.format_help()
        for a in p._actions:
            if isinstance(a, (argparse._HelpAction, argparse._SubParsersAction)):
                continue
            name = "/".join(a.option_strings) or a.dest
            assert a.help and len(a.help) > 8, f"{p.prog} {name}: no help text"
            if (
                a.option_strings
                and not a.required
                and a.default not in (None, False)
                and not isinstance(a, argparse._StoreTrueAction)
            ):
                shown = " ".join(text.split())
                assert f"default: {a.default}" in shown or "default" in a.help, (
                    f"{p.prog} {name}: default {a.default!r} not shown"
                )


def test_help_exits_zero_and_usage_errors_are_one_line(capsys):
    assert main(["render", "--help"]) == 0
    assert "--max-depth" in capsys.readouterr().out
    assert main(["render", str(SCENES / "white_plane.toml"), "--out", "x", "--spp", "zero"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert (
        len(err) == 1
        and err[0].startswith("simbench: error: render: argument --spp")
        and "see simbench render --help" in err[0]
    )


def test_robust_preset_switches_that_a_setting_excludes_are_named_together(tmp_path, capsys):
    """A new user's audit (2026-11-30): `--robust --decoder phase_method=ftp` (the help's own
    example setting) was refused for carrier_bank, which the user never set; fixed by hand it then
    failed for centroid_correction.  One line names every preset switch the setting excludes and
    the assignments that lift them; given, the decoder is the robust one with the Fourier phase."""
    from simbench.systems.files import DecodeRequest
    from simbench.systems.proposed_folder import _decoder_params

    argv = ["decode", str(tmp_path / "nope"), "--robust", "--decoder", "phase_method=ftp", "--out", "x.npy"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "--robust sets carrier_bank=true, centroid_correction=true" in err, err
    assert "add --decoder carrier_bank=false centroid_correction=false" in err, err
    assert len(err.strip().splitlines()) == 1, err
    request = DecodeRequest(
        capture="x",
        out="x.npy",
        robust=True,
        decoder=("phase_method=ftp", "carrier_bank=false", "centroid_correction=false"),
    )
    params = _decoder_params(request)
    assert params.phase_method == "ftp" and params.unmix and params.color_normalize


def test_decode_robust_needs_the_reference_and_its_calibration_frames(tmp_path, capsys):
    """The colour-robust decoder calibrates its unmixing on the reference plane: without the
    reference or its four calibration frames, one clear line and exit 2, nothing written."""
    import numpy as np

    from simbench.io import save_png
    from simbench.rig import paper_rig, save_rig, scale_camera

    rig = scale_camera(paper_rig(), 0.25)
    save_rig(rig, tmp_path / "rig.toml")
    img = np.full(rig.camera.size_hw + (3,), 90, np.uint8)
    for name in ("c.png", "ref.png"):
        save_png(tmp_path / name, img)
    base = [
        "decode",
        str(tmp_path / "c.png"),
        "--rig",
        str(tmp_path / "rig.toml"),
        "--out",
        str(tmp_path / "d.npy"),
        "--robust",
    ]
    assert main([*base, "--mode", "calibrated"]) == 2
    assert "--reference" in capsys.readouterr().err
    assert main([*base, "--reference", str(tmp_path / "ref.png")]) == 2
    err = capsys.readouterr().err
    assert "calibration_dark.png" in err and "--calibration-frames" in err
    # --decoder overrides are checked against the decoder they change: the robust one's options
    # pass the early check (which once tried them on the paper's decoder: "needs color_normalize")
    assert main([*base, "--reference", str(tmp_path / "ref.png"), "--decoder", "albedo_flatten=true"]) == 2
    err = capsys.readouterr().err
    assert "calibration_dark.png" in err and "color_normalize" not in err
    assert main([*base[:-1], "--reference", str(tmp_path / "ref.png"), "--decoder", "albedo_flatten=true"]) == 2
    assert "albedo_flatten needs color_normalize" in capsys.readouterr().err
    # the narrow window's SNR is the stability term's fit: refused on a decoder without it
    assert main([*base[:-1], "--reference", str(tmp_path / "ref.png"), "--decoder", "narrow_snr=true"]) == 2
    assert "narrow_snr needs phase_stability" in capsys.readouterr().err
    assert not (tmp_path / "d.npy").exists()


@pytest.mark.slow
def test_render_calibration_frames_then_robust_decode(tmp_path, capsys, variant):
    """`simbench render --calibration-frames` writes the four frames beside the reference (in
    its manifest); `simbench decode --robust` finds them there and decodes a measured blue
    board (the hardest crosstalk case of Table 1) by triangulation."""
    out = tmp_path / "blue"
    assert (
        main(
            [
                "render",
                str(SCENES / "plane_measured_blue.toml"),
                "--out",
                str(out),
                "--spp",
                "4",
                "--calibration-frames",
            ]
        )
        == 0
    )
    meta = json.loads((out / "meta.json").read_text())
    for k in ("dark", "red", "green", "blue"):
        assert (out / f"calibration_{k}.png").is_file() and meta["files"][f"calibration_{k}"] == f"calibration_{k}.png"
        assert any(label.startswith("reference/") and label.endswith(f"/{k}") for label in meta["seeds"])
    assert (
        _decode_render_folder(
            out, tmp_path / "d.npy", "--robust", "--mode", "calibrated", "--debug-dir", str(tmp_path / "dbg")
        )
        == 0
    )
    m = _score_json(capsys, tmp_path / "d.npy", gt=out / "gt_depth.npy", column=tmp_path / "dbg" / "column.npy")
    assert m["completeness"] > 0.99 and m["stripe_order_errors"] == 0 and m["mae_mm"] < 0.6


def test_render_at_a_camera_scale_decodes_from_its_folder(tmp_path, capsys, variant):
    """`simbench render --camera-scale` (a new user's audit: a small, fast render needed a rig TOML
    of one's own or Python): the camera's resolution scaled with its field of view, the recording's
    rig.toml the scaled one, so that `simbench decode FOLDER` decodes it as it is, with each
    decoder; meta.json records the factor.  A quarter of the paper's camera (320x240, a 5.4-px
    camera period) decodes the white board whole (measured: 0.33 mm median error, 99.99 %)."""
    from simbench.rig import load_rig, paper_rig

    out = tmp_path / "wp"
    argv = ["render", "white_plane", "--camera-scale", "0.25", "--spp", "4", "--calibration-frames"]
    assert main([*argv, "--out", str(out), "--cache", str(tmp_path / "cache")]) == 0
    said = capsys.readouterr().out
    assert "rendered white_plane at 320x240 (--camera-scale 0.25) with" in said and "li2017@0.25x" in said
    assert load_image(out / "capture.png").shape == (240, 320, 3)
    camera, full = load_rig(out / "rig.toml").camera, paper_rig().camera
    assert camera.size_hw == (240, 320) and camera.focal_px == pytest.approx(full.focal_px / 4)
    assert json.loads((out / "meta.json").read_text())["camera_scale"] == 0.25
    for extra in ([], ["--robust"]):
        depth, dbg = tmp_path / f"d{len(extra)}.npy", tmp_path / f"dbg{len(extra)}"
        assert main(["decode", str(out), "--out", str(depth), "--debug-dir", str(dbg), *extra]) == 0
        m = _score_json(capsys, depth, gt=out / "gt_depth.npy", column=dbg / "column.npy")
        assert m["completeness"] > 0.9 and m["mae_mm"] < 1.0 and m["stripe_order_errors"] == 0


def test_render_reruns_from_the_render_cache(tmp_path, capsys, variant):
    """A second `simbench render` of the same scene, settings and seed takes every render from
    the cache and writes the same bytes; --no-cache renders and stores nothing."""
    from tests.test_bad_inputs import TINY_RIG

    (tmp_path / "rig.toml").write_text(TINY_RIG)
    (tmp_path / "s.toml").write_text(TINY_SCENE)
    base = [
        "render",
        str(tmp_path / "s.toml"),
        "--sensor",
        "paper",
        "--spp",
        "4",
        "--seed",
        "5",
        "--cache",
        str(tmp_path / "cache"),
    ]
    assert main([*base, "--out", str(tmp_path / "a")]) == 0
    first = capsys.readouterr().out
    assert main([*base, "--out", str(tmp_path / "b")]) == 0
    second = capsys.readouterr().out
    n = len(list((tmp_path / "cache").glob("*.npz")))
    import re

    # the rerun looks up fewer entries than the first run stored (a cached drive digest spares
    # building the drive, and with it the defocus depth map), and finds every one
    made = re.search(r"render cache: 0 entries read, (\d+) made", first)
    hits = re.search(r"render cache: (\d+) entries read, 0 made", second)
    assert n > 0 and made and int(made.group(1)) == n and hits and 0 < int(hits.group(1)) <= n
    for name in ("capture.png", "reference.png", "gt_depth.npy"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name
    assert main([*base[:-2], "--no-cache", "--out", str(tmp_path / "c")]) == 0
    assert len(list((tmp_path / "cache").glob("*.npz"))) == n
    assert (tmp_path / "c" / "capture.png").read_bytes() == (tmp_path / "a" / "capture.png").read_bytes()


def test_decode_keeps_the_decoded_reference(tmp_path, capsys):
    """The reference plane is decoded once and kept in the cache (issue 16): a second decode
    reads it back and writes the same depth bytes as a decode without the cache; another
    reference image, or other decoder settings, is another entry."""
    import numpy as np

    args = _synthetic_recording(tmp_path)
    cache = ["--cache", str(tmp_path / "cache")]
    outs = []
    for i, extra in enumerate((cache, cache, ["--no-cache"])):
        outs.append(tmp_path / f"d{i}.npy")
        assert main(["decode", *args, "--out", str(outs[-1]), *extra]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert (
        "reference decoded and cached" in printed[0]
        and "reference map from the cache" in printed[1]
        and "reference decoded, rig " in printed[2]
    )
    assert outs[0].read_bytes() == outs[1].read_bytes() == outs[2].read_bytes()
    entries = sorted((tmp_path / "cache").glob("reference_map-*.npz"))
    assert len(entries) == 1
    assert main(["decode", *args, "--out", str(tmp_path / "v.npy"), *cache, "--decoder", "voting=false"]) == 0
    assert len(list((tmp_path / "cache").glob("reference_map-*.npz"))) == 2
    assert np.nanmedian(np.load(outs[0])) == pytest.approx(1.1, abs=1e-3)


def test_cached_reference_key_follows_the_decoder_code(tmp_path, monkeypatch):
    """A decoded reference stored by one version of the decoder is never read by another: the
    key holds a digest of the decoder's source files."""
    import numpy as np

    from simbench.cache import RenderCache
    from simbench.decode import DecoderParams, decode_reference
    from simbench.decode import persist
    from simbench.io import load_image
    from simbench.rig import load_rig

    _synthetic_recording(tmp_path)
    rig = load_rig(tmp_path / "rig.toml")
    ref = load_image(tmp_path / "reference.png")
    cache = RenderCache(tmp_path / "cache")

    def cached(params):
        result, store = persist.lookup_decoded_reference(ref, rig=rig, params=params, cache=cache)
        store()
        return result

    got = cached(DecoderParams())
    again = cached(DecoderParams(threads=1))  # threads do not matter
    fresh = decode_reference(ref, rig=rig, params=DecoderParams())
    for a, b in (
        (got.column_px, fresh.column_px),
        (again.inverse, fresh.inverse),
        (again.expected_px, fresh.expected_px),
    ):
        assert np.array_equal(a, b, equal_nan=True)
    assert cache.hits == 1 and cache.misses == 1 and got.z0_m == fresh.z0_m and got.mixing is None
    monkeypatch.setattr(persist, "decoder_fingerprint", lambda: "another decoder")
    cached(DecoderParams())
    assert cache.misses == 2


def test_cache_info_and_prune(tmp_path, capsys):
    """``simbench cache info`` lists kinds with counts and sizes; ``prune`` removes the least
    recently used down to a size (a dry run removes nothing) and needs a bound."""
    import numpy as np

    from simbench.cache import RenderCache, cache_entries

    d = tmp_path / "c"
    cache = RenderCache(d)
    for i in range(3):
        cache.store("radiance", {"i": i}, {"a": np.zeros(50_000, np.float32)})
    cache.store("truth", {"i": 0}, {"a": np.zeros(10, np.float32)})
    assert main(["cache", "info", "--cache", str(d)]) == 0
    out = capsys.readouterr().out
    assert f"cache {d}: 4 entries" in out
    (radiance,) = [line.split() for line in out.splitlines() if line.startswith("radiance ")]
    assert radiance[1] == "3" and radiance[3] == "KiB" and float(radiance[2]) == pytest.approx(3 * 195.6, rel=0.01)

    assert main(["cache", "prune", "--cache", str(d), "--max-size", "300K", "--dry-run"]) == 0
    assert "would remove 2 entries" in capsys.readouterr().out and len(cache_entries(d)) == 4
    assert main(["cache", "prune", "--cache", str(d), "--max-size", "0.3M"]) == 0
    assert "removed 2 entries" in capsys.readouterr().out and len(cache_entries(d)) == 2
    assert main(["cache", "prune", "--cache", str(d)]) == 2
    assert "give --max-size, --unused-days or both" in capsys.readouterr().err
    assert main(["cache", "prune", "--cache", str(d), "--max-size", "lots"]) == 2
    assert "expected a size such as 500M" in capsys.readouterr().err
    # a value beginning with "-" is the option's value, checked as such (argparse alone said
    # "expected one argument" of "-1G", taking it for an option)
    assert main(["cache", "prune", "--cache", str(d), "--max-size", "-1G"]) == 2
    assert "expected a size such as 500M, 10G or 1.5GiB, got '-1G'" in capsys.readouterr().err
    assert main(["cache", "info", "--cache", str(tmp_path / "none")]) == 2
    assert "no such cache folder" in capsys.readouterr().err
    # the default folder before any render made it (a fresh checkout, this test's empty working
    # folder): an empty cache, not an error (a new user's audit, 2026-11-29)
    assert not Path(DEFAULT_CACHE).exists()
    assert main(["cache", "info"]) == 0 and "not made yet (0 entries" in capsys.readouterr().out
    assert main(["cache", "prune", "--max-size", "1G"]) == 0 and "nothing to remove" in capsys.readouterr().out
    assert not Path(DEFAULT_CACHE).exists()


@pytest.mark.parametrize(
    "argv, expect",
    [
        (["x", "--max-size", "-1G"], ["x", "--max-size=-1G"]),
        (["--near", "-inf", "--far", "-1e3"], ["--near=-inf", "--far=-1e3"]),
        (["--seed", "-1"], ["--seed=-1"]),
        (["--max-size=-1G", "-1"], ["--max-size=-1G", "-1"]),  # attached already; a bare "-1" stays
        (["-h", "-1"], ["-h", "-1"]),  # a short option is left to argparse
        (["--out", "-dir"], ["--out", "-dir"]),  # not a number: argparse's own error
    ],
)
def test_option_values_that_begin_with_a_minus_are_attached(argv, expect):
    from simbench.cli import _negative_values_attached

    assert _negative_values_attached(argv) == expect


@pytest.mark.parametrize(
    ("text", "n"), [("0", 0), ("12345", 12345), ("500M", 500 << 20), ("10g", 10 << 30), ("1.5GiB", 3 << 29)]
)
def test_cache_sizes_are_read_the_way_du_writes_them(text, n):
    from simbench.cli.options import size_bytes as _size_bytes

    assert _size_bytes(text) == n


def test_a_full_disk_is_one_line_saying_where_and_how_to_free_the_cache(tmp_path, monkeypatch, capsys):
    import errno
    import os

    def full(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    import simbench.cli as cli

    monkeypatch.setattr(os, "fsync", full)
    monkeypatch.setattr(cli, "DEFAULT_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "o"
    out.mkdir()
    assert main(["pattern", "--out", str(out / "p.png")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "No space left on device" in err and "p.png" in err
    # a command without a cache, and no cache at the default: none named (an audit: one was)
    assert "free there now)" in err and "simbench cache" not in err
    (tmp_path / "cache").mkdir()
    assert main(["pattern", "--out", str(out / "p.png")]) == 2
    err = capsys.readouterr().err
    assert "free there now" in err and f"simbench cache prune --cache {tmp_path / 'cache'}" in err
    assert not list(out.iterdir())


def test_a_closed_output_pipe_ends_quietly(tmp_path):
    """``simbench ... | head``: output to a reader that has gone stops the command without an
    error line or traceback, with the status a SIGPIPE'd program has (141)."""
    import subprocess
    import sys

    import numpy as np

    from simbench.cache import RenderCache

    RenderCache(tmp_path).store("radiance", {}, {"a": np.zeros(1)})
    exe = Path(sys.executable).parent / "simbench"
    proc = subprocess.Popen(
        [str(exe), "cache", "info", "--cache", str(tmp_path)], stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )
    proc.stdout.close()  # before the process has imported anything: its first write fails
    with proc.stderr:
        err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 141 and err == ""


def test_score_json_is_strict_json_when_nothing_decoded(tmp_path, capsys):
    """Issue 33: ``--json`` printed bare NaN (not JSON) for a depth map with no valid pixel."""
    import numpy as np

    from tests.test_bad_inputs import render_folder

    r = render_folder(tmp_path)
    np.save(tmp_path / "none.npy", np.full((120, 160), np.nan, np.float32))
    assert main(["score", str(tmp_path / "none.npy"), "--gt", str(r / "gt_depth.npy"), "--json"]) == 0
    out = capsys.readouterr().out

    def no_constants(name):
        raise AssertionError(f"{name} in --json output")

    m = json.loads(out, parse_constant=no_constants)
    assert m["completeness"] == 0 and m["mae_mm"] is None and m["n_region"] == 120 * 160


@pytest.mark.slow
def test_sigterm_ends_a_run_cleanly(tmp_path):
    """Issue 33: SIGTERM exited 143 with no message and left lock files in the cache.  Now it
    unwinds like Ctrl-C: one line, exit 143, no lock, no temporary folder, the old folder whole.
    The signal is sent while the run holds a cache lock (making an entry), twice: at the first
    lock seen and at a later one."""
    import signal
    import subprocess
    import sys
    import time
    from pathlib import Path

    from tests.test_bad_inputs import TINY_RIG

    (tmp_path / "rig.toml").write_text(TINY_RIG)
    (tmp_path / "s.toml").write_text(TINY_SCENE)
    exe = str(Path(sys.executable).parent / "simbench")

    def render(seed, cache):
        argv = [exe, "render", str(tmp_path / "s.toml"), "--out", str(tmp_path / "out"), "--overwrite"]
        argv += ["--sensor", "ideal", "--spp", "4", "--seed", str(seed), "--cache", str(tmp_path / cache)]
        return subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)

    first = render(1, "c0")
    first.communicate(timeout=300)
    assert first.returncode == 0
    for k, nth_lock in enumerate((1, 3)):
        cache = tmp_path / f"c{k + 1}"
        p = render(10 + k, cache.name)
        seen: set[str] = set()
        deadline = time.monotonic() + 120
        while len(seen) < nth_lock and p.poll() is None and time.monotonic() < deadline:
            seen |= {x.name for x in cache.glob("*.lock")} if cache.exists() else set()
            time.sleep(0.002)
        assert len(seen) >= nth_lock, "the run ended before holding the lock to interrupt"
        p.send_signal(signal.SIGTERM)
        _, err = p.communicate(timeout=120)
        assert p.returncode == 143 and err.strip().splitlines() == [
            "simbench: terminated (SIGTERM); partial outputs and cache locks removed"
        ], (p.returncode, err)
        assert not list(cache.glob("*.lock")) and not list(cache.glob(".*.tmp"))
        assert _folder_is_whole(tmp_path / "out")
    assert not [x.name for x in tmp_path.iterdir() if x.name.startswith(".out")], "a temporary folder was left"


def test_a_cache_that_cannot_take_the_reference_leaves_no_output(tmp_path, capsys, monkeypatch):
    """Issue 33: ``decode --cache`` whose entry could not be stored (an entry that is a folder,
    a read-only mount) failed with exit 2 after depth.npy was written.  A failed write leaves no
    output; a read-only cache is read (the decode goes on, its reference not stored, one warning)."""
    import errno

    import simbench.cache as cache_module
    from tests.test_bad_inputs import render_folder

    r = render_folder(tmp_path)
    out = tmp_path / "d.npy"
    argv = ["decode", str(r), "--out", str(out), "--ply", str(tmp_path / "p.ply"), "--cache", str(tmp_path / "c")]

    def failing(*args, **kwargs):
        raise OSError(errno.EIO, "Input/output error", str(tmp_path / "c" / "x.npz"))

    monkeypatch.setattr(cache_module, "atomic_write_bytes", failing)
    rc = main(argv)
    err = capsys.readouterr().err
    assert rc == 2 and "Input/output error" in err and not out.exists() and not (tmp_path / "p.ply").exists()

    def refuse(*args, **kwargs):
        raise OSError(errno.EROFS, "Read-only file system", str(tmp_path / "c" / "x.npz"))

    monkeypatch.setattr(cache_module, "atomic_write_bytes", refuse)
    assert main(argv) == 0
    err = capsys.readouterr().err
    assert "is read only (Read-only file system)" in err and out.is_file() and (tmp_path / "p.ply").is_file()


def test_a_debug_dir_is_reused_by_later_decodes(tmp_path, capsys):
    """--debug-dir writes stages.json (the folder is recognised as a decode's, with the decode's
    settings), so decoding again into it replaces its stage images and removes those it listed that
    the new decode has not; a folder of someone else's files is refused (test_bad_inputs)."""
    import json

    from tests.test_bad_inputs import render_folder

    r = render_folder(tmp_path)
    dbg = tmp_path / "dbg"
    base = ["decode", str(r), "--out", str(tmp_path / "d.npy"), "--debug-dir", str(dbg)]
    # first with a stage the second decode does not make: it must not stay behind (a new user's
    # audit found the colour-robust decoder's stages beside a later paper decode's)
    assert main([*base, "--decoder", "crease_doubt=true"]) == 0
    assert (dbg / "crease_bias.npy").is_file()
    (dbg / "notes.txt").write_text("mine")  # not the command's: kept
    assert main(base) == 0
    info = json.loads((dbg / "stages.json").read_text())
    assert not (dbg / "crease_bias.npy").exists() and (dbg / "notes.txt").read_text() == "mine"
    assert sorted(info["files"]) == sorted(p.name for p in dbg.iterdir() if p.name not in ("stages.json", "notes.txt"))
    assert info["decoded"].startswith("reference mode") and "fringe SNR" in info["confidence"]
    # the decode's settings (a fourth audit: docs/usage.md promised them, none were there)
    assert info["system"] == "proposed" and info["settings"]["rig"] == str(r / "rig.toml")
    decoder = info["settings"]["decoder"]
    assert decoder["crease_doubt"] is False and decoder["pattern"]["period_px"] == 21 and decoder["mode"] == "reference"
    assert main([*base, "--min-confidence", "2.5"]) == 0
    assert json.loads((dbg / "stages.json").read_text())["settings"]["decoder"]["min_confidence"] == 2.5


def test_after_sigterm_a_half_built_objects_finalizer_prints_nothing(capsys, monkeypatch):
    """CI saw the SIGTERM line followed by "Exception ignored in ZipFile.__del__" (a ZipFile
    whose __init__ the signal cut short).  After the termination line such finalizer errors are
    dropped; with --debug they stay."""
    import gc
    import sys
    import types

    from simbench.cli import _quiet_finalizers

    class Broken:
        def __del__(self):
            raise AttributeError("'ZipFile' object has no attribute '_writing'")

    before = sys.unraisablehook
    monkeypatch.setattr(sys, "unraisablehook", before)
    _quiet_finalizers(types.SimpleNamespace(debug=True))
    assert sys.unraisablehook is before
    _quiet_finalizers(types.SimpleNamespace(debug=False))
    assert sys.unraisablehook is not before
    Broken()
    gc.collect()
    assert capsys.readouterr().err == ""


def test_reproduce_help_names_every_target():
    """The reproduce command's help lists its targets by name (not imported, for start-up time):
    every registered target, and no other."""
    import argparse
    import re

    from simbench.cli import _parser
    from simbench.experiments.reproduce import TARGETS

    sub = next(a for a in _parser()._actions if isinstance(a, argparse._SubParsersAction))  # noqa: SLF001
    help_text = next(a.help for a in sub.choices["reproduce"]._actions if a.dest == "targets")  # noqa: SLF001
    listed = set(re.findall(r"\b[a-z][a-z0-9_]+\b", help_text.split(" or all")[0]))
    assert listed == set(TARGETS)


def test_render_says_the_sensor_models_lens_distortion_is_on_the_users_rig(tmp_path, capsys):
    """A new user's audit: their undistorted rig came back in rig.toml with the `paper` sensor's
    lens distortion, without a word; render names the coefficients it put on the rig."""
    from tests.test_bad_inputs import TINY_RIG

    (tmp_path / "rig.toml").write_text(TINY_RIG)
    (tmp_path / "s.toml").write_text(TINY_SCENE)
    argv = ["render", str(tmp_path / "s.toml"), "--out", str(tmp_path / "o"), "--cache", str(tmp_path / "c")]
    assert main([*argv, "--spp", "1"]) == 0
    out_text = capsys.readouterr().out
    assert "the sensor model's lens distortion is on rig 'tiny': camera k1 = -0.08" in out_text, out_text
    assert "projector k1 = -0.02" in out_text


def test_render_replaces_a_recording_of_any_system_and_says_so_but_never_a_foreign_folder(tmp_path, capsys):
    """A recording folder of another system (its device.json) is replaced like one of the same
    system, with a line naming what was there (the audit found it refused as "not written by this
    command", --overwrite or not); a folder simbench did not write is refused, and the message says
    that --overwrite does not change that."""
    from tests.test_bad_inputs import TINY_RIG

    (tmp_path / "rig.toml").write_text(TINY_RIG)
    (tmp_path / "s.toml").write_text(TINY_SCENE)
    out, cache = tmp_path / "out", tmp_path / "cache"

    def render(*extra):
        argv = ["render", str(tmp_path / "s.toml"), "--out", str(out), "--cache", str(cache), "--spp", "4", *extra]
        return main(argv)

    assert render("--system", "tof") == 0
    out_text = capsys.readouterr().out
    assert "replaced" not in out_text
    # the device's own rig, said (a new user's audit: their rig was set aside without a word)
    assert "own 176x144 rig: the scene's rig 'tiny' set aside" in out_text
    assert render("--sensor", "ideal") == 0
    out_text = capsys.readouterr().out
    assert "(replaced a tof recording of scene" in out_text
    assert "lens distortion is on rig" not in out_text  # the ideal sensor has no lenses of its own
    assert (out / "meta.json").is_file() and not (out / "device.json").exists()
    # each manifest names the scene alike: its name, its file and its render content's SHA-256 (a
    # fourth audit: meta.json held the name alone, device.json the path as typed)
    meta = json.loads((out / "meta.json").read_text())
    assert meta["scene"] == "tiny" and meta["scene_file"] == str(tmp_path / "s.toml")
    assert render("--system", "tof") == 0
    assert "(replaced a proposed recording of scene tiny there)" in capsys.readouterr().out
    device = json.loads((out / "device.json").read_text())
    assert device["scene"] == "tiny" and device["scene_file"] == meta["scene_file"]
    assert device["scene_sha256"] == meta["scene_sha256"] and len(meta["scene_sha256"]) == 64
    (tmp_path / "s.toml").write_text(TINY_SCENE.replace("1.1]", "1.2]"))  # the same name, another scene
    assert render("--system", "tof") == 0
    assert json.loads((out / "device.json").read_text())["scene_sha256"] != meta["scene_sha256"]
    # --overwrite over a folder holding a file of the user's: the line names what went with it
    # (a bring-your-own-decoder audit, 2026-12-05)
    np.save(out / "mydepth.npy", np.zeros((2, 2), np.float32))
    assert render("--system", "tof") == 2
    capsys.readouterr()
    assert render("--system", "tof", "--overwrite") == 0
    said = capsys.readouterr().out
    assert "of scene tiny, and with it 1 file(s) it did not record or that changed since: mydepth.npy there)" in said
    assert not (out / "mydepth.npy").exists()
    foreign = tmp_path / "mine"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("keep me")
    for extra in ((), ("--overwrite",)):
        argv = ["render", str(tmp_path / "s.toml"), "--out", str(foreign), "--system", "tof", "--no-cache", *extra]
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert "never replaces such a folder, --overwrite or not" in err, err
        assert (foreign / "notes.txt").read_text() == "keep me"


@pytest.mark.parametrize(
    "level, why",
    [(0, "the capture is dark (its brightest value 0 of 255)"), (255, "100 % of the capture's pixels are saturated")],
)
def test_a_capture_that_decodes_to_nothing_is_decoded_and_named_on_stderr(tmp_path, capsys, level, why):
    """A black or white frame is a legal image: decoded (all NaN, exit 0), but the user hears why
    nothing came out instead of a quiet "decoded 0.00 %" (the audit's find)."""
    import numpy as np

    from simbench.io import save_png
    from tests.test_bad_inputs import render_folder

    r = render_folder(tmp_path)
    save_png(tmp_path / "flat.png", np.full((120, 160, 3), level, np.uint8))
    argv = ["decode", str(tmp_path / "flat.png"), "--reference", str(r / "reference.png")]
    assert main(argv + ["--rig", str(r / "rig.toml"), "--out", str(tmp_path / "d.npy")]) == 0
    captured = capsys.readouterr()
    assert "decoded 0.00 % of the image's pixels" in captured.out
    assert f"flat.png: no pixel decoded: {why}" in captured.err, captured.err
    assert np.isnan(np.load(tmp_path / "d.npy")).all()
    # a capture that decodes says nothing of the kind
    assert main(["decode", str(r), "--out", str(tmp_path / "e.npy")]) == 0
    assert "decoded" not in capsys.readouterr().err


def test_python_m_simbench_runs_the_command_line(tmp_path):
    import subprocess
    import sys

    res = subprocess.run(
        [sys.executable, "-m", "simbench", "pattern", "--out", str(tmp_path / "p.png")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert res.returncode == 0 and "period 21 px" in res.stdout, res.stderr
    bad = subprocess.run([sys.executable, "-m", "simbench", "pattern"], capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "--out" in bad.stderr


def test_the_working_range_options_and_the_decoder_setting_cannot_disagree(tmp_path, capsys):
    """--near/--far and --decoder depth_range_m= say one thing: a pair that disagrees is refused,
    as --mode against --decoder mode= is (the audit: depth_range_m silently won); --near >= --far
    is named as such; a working range that leaves nothing decoded is named in the warning."""
    from simbench.decode import DecoderParams
    from simbench.systems.files import WORKING_RANGE_M
    from tests.test_bad_inputs import render_folder

    assert DecoderParams().depth_range_m == WORKING_RANGE_M  # the command line's defaults, the decoder's
    r = render_folder(tmp_path)
    out = str(tmp_path / "d.npy")
    argv = ["decode", str(r), "--out", out, "--decoder", "depth_range_m=[0.8, 1.5]", "--near", "1.2", "--far", "1.3"]
    assert main(argv) == 2
    assert "--near 1.2 --far 1.3 and --decoder depth_range_m=[0.8, 1.5] disagree: give one" in capsys.readouterr().err
    assert main(["decode", str(r), "--out", out, "--near", "2", "--far", "1"]) == 2
    assert "--near 2 must be less than --far 1" in capsys.readouterr().err
    assert main(["decode", str(r), "--out", out, "--near", "1.5", "--far", "1.7"]) == 0  # the plane is at 1.1 m
    assert "within the working range asked for, 1.5-1.7 m (--near, --far)" in capsys.readouterr().err
    assert main(["decode", str(r), "--out", out, "--decoder", "depth_range_m=[0.8, 1.5]"]) == 0


def test_calibration_frames_without_the_robust_decoder_are_refused(tmp_path, capsys):
    """--calibration names the colour-robust decoder's frames; without --robust they were ignored."""
    from tests.test_bad_inputs import render_folder

    r = render_folder(tmp_path)
    assert main(["decode", str(r), "--out", str(tmp_path / "d.npy"), "--calibration", str(r)]) == 2
    assert "add --robust (or --decoder unmix=true)" in capsys.readouterr().err
    assert not (tmp_path / "d.npy").exists()


def test_score_warns_of_a_depth_map_that_cannot_be_this_scene_in_metres(tmp_path, capsys):
    """All NaN, millimetres, negative: scored (the numbers say how far off), with a warning each
    (the audit: an MAE of 1,071,028 mm came without a word)."""
    import numpy as np

    gt = np.full((40, 50), 1.1, np.float32)
    np.save(tmp_path / "gt.npy", gt)
    cases = {
        "nan": (np.full_like(gt, np.nan), "holds no finite depth where the scene is scored"),
        "mm": (gt * 1000, "its median depth is 1e+03x the ground truth's (1.1 m): is it in metres"),
        "neg": (
            np.where(np.arange(50) < 5, -1.0, 1.1).astype(np.float32)[None].repeat(40, 0),
            "200 of its depths are <= 0 m",
        ),
    }
    for name, (depth, warning) in cases.items():
        np.save(tmp_path / f"{name}.npy", depth)
        assert main(["score", str(tmp_path / f"{name}.npy"), "--gt", str(tmp_path / "gt.npy")]) == 0
        assert warning in capsys.readouterr().err, name
    np.save(tmp_path / "good.npy", gt + np.float32(0.0004))
    assert main(["score", str(tmp_path / "good.npy"), "--gt", str(tmp_path / "gt.npy")]) == 0
    assert "warning" not in capsys.readouterr().err


def test_score_refuses_a_lit_mask_that_is_not_one_and_warns_of_inputs_that_are_not_what_it_asked(tmp_path, capsys):
    """A new user's audit: a float or id map as --lit was cast to bool (NaN and every non-zero
    value lit); a depth map in a recording scored against another recording's truth, and a depth
    map given as --column, went without a word."""
    import numpy as np

    from tests.test_bad_inputs import render_folder

    gt = np.full((40, 50), 1.1, np.float32)
    np.save(tmp_path / "gt.npy", gt)
    np.save(tmp_path / "d.npy", gt + np.float32(0.0004))
    base = ["score", str(tmp_path / "d.npy"), "--gt", str(tmp_path / "gt.npy")]
    for name, lit in (("float", gt), ("ids", np.arange(2000).reshape(40, 50) % 3)):
        np.save(tmp_path / f"lit_{name}.npy", lit)
        assert main([*base, "--lit", str(tmp_path / f"lit_{name}.npy")]) == 2
        assert "--lit must be a boolean mask (as gt_lit.npy)" in capsys.readouterr().err, name
    np.save(tmp_path / "lit01.npy", (np.arange(2000).reshape(40, 50) % 2).astype(np.uint8))
    assert main([*base, "--lit", str(tmp_path / "lit01.npy"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["n_region"] == 1000
    # --column given a depth map
    np.save(tmp_path / "gt_column.npy", np.full((40, 50), 900.0, np.float32))
    assert main([*base, "--column", str(tmp_path / "d.npy"), "--gt-column", str(tmp_path / "gt_column.npy")]) == 0
    assert "far below the ground truth's projector columns" in capsys.readouterr().err
    # a depth map in a recording's folder, scored against another recording's ground truth
    r = render_folder(tmp_path)
    np.save(r / "decoded.npy", gt[:1].repeat(120, 0)[:, :1].repeat(160, 1))
    other = tmp_path / "other"
    other.mkdir()
    np.save(other / "gt_depth.npy", np.full((120, 160), 1.3, np.float32))
    assert main(["score", str(r / "decoded.npy"), "--gt", str(other / "gt_depth.npy")]) == 0
    err = capsys.readouterr().err
    assert f"lies in the recording {r}, whose ground truth is not {other / 'gt_depth.npy'}" in err, err
    assert main(["score", str(r / "decoded.npy"), "--gt", str(r / "gt_depth.npy")]) == 0
    assert "warning" not in capsys.readouterr().err
    # a meta.json of the user's own beside the depth map is no recording: scored as any file
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "meta.json").write_text('{"note": "mine"}')
    np.save(mine / "d.npy", gt + np.float32(0.0004))
    assert main(["score", str(mine / "d.npy"), "--gt", str(tmp_path / "gt.npy")]) == 0
    assert "warning" not in capsys.readouterr().err
    # nor beside the ground truth (a lab's dataset folder: it was refused as "a manifest of format None")
    np.save(mine / "gt.npy", gt)
    assert main(["score", str(mine / "d.npy"), "--gt", str(mine / "gt.npy")]) == 0
    assert "warning" not in capsys.readouterr().err
    # a recording's manifest edited (its format taken out) is still refused
    meta = json.loads((r / "meta.json").read_text())
    del meta["manifest_format"]
    (r / "meta.json").write_text(json.dumps(meta))
    assert main(["score", str(r / "decoded.npy"), "--gt", str(r / "gt_depth.npy")]) == 2
    assert "a manifest of format None" in capsys.readouterr().err


def test_a_depth_decoded_into_another_recordings_folder_is_scored_as_the_recording_it_came_from(tmp_path, capsys):
    """An audit (2026-12-05): `decode A --out B/depth.npy` put A's depth in recording B's folder,
    where `score` took it for B's: scored against B's truth without a word, against A's with a
    false "another recording's truth?".  The decode record now names the decoded recording's
    ground truth (format 2), score checks --gt against it, and the decode warns of the folder."""
    import numpy as np

    from simbench.io import save_npy
    from simbench.manifest import file_sha256
    from tests.test_bad_inputs import _seal, render_folder

    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    a, b = render_folder(tmp_path / "a"), render_folder(tmp_path / "b")
    (b / "gt_depth.npy").unlink()
    save_npy(b / "gt_depth.npy", np.full((120, 160), 1.3, np.float32))
    _seal(b, reference_depth_m=1.0)  # b: another scene's truth
    out = b / "from_a.npy"
    assert main(["decode", str(a), "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert f"written into the recording {b}, but it is the depth of the recording {a.resolve()}" in err, err
    record = json.loads((b / "from_a_decode.json").read_text())
    assert record["format"] == 2 and record["ground_truth"]["recording"] == str(a.resolve())
    assert any("written into the recording" in w for w in record["warnings"])
    # scored against the folder's (b's) truth: warned, by the record; against its own (a's): not
    assert main(["score", str(out), "--gt", str(b / "gt_depth.npy")]) == 0
    err = capsys.readouterr().err
    assert f"says it is the depth of the recording {a.resolve()}, whose ground truth is not" in err, err
    assert main(["score", str(out), "--gt", str(a / "gt_depth.npy")]) == 0
    assert "warning" not in capsys.readouterr().err
    # moved elsewhere with its record, it still knows whose it is
    moved = tmp_path / "elsewhere"
    moved.mkdir()
    for name in ("from_a.npy", "from_a_decode.json"):
        (b / name).rename(moved / name)
    assert main(["score", str(moved / "from_a.npy"), "--gt", str(b / "gt_depth.npy")]) == 0
    assert "says it is the depth of the recording" in capsys.readouterr().err
    # decoded into its own folder, or outside any recording: no warning; the record still names the truth
    assert main(["decode", str(a), "--out", str(a / "mine.npy")]) == 0
    assert "written into the recording" not in capsys.readouterr().err
    assert json.loads((a / "mine_decode.json").read_text())["ground_truth"]["sha256"]["gt_depth"]
    # a map written over since the decode (another decoder's depth of b, saved over it): its record
    # is not believed, and the map is judged by the folder it lies in
    (moved / "from_a.npy").rename(b / "x.npy")
    (moved / "from_a_decode.json").rename(b / "x_decode.json")
    np.save(b / "x.npy", np.full((120, 160), 1.3, np.float32))
    assert main(["score", str(b / "x.npy"), "--gt", str(b / "gt_depth.npy")]) == 0
    assert "warning" not in capsys.readouterr().err
    # hand-edited records are not believed either, and crash nothing
    for truth in ({"sha256": {"gt_depth": "x"}}, {"recording": "r", "sha256": {"gt_depth": ["x"]}}, "r", 3):
        record = json.loads((b / "x_decode.json").read_text())
        record["depth"]["sha256"] = file_sha256(b / "x.npy")
        record["ground_truth"] = truth
        (b / "x_decode.json").write_text(json.dumps(record))
        assert main(["score", str(b / "x.npy"), "--gt", str(b / "gt_depth.npy")]) == 0, truth
        assert "warning" not in capsys.readouterr().err
    # a bare capture (outside any recording) decoded into b: the decode warns, and so does score
    bare = tmp_path / "bare"
    bare.mkdir()
    for name in ("capture.png", "reference.png", "rig.toml"):
        (bare / name).write_bytes((a / name).read_bytes())
    argv = ["decode", str(bare / "capture.png"), "--reference", str(bare / "reference.png"), "--rig"]
    assert main([*argv, str(bare / "rig.toml"), "--z0", "1.0", "--out", str(b / "y.npy")]) == 0
    assert "but it is the depth of a capture outside any recording" in capsys.readouterr().err
    assert json.loads((b / "y_decode.json").read_text())["ground_truth"] is None
    assert main(["score", str(b / "y.npy"), "--gt", str(b / "gt_depth.npy")]) == 0
    assert "a capture outside any recording: is it this recording's depth?" in capsys.readouterr().err
    # a folder with a meta.json of the user's own is no recording: decoded into without a word
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "meta.json").write_text('{"experiment": "x"}')
    assert main(["decode", str(a), "--out", str(mine / "d.npy")]) == 0
    assert "written into the recording" not in capsys.readouterr().err


def test_score_counts_every_decoded_pixel_and_reads_what_a_researchers_own_decoder_writes(tmp_path, capsys):
    """A bring-your-own-decoder audit (2026-12-05): depths written outside the lit region (a
    shadow filled with 0.5 m) scored as the clean map; 0 for "not decoded" scored as decoded
    depth at 100 % completeness; a recording's gt_column.npy or gt_object_id.npy as --gt was
    scored (701570 mm) or crashed (a ground truth of median 0); a ground truth copied out of its
    recording silently scored its shadows; a float32 TIFF was refused as an image of integers."""
    import cv2
    import numpy as np

    from tests.test_bad_inputs import render_folder

    gt = np.full((40, 50), 1.1, np.float32)
    lit = np.ones((40, 50), bool)
    lit[:, :10] = False  # a shadow: its truth is there, the projector is not
    np.save(tmp_path / "gt.npy", gt)
    np.save(tmp_path / "lit.npy", lit)
    clean = gt + np.float32(0.001)
    clean[:, :10] = np.nan
    filled = clean.copy()
    filled[:, :10] = 0.5  # the shadow filled with wrong depths
    np.save(tmp_path / "clean.npy", clean)
    np.save(tmp_path / "filled.npy", filled)
    base = ["--gt", str(tmp_path / "gt.npy"), "--lit", str(tmp_path / "lit.npy"), "--json"]
    scores = {}
    for name in ("clean", "filled"):
        assert main(["score", str(tmp_path / f"{name}.npy"), *base]) == 0
        scores[name] = json.loads(capsys.readouterr().out)
    assert scores["clean"]["mae_mm"] == scores["filled"]["mae_mm"]  # the region's errors alike ...
    assert scores["clean"]["wrong_share_all"] == 0 and scores["clean"]["n_decoded_outside"] == 0
    assert scores["filled"]["n_decoded"] == 2000 and scores["filled"]["n_decoded_outside"] == 400  # ... not these
    assert scores["filled"]["wrong_share_all"] == pytest.approx(0.2)
    assert scores["filled"]["region"] == str(tmp_path / "lit.npy")
    assert main(["score", str(tmp_path / "filled.npy"), *base[:-1]]) == 0
    assert (
        "every decoded pixel: 2000 (400 outside the region), 20.000 % of them > 5 mm wrong" in capsys.readouterr().out
    )
    # 0 marking holes: scored as depth, said so; --zero-is-hole reads them as holes
    zero = np.nan_to_num(clean, nan=0.0)
    np.save(tmp_path / "zero.npy", zero)
    assert main(["score", str(tmp_path / "zero.npy"), *base]) == 0
    out, err = capsys.readouterr()
    assert "400 of its depths are <= 0 m, scored as decoded depths (and wrong)" in err  # (outside the region too)
    assert json.loads(out)["wrong_share_all"] == pytest.approx(0.2)
    assert main(["score", str(tmp_path / "zero.npy"), *base, "--zero-is-hole"]) == 0
    assert json.loads(capsys.readouterr().out)["wrong_share_all"] == 0
    # an integer map (millimetres, 0 = hole) with --zero-is-hole: its zeros holes, not a cast NaN
    np.save(tmp_path / "mm.npy", np.round(zero * 1000).astype(np.int32))
    assert main(["score", str(tmp_path / "mm.npy"), *base, "--zero-is-hole"]) == 0
    out, err = capsys.readouterr()
    assert json.loads(out)["n_decoded"] == 1600 and "<= 0 m" not in err and "is it in metres" in err
    # a confidence map of the user's decoder (its own scale): the curve over its quantiles, and a threshold
    conf = np.full((40, 50), 9.0, np.float32)
    conf[:, :10] = 1.0  # the filled shadow: unsure
    conf[0, 20] = np.nan  # a confidence of NaN: sure of nothing
    np.save(tmp_path / "conf.npy", conf)
    with_conf = [*base, "--confidence", str(tmp_path / "conf.npy")]
    assert main(["score", str(tmp_path / "filled.npy"), *with_conf]) == 0
    curve = json.loads(capsys.readouterr().out)["confidence_curve"]
    assert [c["threshold"] for c in curve[:2]] == [1.0, 1.0] and curve[-1]["threshold"] == 9.0
    assert curve[0]["wrong_share_all"] == pytest.approx(400 / 1999) and curve[-1]["wrong_share_all"] == 0
    assert curve[-1]["completeness"] == pytest.approx(1599 / 1600)  # (the NaN confidence's pixel left out)
    assert main(["score", str(tmp_path / "filled.npy"), *with_conf, "--min-confidence", "5"]) == 0
    kept = json.loads(capsys.readouterr().out)
    assert kept["wrong_share_all"] == 0 and kept["n_decoded"] == 1599 and kept["confidence_curve"][0]["threshold"] == 9
    assert main(["score", str(tmp_path / "filled.npy"), *base[:-1], "--confidence", str(tmp_path / "conf.npy")]) == 0
    assert "kept at confidence >=" in capsys.readouterr().out
    assert main(["score", str(tmp_path / "filled.npy"), *base, "--min-confidence", "5"]) == 2
    assert "--min-confidence needs --confidence" in capsys.readouterr().err
    np.save(tmp_path / "conf_small.npy", conf[:20])
    assert main(["score", str(tmp_path / "filled.npy"), *base, "--confidence", str(tmp_path / "conf_small.npy")]) == 2
    capsys.readouterr()
    # a --lit that is not there: refused, not every finite truth in its place
    assert main(["score", str(tmp_path / "clean.npy"), "--gt", str(tmp_path / "gt.npy"), "--lit", "nope.npy"]) == 2
    assert "--lit nope.npy: no such file" in capsys.readouterr().err
    zero[5, 20] = 0.0
    np.save(tmp_path / "zero.npy", zero)
    assert main(["score", str(tmp_path / "zero.npy"), *base]) == 0
    out, err = capsys.readouterr()
    assert "1 of its depths are <= 0 m, scored as decoded depths (and wrong)" in err and "--zero-is-hole" in err
    assert json.loads(out)["completeness"] == 1.0
    assert main(["score", str(tmp_path / "zero.npy"), *base, "--zero-is-hole"]) == 0
    out, err = capsys.readouterr()
    assert json.loads(out)["completeness"] == pytest.approx(1 - 1 / 1600) and "<= 0 m" not in err
    read = json.loads(out)
    assert read["mae_mm"] == pytest.approx(scores["clean"]["mae_mm"]) and read["wrong_share_all"] == 0
    # no gt_lit.npy beside --gt and no --lit: a note, and the JSON names the region
    assert main(["score", str(tmp_path / "clean.npy"), "--gt", str(tmp_path / "gt.npy")]) == 0
    assert "note: no gt_lit.npy beside --gt: the region is every pixel with a finite ground truth" in (
        capsys.readouterr().err
    )
    assert main(["score", str(tmp_path / "clean.npy"), "--gt", str(tmp_path / "gt.npy"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["region"] == "finite ground truth"
    # a ground truth of median 0, or no depth > 0: refused in one line, not a crash
    np.save(tmp_path / "zeros.npy", np.zeros((40, 50), np.float32))
    assert main(["score", str(tmp_path / "clean.npy"), "--gt", str(tmp_path / "zeros.npy")]) == 2
    assert "has no depth > 0 m: is it a depth map in metres?" in capsys.readouterr().err
    half = gt.copy()
    half[:25] = 0.0
    np.save(tmp_path / "half.npy", half)
    assert main(["score", str(tmp_path / "clean.npy"), "--gt", str(tmp_path / "half.npy")]) == 0
    assert "the ground truth's median depth is 0 m: is it a depth map in metres?" in capsys.readouterr().err
    # a recording's other files as --gt: refused by name
    from simbench.io import save_json
    from simbench.manifest import seal_manifest

    r = render_folder(tmp_path)
    meta = json.loads((r / "meta.json").read_text())
    listed = {**meta["files"], "gt_column": "gt_column.npy", "gt_lit": "gt_lit.npy"}
    (r / "meta.json").unlink()  # sealed anew, listing them as `simbench render` does
    save_json(r / "meta.json", seal_manifest(r, meta, listed))
    for name in ("gt_column.npy", "gt_lit.npy"):
        assert main(["score", str(r / "depth.npy"), "--gt", str(r / name)]) == 2
        err = capsys.readouterr().err
        assert f"is the recording's {name[:-4]}, not its ground-truth depth: give {r / 'gt_depth.npy'}" in err
    # a float32 TIFF in metres is read (as the .npy); an integer one refused as before
    cv2.imwrite(str(tmp_path / "clean.tif"), clean)
    assert main(["score", str(tmp_path / "clean.tif"), *base]) == 0
    assert json.loads(capsys.readouterr().out) == scores["clean"]
    cv2.imwrite(str(tmp_path / "mm.tif"), np.nan_to_num(clean * 1000).astype(np.uint16))
    assert main(["score", str(tmp_path / "mm.tif"), *base]) == 2
    assert "this image file holds integers in units of its own" in capsys.readouterr().err


def test_a_competitors_min_confidence_that_removes_nothing_says_so(tmp_path, capsys):
    """The fresh-clone audit: a ToF folder decoded with --min-confidence 0.9 said nothing of the
    threshold doing nothing (its decoded pixels all hold thousands of electrons)."""
    folder = tmp_path / "tof"
    assert main(["render", str(SCENES / "step.toml"), "--system", "tof", "--out", str(folder), "--no-cache"]) == 0
    capsys.readouterr()
    assert main(["decode", str(folder), "--out", str(tmp_path / "d.npy"), "--min-confidence", "0.9"]) == 0
    out = capsys.readouterr().out
    assert "below 0.9, which removed no pixel (the least confident decoded one has " in out
    assert main(["decode", str(folder), "--out", str(tmp_path / "e.npy"), "--min-confidence", "1e6"]) == 0
    out, err = capsys.readouterr()
    assert "below 1e+06)" in out and "removed no pixel" not in out and "decoded 0.00 %" in out
    assert "no pixel decoded: --min-confidence 1e+06 made holes of " in err  # not "lit by this pattern?"


def test_the_nothing_decoded_hint_blames_the_threshold_only_for_holes_it_made():
    """Phase shifting's confidence (the fringe modulation) is positive at pixels it never
    decoded: a dark capture decoded with a threshold above that modulation must be called dark
    (or unlit), not the threshold's doing, when the system says which holes the threshold made."""
    import numpy as np

    from simbench.systems.files import nothing_decoded_hint

    valid = np.zeros((20, 30), bool)
    conf = np.full((20, 30), 0.05, np.float32)
    dim = np.full((20, 30, 3), 40, np.uint8)
    blamed = nothing_decoded_hint(valid, dim, confidence=conf, min_confidence=0.1)
    assert "--min-confidence 0.1 made holes of 100.0 % of the pixels" in blamed  # no mask: by the confidence alone
    none_made = nothing_decoded_hint(valid, dim, confidence=conf, min_confidence=0.1, thresholded=np.zeros_like(valid))
    assert "--min-confidence" not in none_made and "lit by this pattern" in none_made
    some = np.zeros_like(valid)
    some[:5] = True
    made = nothing_decoded_hint(valid, dim, confidence=conf, min_confidence=0.1, thresholded=some)
    assert "made holes of 25.0 % of the pixels" in made
    # one channel clipped over most of the capture (the fringe's, three times too bright) is named
    bright = dim.copy()
    bright[..., 2] = 255
    bright[:4, :, 2] = 200
    assert "the capture is saturated: B on 80 % of its pixels (at 255)" in nothing_decoded_hint(valid, bright)


@pytest.mark.slow
def test_render_warns_of_a_reference_plane_outside_the_working_range(tmp_path, capsys, variant):
    """A new user's audit: Z0 = 100 m rendered without a word (a 270-s exposure), and its decode
    blamed saturation.  Rendered at 2.5 m here: legal, with a warning naming the range and the
    exposure."""
    scene = tmp_path / "far.toml"
    scene.write_text(
        'rig = "paper"\nreference_depth_m = 2.5\n\n[[object]]\ntype = "plane"\ncenter_m = [0.0, 0.0, 2.5]\n'
        "size_m = [4.0, 3.0]\n"
    )
    argv = ["render", str(scene), "--out", str(tmp_path / "o"), "--spp", "1", "--no-cache", "--sensor", "minimal"]
    assert main(argv) == 0
    err = capsys.readouterr().err
    assert "its reference plane (reference_depth_m = 2.5 m) lies outside the decoder's default working range" in err
    scene.write_text(scene.read_text().replace("2.5", "1.2"))
    assert main(["render", str(scene), "--out", str(tmp_path / "n"), "--spp", "1", "--no-cache"]) == 0
    assert "working range" not in capsys.readouterr().err


def test_cache_and_no_cache_exclude_each_other_in_every_command(capsys):
    """A user's audit (2026-11-30): ``--no-cache --cache X`` ignored X without a word, even a file.
    Every command that takes both refuses the pair, before any work."""
    from simbench.cli import _parser

    parser = _parser()
    commands = [
        name
        for action in parser._subparsers._group_actions
        for name, sub in action.choices.items()
        if {"--cache", "--no-cache"} <= set(sub._option_string_actions)
    ]
    assert {"render", "decode", "calibrate", "demo", "reproduce", "ablate"} <= set(commands), commands
    for name in commands:
        with pytest.raises(SystemExit) as stop:
            parser.parse_args([name, "--no-cache", "--cache", "somewhere"])
        assert stop.value.code == 2
        assert "argument --cache: not allowed with argument --no-cache" in capsys.readouterr().err, name


def test_score_refuses_a_recording_that_lost_a_file_its_manifest_lists(tmp_path, capsys):
    """A user's audit (2026-11-30): with gt_lit.npy removed from a recording, `score` took every
    finite pixel as its region (95.23 % of 1228800 pixels instead of 98.54 % of 1187520), exit 0,
    while `decode` refuses such a folder.  A file the manifest lists and score reads by default
    (the region, the object ids of the edge band) must be there; one given (--lit) stands in."""
    import numpy as np

    import json

    from simbench.io import save_json, save_npy
    from simbench.manifest import seal_manifest
    from tests.test_bad_inputs import render_folder

    r = render_folder(tmp_path)
    save_npy(r / "gt_object_id.npy", np.zeros((120, 160), np.int32))
    data = json.loads((r / "meta.json").read_text())
    (r / "meta.json").unlink()
    save_json(
        r / "meta.json",
        seal_manifest(r, data, {**data["files"], "gt_lit": "gt_lit.npy", "gt_object_id": "gt_object_id.npy"}),
    )
    argv = ["score", str(r / "depth.npy"), "--gt", str(r / "gt_depth.npy")]
    assert main(argv) == 0 and "band" not in capsys.readouterr().out
    # (a new user's audit, 2026-11-30: the text named no edge band; the pixels it leaves out now)
    assert main([*argv, "--edge-band", "5"]) == 0
    out = capsys.readouterr().out
    assert "(errors off a 5-px band at depth edges and object boundaries: " in out and " pixels left out)" in out, out
    lit = (r / "gt_lit.npy").read_bytes()
    (r / "gt_lit.npy").unlink()
    assert main(argv) == 2
    assert f"{r / 'gt_lit.npy'} is missing: the recording's manifest lists it" in capsys.readouterr().err
    save_npy(tmp_path / "mine.npy", np.ones((120, 160), bool))
    assert main([*argv, "--lit", str(tmp_path / "mine.npy")]) == 0
    (r / "gt_lit.npy").write_bytes(lit)
    (r / "gt_object_id.npy").unlink()
    assert main(argv) == 0  # the edge band is not asked for
    assert main([*argv, "--edge-band", "5"]) == 2
    assert "gt_object_id.npy is missing: the recording's manifest lists it (the edge band" in capsys.readouterr().err


def test_score_counts_stripe_order_errors_in_the_recordings_period(capsys):
    """A third audit: `score --column` counted a period-30 recording's columns against 21 px
    unless --period was given; the recording's meta.json names its pattern."""
    from simbench.cli.decode import _score_period

    recorded = {"pattern": {"period_px": 30.0}}
    assert _score_period(None, recorded) == 30.0 and _score_period(None, None) == 21.0
    assert _score_period(None, {"device": "kinect"}) == 21.0
    assert _score_period(None, {"device": "phase_shift", "period_px": 18}) == 18.0
    assert _score_period(30.0, recorded) == 30.0 and capsys.readouterr().err == ""
    assert _score_period(21.0, recorded) == 21.0  # as given, with a word
    assert "--period 21, but the recording was made with a period of 30 px" in capsys.readouterr().err


def test_decode_warns_of_a_capture_whose_channels_are_out_of_order(tmp_path, capsys):
    """A capture saved BGR as RGB (a new user's audit: the colour-robust decoder read 2-9 % of it
    0.1-0.7 m wrong at full confidence, silently): `decode` says which channel holds the fringe."""
    from simbench.io import load_image, save_png
    from tests.test_bad_inputs import render_folder

    r = render_folder(tmp_path)
    save_png(tmp_path / "bgr.png", load_image(r / "capture.png")[..., ::-1])
    argv = ["decode", str(tmp_path / "bgr.png"), "--reference", str(r / "reference.png"), "--rig", str(r / "rig.toml")]
    assert main([*argv, "--out", str(tmp_path / "d.npy")]) == 0
    assert "the fringe seems to be in the red channel" in capsys.readouterr().err
    argv[1] = str(r / "capture.png")
    assert main([*argv, "--out", str(tmp_path / "e.npy")]) == 0
    assert "fringe seems" not in capsys.readouterr().err


def test_debug_after_the_command_shows_the_traceback_and_keeps_the_exit_status(tmp_path, capsys):
    """A new user's audit (2026-11-29): ``decode --debug DIR ...`` was taken for ``--debug-dir DIR``
    (argparse's prefixes) and wrote stage images; ``--debug`` after the command was refused, and
    with it bad input exited 1 (the traceback raised) where it exits 2."""
    missing = [
        "decode",
        str(tmp_path / "none.png"),
        "--rig",
        str(tmp_path / "none.toml"),
        "--out",
        str(tmp_path / "d.npy"),
    ]
    for argv in (["--debug", *missing], [*missing, "--debug"], [missing[0], "--debug", *missing[1:]]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert "Traceback" in err and err.rstrip().endswith("rig file not found: " + str(tmp_path / "none.toml")), err
    assert main(missing) == 2 and "Traceback" not in capsys.readouterr().err
    # no prefixes: --debug-d is no --debug-dir
    assert main([*missing, "--debug-d", str(tmp_path / "dbg")]) == 2
    assert "unrecognized arguments: --debug-d" in capsys.readouterr().err and not (tmp_path / "dbg").exists()
    # an option the command does not take points at the command's help (it said "see simbench --help")
    assert main([*missing, "--foo"]) == 2
    assert "error: decode: unrecognized arguments: --foo (see simbench decode --help)" in capsys.readouterr().err
    assert main(["cache", "info", "--foo"]) == 2
    assert "cache info: unrecognized arguments: --foo (see simbench cache info --help)" in capsys.readouterr().err


def test_the_apis_warnings_are_the_command_lines_one_line_messages(tmp_path, monkeypatch, capsys):
    """``simbench render`` records through the Python API, whose sanity messages are
    ``simbench.SimbenchWarning`` (a review: the command line printed them in Python's
    ``file:line: SimbenchWarning:`` form, with the source line): one ``simbench: ...`` line, each time,
    and pytest's warnings-as-errors (as ``python -W error``) do not turn them into a traceback."""
    import warnings

    import simbench
    from simbench import api

    def record(*args, **kwargs):
        warnings.warn("scene told: an object 40 m across", simbench.SimbenchWarning, stacklevel=2)
        warnings.warn("scene told: an object 40 m across", simbench.SimbenchWarning, stacklevel=2)
        raise ValueError("stopped before rendering")

    monkeypatch.setattr(api, "record", record)
    argv = ["render", str(SCENES / "step.toml"), "--out", str(tmp_path / "out"), "--cache", str(tmp_path / "c")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("simbench: warning: scene told: an object 40 m across\n") == 2, err
    assert "SimbenchWarning" not in err and "warnings.warn" not in err
    assert "simbench: error: stopped before rendering" in err


def test_decode_writes_a_record_of_what_its_files_are(tmp_path, capsys):
    """A new user's audit (2026-11-30): depth.npy and its confidence said nothing of their units,
    decoder or threshold - only stdout did.  Beside --out, NAME_decode.json records what the depth
    and the confidence are, the operating point, the capture, the settings and the command; it is
    an output like the others (checked before the decode, written with them)."""
    import json

    from tests.test_bad_inputs import render_folder

    r = render_folder(tmp_path)
    out = tmp_path / "o" / "d.npy"
    argv = ["decode", str(r), "--out", str(out), "--min-confidence", "2", "--no-cache"]
    assert main(argv) == 0
    assert "record -> " in capsys.readouterr().out
    record = json.loads((tmp_path / "o" / "d_decode.json").read_text())
    assert record["format"] == 2 and record["system"] == "proposed" and record["min_confidence"] == 2.0
    assert record["command"].startswith("simbench decode") and record["capture"].endswith("capture.png")
    assert record["depth"]["file"] == "d.npy" and "z-depth in metres" in record["depth"]["meaning"]
    assert 0.9 < record["depth"]["valid_share"] <= 1.0
    assert record["confidence"]["file"] == "d_confidence.npy" and "SNR" in record["confidence"]["meaning"]
    # what a confidence means in noise for this rig (DecoderParams.column_noise_px)
    assert "the column's random noise at fringe SNR s ~" in record["confidence"]["meaning"]
    assert record["settings"]["decoder"]["min_confidence"] == 2.0 and record["point_cloud"] is None
    assert main(["decode", str(r), "--out", str(tmp_path / "o" / "d.npy"), "--ply", str(tmp_path / "o" / "d.ply")]) == 0
    record = json.loads((tmp_path / "o" / "d_decode.json").read_text())
    assert record["point_cloud"] == "d.ply" and record["min_confidence"] == 0.0  # (the paper decoder: none)
    capsys.readouterr()
    # a second audit (2026-11-30): --debug-dir named as the record wrote the depth, then failed
    rc = main(
        ["decode", str(r), "--out", str(tmp_path / "p" / "w.npy"), "--debug-dir", str(tmp_path / "p" / "w_decode.json")]
    )
    assert rc == 2 and "--debug-dir" in capsys.readouterr().err and not (tmp_path / "p").exists()
    # ... and a confidence written over an earlier depth left that depth's record calling it a depth
    assert (
        main(["decode", str(r), "--out", str(tmp_path / "o" / "y.npy"), "--confidence", str(tmp_path / "o" / "d.npy")])
        == 0
    )
    assert not (tmp_path / "o" / "d_decode.json").exists() and (tmp_path / "o" / "y_decode.json").is_file()


def test_the_render_cache_default_follows_its_environment_variable(tmp_path):
    """A new user's audit (2026-11-30): a library scene rendered from two working folders rendered
    twice (the default cache is .cache/simbench under each), and SIMBENCH_CACHE_DIR, the small
    memos' folder, read like the render cache's.  SIMBENCH_RENDER_CACHE names the default render
    cache of every command (a fresh process: the default is read at import)."""
    import os
    import subprocess
    import sys

    from simbench.api import RENDER_CACHE_VARIABLE

    assert RENDER_CACHE_VARIABLE == "SIMBENCH_RENDER_CACHE"
    exe = [sys.executable, "-m", "simbench"]
    env = {**os.environ, RENDER_CACHE_VARIABLE: str(tmp_path / "rc")}
    run = subprocess.run([*exe, "cache", "info"], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0 and f"cache {tmp_path / 'rc'}: not made yet" in run.stdout, run.stdout + run.stderr
    helped = subprocess.run([*exe, "render", "--help"], env=env, capture_output=True, text=True, timeout=120)
    assert "$SIMBENCH_RENDER_CACHE sets another" in " ".join(helped.stdout.split()), helped.stdout
    env.pop(RENDER_CACHE_VARIABLE)
    run = subprocess.run([*exe, "cache", "info"], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert "cache .cache/simbench: not made yet" in run.stdout, run.stdout + run.stderr
