"""simbench: a physically based testbed for single-shot structured-light depth sensing.

The common case in three calls (:mod:`simbench.api`)::

    import simbench

    rec = simbench.record("scenes/step.toml", system="proposed", sensor="paper")
    depth = simbench.depth(rec)
    simbench.score(depth, rec)
"""

__version__ = "0.1.0"

__all__ = ["record", "depth", "score", "Recorded", "SimbenchWarning"]

_API = frozenset(["record", "depth", "score", "Recorded"])


class SimbenchWarning(UserWarning):
    """The Python API's sanity checks, told to the caller: a scene whose objects leave the view
    (:func:`record`), a capture that is dark, saturated or off the reference plane's
    registration, stripes read out of the pattern's order (:func:`depth`), a depth map in other
    units or of another scene (:func:`score`).  (Notices about the set-up - a sensor file that
    leaves keys out, a projector principal point rendered elsewhere, the Mitsuba variant - are
    logged, logger ``simbench``.)  The call still returns its result.  A
    warning, not a logged line, so that a script can filter it or turn it into an error
    (``warnings.simplefilter("error", simbench.SimbenchWarning)``); the command line prints each
    as a ``simbench: ...`` line."""


def __getattr__(name: str):
    # imported on first use: `import simbench` stays cheap and touches neither Mitsuba nor Dr.Jit
    if name in _API:
        from simbench import api

        return getattr(api, name)
    raise AttributeError(f"module 'simbench' has no attribute {name!r}")
