import numpy as np
import pytest

from simbench.rig import paper_rig
from simbench.sim.synthetic import synthetic_plane_capture


def test_a_sequence_gives_each_frame_the_bits_of_its_own_capture():
    """The plane traced once for a stack of drives: each image is the capture of its drive
    alone, bit for bit (a tilted plane that leaves part of the image unlit, 2 x 2 rays a pixel)."""
    rig = paper_rig()
    rng = np.random.default_rng(5)
    drives = rng.random((3, *rig.projector.size_hw, 3), dtype=np.float32)
    plane = {"normal": (0.8, 0.0, -1.0), "point_m": (0.0, 0.0, 0.4), "supersample": 2, "albedo": 0.7}
    images, col, z = synthetic_plane_capture(drives, rig, **plane)
    assert images.shape == (3, *rig.camera.size_hw, 3) and images.dtype == np.float32
    assert 0 < (images[0].sum(axis=-1) == 0).mean() < 0.5
    for image, drive in zip(images, drives):
        one, col_one, z_one = synthetic_plane_capture(drive, rig, **plane)
        assert np.array_equal(image, one)
    assert np.array_equal(col, col_one, equal_nan=True) and np.array_equal(z, z_one, equal_nan=True)
    with pytest.raises(ValueError, match="projector"):
        synthetic_plane_capture(drives[:, :10], rig)
