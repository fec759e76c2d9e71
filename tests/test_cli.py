import json

import pytest

from simbench.cli import main
from simbench.io import load_image

from .conftest import SCENES


def test_pattern_command(tmp_path, capsys):
    assert main(["pattern", "--out", str(tmp_path / "p.png")]) == 0
    img = load_image(tmp_path / "p.png")
    assert img.shape == (1140, 1824, 3)
    assert "p.png" in capsys.readouterr().out


@pytest.mark.parametrize(
    "argv, match",
    [
        (["decode", "missing.png", "--rig", "missing.toml", "--out", "d.npy"], "rig file not found"),
        (["render", "missing.toml", "--out", "x"], "scene file not found"),
        (["score", "nope.npy", "--gt", "gt.npy"], "file not found"),
        (["pattern", "--out", "p.png", "--period", "2"], "period_px"),
        (["pattern", "--out", "p.png", "--sequence", "0101"], "repeats"),
        (["pattern", "--out", "p.png", "--sequence", "01x"], "0 and 1"),
        (["pattern", "--out", "p.png", "--channels", "rgg"], "permutation of 'rgb'"),
        (["bench", "--device", "tof", "--scene", "shadow", "--repeats", "1"], "only the plane"),
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
    (tmp_path / "r.toml").write_text("[camera]\nwidth_px=1280\nheight_px=960\nfocal_px=0\n[projector]\nwidth_px=10\nheight_px=10\nfocal_px=5\n")
    assert main(["decode", str(tmp_path / "c.png"), "--rig", str(tmp_path / "r.toml"), "--out", str(tmp_path / "d.npy")]) == 2
    assert "focal_px" in capsys.readouterr().err


@pytest.mark.slow
@pytest.mark.parametrize("sensor, max_mae_mm", [("minimal", 0.3), ("paper", 1.0)])
def test_render_decode_score_end_to_end(tmp_path, capsys, variant, sensor, max_mae_mm):
    """The pipeline issue's bound with the minimal camera; with the physical paper model
    (distortion in rig.toml, undistorted by decode) the error grows but stays sub-millimetre."""
    out = tmp_path / "wp"
    assert main(["render", str(SCENES / "white_plane.toml"), "--out", str(out), "--seed", "3", "--sensor", sensor]) == 0
    for f in ("capture.png", "reference.png", "gt_depth.npy", "gt_depth.exr", "gt_column.npy", "gt_lit.npy", "rig.toml", "meta.json"):
        assert (out / f).is_file(), f
    meta = json.loads((out / "meta.json").read_text())
    assert meta["seed"] == 3 and meta["spp"] == 16 and meta["variant"] == variant
    assert main(["decode", str(out / "capture.png"), "--reference", str(out / "reference.png"), "--rig", str(out / "rig.toml"),
                 "--out", str(tmp_path / "d.npy"), "--ply", str(tmp_path / "c.ply"), "--debug-dir", str(tmp_path / "dbg")]) == 0
    assert (tmp_path / "c.ply").is_file() and (tmp_path / "dbg" / "wrapped_phase.npy").is_file()
    capsys.readouterr()
    assert main(["score", str(tmp_path / "d.npy"), "--gt", str(out / "gt_depth.npy"), "--column", str(tmp_path / "dbg" / "column.npy"), "--json"]) == 0
    m = json.loads(capsys.readouterr().out)
    assert m["mae_mm"] < max_mae_mm and m["completeness"] > 0.99 and m["stripe_order_errors"] == 0
    assert meta["sensor"]["name"] == sensor
    # the same seed renders the same capture, bit for bit
    assert main(["render", str(SCENES / "white_plane.toml"), "--out", str(tmp_path / "wp2"), "--seed", "3", "--sensor", sensor]) == 0
    assert (out / "capture.png").read_bytes() == (tmp_path / "wp2" / "capture.png").read_bytes()


def _synthetic_recording(tmp_path):
    import numpy as np

    from simbench.io import save_png
    from simbench.pattern import PatternSpec, fringe_pattern, quantize
    from simbench.projector import transfer_curve
    from simbench.rig import paper_rig, save_rig
    from simbench.synthetic import synthetic_plane_capture

    rig = paper_rig()
    drive = transfer_curve(quantize(fringe_pattern(PatternSpec())), transfer="linear")
    for name, depth in (("capture", 1.1), ("reference", 1.0)):
        img = synthetic_plane_capture(drive, rig, point_m=(0, 0, depth))[0]
        save_png(tmp_path / f"{name}.png", np.round(np.clip(img, 0, 1) * 255).astype(np.uint8))
    save_rig(rig, tmp_path / "rig.toml")
    return [str(tmp_path / "capture.png"), "--reference", str(tmp_path / "reference.png"), "--rig", str(tmp_path / "rig.toml")]


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
    assert "unknown phase_method 'nope'" in err and "'ftp'" in err and "'wfr'" in err
