import tempfile
from pathlib import Path

import numpy as np
import pytest

from simbench.io import atomic_write_text, load_image, load_npy, save_npy, save_ply, save_png


def test_atomic_write_leaves_no_temporary(tmp_path):
    atomic_write_text(tmp_path / "a" / "x.txt", "hello")
    assert (tmp_path / "a" / "x.txt").read_text() == "hello"
    assert [p.name for p in (tmp_path / "a").iterdir()] == ["x.txt"]


def test_png_round_trip_keeps_rgb_order(tmp_path):
    img = np.zeros((4, 5, 3), np.uint8)
    img[..., 0] = 200
    save_png(tmp_path / "x.png", img)
    assert np.array_equal(load_image(tmp_path / "x.png"), img)
    with pytest.raises(ValueError, match="5x4"):
        load_image(tmp_path / "x.png", expected_size_hw=(960, 1280))


def test_load_image_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        load_image(tmp_path / "missing.png")
    (tmp_path / "junk.png").write_bytes(b"not a png")
    with pytest.raises(ValueError, match="not a readable image"):
        load_image(tmp_path / "junk.png")
    save_png(tmp_path / "grey.png", np.zeros((3, 3), np.uint8))
    with pytest.raises(ValueError, match="RGB"):
        load_image(tmp_path / "grey.png")


def test_npy(tmp_path):
    save_npy(tmp_path / "a.npy", np.arange(6).reshape(2, 3))
    assert load_npy(tmp_path / "a.npy", expected_shape=(2, 3)).sum() == 15
    with pytest.raises(ValueError, match="shape"):
        load_npy(tmp_path / "a.npy", expected_shape=(3, 2))
    (tmp_path / "b.npy").write_bytes(b"garbage")
    with pytest.raises(ValueError):
        load_npy(tmp_path / "b.npy")


def test_ply_is_readable_by_trimesh(tmp_path):
    import trimesh

    pts = np.random.default_rng(0).random((50, 3))
    save_ply(tmp_path / "c.ply", pts, np.full((50, 3), 7, np.uint8))
    cloud = trimesh.load(tmp_path / "c.ply")
    assert np.allclose(np.asarray(cloud.vertices), pts, atol=1e-6)


def test_failed_output_directory_leaves_nothing_and_keeps_the_error(tmp_path):
    """A block that fails inside output_directory re-raises its own error, and the folders made
    for it (missing parents included) are gone."""
    from simbench.io import output_directory

    with pytest.raises(RuntimeError, match="boom"):
        with output_directory(tmp_path / "a" / "b" / "out", manifest="meta.json") as tmp:
            (tmp / "x.txt").write_text("x")
            raise RuntimeError("boom")
    assert list(tmp_path.iterdir()) == []


def test_a_failed_write_names_its_file_keeps_the_old_one_and_leaves_no_temporary(tmp_path, monkeypatch):
    """A full disk reported by fsync (or write) carries no file name of its own: the error
    names the target; the previous file is untouched."""
    import errno
    import os

    target = tmp_path / "x.txt"
    atomic_write_text(target, "old")

    def full(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", full)
    with pytest.raises(OSError, match=r"No space left on device: '.*x\.txt'") as info:
        atomic_write_text(target, "new")
    assert info.value.errno == errno.ENOSPC and info.value.filename == str(target)
    assert [p.name for p in tmp_path.iterdir()] == ["x.txt"] and target.read_text() == "old"


def test_a_folder_that_refuses_the_temporary_file_names_the_file_asked_for(tmp_path, monkeypatch):
    """The second audit's `--ply` into a folder it could not write: the error named the
    temporary sibling (".cloud.k2j4.ply: Permission denied"), a file the user never asked for.
    (Simulated: root, which runs these tests, may write anywhere.)"""
    import errno
    import tempfile

    from simbench.io import save_ply

    def refused(prefix="", suffix="", dir=None, **kw):
        raise PermissionError(errno.EACCES, "Permission denied", str(Path(dir) / f"{prefix}x8k2{suffix}"))

    monkeypatch.setattr(tempfile, "mkstemp", refused)
    target = tmp_path / "cloud.ply"
    with pytest.raises(PermissionError, match=r"Permission denied: '.*/cloud\.ply'$") as info:
        save_ply(target, np.zeros((4, 3), np.float32))
    assert info.value.filename == str(target)
    # another file's name in an error stays: it is not ours to rename
    from simbench.io import _raise_with_filename

    other = OSError(errno.EACCES, "Permission denied", "/elsewhere/model.ply")
    _raise_with_filename(other, target)  # returns: the caller raises the original


def test_an_output_folder_given_as_a_symbolic_link_is_refused_before_any_work(tmp_path):
    """Issue 33: ``render --out LINK`` (a link to an earlier render) swapped the new render in,
    then failed on rmtree of the link, leaving a temporary folder."""
    import os

    from simbench.io import check_output_directory, output_directory

    with output_directory(tmp_path / "real", manifest="m.json") as d:
        (d / "m.json").write_text('{"files": {}}')
    os.symlink(tmp_path / "real", tmp_path / "link")
    with pytest.raises(ValueError, match="is a symbolic link"):
        check_output_directory(tmp_path / "link", manifest="m.json")
    with pytest.raises(ValueError, match="is a symbolic link"):
        with output_directory(tmp_path / "link", manifest="m.json"):
            pass
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link", "real"] and (tmp_path / "link").is_symlink()


def test_an_old_output_that_cannot_be_removed_is_refused_before_any_work(tmp_path, monkeypatch):
    """A read-only recording folder given as ``--out`` again: the new render was swapped in, then
    removing the old one failed, so the command reported a failure that had replaced the folder
    and left the old one as a hidden sibling.  Now a folder whose files cannot be removed is
    refused before any work (the permission faked: root may remove anything), and nothing
    changes."""
    import os

    from simbench.io import check_output_directory, output_directory

    out = tmp_path / "rec"
    with output_directory(out, manifest="m.json") as d:
        (d / "m.json").write_text('{"files": {"sub": "sub"}}')
        (d / "sub").mkdir()
        (d / "sub" / "x.txt").write_text("old")
    real_access = os.access
    locked = {str(out / "sub")}
    monkeypatch.setattr(os, "access", lambda p, mode: False if str(p) in locked else real_access(p, mode))
    with pytest.raises(
        ValueError, match=r"rec cannot be replaced: its files cannot be removed \(.*sub is not writable"
    ):
        check_output_directory(out, manifest="m.json")
    with pytest.raises(ValueError, match="cannot be replaced"):
        with output_directory(out, manifest="m.json"):
            raise AssertionError("the block ran")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec"] and (out / "sub" / "x.txt").read_text() == "old"


def test_an_old_output_whose_removal_fails_after_the_swap_leaves_the_new_one_and_says_where(tmp_path, monkeypatch):
    """Should the old output's removal still fail once the new one is in place (a file made
    read-only between the check and the swap), the write has succeeded: no error, and a
    SimbenchWarning names where the old folder was left."""
    import shutil

    import simbench
    from simbench.io import output_directory

    def write(text):
        with output_directory(tmp_path / "rec", manifest="m.json") as d:
            (d / "m.json").write_text('{"files": {"x.txt": "x.txt"}}')
            (d / "x.txt").write_text(text)

    def refuse(path, *args, **kwargs):
        raise PermissionError(13, "Permission denied")

    write("old")
    monkeypatch.setattr(shutil, "rmtree", refuse)
    message = r"rec was written, but the output it replaced could not be removed \(Permission denied\): it is left as "
    with pytest.warns(simbench.SimbenchWarning, match=message):
        write("new")
    assert (tmp_path / "rec" / "x.txt").read_text() == "new"
    left = [p for p in tmp_path.iterdir() if p.name != "rec"]
    assert len(left) == 1 and left[0].name.startswith(".rec.") and (left[0] / "x.txt").read_text() == "old"


def test_a_full_disk_names_the_file_in_every_writer(tmp_path, monkeypatch):
    """Issue 33: a full disk named no file (so the CLI's free-space hint measured the working
    folder's disk, not the one written): write_files and output_directory name their target."""
    import errno
    import os

    from simbench.io import output_directory, write_files

    def full(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", full)
    with pytest.raises(OSError) as info:
        write_files({tmp_path / "a.npy": b"1", tmp_path / "sub" / "b.npy": b"2"})
    assert info.value.errno == errno.ENOSPC and info.value.filename == str(tmp_path / "a.npy")
    assert list(tmp_path.iterdir()) == []
    monkeypatch.undo()
    with pytest.raises(OSError) as info:
        with output_directory(tmp_path / "out", manifest="m.json"):
            raise OSError(errno.ENOSPC, "No space left on device")
    assert info.value.filename == str(tmp_path / "out") and list(tmp_path.iterdir()) == []


def test_an_interrupt_between_a_sets_renames_takes_effect_after_the_last(tmp_path, monkeypatch):
    """write_files renames its set under termination.held(): Ctrl-C or SIGTERM (the CLI's handlers
    call run_or_hold) after the first rename waits until the last, so the set is whole."""
    import os

    from simbench import io, termination

    real, done = os.replace, []

    def interrupt():
        raise KeyboardInterrupt

    def replace(src, dst):
        real(src, dst)
        done.append(dst)
        if len(done) == 1:  # the signal arrives between the renames
            termination.run_or_hold(interrupt)

    monkeypatch.setattr(io.os, "replace", replace)
    with pytest.raises(KeyboardInterrupt):
        io.write_files({tmp_path / "a.csv": b"new a", tmp_path / "b.json": b"new b"})
    assert (tmp_path / "a.csv").read_bytes() == b"new a" and (tmp_path / "b.json").read_bytes() == b"new b"
    assert len(done) == 2 and not list(tmp_path.glob(".*.tmp"))


def test_an_output_whose_listed_file_was_edited_needs_overwrite(tmp_path):
    """A folder the command wrote, whose manifest lists its files with their SHA-256 (a sealed
    recording, a calibration): replaced by a rerun while every file is as written; once a file
    was changed (a rig.toml edited by hand - an audit, 2026-11-30, saw calibrate replace it without
    a word) only with --overwrite.  A manifest without digests is replaced as before."""
    import hashlib
    import json

    from simbench.io import check_output_directory

    out = tmp_path / "cal"
    out.mkdir()
    (out / "rig.toml").write_text("focal_px = 2000.0\n")
    digest = hashlib.sha256(b"focal_px = 2000.0\n").hexdigest()
    manifest = {"files": {"rig": "rig.toml"}, "sha256": {"rig": digest}}
    (out / "calibration.json").write_text(json.dumps(manifest))
    check_output_directory(out, manifest="calibration.json")
    (out / "rig.toml").write_text("focal_px = 2010.0\n")
    with pytest.raises(ValueError, match=r"rig.toml changed since this command wrote it.*--overwrite"):
        check_output_directory(out, manifest="calibration.json")
    check_output_directory(out, manifest="calibration.json", overwrite=True)
    (out / "calibration.json").write_text(json.dumps({"files": {"rig": "rig.toml"}}))
    check_output_directory(out, manifest="calibration.json")


def test_one_writer_of_an_output_at_a_time(tmp_path, capsys):
    """An audit (2026-11-30): two ``calibrate`` runs into one --out both reported success, the
    later silently replacing the earlier.  A second claim on an output (another process's - or
    another open file description's, as here) fails at once, naming the output, however the path
    is spelled and after the first's work made its folders (a review: the lock had moved with the
    nearest existing folder); the claim is let go, and its lock file removed, when the block ends,
    by an error too.  Through the command line: render and calibrate refuse before their work."""
    import os
    import subprocess
    import sys

    from simbench.cli import main
    from simbench.io import claim_output

    out = tmp_path / "new" / "out"
    (tmp_path / "link").symlink_to(tmp_path)
    folder = Path(tempfile.gettempdir(), f"simbench-outputs-{os.getuid()}")
    others = set(folder.glob("*.lock"))  # (other processes' claims)
    with claim_output(out):
        locks = set(folder.glob("*.lock")) - others
        with pytest.raises(ValueError, match=r"--out .*out: another process is writing it now"):
            with claim_output(out):
                pass
        out.mkdir(parents=True)  # the work made its folders
        for spelling in (out, tmp_path / "link" / "new" / "out", f"{tmp_path}/new/../new/out"):
            with pytest.raises(ValueError, match="another process is writing it now"):
                with claim_output(spelling):
                    pass
        with claim_output(tmp_path / "other"):  # another output: free
            pass
        # another process
        code = "import sys; from simbench.io import claim_output\nwith claim_output(sys.argv[1]): pass"
        res = subprocess.run([sys.executable, "-c", code, str(out)], capture_output=True, text=True)
        assert res.returncode == 1 and "another process is writing it now" in res.stderr
        for argv in (
            ["render", "white_plane", "--out", str(out)],
            ["calibrate", "--poses", "3", "--out", str(out)],
        ):
            assert main(argv) == 2
            err = capsys.readouterr().err
            assert err.count("\n") == 1 and "another process is writing it now" in err
    assert locks and not any(p.exists() for p in locks)
    with pytest.raises(RuntimeError):
        with claim_output(out):
            raise RuntimeError("the work failed")
    with claim_output(out):  # let go
        pass


def test_an_output_path_through_a_missing_folder_and_back_is_the_folder_it_names(tmp_path, monkeypatch):
    """A hands-on run (2026-11-30): ``render --out ./x/../out`` with no x made x, then failed on a
    raw "[Errno 17] File exists: 'x/..'" (the kernel resolves x/.. only once x exists).  The real
    path is written: out, and no x; a file output likewise."""
    from simbench.io import output_directory, write_files

    monkeypatch.chdir(tmp_path)
    with output_directory("x/../out", manifest="m.json") as tmp:
        (tmp / "m.json").write_text('{"files": {}}')
    assert (tmp_path / "out" / "m.json").is_file() and not (tmp_path / "x").exists()
    assert write_files({"y/../f.bin": b"abc"}) == [Path("y/../f.bin")]
    assert (tmp_path / "f.bin").read_bytes() == b"abc" and not (tmp_path / "y").exists()
