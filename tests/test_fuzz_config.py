"""Property-based fuzzing of every configuration input (Hypothesis): rig, scene, sensor and
sweep tables, and ``--decoder NAME=VALUE``.  Whatever the values, the result is a valid object
or a ``ValueError`` / ``FileNotFoundError`` with a one-line message: never another exception
type (a crash), never an accepted value of the wrong type."""

from __future__ import annotations

import copy
import dataclasses
import io
import math
import tomllib
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from simbench.decode import DecoderParams
from simbench.sim.sensor import get_sensor, sensor_from_dict, sensor_to_dict
from simbench.experiments.ablate import sweep_from_dict
from simbench.rig import paper_rig, rig_from_dict, rig_to_dict
from simbench.sim.scene import scene_from_dict

ROOT = Path(__file__).resolve().parents[1]
CONFIG_ERRORS = (ValueError, FileNotFoundError)

scalars = st.one_of(
    st.booleans(),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=12),
)
values = st.recursive(
    scalars,
    lambda inner: st.one_of(st.lists(inner, max_size=6), st.dictionaries(st.text(max_size=8), inner, max_size=4)),
    max_leaves=12,
)
FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow], derandomize=True)


def _paths(d: dict, prefix=()) -> list[tuple]:
    out = []
    for k, v in d.items():
        if isinstance(v, dict):
            out += _paths(v, prefix + (k,))
        else:
            out.append(prefix + (k,))
    return out


def _mutate(base: dict, data) -> dict:
    """``base`` with 1-4 leaves replaced by arbitrary values, or deleted, or a key added."""
    d = copy.deepcopy(base)
    leaves = _paths(d)
    for _ in range(data.draw(st.integers(1, 4))):
        path = data.draw(st.sampled_from(leaves))
        node = d
        for k in path[:-1]:
            node = node.get(k) if isinstance(node, dict) else None
            if not isinstance(node, dict):
                break
        else:
            action = data.draw(st.sampled_from(["replace", "replace", "replace", "delete", "add"]))
            if action == "replace":
                node[path[-1]] = data.draw(values)
            elif action == "delete":
                node.pop(path[-1], None)
            else:
                node[data.draw(st.text(min_size=1, max_size=8))] = data.draw(values)
    return d


def _one_line(exc: BaseException) -> None:
    msg = str(exc)
    assert msg and "\n" not in msg.strip(), repr(msg)


def _check(fn, *args, **kw):
    try:
        return fn(*args, **kw)
    except CONFIG_ERRORS as exc:
        _one_line(exc)
        return None


def _finite_tree(x) -> bool:
    if isinstance(x, float):
        return math.isfinite(x)
    if isinstance(x, (list, tuple)):
        return all(_finite_tree(v) for v in x)
    if isinstance(x, dict):
        return all(_finite_tree(v) for v in x.values())
    return True


RIG = rig_to_dict(paper_rig())


@FUZZ
@given(st.data())
def test_rig_tables(data):
    rig = _check(rig_from_dict, _mutate(RIG, data))
    if rig is not None:  # an accepted rig is a usable one
        assert rig.camera.width_px >= 1 and rig.camera.focal_px > 0 and rig.baseline_m > 0
        assert _finite_tree(rig_to_dict(rig))
        assert rig_from_dict(rig_to_dict(rig)) == rig


SCENE = tomllib.loads((ROOT / "scenes" / "sphere.toml").read_text())


@FUZZ
@given(st.data())
def test_scene_tables(data):
    scene = _check(scene_from_dict, _mutate(SCENE, data), base_dir=ROOT / "scenes")
    if scene is not None:
        assert scene.objects and scene.reference_depth_m > 0 and math.isfinite(scene.reference_depth_m)
        for o in scene.objects:
            assert all(0.0 <= c <= 1.0 for c in o.material.rgb)


SENSOR = sensor_to_dict(get_sensor("paper"))


@FUZZ
@given(st.data())
def test_sensor_tables(data):
    sensor = _check(sensor_from_dict, _mutate(SENSOR, data))
    if sensor is not None:
        assert isinstance(sensor.crosstalk, bool) and math.isfinite(sensor.ambient_ratio)
        if hasattr(sensor.camera, "noise"):
            assert isinstance(sensor.camera.noise, bool)
        assert isinstance(sensor.camera_lens.defocus, bool) and isinstance(sensor.projector.lens.defocus, bool)
        assert 0 < sensor.projector.gamma <= 10
        assert sensor_from_dict(sensor_to_dict(sensor)) == sensor


SWEEP = tomllib.loads((ROOT / "simbench" / "studies" / "period.toml").read_text())


@FUZZ
@given(st.data())
def test_sweep_tables(data):
    sweep = _check(sweep_from_dict, _mutate(SWEEP, data))
    if sweep is not None:
        assert isinstance(sweep.repeats, int) and sweep.repeats >= 1 and isinstance(sweep.seed, int) and sweep.seed >= 0


DECODER_FIELDS = [f.name for f in dataclasses.fields(DecoderParams)]
toml_texts = st.one_of(
    st.sampled_from(
        [
            "true",
            "false",
            "1",
            "0",
            "-1",
            "0.5",
            "inf",
            "-inf",
            "nan",
            "1e309",
            '"ftp"',
            "ftp",
            "[1, 2]",
            "[0.5, 2.0]",
            "[]",
            "{}",
            '"0101"',
            "maybe",
            "",
        ]
    ),
    st.text(max_size=10),
    st.floats(allow_nan=True).map(repr),
    st.integers(-(2**65), 2**65).map(str),
)


@FUZZ
@given(name=st.one_of(st.sampled_from(DECODER_FIELDS), st.text(max_size=8)), text=toml_texts)
def test_decoder_overrides(name, text):
    from simbench.decode import with_assignments

    params = _check(with_assignments, DecoderParams(), [f"{name}={text}"])
    if params is not None:
        for f in dataclasses.fields(params):
            v = getattr(params, f.name)
            assert _finite_tree(v) or f.name == "max_residual", (f.name, v)
            if f.type in ("bool",):
                assert isinstance(v, bool)
        assert DecoderParams(**dataclasses.asdict(params)) == params


@settings(max_examples=40, deadline=None, derandomize=True)
@given(name=st.sampled_from(DECODER_FIELDS), text=toml_texts)
def test_decoder_option_through_the_cli_is_a_result_or_one_line(tmp_path_factory, name, text):
    """``simbench decode --decoder NAME=VALUE`` on a rig whose file does not exist: a bad value
    is reported before anything is read; a good one reaches the missing-file error."""
    from simbench.cli import main

    d = tmp_path_factory.mktemp("fuzz")
    err = io.StringIO()
    with redirect_stderr(err), redirect_stdout(io.StringIO()):
        rc = main(
            [
                "decode",
                str(d / "c.png"),
                "--rig",
                str(d / "rig.toml"),
                "--out",
                str(d / "o.npy"),
                "--decoder",
                f"{name}={text}",
            ]
        )
    lines = err.getvalue().strip().splitlines()
    assert rc == 2 and len(lines) == 1 and lines[0].startswith("simbench: error:"), err.getvalue()
    assert not any(d.iterdir())


@pytest.mark.parametrize("field", ["voting", "color_normalize", "link_check"])
def test_booleans_only_from_booleans(field):
    for bad in ("false", "true", 0, 1, "maybe", None):
        with pytest.raises(ValueError, match=field):
            DecoderParams(**{field: bad})


@pytest.mark.parametrize("value", [[1, 2], {"a": 1}, 3, None])
def test_registered_names_only_from_strings(value):
    """A list or table where a registry's name goes is a ValueError naming the field (a dict lookup
    of the unhashable value raised TypeError: the fuzzer found ``phase_method=[1, 2]`` in CI)."""
    with pytest.raises(ValueError, match="phase_method"):
        DecoderParams(phase_method=value)
    scene = copy.deepcopy(SCENE)
    scene["object"][0]["type"] = value
    with pytest.raises(ValueError, match=r"object\[0\]: type"):
        scene_from_dict(scene, base_dir=ROOT / "scenes")
