"""The warning simbench's library gives its caller (:class:`SimbenchWarning`): a module of the
base layer, so that every layer may warn with it; ``simbench.SimbenchWarning`` is the same class."""

__all__ = ["SimbenchWarning"]


class SimbenchWarning(UserWarning):
    """The library's sanity checks, told to the caller: a scene whose objects leave the view
    (:func:`simbench.record`), a capture that is dark, saturated or off the reference plane's
    registration, stripes read out of the pattern's order, a ``rig=`` off the recording's within
    the tolerance (:func:`simbench.depth`), a depth map
    in other units or of another scene (:func:`simbench.score`), an output folder replaced whose
    old copy could not be removed (:func:`simbench.io.output_directory`).  (Notices about the
    set-up - a sensor file that leaves keys out, a projector principal point rendered elsewhere,
    the Mitsuba variant - are logged, logger ``simbench``.)  The call still returns its result.
    A warning, not a logged line, so that a script can filter it or turn it into an error
    (``warnings.simplefilter("error", simbench.SimbenchWarning)``); the command line prints each
    as a ``simbench: ...`` line."""
