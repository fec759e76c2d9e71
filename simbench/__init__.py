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

from simbench.warn import SimbenchWarning  # noqa: E402  (a base module: io warns with it too)


def __getattr__(name: str):
    # imported on first use: `import simbench` stays cheap and touches neither Mitsuba nor Dr.Jit
    if name in _API:
        from simbench import api

        return getattr(api, name)
    raise AttributeError(f"module 'simbench' has no attribute {name!r}")
