"""Seeds: one default, one derivation scheme, one log of every seed a run used.

Every random draw of a run descends from one base seed (:data:`DEFAULT_SEED` unless the user
gives another).  A capture's seeds are derived from the base seed and the capture's *label*, a
path-like name such as ``table1/white_paint/render`` (:func:`derive_seed`: ``SeedSequence([base,
sha256(label)])``), so a capture keeps its seeds when experiments, scenes or systems are added,
removed or run alone, and two runs that name the same capture the same way render the same
image.  Inside one render, the few independent streams a model needs (the ambient render, the
DLP exposure phase, the Kinect's speckle) are numbered children of that render's seed
(:func:`child_seed`, numbers listed in :data:`CHILD_STREAMS`); a sweep's repetitions number
theirs (:func:`repetition_seed`).  Every derived seed is recorded
(:class:`SeedLog`) and written to the result rows and provenance files.
"""

from __future__ import annotations

import hashlib

import numpy as np

__all__ = [
    "RngLike",
    "DEFAULT_SEED",
    "CHILD_STREAMS",
    "check_seed",
    "derive_seed",
    "child_seed",
    "frame_seed",
    "slice_seed",
    "repetition_seed",
    "SeedLog",
]

# the paper's year; any non-negative integer works
DEFAULT_SEED = 2017

# numbered streams below one render seed (numbers are part of the results: never renumber)
CHILD_STREAMS = {
    # the Kinect's factory reference: its speckle and its camera noise (simbench.systems.kinect)
    "kinect_calibration_frames": 1,
    "kinect_speckle": 2,  # the speckle frozen to a captured scene (simbench.systems.kinect)
    "ambient_render": 3,  # the ambient-only render beside the projector render (simbench.sim.capture)
    "dlp_exposure_phase": 5,  # where the exposure starts in a video-mode DLP frame (simbench.sim.drive)
}

# the time slices of a moving scene's exposure (simbench.sim.capture; a 3-word entropy)
SLICE_STREAM = 17

# the numbered frames of a multi-shot recording (a 3-word entropy: never equal to a child stream)
FRAME_STREAM = 16


def check_seed(seed: object) -> int:
    """``seed`` as an int, or ValueError: seeds are non-negative integers (SeedSequence's rule)."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    return int(seed)


def derive_seed(base: int, label: str) -> int:
    """A 32-bit seed for ``label`` under the base seed ``base``, independent of which other
    labels a run uses."""
    h = int.from_bytes(hashlib.sha256(label.encode()).digest()[:8], "little")
    return int(np.random.SeedSequence([check_seed(base), h]).generate_state(1)[0])


def child_seed(seed: int, stream: str) -> np.random.SeedSequence:
    """The numbered stream ``stream`` (a key of :data:`CHILD_STREAMS`) below ``seed``."""
    if stream not in CHILD_STREAMS:
        raise ValueError(f"unknown seed stream {stream!r}; valid: {sorted(CHILD_STREAMS)}")
    return np.random.SeedSequence([int(seed), CHILD_STREAMS[stream]])


def frame_seed(seed: int, frame: int) -> np.random.SeedSequence:
    """The camera-noise stream of frame ``frame`` of a multi-shot recording whose noise seed is
    ``seed`` (each exposure of a sequence has its own noise)."""
    return np.random.SeedSequence([check_seed(seed), FRAME_STREAM, int(frame)])


def slice_seed(seed: int, index: int) -> int:
    """The render seed of time slice ``index`` of a moving scene's exposure rendered with
    ``seed`` (each slice samples its own paths)."""
    return int(np.random.SeedSequence([check_seed(seed), SLICE_STREAM, int(index)]).generate_state(1)[0])


def repetition_seed(base: int, repeat: int) -> int:
    """The base seed of repetition ``repeat`` of a sweep (``simbench ablate``): the same in every
    parameter set, so a sweep compares its settings under common random numbers."""
    return int(np.random.SeedSequence([check_seed(base), int(repeat)]).generate_state(1)[0])


class SeedLog:
    """The seeds of one run: derives them from the base seed and records each under its key."""

    def __init__(self, base: int = DEFAULT_SEED) -> None:
        self.base = check_seed(base)
        self.used: dict[str, dict] = {}

    def seed(self, label: str) -> int:
        """The seed of ``label`` (not recorded: record what a capture used with :meth:`record`)."""
        return derive_seed(self.base, label)

    def record(self, key: str, seeds: dict) -> dict:
        self.used[key] = seeds
        return seeds

    def capture(self, label: str, *, repeats: int = 1) -> tuple[int, list[int]]:
        """(render seed, one noise seed per repeat) of the capture ``label``, recorded under
        ``label`` (one repeat) or ``label/k``."""
        render = self.seed(f"{label}/render")
        noise = [self.seed(f"{label}/noise/{k}") for k in range(repeats)]
        for k, n in enumerate(noise):
            self.record(f"{label}/{k}" if repeats > 1 else label, {"render": render, "noise": n})
        return render, noise


# what every stochastic function accepts as ``rng`` (numpy.random.default_rng's inputs)
RngLike = np.random.Generator | np.random.SeedSequence | int | None
