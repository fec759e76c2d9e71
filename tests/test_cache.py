"""The content-hash render cache."""

import dataclasses
import itertools
import json
import os
from pathlib import Path

import numpy as np
import pytest

from simbench.cache import RenderCache, array_digest
from simbench.sim.scene import scene_fingerprint
from simbench.sim.scene import scene_from_dict

from .conftest import SCENES


def test_get_or_make_stores_then_hits(tmp_path):
    cache = RenderCache(tmp_path)
    calls = []

    def make():
        calls.append(1)
        return {"a": np.arange(5, dtype=np.float32)}

    a = cache.get_or_make("radiance", {"x": 1}, make)
    b = cache.get_or_make("radiance", {"x": 1}, make)
    c = cache.get_or_make("radiance", {"x": 2}, make)
    assert len(calls) == 2 and (cache.hits, cache.misses) == (1, 2)
    assert np.array_equal(a["a"], b["a"]) and b["a"].dtype == np.float32 and np.array_equal(c["a"], a["a"])
    assert len(list(tmp_path.glob("*.npz"))) == 2 and not list(tmp_path.glob(".*tmp"))


def test_damaged_entry_is_remade(tmp_path):
    cache = RenderCache(tmp_path)
    cache.get_or_make("k", {"x": 1}, lambda: {"a": np.ones(3)})
    (entry,) = tmp_path.glob("*.npz")
    entry.write_bytes(b"garbage")
    out = cache.get_or_make("k", {"x": 1}, lambda: {"a": np.zeros(3)})
    assert np.array_equal(out["a"], np.zeros(3)) and cache.misses == 2


def test_an_entry_under_another_entrys_name_is_damaged_not_served(tmp_path):
    """Two entries' files swapped (by hand, a sync tool): each checksum still matches its arrays,
    but the key stored under it does not match the file's name - both re-made, never served as
    the other key's (an audit, 2026-11-30: two recordings swapped, `render` sealed the other
    capture, exit 0).  An entry written before the key was stored (none) is read as before."""
    cache = RenderCache(tmp_path)
    cache.get_or_make("recording", {"x": 1}, lambda: {"a": np.ones(3)})
    cache.get_or_make("recording", {"x": 2}, lambda: {"a": np.full(3, 2.0)})
    one, two = (tmp_path / f"{cache.key('recording', {'x': x})}.npz" for x in (1, 2))
    swap = tmp_path / "swap"
    one.rename(swap), two.rename(one), swap.rename(two)
    fresh = RenderCache(tmp_path)
    out = fresh.get_or_make("recording", {"x": 1}, lambda: {"a": np.zeros(3)})
    assert np.array_equal(out["a"], np.zeros(3)) and (fresh.hits, fresh.damaged) == (0, 1)
    with np.load(two) as z:  # an older entry: no key inside, its checksum re-made over the rest
        arrays = {k: z[k] for k in z.files if k not in ("__key__", "__sha256__")}
    from simbench.cache import _arrays_digest

    np.savez(two, **arrays, __sha256__=np.frombuffer(bytes.fromhex(_arrays_digest(arrays)), np.uint8))
    assert np.array_equal(RenderCache(tmp_path).lookup("recording", {"x": 2})["a"], np.ones(3))


@pytest.mark.parametrize(
    "damage", ["truncate", "flip_zip_byte", "flip_array_byte", "empty", "no_checksum", "wrong_checksum"]
)
def test_every_kind_of_damage_is_remade_and_later_runs_hit(tmp_path, damage):
    """A damaged entry (zip CRC error, truncated file, an array changed behind the zip's back, an
    entry written without or with a wrong checksum) is re-made once; the run after that hits."""
    import io as _io
    import zipfile

    cache = RenderCache(tmp_path)
    good = {"a": np.arange(1000, dtype=np.float32), "b": np.ones((3, 4), np.uint8)}
    cache.get_or_make("radiance", {"x": 1}, lambda: good)
    (entry,) = tmp_path.glob("*.npz")
    data = bytearray(entry.read_bytes())
    if damage == "truncate":
        data = data[: len(data) // 2]
    elif damage == "flip_zip_byte":
        data[len(data) // 3] ^= 0x40
    elif damage == "empty":
        data = bytearray()
    else:
        with np.load(entry) as z:
            arrays = {k: z[k].copy() for k in z.files}
        if damage == "flip_array_byte":
            arrays["a"][10] += 1  # rewritten with valid zip CRCs: only the checksum can tell
        elif damage == "no_checksum":
            arrays.pop("__sha256__")
        else:
            arrays["__sha256__"] = np.zeros(32, np.uint8)
        buf = _io.BytesIO()
        np.savez(buf, **arrays)
        data = bytearray(buf.getvalue())
        assert zipfile.is_zipfile(_io.BytesIO(data))
    entry.write_bytes(bytes(data))
    fresh = RenderCache(tmp_path)
    out = fresh.get_or_make("radiance", {"x": 1}, lambda: {k: v + 0 for k, v in good.items()})
    assert fresh.damaged == 1 and fresh.misses == 1
    assert all(np.array_equal(out[k], good[k]) for k in good)
    again = RenderCache(tmp_path)
    again.get_or_make("radiance", {"x": 1}, lambda: pytest.fail("re-made a good entry"))
    assert (again.hits, again.damaged) == (1, 0)


def test_disabled_cache_always_makes():
    cache = RenderCache(None)
    n = []
    for _ in range(2):
        cache.get_or_make("k", {}, lambda: n.append(1) or {"a": np.zeros(1)})
    assert len(n) == 2


def test_fingerprint_sees_what_affects_a_render(tmp_path):
    base = {"object": [{"type": "plane", "size_m": [1, 1], "rgb": [0.5, 0.5, 0.5]}]}
    s = scene_from_dict(base)
    assert scene_fingerprint(s) == scene_fingerprint(scene_from_dict(base))
    assert scene_fingerprint(s) != scene_fingerprint(
        scene_from_dict({"object": [{"type": "plane", "size_m": [1, 1], "rgb": [0.5, 0.5, 0.6]}]})
    )
    assert scene_fingerprint(s) != scene_fingerprint(dataclasses.replace(s, ambient_rgb=(0.1, 0.1, 0.1)))
    # descriptions and names of the scene do not matter; a mesh's bytes do
    assert scene_fingerprint(s) == scene_fingerprint(dataclasses.replace(s, name="other", description="x"))
    mesh = tmp_path / "m.ply"
    mesh.write_bytes((SCENES / "meshes" / "cone.ply").read_bytes())
    m = {"object": [{"type": "mesh", "file": str(mesh)}]}
    f1 = scene_fingerprint(scene_from_dict(m))
    mesh.write_bytes((SCENES / "meshes" / "cylinder.ply").read_bytes())
    assert scene_fingerprint(scene_from_dict(m)) != f1


def test_array_digest_sees_dtype_shape_and_values():
    a = np.zeros((2, 3), np.float32)
    assert array_digest(a) != array_digest(a.astype(np.float64))
    assert array_digest(a) != array_digest(a.reshape(3, 2))
    b = a.copy()
    b[1, 2] = 1e-7
    assert array_digest(a) != array_digest(b)


def test_array_digest_is_the_sha256_of_the_arrays_bytes():
    """The cache's keys stay what they were: the dtype, the shape and tobytes()' bytes, for
    views, byte orders and record dtypes too (the digest hashes them without tobytes' copy)."""
    import hashlib

    rng = np.random.default_rng(5)
    arrays = [
        rng.random((40, 60, 3), dtype=np.float32),
        rng.random((5, 7))[::2, 1::3].T,
        np.arange(7, dtype=">i2"),
        np.array([True, False, True]),
        np.zeros(0),
        np.zeros(3, dtype=[("a", "<i4"), ("b", "<f8")]),
    ]
    for a in arrays:
        c = np.ascontiguousarray(a)
        assert array_digest(a) == hashlib.sha256(f"{c.dtype.str}{c.shape}".encode() + c.tobytes()).hexdigest()


@pytest.mark.slow
def test_decoder_change_does_not_rerender(tmp_path, variant, monkeypatch):
    """A second run with other decoder settings takes every render from the cache without even
    building a projector drive (the render keys' drive digests are cached by the drive's
    inputs), and the cached run's tables equal an uncached run's byte for byte.  On the flatness
    study's quick form (three boards, both protocols: ~10 s a run), the cheapest target that
    renders, builds drives and decodes (table3's competitors made it ~70 s in CI)."""
    from simbench.decode import DecoderParams
    from simbench.sim import drive
    from simbench.experiments.common import RunConfig
    from simbench.experiments.reproduce import reproduce

    cfg = RunConfig.preset(quick=True, compare_rigs=False)  # no calibration: this test is about renders
    quiet = lambda s: None  # noqa: E731
    reproduce(
        ["flatness"], config=cfg, out_dir=tmp_path / "a", cache_dir=tmp_path / "cache", progress=quiet, command="t"
    )
    renders = sorted((tmp_path / "cache").glob("radiance-*.npz"))
    assert renders and list((tmp_path / "cache").glob("drive_digests-*.npz"))
    other = dataclasses.replace(cfg, decoder=DecoderParams(sigma_periods=0.3))

    def no_drive(*args, **kwargs):
        raise AssertionError("a warm run built a projector drive")

    with monkeypatch.context() as m:
        m.setattr(drive, "_build_drive", no_drive)
        reproduce(
            ["flatness"],
            config=other,
            out_dir=tmp_path / "b",
            cache_dir=tmp_path / "cache",
            progress=quiet,
            command="t",
        )
    assert sorted((tmp_path / "cache").glob("radiance-*.npz")) == renders
    reproduce(["flatness"], config=cfg, out_dir=tmp_path / "c", cache_dir=None, progress=quiet, command="t")
    b = (tmp_path / "b" / "flatness.csv").read_text()
    assert b != (tmp_path / "a" / "flatness.csv").read_text()  # the decoder change changed the scores
    for f in ("flatness.csv", "flatness.md", "flatness.png"):
        assert (tmp_path / "a" / f).read_bytes() == (tmp_path / "c" / f).read_bytes(), f


def test_projector_drive_digests_match_the_drive_and_are_cached(tmp_path, variant):
    """ProjectorDrive's digests are those of projector_drive_for's array and of its
    single-primary drives (empty for a primary the drive leaves off); a second ProjectorDrive
    of the same inputs reads them from the cache without building the drive, and other inputs
    (another pattern, another exposure phase in video mode) are another entry."""
    from simbench.sim.sensor import get_sensor
    from simbench.pattern import calibration_frames
    from simbench.sim.drive import ProjectorDrive, mono_drive, projector_drive_for
    from simbench.sim.capture import physical_scene
    from simbench.experiments.common import Session, RunConfig

    sensor = get_sensor("paper")
    session = Session(RunConfig.preset(quick=True), out_dir=tmp_path, cache_dir=None, progress=lambda s: None)
    scene = physical_scene(session.scene("plane_white"), sensor)
    pattern = session.proposed.pattern_u8
    cache = RenderCache(tmp_path / "cache")
    first = ProjectorDrive(scene, pattern, sensor, cache=cache)
    array = projector_drive_for(scene, pattern, sensor)
    assert first.digests() == {
        "rgb": array_digest(array),
        **{f"mono{p}": array_digest(mono_drive(array, p)) for p in range(3)},
    }
    second = ProjectorDrive(scene, pattern, sensor, cache=cache)
    assert second.digests() == first.digests() and second._array is None
    red = calibration_frames(pattern)["red"]
    only_red = ProjectorDrive(
        scene, red, get_sensor("ideal"), cache=cache
    ).digests()  # a perfect black: green and blue off
    assert only_red["mono0"] and only_red["mono1"] == "" and only_red["mono2"] == ""
    video = dataclasses.replace(sensor, projector=dataclasses.replace(sensor.projector, timing="video"))
    a = ProjectorDrive(scene, pattern, video, cache=cache, phase=0.1).digests()
    b = ProjectorDrive(scene, pattern, video, cache=cache, phase=0.6).digests()
    assert a["rgb"] != b["rgb"] != first.digests()["rgb"]


def test_drives_of_kept_patterns_are_keyed_by_their_kept_digests(tmp_path, monkeypatch, variant):
    """The proposed pattern and the phase-shift frames are made and hashed once per process;
    a drive given that digest has the inputs (the cache key) of one that hashes the pattern,
    and so has a drive of a DriveImage, which makes its pattern only when the drive is built.
    The phase-shift frames' digests are also kept in the render cache: a process that finds
    them there never makes the frames."""
    from simbench.sim.sensor import get_sensor
    from simbench.sim.scene import load_scene
    from simbench.sim.drive import DriveImage, ProjectorDrive
    from simbench.sim.capture import physical_scene
    from simbench.systems import phase_shift, proposed
    from simbench.systems.phase_shift import PhaseShiftSystem

    sensor = get_sensor("paper")
    system = proposed.ColourFringeSystem()
    scene = physical_scene(system.prepare(load_scene(SCENES / "white_plane.toml")), sensor)
    kept = proposed.pattern_digest(system.pattern)
    assert kept == array_digest(system.pattern_u8)
    with_digest = ProjectorDrive(scene, DriveImage(kept, lambda: system.pattern_u8), sensor).inputs()
    assert with_digest == ProjectorDrive(scene, system.pattern_u8, sensor).inputs()
    made = []
    lazy = ProjectorDrive(scene, DriveImage(kept, lambda: made.append(1) or system.pattern_u8), sensor)
    assert lazy.inputs() == with_digest and made == []
    assert np.array_equal(lazy.array(), ProjectorDrive(scene, system.pattern_u8, sensor).array()) and made == [1]
    shifts = PhaseShiftSystem()
    cache = RenderCache(tmp_path / "cache")
    monkeypatch.setattr(phase_shift, "_digests", {})
    digests = phase_shift._frame_digests(shifts.spec, cache)
    assert list(digests) == [array_digest(f) for f in shifts.frames_u8()] and len(set(digests)) == len(digests)
    assert cache.misses == 1 and phase_shift._frame_digests(shifts.spec) == digests
    monkeypatch.setattr(phase_shift, "_digests", {})  # another process: the frames' digests from the cache

    def no_frames(spec):
        raise AssertionError("the frames were made again")

    monkeypatch.setattr(phase_shift, "_frames_u8", no_frames)
    assert phase_shift._frame_digests(shifts.spec, cache) == digests and cache.hits == 1


def test_recordings_are_cached_with_the_bits_of_a_fresh_recording(tmp_path, variant, monkeypatch):
    """record_channels gives record(render_channels(...)) for each noise seed (an integer or a
    SeedSequence); a second call reads the cached recordings, neither renders, drive digests nor
    camera noise (renders deleted, the camera model and the digests broken); another noise seed,
    sensor setting, reference depth, pattern or render seed is another recording; a Generator is
    recorded afresh, never cached."""
    from simbench.sim import capture
    from simbench.sim.sensor import get_sensor
    from simbench.sim.mitsuba_dict import RenderSettings
    from simbench.rig import scale_camera
    from simbench.sim.scene import load_scene
    from simbench.sim.drive import ProjectorDrive
    from simbench.sim.capture import physical_scene, record, record_channels, render_channels
    from simbench.systems.proposed import pattern_u8
    from simbench.pattern import PatternSpec

    sensor = get_sensor("paper")
    assert sensor.crosstalk  # the per-primary renders and their weights are in the key
    scene = load_scene(SCENES / "white_plane.toml")
    scene = physical_scene(dataclasses.replace(scene, rig=scale_camera(scene.rig, 0.1)), sensor)
    pattern = pattern_u8(PatternSpec())
    # an integer, and two SeedSequences that differ as a multi-shot sequence's frames do
    seeds = [11, np.random.SeedSequence([11, 7, 2]), np.random.SeedSequence([11, 7, 3])]
    plain = RenderSettings(spp=4, sampler="independent")
    q = render_channels(scene, ProjectorDrive(scene, pattern, sensor), sensor, seed=3, render=plain)
    fresh = [record(q, sensor=sensor, scene=scene, rng=n) for n in seeds]
    cache = RenderCache(tmp_path / "cache")
    cached = dataclasses.replace(plain, cache=cache)

    def recordings(**kw):
        args = {"scene": scene, "sensor": sensor, "seeds": seeds, "pattern": pattern, "seed": 3} | kw
        drive = ProjectorDrive(args["scene"], args["pattern"], args["sensor"], cache=cache)
        return record_channels(
            args["scene"], drive, args["sensor"], seed=args["seed"], render=cached, rngs=args["seeds"]
        )

    first = recordings()
    for a, b in zip(first, fresh):
        assert a.dtype == b.dtype and np.array_equal(a, b)
    files = sorted((tmp_path / "cache").glob("recording-*.npz"))
    assert len(files) == 3
    for f in (tmp_path / "cache").glob("radiance-*.npz"):
        f.unlink()

    def broken(*args, **kwargs):
        raise AssertionError("a cached recording was recorded again")

    with monkeypatch.context() as m:
        m.setattr(capture, "emva_camera", broken)
        m.setattr(ProjectorDrive, "digests", broken)  # keyed by the drive's inputs: no digest read
        again = recordings()
    for a, b in zip(again, first):
        assert np.array_equal(a, b)
    noisier = dataclasses.replace(
        sensor, camera=dataclasses.replace(sensor.camera, dark_noise_e=sensor.camera.dark_noise_e + 1)
    )
    farther = dataclasses.replace(scene, reference_depth_m=scene.reference_depth_m + 0.1)
    made = cache.misses
    recordings(seeds=[12])
    recordings(sensor=noisier, seeds=[11])
    recordings(scene=farther, seeds=[11])
    recordings(pattern=pattern[:, ::-1].copy(), seeds=[11])
    recordings(seed=4, seeds=[11])
    assert len(list((tmp_path / "cache").glob("recording-*.npz"))) == 8
    assert cache.misses > made
    recordings(seeds=[np.random.default_rng(11)])
    assert len(list((tmp_path / "cache").glob("recording-*.npz"))) == 8


def test_simulator_code_digest_holds_the_lens_loops_and_not_the_decoders(tmp_path, monkeypatch):
    """The simulator's code digest (part of every recording's and projector drive's key) changes
    with the lens model's C source (simbench/_lens.c) and with any simulator module, and not
    with the decoder's C source (simbench/_ckernels.c), so an edit of a decoder loop re-records
    nothing; the loops they call (the lens maps, the defocus blur's levels) are defined in the
    hashed file, and only there (the projector model's too: drives depend on them)."""
    import re

    from simbench import native, optics
    from simbench.sim import keys, projector

    lens, kernels = native.LENS_SOURCE.read_text(), native.SOURCE.read_text()
    for name in [*optics._BROWN, *optics._BLUR, *projector._LUT, *projector._DMD]:
        defined = re.compile(rf"^\w+ {name}\(", re.M)
        assert defined.search(lens) and not defined.search(kernels), name

    def digest():
        keys.sim_code_digest.cache_clear()
        return keys.sim_code_digest()

    base = digest()
    for attr in ("SOURCE", "LENS_SOURCE"):
        edited = tmp_path / getattr(native, attr).name
        edited.write_bytes(getattr(native, attr).read_bytes() + b"\n/* edited */\n")
        with monkeypatch.context() as m:
            m.setattr(native, attr, edited)
            changed = digest() != base
        assert changed == (attr == "LENS_SOURCE"), attr
    # a simulator module: every file of simbench/sim is hashed (no hand-kept list) - by what its
    # code does: a comment, a docstring or the layout changed keeps the digest
    sim_dir = Path(keys.__file__).parent
    for edit, changes in (
        (lambda text: text + b"\n_EDITED = 1\n", True),
        (lambda text: text + b"\n# edited\n", False),
        (
            lambda text: text.replace(b'"""', b'"""An edited docstring. ', 1).replace(b"\n\ndef ", b"\n\n\n\ndef "),
            False,
        ),
    ):
        copy = tmp_path / f"sim{len(list(tmp_path.glob('sim*')))}"
        copy.mkdir()
        for f in sim_dir.glob("*.py"):
            (copy / f.name).write_bytes(edit(f.read_bytes()) if f.name == "camera.py" else f.read_bytes())
        with monkeypatch.context() as m:
            m.setattr(keys, "__file__", str(copy / "keys.py"))
            assert (digest() != base) == changes, changes
    assert digest() == base


def test_source_digest_follows_the_code_not_its_comments_docstrings_or_layout(tmp_path, monkeypatch):
    """simbench.cache.source_digest: a Python file by its syntax tree less docstrings (module,
    class and function ones; a string elsewhere is code), kept in a memo by the file's bytes -
    a damaged memo recomputed, the memo off when SIMBENCH_CACHE_DIR is empty - and a C file by
    its bytes."""
    from simbench import cache as cache_mod

    monkeypatch.setenv("SIMBENCH_CACHE_DIR", str(tmp_path / "memo"))
    src = tmp_path / "m.py"
    stamps = itertools.count(1)

    def digest(text: str) -> str:
        src.write_text(text)
        os.utime(src, ns=(1, next(stamps)))  # a new modification time: not the in-process memo's entry
        return cache_mod.source_digest([src])

    base = digest(
        '"""Module."""\n\ndef f(x):\n    """Doc."""\n    return x + 1  # one\n\nclass A:\n    """A."""\n    y = "s"\n'
    )
    same = (
        '# a comment\n"""Other module text."""\ndef f(x):\n    return (x +\n            1)\n'
        'class A:\n    """B."""\n    y = "s"\n'
    )
    assert digest(same) == base
    for changed in (
        '"""Module."""\ndef f(x):\n    return x + 2\nclass A:\n    y = "s"\n',  # a constant
        '"""Module."""\ndef f(x):\n    return x + 1\nclass A:\n    y = "t"\n',  # a string that is code
        '"""Module."""\ndef f(y):\n    return y + 1\nclass A:\n    y = "s"\n',  # a name
    ):
        assert digest(changed) != base, changed
    memo = next((tmp_path / "memo").glob(f"code-digests-v{cache_mod.CODE_TEXT_VERSION}-python*.json"))
    assert len(json.loads(memo.read_text())) >= 4
    memo.write_text("{not json")
    assert digest(same) == base and isinstance(json.loads(memo.read_text()), dict)
    monkeypatch.setenv("SIMBENCH_CACHE_DIR", "")
    assert digest(same) == base
    # a file that does not parse (one being written, say) counts by its bytes
    broken = digest("def f(:\n")
    assert broken != base and digest("def f(:\n ") != broken
    c = tmp_path / "k.c"
    c.write_bytes(b"int f(void) { return 1; }\n")
    one = cache_mod.source_digest([c])
    c.write_bytes(b"int f(void) { return 1; } /* a comment */\n")
    os.utime(c, ns=(1, 2))
    assert cache_mod.source_digest([c]) != one


def _make_once(root: str, log: str, start) -> tuple[int, int, list]:
    """In a spawned process: get_or_make of one key whose make takes a while and logs itself."""
    import os
    import time

    cache = RenderCache(root)
    start.wait()  # both processes look up together

    def make():
        with open(log, "a") as fh:
            fh.write(f"{os.getpid()}\n")
        time.sleep(0.5)
        return {"a": np.arange(5.0)}

    out = cache.get_or_make("shared", {"x": 1}, make)
    return cache.hits, cache.misses, out["a"].tolist()


def test_processes_sharing_the_cache_make_an_entry_once(tmp_path):
    """Two processes missing the same entry at once: one makes it, the other waits for its lock
    and reads it (a hit); no lock file is left behind."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    ctx = mp.get_context("spawn")
    start = ctx.Manager().Barrier(2)
    log = tmp_path / "made.txt"
    with ProcessPoolExecutor(2, mp_context=ctx) as pool:
        futures = [pool.submit(_make_once, str(tmp_path / "cache"), str(log), start) for _ in range(2)]
        results = sorted(f.result() for f in futures)
    assert len(log.read_text().split()) == 1
    assert results == [(0, 1, [0.0, 1.0, 2.0, 3.0, 4.0]), (1, 0, [0.0, 1.0, 2.0, 3.0, 4.0])]
    assert [p.name for p in (tmp_path / "cache").iterdir() if p.suffix != ".npz"] == ["CACHEDIR.TAG"]


def test_a_caller_that_does_not_wait_skips_an_entry_another_holder_is_making(tmp_path):
    """``wait=False``: None at once while another holder has the entry's lock (nothing made,
    nothing counted), the entry made once the lock is free; and a holder that gets the lock
    after the entry was stored reads it rather than making it again."""
    from simbench.cache import _KeyLock

    cache = RenderCache(tmp_path)
    made = []

    def make():
        made.append(1)
        return {"a": np.arange(3.0)}

    other = _KeyLock(tmp_path, cache.key("k", {"x": 1}))  # its own open file: another holder to flock
    assert other.acquire_now()
    assert cache.get_or_make("k", {"x": 1}, make, wait=False) is None
    assert made == [] and (cache.hits, cache.misses) == (0, 0)
    other.__exit__(None, None, None)
    assert cache.get_or_make("k", {"x": 1}, make, wait=False)["a"].tolist() == [0.0, 1.0, 2.0]
    assert made == [1] and (cache.hits, cache.misses) == (0, 1)

    # the lookup missed, then the maker stored the entry and let the lock go: read, not made
    lookup = cache.lookup
    cache.lookup = lambda kind, parts: (setattr(cache, "misses", cache.misses + 1), None)[1]
    assert cache.get_or_make("k", {"x": 1}, make)["a"].tolist() == [0.0, 1.0, 2.0]
    cache.lookup = lookup
    assert made == [1] and (cache.hits, cache.misses) == (1, 1)
    assert RenderCache(None).get_or_make("k", {}, make, wait=False)["a"].tolist() == [0.0, 1.0, 2.0]


def test_a_lock_held_too_long_is_passed_with_a_warning(tmp_path, monkeypatch):
    """The backstop: a waiter whose entry another holder keeps locked past ``LOCK_WAIT_S`` makes
    the entry itself, with a warning that names it."""
    import simbench.cache as cache_module

    monkeypatch.setattr(cache_module, "LOCK_WAIT_S", 0.2)
    cache = RenderCache(tmp_path)
    other = cache_module._KeyLock(tmp_path, cache.key("k", {}))
    assert other.acquire_now()
    with pytest.warns(UserWarning, match="another process held it"):
        assert cache.get_or_make("k", {}, lambda: {"a": np.ones(2)})["a"].tolist() == [1.0, 1.0]
    other.__exit__(None, None, None)


def test_a_failed_make_frees_its_key_and_entries_nest(tmp_path):
    """A make that raises leaves neither an entry nor a lock, and the key can be made after; an
    entry made from another entry (nested keys) is made, each once."""

    def fails():
        raise RuntimeError("make failed")

    cache = RenderCache(tmp_path)
    with pytest.raises(RuntimeError, match="make failed"):
        cache.get_or_make("k", {}, fails)
    assert [p.name for p in tmp_path.iterdir()] == ["CACHEDIR.TAG"]
    assert cache.get_or_make("k", {}, lambda: {"a": np.ones(2)})["a"].tolist() == [1.0, 1.0]

    def outer():
        return {"b": cache.get_or_make("inner", {}, lambda: {"c": np.full(2, 3.0)})["c"] * 2}

    assert cache.get_or_make("outer", {}, outer)["b"].tolist() == [6.0, 6.0]
    assert sorted(p.suffix for p in tmp_path.glob("*-*")) == [".npz"] * 3 and cache.misses == 4


def test_made_entries_are_counted_per_kind_with_their_own_time(tmp_path, monkeypatch):
    """A recording made around a render it needs is counted as one recording and one render,
    each with its own seconds (the recording's less the render's); a failed make is not counted."""
    import simbench.cache as module

    clock = [0.0]
    monkeypatch.setattr(module.time, "perf_counter", lambda: clock[0])
    cache = RenderCache(tmp_path)

    def render():
        clock[0] += 3.0
        return {"r": np.ones(2)}

    def record():
        clock[0] += 1.0
        cache.get_or_make("radiance", {"x": 1}, render)
        clock[0] += 0.5
        return {"i": np.ones(2)}

    cache.get_or_make("recording", {"x": 1}, record)
    cache.get_or_make("recording", {"x": 1}, record)  # a hit: nothing made
    assert cache.made == {"recording": (1, 1.5), "radiance": (1, 3.0)}

    def broken():
        clock[0] += 7.0
        raise RuntimeError("render failed")

    with pytest.raises(RuntimeError, match="render failed"):
        cache.get_or_make("radiance", {"x": 2}, broken)
    assert cache.made["radiance"] == (1, 3.0) and cache.misses == 3
    cache.add_made({"radiance": (2, 4.0), "truth": (1, 0.5)})  # a worker's counts
    assert cache.made_summary() == "radiance 3 (7.0 s), recording 1 (1.5 s), truth 1 (0.5 s)"
    assert RenderCache(None).made_summary() == "nothing"


def test_the_ambient_renders_sample_count_is_a_quarter_that_the_sampler_accepts():
    """simbench.sim.mitsuba_dict.ambient_spp: the largest count at most spp / 4 that the sampler
    renders exactly (check_sampler), at least 1; the projector's own where the sampler accepts no
    smaller count."""
    from simbench.sim.mitsuba_dict import SAMPLERS, ambient_spp, check_sampler

    assert [ambient_spp(s, "multijitter") for s in (1, 4, 9, 16, 36, 64, 100)] == [1, 1, 1, 4, 9, 16, 25]
    assert [ambient_spp(s, "independent") for s in (1, 3, 4, 10, 36)] == [1, 1, 1, 2, 9]
    assert [ambient_spp(s, "ldsampler") for s in (4, 16, 64, 256)] == [1, 4, 16, 64]
    assert [ambient_spp(s, "orthogonal") for s in (4, 9, 25, 49, 121)] == [4, 9, 4, 9, 25]
    for sampler in SAMPLERS:
        for spp in (1, 4, 9, 16, 25, 36, 49, 64, 121, 256):
            try:
                check_sampler(sampler, spp)
            except ValueError:
                continue
            n = ambient_spp(spp, sampler)
            check_sampler(sampler, n)
            assert n <= max(1, spp // 4) or n == spp


def test_samples_per_pass_keep_every_pixel_in_one_dr_jit_work_unit(variant):
    """A pass's sample count divides 16384 (the work unit of a large wavefront) and 4 (the
    SIMD packet, the unit's granularity on a small one), and the passes make up the count;
    a power of two on a full-resolution render stays one pass (its images, and cache keys,
    unchanged)."""
    from simbench.sim.mitsuba_dict import pass_settings, samples_per_pass

    full, small = 1280 * 960, 160 * 120
    for spp in (1, 2, 3, 4, 9, 16, 25, 36, 49, 64, 100, 256):
        for pixels in (full, small):
            n = samples_per_pass(spp, pixels=pixels)
            assert spp % n == 0 and 16384 % n == 0
            assert n == spp or 4 % n == 0
    assert [samples_per_pass(s, pixels=full) for s in (1, 4, 9, 16, 25, 36, 64)] == [1, 4, 1, 16, 1, 4, 64]
    assert [samples_per_pass(s, pixels=small) for s in (4, 16, 36, 64)] == [4, 4, 4, 4]
    assert samples_per_pass(4, pixels=640 * 480) == 4 and samples_per_pass(16, pixels=640 * 480) == 16
    jit = {} if variant.startswith("scalar") else {"samples_per_pass": 4}  # scalar: a pixel is one thread's
    assert pass_settings(36, pixels=full) == jit and pass_settings(64, pixels=full) == {}


def test_film_settings_mark_the_films_dr_jit_added_into_by_expansion(variant):
    """A render's cache key says "film_adds: atomic" exactly where Dr.Jit's default threshold
    would have added into the film through per-thread copies (H x W x the film's channels <=
    2^20 entries; the channel count read from Mitsuba's film): the ToF camera's and the small
    test renders, not 640x480 or 1280x960, whose images and keys are unchanged."""
    import drjit as dr
    import mitsuba as mi

    from simbench.sim.mitsuba_dict import FILM_CHANNELS, atomic_film_adds, film_settings

    film = {"type": "hdrfilm", "width": 8, "height": 4, "rfilter": {"type": "box"}, "pixel_format": "rgb"}
    scene = mi.load_dict({"type": "scene", "sensor": {"type": "perspective", "film": film}})
    assert scene.sensors()[0].film().prepare([]) == FILM_CHANNELS
    jit = {} if variant.startswith("scalar") else {"film_adds": "atomic"}
    assert film_settings(pixels=176 * 144) == jit and film_settings(pixels=512 * 512) == jit
    assert film_settings(pixels=640 * 480) == {} and film_settings(pixels=1280 * 960) == {}
    before = dr.expand_threshold()
    with atomic_film_adds():
        assert dr.expand_threshold() == 0
    assert dr.expand_threshold() == before


# ---------------------------------------------------------------------------------------
# What a cache holds, pruning it, and a full disk.


def _entry_path(cache, kind, parts):
    return cache.root / f"{cache.key(kind, parts)}.npz"


def _aged(path, age_s, now_s):
    import os

    os.utime(path, (now_s - age_s, now_s - age_s))


def test_a_hit_marks_its_entry_used_and_pruning_removes_the_least_recently_used(tmp_path):
    """Three entries written long ago; one is hit now: a size bound keeps the hit one and the
    most recently written of the others, and a dry run removes nothing."""
    import time

    from simbench.cache import cache_entries, cache_usage, prune_cache

    cache = RenderCache(tmp_path)
    now = time.time()
    for i, age_days in enumerate((30, 20, 10)):
        cache.get_or_make("radiance", {"i": i}, lambda: {"a": np.zeros(1000, np.float32)})
        _aged(_entry_path(cache, "radiance", {"i": i}), age_days * 86400, now)
    cache.get_or_make("truth", {"i": 9}, lambda: {"d": np.zeros(10, np.float32)})
    _aged(_entry_path(cache, "truth", {"i": 9}), 1, now)  # file times tick coarsely: written before the hit
    size = _entry_path(cache, "radiance", {"i": 0}).stat().st_size
    assert cache.get_or_make("radiance", {"i": 0}, lambda: pytest.fail("a hit")) is not None
    assert cache_entries(tmp_path)[-1].path == _entry_path(cache, "radiance", {"i": 0})  # the hit: the latest use
    assert cache_usage(tmp_path)["radiance"] == (3, 3 * size)

    truth_size = _entry_path(cache, "truth", {"i": 9}).stat().st_size
    keep = 2 * size + truth_size
    would = prune_cache(tmp_path, max_bytes=keep, dry_run=True)
    assert would.paths == [_entry_path(cache, "radiance", {"i": 1})]
    assert len(cache_entries(tmp_path)) == 4
    removed = prune_cache(tmp_path, max_bytes=keep)
    assert removed == would
    left = {c.path for c in cache_entries(tmp_path)}
    assert left == {_entry_path(cache, "radiance", {"i": i}) for i in (0, 2)} | {_entry_path(cache, "truth", {"i": 9})}
    assert cache.get_or_make("radiance", {"i": 1}, lambda: {"a": np.ones(1000, np.float32)})["a"][0] == 1  # re-made


def test_pruning_by_age_and_its_bounds(tmp_path):
    import time

    from simbench.cache import cache_entries, prune_cache

    cache = RenderCache(tmp_path)
    now = time.time()
    for i, age_days in enumerate((9, 6, 1)):
        cache.store("recording", {"i": i}, {"a": np.zeros(10)})
        _aged(_entry_path(cache, "recording", {"i": i}), age_days * 86400, now)
    removed = prune_cache(tmp_path, unused_for_s=5 * 86400, now_s=now)
    assert set(removed.paths) == {_entry_path(cache, "recording", {"i": i}) for i in (0, 1)}
    assert [c.path for c in cache_entries(tmp_path)] == [_entry_path(cache, "recording", {"i": 2})]
    assert prune_cache(tmp_path, max_bytes=0, dry_run=True).entries  # 0 empties it
    with pytest.raises(ValueError, match="max_bytes or unused_for_s"):
        prune_cache(tmp_path)
    with pytest.raises(ValueError, match=">= 0"):
        prune_cache(tmp_path, max_bytes=-1)
    with pytest.raises(FileNotFoundError, match="no such cache folder"):
        prune_cache(tmp_path / "nope", max_bytes=0)


def test_pruning_removes_killed_writers_leftovers_and_only_those(tmp_path):
    """A temporary file older than STALE_TEMP_S and a lock no process holds go; a fresh
    temporary (a live writer's) and a held lock stay."""
    import fcntl
    import os
    import time

    from simbench.cache import STALE_TEMP_S, claim_cache_folder, prune_cache

    now = time.time()
    claim_cache_folder(tmp_path)  # marks it
    old_tmp, new_tmp = tmp_path / f".radiance-{'a' * 32}.x1_k9.tmp", tmp_path / f".radiance-{'b' * 32}.x2.tmp"
    free_lock, held_lock = tmp_path / f"radiance-{'c' * 32}.lock", tmp_path / f"radiance-{'d' * 32}.lock"
    for p in (old_tmp, new_tmp, free_lock, held_lock):
        p.write_bytes(b"")
    _aged(old_tmp, STALE_TEMP_S + 60, now)
    fd = os.open(held_lock, os.O_RDWR)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        would = prune_cache(tmp_path, max_bytes=1 << 30, now_s=now, dry_run=True)
        assert would.paths == sorted([old_tmp, free_lock]) and old_tmp.exists() and free_lock.exists()
        assert prune_cache(tmp_path, max_bytes=1 << 30, now_s=now) == would
    finally:
        os.close(fd)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["CACHEDIR.TAG", new_tmp.name, held_lock.name])


def test_a_full_disk_leaves_entries_unstored_and_the_run_going(tmp_path, monkeypatch, caplog):
    """ENOSPC (or a quota) writing an entry: the made arrays are returned, nothing is stored,
    one warning names the cache and how to free it; other write errors (but a read-only cache's,
    below) still raise."""
    import errno
    import logging

    import simbench.cache as module

    def full(path, data):
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    monkeypatch.setattr(module, "atomic_write_bytes", full)
    cache = RenderCache(tmp_path)
    with caplog.at_level(logging.WARNING, logger="simbench.cache"):
        a = cache.get_or_make("radiance", {"x": 1}, lambda: {"a": np.arange(3.0)})
        b = cache.get_or_make("radiance", {"x": 2}, lambda: {"a": np.arange(4.0)})
    assert np.array_equal(a["a"], np.arange(3.0)) and np.array_equal(b["a"], np.arange(4.0))
    assert cache.unstored == 2 and not list(tmp_path.glob("*.npz")) and not list(tmp_path.glob("*.lock"))
    (record,) = caplog.records
    assert str(tmp_path) in record.getMessage() and "simbench cache prune" in record.getMessage()

    def failing(path, data):
        raise OSError(errno.EIO, "Input/output error", str(path))

    monkeypatch.setattr(module, "atomic_write_bytes", failing)
    with pytest.raises(OSError, match="Input/output"):
        cache.get_or_make("radiance", {"x": 3}, lambda: {"a": np.arange(2.0)})


def test_a_cache_this_process_cannot_write_is_read(tmp_path, monkeypatch, caplog):
    """A cache shared read only (a read-only mount, another user's folder): its entries are
    served, a miss is made, used and not stored, no lock is taken, one warning says so - whether
    the folder is unwritable from the start or a write is refused (EACCES, EROFS) mid-run.  An
    audit (2026-11-30): the docstrings said reading such a cache worked; every command refused it.
    (Simulated: the tests run as root, for whom a chmod-ed folder stays writable.)"""
    import errno
    import logging

    import simbench.cache as module
    from simbench.cache import CACHE_HINT, check_cache_location

    RenderCache(tmp_path).get_or_make("radiance", {"x": 1}, lambda: {"a": np.arange(3.0)})
    before = sorted(p.name for p in tmp_path.iterdir())
    monkeypatch.setattr(module, "_can_write", lambda root: False)

    def refused(path, data):  # nothing may be written
        pytest.fail(f"wrote {path}")

    monkeypatch.setattr(module, "atomic_write_bytes", refused)
    with caplog.at_level(logging.WARNING, logger="simbench.cache"):
        cache = RenderCache(tmp_path)
        assert cache.read_only
        hit = cache.get_or_make("radiance", {"x": 1}, lambda: pytest.fail("a hit"))
        made = cache.get_or_make("radiance", {"x": 2}, lambda: {"a": np.arange(4.0)})
        cache.get_or_make("radiance", {"x": 3}, lambda: {"a": np.arange(5.0)}, wait=False)
    assert np.array_equal(hit["a"], np.arange(3.0)) and np.array_equal(made["a"], np.arange(4.0))
    assert (cache.hits, cache.misses, cache.unstored) == (1, 2, 2)
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # no entry, lock or temporary
    (record,) = caplog.records
    assert "is read only" in record.getMessage() and str(tmp_path) in record.getMessage()

    # a write refused mid-run: the same, from then on
    monkeypatch.setattr(module, "_can_write", lambda root: True)
    calls = []

    def denied(path, data):
        calls.append(path)
        raise PermissionError(errno.EACCES, "Permission denied", str(path))

    monkeypatch.setattr(module, "atomic_write_bytes", denied)
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="simbench.cache"):
        cache = RenderCache(tmp_path)
        for x in (4, 5):
            assert np.array_equal(cache.get_or_make("radiance", {"x": x}, lambda: {"a": np.zeros(x)})["a"], np.zeros(x))
    assert cache.read_only and cache.unstored == 2 and len(calls) == 1 and len(caplog.records) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == before

    # the command line's check takes a marked cache it cannot write, not an unmarked folder
    import simbench.io

    def unwritable(path, *, what="output"):
        raise ValueError(f"{what}: cannot write in {path} (Read-only file system)")

    monkeypatch.setattr(simbench.io, "check_output_folder", unwritable)
    assert check_cache_location(tmp_path, what="--cache", hint=CACHE_HINT) == tmp_path
    (tmp_path / "other").mkdir()
    with pytest.raises(ValueError, match="cannot write in .*other.*--no-cache"):
        check_cache_location(tmp_path / "other", what="--cache", hint=CACHE_HINT)


def test_a_hit_marks_what_its_entry_was_made_from_used_too(tmp_path):
    """A recording made from a render (made inside it) and a ground truth (a hit inside it,
    itself made from a drive): a later hit of the recording alone marks all four used, so
    pruning after warm runs, which read recordings and not renders, keeps the renders.  An
    entry read elsewhere marks nothing of the others."""
    import time

    from simbench.cache import cache_entries, prune_cache

    cache = RenderCache(tmp_path)
    cache.get_or_make(
        "truth", {"i": 0}, lambda: {"d": cache.get_or_make("drive", {"i": 0}, lambda: {"p": np.ones(4)})["p"] * 2}
    )
    cache.get_or_make("other", {"i": 0}, lambda: {"o": np.zeros(2)})

    def record():
        r = cache.get_or_make("radiance", {"i": 0}, lambda: {"r": np.full(3, 5.0)})["r"]
        t = cache.get_or_make("truth", {"i": 0}, lambda: pytest.fail("a hit"))["d"]
        return {"image": r.sum() + t}

    out = cache.get_or_make("recording", {"i": 0}, record)
    assert set(out) == {"image"} and out["image"].shape == (4,)
    now = time.time()
    for c in cache_entries(tmp_path):
        _aged(c.path, 10 * 86400, now)
    again = cache.get_or_make("recording", {"i": 0}, lambda: pytest.fail("a hit"))
    assert set(again) == {"image"} and np.array_equal(again["image"], out["image"])
    removed = prune_cache(tmp_path, unused_for_s=86400)
    assert [c.kind for c in removed.entries] == ["other"]
    assert sorted(c.kind for c in cache_entries(tmp_path)) == ["drive", "radiance", "recording", "truth"]


# A user's files in a folder given as the cache by mistake: every one a name the old pruning took
# for a cache's own (``*-*.npz``, ``*.lock``, ``.*.tmp``), or close to one.
_USERS_FILES = {
    "my-data.npz": None,  # a real .npz of the user's (written below)
    "uv.lock": b"version = 1\n",
    "Cargo.lock": b"# cargo\n",
    ".notes.tmp": b"draft\n",
    f"radiance-{'e' * 32}.npz": b"not a zip",  # named as an entry, not one
    f"radiance-{'f' * 32}.lock": b"pid 42\n",  # named as a lock, but ours are empty
    "README.md": b"# my project\n",
}


def _users_folder(path):
    import os

    path.mkdir(parents=True, exist_ok=True)
    for name, data in _USERS_FILES.items():
        if data is None:
            np.savez(path / name, a=np.arange(3))
        else:
            (path / name).write_bytes(data)
    old = 0.0  # 1970: older than any bound, and than STALE_TEMP_S
    for p in path.iterdir():
        os.utime(p, (old, old))
    return {p.name: p.read_bytes() for p in path.iterdir()}


def test_a_folder_of_a_users_files_is_neither_a_cache_nor_pruned(tmp_path):
    """Issue 33: ``cache prune --cache SOME_PROJECT_DIR --max-size 0`` deleted ``my-data.npz``,
    ``uv.lock`` and old ``.*.tmp``.  Such a folder is refused for pruning and listing and as a
    cache to render into, and nothing in it changes."""
    from simbench.cache import NotACacheError, cache_entries, prune_cache

    before = _users_folder(tmp_path / "project")
    for call in (
        lambda: prune_cache(tmp_path / "project", max_bytes=0),
        lambda: prune_cache(tmp_path / "project", max_bytes=0, dry_run=True),
        lambda: cache_entries(tmp_path / "project"),
        lambda: RenderCache(tmp_path / "project"),
    ):
        with pytest.raises(NotACacheError, match="not a simbench render cache.*Cargo.lock"):
            call()
    assert {p.name: p.read_bytes() for p in (tmp_path / "project").iterdir()} == before


def test_the_per_user_memos_may_share_the_render_caches_folder(tmp_path, monkeypatch):
    """``simbench render`` run from the home folder: the render cache's default ``.cache/simbench``
    is then ``~/.cache/simbench``, where the per-user memos (code digests, spectral values) were
    written first, and the cache refused the folder as "holding other files".  The memos, named
    by their own writers (and their temporary files), are tolerated; a prune leaves them; a
    user's file beside them is still refused."""
    import shutil

    from simbench.cache import NotACacheError, check_cache_folder, prune_cache, source_digest
    from simbench.sim import spectral

    home = tmp_path / "home"
    monkeypatch.setenv("SIMBENCH_CACHE_DIR", str(home))
    (tmp_path / "m.py").write_text("x = 1\n")
    source_digest([tmp_path / "m.py"])  # writes the code-digest memo, by its writer's name
    memo = spectral.memo_path()
    memo.write_text("{}")  # the spectral memo, by the name its writer gives it
    (home / f".{memo.stem}.a1B2_c3d4.tmp").write_text("")  # an atomic write's temporary file
    names = {p.name for p in home.iterdir()}
    assert len(names) == 3 and any(n.startswith("code-digests-") for n in names), names

    other = tmp_path / "other"
    shutil.copytree(home, other)
    assert check_cache_folder(other) == other  # unmarked, the memos alone: a cache
    (other / "notes.json").write_text("{}")
    with pytest.raises(NotACacheError, match=r"other files \(notes\.json\)"):
        check_cache_folder(other)

    cache = RenderCache(home)
    cache.store("truth", {"i": 1}, {"d": np.ones(2)})
    assert cache.lookup("truth", {"i": 1})["d"][0] == 1
    prune_cache(home, max_bytes=0, unused_for_s=0)
    assert names <= {p.name for p in home.iterdir()}


def test_a_marked_cache_prunes_only_its_own_files(tmp_path):
    """A user's files copied into a real cache stay through a prune to size 0; its entries go."""
    import os

    from simbench.cache import MARKER_NAME, cache_entries, prune_cache

    cache = RenderCache(tmp_path)
    cache.store("radiance", {"i": 0}, {"a": np.zeros(10)})
    entry = _entry_path(cache, "radiance", {"i": 0})
    users = _users_folder(tmp_path)
    del users[entry.name], users[MARKER_NAME]
    assert [c.path for c in cache_entries(tmp_path)] == [entry]
    result = prune_cache(tmp_path, max_bytes=0, unused_for_s=0)
    assert result.paths == [entry] and not entry.exists()
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.name != MARKER_NAME} == users
    assert os.path.isfile(tmp_path / MARKER_NAME)


def test_the_cache_marker(tmp_path):
    """A new folder is made and marked with its first entry (a CACHEDIR.TAG: backup tools skip
    it); an unmarked folder of cache files alone (made before markers) is read, and marked
    when written to; another format, or another tool's tag, is refused; pruning an unmarked
    folder is refused even when its names look like ours."""
    from simbench.cache import CACHE_FORMAT, MARKER_NAME, NotACacheError, prune_cache

    cache = RenderCache(tmp_path / "new" / "cache")
    assert not (tmp_path / "new").exists()  # nothing written before the first entry
    cache.store("truth", {"i": 1}, {"d": np.ones(2)})
    tag = (tmp_path / "new" / "cache" / MARKER_NAME).read_text()
    assert tag.startswith("Signature: 8a477f597d28d172789f06886806bc55\n") and f"format {CACHE_FORMAT}" in tag

    legacy = tmp_path / "legacy"
    legacy.mkdir()
    entry = _entry_path(cache, "truth", {"i": 1})
    (legacy / entry.name).write_bytes(entry.read_bytes())
    with pytest.raises(NotACacheError, match="not pruned"):
        prune_cache(legacy, max_bytes=0)
    assert (legacy / entry.name).exists()
    old = RenderCache(legacy)
    assert old.lookup("truth", {"i": 1})["d"][0] == 1 and not (legacy / MARKER_NAME).exists()
    old.store("truth", {"i": 2}, {"d": np.zeros(2)})
    assert (legacy / MARKER_NAME).read_text() == tag

    (legacy / MARKER_NAME).write_text(tag.replace(f"format {CACHE_FORMAT}", f"format {CACHE_FORMAT + 1}"))
    with pytest.raises(NotACacheError, match=f"format {CACHE_FORMAT + 1}"):
        RenderCache(legacy)
    (legacy / MARKER_NAME).write_text("Signature: 8a477f597d28d172789f06886806bc55\n# cargo\n")
    with pytest.raises(NotACacheError, match="other files.*CACHEDIR.TAG"):
        RenderCache(legacy)
    # our own marker damaged (emptied): the error says how to keep the cache, and that works
    (legacy / MARKER_NAME).write_text("")
    with pytest.raises(NotACacheError, match="was damaged, delete that file"):
        RenderCache(legacy)
    (legacy / MARKER_NAME).unlink()
    assert RenderCache(legacy).lookup("truth", {"i": 2})["d"][0] == 0


def test_a_folder_another_process_marks_while_it_is_checked_is_a_cache(tmp_path, monkeypatch):
    """Two processes starting on one new cache folder: the first marks it after the second
    found no marker but before the second listed the folder, which then saw a CACHEDIR.TAG
    among 'other files' and refused the cache (found with `ablate --workers 2`, one failed run)."""
    import simbench.cache as cache_module
    from simbench.cache import MARKER_NAME, NotACacheError, check_cache_folder, claim_cache_folder

    marked = tmp_path / "marked"
    claim_cache_folder(marked)
    tag = (marked / MARKER_NAME).read_bytes()
    new = tmp_path / "new"
    new.mkdir()
    real = cache_module._marker_format
    looks = []

    def other_process_marks_after_our_first_look(root):
        looks.append(root)
        out = real(root)
        if len(looks) == 1:
            (new / MARKER_NAME).write_bytes(tag)
        return out

    monkeypatch.setattr(cache_module, "_marker_format", other_process_marks_after_our_first_look)
    assert check_cache_folder(new) == new and len(looks) == 2
    # a marker of another tool's, or another file beside ours, is still refused
    looks.clear()
    (new / MARKER_NAME).unlink()
    monkeypatch.setattr(cache_module, "_marker_format", real)
    (new / MARKER_NAME).write_text("Signature: 8a477f597d28d172789f06886806bc55\n# cargo\n")
    with pytest.raises(NotACacheError, match="other files"):
        check_cache_folder(new)


def test_a_signal_while_a_lock_is_taken_or_let_go_leaves_no_lock_file(tmp_path, monkeypatch):
    """CI's SIGTERM test, rarely, under load, found a lock file left after the run ended: the
    handler's exception came between creating the file and holding it (or holding it and
    removing it), where nothing removed it.  Now those steps hold the exception back
    (simbench.termination.held) and raise it on leaving, which lets the lock go with its file.
    A real SIGTERM, with the command line's handler, is sent from inside the lock taking and,
    once more, inside the letting go; the handler also runs at once outside such a step."""
    import fcntl
    import os
    import signal
    from pathlib import Path

    from simbench import cache, termination
    from simbench.cli import _on_sigterm_raise, _Terminated

    previous = _on_sigterm_raise()
    real_flock = fcntl.flock
    try:

        def flock_then_signal(fd, op):
            real_flock(fd, op)
            os.kill(os.getpid(), signal.SIGTERM)  # its exception would come now, were it not held

        monkeypatch.setattr(fcntl, "flock", flock_then_signal)
        lock = cache._KeyLock(tmp_path, "radiance-" + "0" * 32)
        with pytest.raises(_Terminated):
            lock.acquire_now()
        assert lock.fd is None and not list(tmp_path.glob("*.lock"))
        monkeypatch.setattr(fcntl, "flock", real_flock)

        store = cache.RenderCache(tmp_path / "c")

        def make():
            real_unlink = Path.unlink

            def unlink_then_signal(self, missing_ok=False):
                os.kill(os.getpid(), signal.SIGTERM)
                real_unlink(self, missing_ok=missing_ok)

            monkeypatch.setattr(Path, "unlink", unlink_then_signal)
            return {"a": np.zeros(3)}

        with pytest.raises(_Terminated):
            store.get_or_make("radiance", {"x": 1}, make)
        monkeypatch.undo()
        assert not list((tmp_path / "c").glob("*.lock"))
        with pytest.raises(_Terminated):  # outside a held step: at once
            os.kill(os.getpid(), signal.SIGTERM)
            for _ in range(1000):
                pass
    finally:
        signal.signal(signal.SIGTERM, previous[0])
        signal.signal(signal.SIGINT, previous[1])
        termination._REQUESTED.clear()


def test_the_write_probe_is_named_as_the_caches_own_temporaries(tmp_path, monkeypatch):
    """A review: the read-only check's probe file, seen by another process checking a new, still
    unmarked cache folder (two workers starting on one new cache), made it "not a simbench render
    cache".  Left behind (the probing process stopped between its create and its delete), it is
    one of the cache's own temporaries."""
    import os

    import simbench.cache as module
    from simbench.cache import check_cache_folder

    monkeypatch.setattr(os, "unlink", lambda path: None)
    assert module._can_write(tmp_path)
    monkeypatch.undo()
    (probe,) = tmp_path.iterdir()
    assert check_cache_folder(tmp_path) == tmp_path and module._is_own_name(probe.name)


def test_damaged_entries_are_counted_by_info_and_removed_by_prune(tmp_path, capsys):
    """An audit (2026-11-30): a damaged entry (truncated, overwritten) was seen by neither `cache
    info` nor `cache prune` - kept for ever unless looked up.  Now info counts it and prune removes
    it (as a look-up does), never a good entry or a user's file."""
    from simbench.cache import damaged_entries, prune_cache
    from simbench.cli import main

    cache = RenderCache(tmp_path)
    cache.get_or_make("radiance", {"x": 1}, lambda: {"a": np.arange(3.0)})
    cache.get_or_make("radiance", {"x": 2}, lambda: {"a": np.arange(4.0)})
    good, bad = sorted(tmp_path.glob("radiance-*.npz"))
    bad.write_bytes(bad.read_bytes()[:40])  # truncated
    (tmp_path / "notes.txt").write_text("mine")  # (a user's file in a marked cache: never touched)
    assert damaged_entries(tmp_path) == [bad]
    assert main(["cache", "info", "--cache", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "1 entries" in out and "and 1 damaged (files named as entries, not readable as one: 40 B" in out
    would = prune_cache(tmp_path, max_bytes=1 << 30, dry_run=True)
    assert would.leftovers == [bad] and bad.exists()
    assert main(["cache", "prune", "--cache", str(tmp_path), "--max-size", "1G"]) == 0
    assert "1 leftovers (killed writers', damaged entries)" in capsys.readouterr().out
    assert not bad.exists() and good.exists() and (tmp_path / "notes.txt").exists()


def test_code_text_parses_from_many_threads_at_once():
    """CPython < 3.11.8 keeps the AST constructor's depth in state an interpreter's threads share
    (python/cpython#106905): two parses interleaved - here by a garbage collection whose callback
    lets another thread run, as a finalizer would - raised SystemError ("AST constructor recursion
    depth mismatch"), as the decoder's bands did digesting a user's phase method.  One parse at a
    time (without the lock this failed 3 of 3 runs on 3.11.7)."""
    import gc
    import time
    from concurrent.futures import ThreadPoolExecutor

    from simbench.cache import code_text

    source = (Path(__file__).resolve().parents[1] / "simbench" / "decode" / "pipeline.py").read_text()
    expected = code_text(source)

    def parse(_):
        return [code_text(source) for _ in range(3)]

    def switch(phase, info):
        time.sleep(0)

    threshold = gc.get_threshold()
    gc.callbacks.append(switch)
    gc.set_threshold(50)
    try:
        with ThreadPoolExecutor(4) as pool:
            texts = [t for got in pool.map(parse, range(8)) for t in got]
    finally:
        gc.callbacks.remove(switch)
        gc.set_threshold(*threshold)
    assert texts == [expected] * 24
