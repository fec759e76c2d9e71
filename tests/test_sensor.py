"""Sensor models: presets, TOML, photometry and the effect switches (simbench.sim.sensor)."""

from __future__ import annotations

import dataclasses
import math
import re
import tomllib

import numpy as np
import pytest

from simbench.sim.sensor import (
    EFFECTS,
    PRESETS_DIR,
    SENSOR_PRESETS,
    apply_to_rig,
    get_sensor,
    load_sensor,
    sensor_from_dict,
    sensor_to_dict,
    with_effects,
)
from simbench.sim.photometry import channel_weights, electrons_per_radiance_s, exposure_s, white_balance_gains
from simbench.rig import paper_rig
from simbench.sim.camera import emva_camera

RIG = paper_rig()


@pytest.mark.parametrize("name", SENSOR_PRESETS)
def test_presets_load_and_round_trip(name, tmp_path):
    s = get_sensor(name)
    assert sensor_from_dict(sensor_to_dict(s)) == s
    import tomli_w

    path = tmp_path / "s.toml"
    path.write_text(tomli_w.dumps(sensor_to_dict(s)))
    assert load_sensor(path) == s


def test_ideal_has_every_effect_off_and_paper_has_them_on():
    ideal, paper = get_sensor("ideal"), get_sensor("paper")
    assert not ideal.camera.noise and ideal.camera.cfa == "none" and not ideal.crosstalk and ideal.ambient_ratio == 0
    assert (
        ideal.projector.transfer == "linear"
        and math.isinf(ideal.projector.contrast_ratio)
        and ideal.projector.dmd == "square"
    )
    assert not ideal.camera_lens.defocus and not ideal.projector.lens.defocus
    assert apply_to_rig(RIG, ideal) == RIG
    for key in EFFECTS:
        if key in ("transfer", "timing"):
            continue  # the paper used the linear pattern mode, triggering the camera
        if key == "lateral_colour":
            continue  # a what-if row until the paper model carries it (device.PAPER_LATERAL_COLOUR_PX)
        moved = with_effects(ideal, paper, [key])
        assert dataclasses.replace(moved, name=ideal.name, description=ideal.description) != ideal, key
    assert with_effects(ideal, paper, list(EFFECTS)).camera == paper.camera


def test_every_paper_number_is_cited_or_marked_an_assumption():
    """Each key of the paper preset follows a comment block that cites a source or says
    'assumption' (the issue's rule); a bare number fails."""
    lines = (PRESETS_DIR / "paper.toml").read_text().splitlines()
    comment: list[str] = []
    for line in lines:
        s = line.strip()
        if s.startswith("#"):
            comment.append(s)
            continue
        m = re.match(r"^([a-z_]+)\s*=", s)
        if m and m.group(1) not in (
            "name",
            "description",
            "model",
            "noise",
            "fixed_pattern_seed",
            "gamma",
            "transmission",
        ):
            text = " ".join(comment).lower()
            assert "assumption" in text or "datasheet" in text or "guide" in text or "simbench/" in text, (
                f"{m.group(1)} has no source"
            )
        if s.startswith("["):
            comment = []
        elif not s:
            comment = []


def test_bad_sensor_files_are_clear():
    base = sensor_to_dict(get_sensor("paper"))
    with pytest.raises(ValueError, match="unknown key"):
        sensor_from_dict({**base, "colour": 1})
    with pytest.raises(ValueError, match="camera.*unknown key.*qe"):
        sensor_from_dict({**base, "camera": {**base["camera"], "q_e": [0.5] * 3}})
    with pytest.raises(ValueError, match="cfa"):
        sensor_from_dict({**base, "camera": {**base["camera"], "cfa": "RGBW"}})
    with pytest.raises(ValueError, match="transfer"):
        sensor_from_dict({**base, "projector": {**base["projector"], "transfer": "srgb"}})
    with pytest.raises(ValueError, match="timing"):
        sensor_from_dict({**base, "projector": {**base["projector"], "timing": "free"}})
    with pytest.raises(ValueError, match="frame_rate_hz"):
        sensor_from_dict({**base, "projector": {**base["projector"], "frame_rate_hz": 0}})
    with pytest.raises(ValueError, match="f_number"):
        sensor_from_dict({**base, "projector": {**base["projector"], "lens": {"f_number": 0}}})
    with pytest.raises(ValueError, match="crosstalk.*emva"):
        sensor_from_dict({**sensor_to_dict(get_sensor("minimal")), "spectral": {"crosstalk": True}})
    with pytest.raises(ValueError, match=r"missing key\(s\) \['pixel_pitch_um'"):
        sensor_from_dict({"camera": {"model": "emva", "qe": [0.5, 0.5, 0.5]}})
    with pytest.raises(ValueError, match="preset"):
        get_sensor("flea3")
    with pytest.raises(FileNotFoundError):
        get_sensor("/nonexistent/sensor.toml")


def test_a_sensors_numbers_out_of_any_cameras_range_are_refused():
    """An audit (2026-11-30): a pixel pitch written in millimetres (0.00345) gave a 13106 s auto
    exposure and a capture of dark current, exit 0; the simple camera took full_well_e = 1e30 and
    read_noise_e = 1e25, which the emva camera refuses.  An auto exposure over an hour - far too
    little light - is refused with what to check."""
    from simbench.sim.photometry import exposure_s, white_board
    from simbench.sim.scene import SceneSpec

    base = sensor_to_dict(get_sensor("paper"))
    with pytest.raises(ValueError, match=r"pixel_pitch_um must be a finite number in \[0.5, 100\]"):
        sensor_from_dict({**base, "camera": {**base["camera"], "pixel_pitch_um": 0.00345}})
    with pytest.raises(ValueError, match="pixel_pitch_um"):
        sensor_from_dict({**base, "projector": {**base["projector"], "pixel_pitch_um": 0.0054}})
    simple = sensor_to_dict(get_sensor("minimal"))
    for key, value in (("full_well_e", 1e30), ("read_noise_e", 1e25)):
        with pytest.raises(ValueError, match=key):
            sensor_from_dict({**simple, "camera": {**simple["camera"], key: value}})
    dim = sensor_from_dict({**base, "projector": {**base["projector"], "lumens": 1e-3}})
    board = white_board(SceneSpec(name="s", rig=RIG, objects=()))
    with pytest.raises(ValueError, match=r"auto exposure comes to 40\d\d s, longer than .* \(3600 s\).*lumens"):
        exposure_s(dim, RIG, **board)
    assert exposure_s(get_sensor("paper"), RIG, **board) == pytest.approx(0.027, rel=0.1)


def test_a_clipped_or_dark_capture_is_warned_of_with_the_sensors_reasons():
    """simbench.api.exposure_warnings: over 5 % of the pixels clipped in some channel, said with why
    (the auto exposure meters the projector's white only: an ambient ratio above 1/0.7 - 1 clips the
    board itself; a hand-set exposure; dark current), or a capture nearly black; a glossy board's
    few clipped pixels and a plain capture, nothing."""
    from simbench.api import exposure_warnings
    from simbench.sim.scene import SceneSpec

    scene = SceneSpec(name="s", rig=RIG, objects=())
    paper = get_sensor("paper")
    ok = np.full((40, 50, 3), 120, np.uint8)
    assert exposure_warnings(ok, scene, paper) == []
    glossy = ok.copy()
    glossy[:3, :, 0] = 255  # 3 rows of 40 clipped in red: 7.5 % of the pixels (1 row of 38: 2.6 %)
    assert exposure_warnings(glossy[2:], scene, paper) == []
    (told,) = exposure_warnings(glossy, scene, paper)
    assert told.startswith("7.5 % of the capture's pixels are clipped in some channel: the auto exposure (")
    assert "ambient" not in told
    roomy = dataclasses.replace(paper, ambient_ratio=2.0)
    (told,) = exposure_warnings(np.full((4, 5, 3), 255, np.uint8), scene, roomy)
    assert "100.0 % of the capture's pixels" in told and "[ambient] ratio 2 of the projector's white" in told
    assert "(above 0.43)" in told
    fixed = dataclasses.replace(paper, camera=dataclasses.replace(paper.camera, exposure_s=13.1, dark_current_e_s=1e3))
    (told,) = exposure_warnings(np.full((4, 5, 3), 255, np.uint8), scene, fixed)
    assert "the exposure set, 13.1 s" in told and "dark current alone fills 100 % of the full well" in told
    (told,) = exposure_warnings(np.full((4, 5, 3), 3, np.uint8), scene, paper)
    assert told.startswith("the capture is dark: its brightest value is 3 of 255")
    # the reference plane's capture (the white board) at its own, lower bound: 1 row of 38 clipped
    from simbench.api import CLIPPED_REFERENCE_SHARE

    (told,) = exposure_warnings(
        glossy[2:], scene, paper, what="reference plane's capture", clipped_share=CLIPPED_REFERENCE_SHARE
    )
    assert told.startswith("2.6 % of the reference plane's capture's pixels are clipped")
    twelve = dataclasses.replace(paper, camera=dataclasses.replace(paper.camera, bits=12))
    assert exposure_warnings(np.full((4, 5, 3), 255, np.uint16), scene, twelve) == []  # 255 of 4095
    frames = np.ones((12, 4, 5), np.float32)  # phase shifting's grey frames in [0, 1]
    assert "100.0 %" in exposure_warnings(frames, scene, paper)[0]


def test_photometry_follows_the_camera_equation():
    paper = get_sensor("paper")
    e = electrons_per_radiance_s(paper, RIG)
    assert e.shape == (3,) and np.all(e > 0)
    # twice the f-number: a quarter of the light; twice the lumens: twice
    slow = dataclasses.replace(
        paper, camera_lens=dataclasses.replace(paper.camera_lens, f_number=2 * paper.camera_lens.f_number)
    )
    assert np.allclose(electrons_per_radiance_s(slow, RIG), e / 4)
    bright = dataclasses.replace(paper, projector=dataclasses.replace(paper.projector, lumens=300.0))
    assert np.allclose(electrons_per_radiance_s(bright, RIG), 2 * e)
    w = channel_weights(paper, RIG)
    assert np.allclose(np.diag(w), 1) and np.allclose(w * w.T, 1)
    assert np.array_equal(channel_weights(get_sensor("minimal"), RIG), np.ones((3, 3)))


@pytest.mark.parametrize("crosstalk", [False, True])
def test_auto_exposure_puts_the_reference_board_at_the_set_fraction(crosstalk):
    """Noise-free: a white board (albedo 0.8, crosstalk or not) at Z0 under full drive of all
    primaries records the brightest channel at auto_exposure_fraction of full scale."""
    from simbench.sim.photometry import REFERENCE_ALBEDO
    from simbench.sim.spectral import crosstalk_matrix

    s = dataclasses.replace(get_sensor("ideal"), crosstalk=crosstalk)
    z0 = 1.3
    t = exposure_s(s, RIG, reference_depth_m=z0, reference_albedo=REFERENCE_ALBEDO)
    k = crosstalk_matrix((REFERENCE_ALBEDO,) * 3) if crosstalk else REFERENCE_ALBEDO * np.eye(3)
    q = (k * channel_weights(s, RIG)).sum(axis=1) / z0**2  # render_channels' output on the board
    img = emva_camera(
        np.broadcast_to(q, (4, 4, 3)).copy(),
        camera=s.camera,
        electrons_per_radiance=electrons_per_radiance_s(s, RIG) * t,
        exposure_s=t,
    )
    assert img.max() == round(s.camera.auto_exposure_fraction * 255)
    fixed = dataclasses.replace(s, camera=dataclasses.replace(s.camera, exposure_s=0.004))
    assert exposure_s(fixed, RIG, reference_depth_m=z0, reference_albedo=0.8) == 0.004


@pytest.mark.parametrize("crosstalk", [False, True])
@pytest.mark.parametrize("cfa", ["none", "RGGB"])
def test_one_push_white_balance_makes_the_reference_board_grey(crosstalk, cfa):
    """Flea3 One Push (Technical Reference Sec. 7.8): red and blue gains relative to green such
    that the white board at Z0 under the projector's white reads 1:1:1; with auto exposure the
    balanced channels sit at the set fraction of full scale.  Without white balance they do not
    (the LED primaries and the channel QEs differ)."""
    from simbench.sim.photometry import REFERENCE_ALBEDO
    from simbench.sim.spectral import crosstalk_matrix

    base = get_sensor("ideal")
    z0 = 1.3
    board = {"reference_depth_m": z0, "reference_albedo": REFERENCE_ALBEDO}
    k = crosstalk_matrix((REFERENCE_ALBEDO,) * 3) if crosstalk else REFERENCE_ALBEDO * np.eye(3)
    images = {}
    for mode in ("off", "one_push"):
        s = dataclasses.replace(
            base, crosstalk=crosstalk, camera=dataclasses.replace(base.camera, white_balance=mode, cfa=cfa)
        )
        gains = white_balance_gains(s, RIG, **board)
        t = exposure_s(s, RIG, **board)
        q = (k * channel_weights(s, RIG)).sum(axis=1) / z0**2
        images[mode] = emva_camera(
            np.broadcast_to(q, (8, 8, 3)).copy(),
            camera=s.camera,
            electrons_per_radiance=electrons_per_radiance_s(s, RIG) * t,
            exposure_s=t,
            white_balance=gains,
        )
        if mode == "off":
            assert np.array_equal(gains, np.ones(3))
        else:
            assert gains[1] == 1.0 and np.all(gains > 0)
    levels = images["one_push"][2:-2, 2:-2].reshape(-1, 3).astype(float)
    # 0.7 x 255 = 178.5: rounding puts each channel on either side of the half
    assert np.all(np.abs(levels - base.camera.auto_exposure_fraction * 255) <= 0.5 + 1e-9)
    off = images["off"][2:-2, 2:-2].reshape(-1, 3)
    assert off.max() - off.min() > 10


def test_white_balance_gain_acts_before_the_adc_clip():
    """A channel with gain > 1 reaches the top of the ADC range before full well."""
    cam = dataclasses.replace(get_sensor("ideal").camera, full_well_e=1000.0)
    rad = np.full((2, 2, 3), 0.6)
    img = emva_camera(
        rad, camera=cam, electrons_per_radiance=(1000.0,) * 3, exposure_s=1e-3, white_balance=(2.0, 1.0, 0.5)
    )
    assert img[0, 0].tolist() == [255, round(0.6 * 255), round(0.3 * 255)]
    with pytest.raises(ValueError, match="white_balance"):
        emva_camera(
            rad, camera=cam, electrons_per_radiance=(1000.0,) * 3, exposure_s=1e-3, white_balance=(1.0, 0.0, 1.0)
        )


def test_paper_preset_balances_white_on_the_camera():
    paper = get_sensor("paper")
    assert paper.camera.white_balance == "one_push"
    gains = white_balance_gains(paper, RIG, reference_depth_m=1.0, reference_albedo=0.8)
    # the LED blue line gives the fewest electrons per unit drive (spectral.py): the largest gain
    assert gains[1] == 1.0 and gains[2] > gains[0] > 1.0
    with pytest.raises(ValueError, match="white_balance"):
        sensor_from_dict(
            {
                "camera": {
                    "model": "emva",
                    "pixel_pitch_um": 5.3,
                    "qe": [0.5] * 3,
                    "full_well_e": 1e4,
                    "dark_noise_e": 1.0,
                    "white_balance": "auto",
                }
            }
        )


def test_apply_to_rig_puts_the_lens_distortion_in_the_rig():
    paper = get_sensor("paper")
    rig = apply_to_rig(RIG, paper)
    assert rig.camera.distortion == paper.camera_lens.distortion
    assert rig.projector.distortion == paper.projector.lens.distortion
    assert apply_to_rig(rig, paper) == rig  # idempotent


def test_with_effects_rejects_unknown_effects():
    with pytest.raises(ValueError, match="noise"):
        with_effects(get_sensor("ideal"), get_sensor("paper"), ["gamma"])
    with pytest.raises(ValueError, match="physical"):
        with_effects(get_sensor("minimal"), get_sensor("paper"), ["noise"])


def test_lateral_colour_is_a_lens_field_left_out_of_the_dict_when_zero(tmp_path):
    """A model without lateral colour writes the dict it wrote before the effect existed (its
    cache keys do not move); with it, the TOML round trip keeps it; bad values are clear."""
    from simbench.sim.sensor import PAPER_LATERAL_COLOUR_PX, with_lateral_colour

    paper = get_sensor("paper")
    assert "lateral_colour_px" not in sensor_to_dict(paper)["camera"]["lens"]
    assert "lateral_colour_px" not in sensor_to_dict(paper)["projector"]["lens"]
    ca = with_lateral_colour(
        paper, camera_px=PAPER_LATERAL_COLOUR_PX["camera"], projector_px=PAPER_LATERAL_COLOUR_PX["projector"]
    )
    d = sensor_to_dict(ca)
    assert d["camera"]["lens"]["lateral_colour_px"] == list(PAPER_LATERAL_COLOUR_PX["camera"])
    assert sensor_from_dict(d) == ca
    moved = with_effects(get_sensor("ideal"), ca, ["lateral_colour"])
    assert moved.camera_lens.lateral_colour_px == PAPER_LATERAL_COLOUR_PX["camera"]
    assert moved.projector.lens.lateral_colour_px == PAPER_LATERAL_COLOUR_PX["projector"]
    d["camera"]["lens"]["lateral_colour_px"] = [0.0, 60.0, 0.0]
    with pytest.raises(ValueError, match="lateral_colour_px"):
        sensor_from_dict(d)
    d["camera"]["lens"]["lateral_colour_px"] = [0.0, 1.0]
    with pytest.raises(ValueError, match="lateral_colour_px"):
        sensor_from_dict(d)


def test_the_projector_drive_carries_the_projector_lens_lateral_colour():
    """The drive of a projector with lateral colour is the drive without it, each channel
    magnified about the projector's principal point (simbench.optics.lateral_colour_image)."""
    from simbench.sim.sensor import with_lateral_colour
    from simbench.optics import lateral_colour_image
    from simbench.pattern import PatternSpec, fringe_pattern, quantize
    from simbench.sim.scene import load_scene
    from simbench.sim.drive import projector_drive_for

    from .conftest import SCENES

    scene = load_scene(SCENES / "white_plane.toml")
    pattern = quantize(fringe_pattern(PatternSpec()))
    ideal = get_sensor("ideal")
    shift = (0.5, 0.0, -0.5)
    plain = projector_drive_for(scene, pattern, ideal)
    dispersed = projector_drive_for(scene, pattern, with_lateral_colour(ideal, camera_px=(0, 0, 0), projector_px=shift))
    assert np.array_equal(dispersed, lateral_colour_image(plain, scene.rig.projector, shift_px=shift))
    assert not np.array_equal(dispersed[..., 0], plain[..., 0]) and np.array_equal(dispersed[..., 1], plain[..., 1])


def test_a_sensor_file_that_leaves_keys_out_is_told_the_values_that_stand_in(tmp_path, caplog):
    """The fresh-clone audit: a copy of paper.toml without `cfa` or `prnu` recorded without a
    mosaic or PRNU and said nothing.  Now the file's load names each key left out and the value
    used; the presets themselves (documented in their comments) load quietly, and a complete copy
    of paper.toml says nothing either."""
    import logging

    from simbench.sim.sensor import PRESETS_DIR, left_out_keys, load_sensor

    text = (PRESETS_DIR / "paper.toml").read_text()
    full = tmp_path / "mine.toml"
    full.write_text(text)
    with caplog.at_level(logging.WARNING, logger="simbench"):
        assert load_sensor(full) == get_sensor("paper")
        for name in SENSOR_PRESETS:
            get_sensor(name)
    assert not caplog.records, [r.getMessage() for r in caplog.records]

    cut = tmp_path / "cut.toml"
    cut.write_text("\n".join(line for line in text.splitlines() if not line.startswith(("prnu", "cfa", "ratio"))))
    with caplog.at_level(logging.WARNING, logger="simbench"):
        sensor = load_sensor(cut)
    assert sensor.camera.prnu == 0.0 and sensor.camera.cfa == "none" and sensor.ambient_ratio == 0.0
    (message,) = [r.getMessage() for r in caplog.records]
    assert f"sensor {cut} leaves out 3 key(s)" in message
    assert message.endswith("camera.prnu = 0.0, camera.cfa = 'none', ambient.ratio = 0.0")
    # a simple camera's file is listed against its own fields; every value the model used
    minimal = tomllib.loads((PRESETS_DIR / "minimal.toml").read_text())
    listed = left_out_keys(minimal, get_sensor("minimal"))
    assert "camera.read_noise_e = 10.0" not in listed and "projector.dmd = 'square'" in listed
    assert "projector.contrast_ratio = 'inf'" in listed and "ambient.ratio = 0.0" in listed
    # (its exposure is a fraction of full scale: no lens photometry, and no crosstalk allowed)
    assert not [k for k in listed if k.startswith(("camera.lens.", "spectral."))], listed


def test_a_rig_whose_lens_is_not_the_sensor_models_is_refused():
    """A render takes its lenses from the sensor model (apply_to_rig): a rig stating another
    distortion would have been replaced without a word; the same distortion, or none, is fine."""
    from simbench.rig import paper_rig
    from simbench.sim.sensor import apply_to_rig, check_rig_lens

    paper = get_sensor("paper")
    check_rig_lens(paper_rig(), paper, where="r")
    check_rig_lens(apply_to_rig(paper_rig(), paper), paper, where="r")  # what calibration records
    rig = paper_rig()
    odd = dataclasses.replace(rig, camera=dataclasses.replace(rig.camera, distortion=(-0.2, 0.0, 0.0, 0.0, 0.0)))
    with pytest.raises(
        ValueError, match=r"^r: the rig's camera distortion \[-0.2, 0.0, 0.0, 0.0, 0.0\] is not the lens"
    ):
        check_rig_lens(odd, paper, where="r")


def test_a_projector_lens_left_out_takes_the_projector_lenses_f_number():
    """A sensor file without [projector.lens] took the camera lens's default f/4 (reported so),
    while the code's projector lens is f/2: now f/2 either way, and so reported."""
    from simbench.sim.sensor import PROJECTOR_F_NUMBER, ProjectorModel, left_out_keys

    base = sensor_to_dict(get_sensor("paper"))
    data = {**base, "projector": {k: v for k, v in base["projector"].items() if k != "lens"}}
    sensor = sensor_from_dict(data)
    assert sensor.projector.lens.f_number == PROJECTOR_F_NUMBER == ProjectorModel().lens.f_number == 2.0
    assert "projector.lens.f_number = 2.0" in left_out_keys(data, sensor)
