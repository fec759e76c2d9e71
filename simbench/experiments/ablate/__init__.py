"""Ablation studies: declarative sweeps over pattern, sensor, decoder and scene (``simbench ablate``).

A sweep file (TOML)::

    name = "period"                      # results/ablations/<name>.csv/.md/.png
    description = "fringe period T"
    repeats = 2                          # recordings per parameter set (own seeds each)
    seed = 2017                          # base seed (default: simbench.seeds.DEFAULT_SEED);
                                         # repetition r uses the same seeds in every
                                         # parameter set (common random numbers)
    plot_metric = "gt_mae_mm"            # y of the plot (default gt_mae_mm)
    combine = "grid"                     # "grid" (every combination) or "zip" (axes in step);
                                         # the sweep's keys come before its tables (TOML)

    [base]                               # any parameter (below) fixed for every run
    "scene.name" = "plane_white"
    "run.camera_scale" = 0.5

    [[axis]]                             # one or more axes
    name = "pattern.period_px"
    values = [11, 15, 21, 31, 41]

    [[axis]]
    name = "decoder.voting"
    values = [true, false]

Parameters (:data:`PARAMETERS`; anything else is rejected with the list):

- ``pattern.period_px``, ``pattern.order``, ``pattern.sequence`` (a 0/1 string),
  ``pattern.channels`` (which colour carries code 1, code 0 and the fringe, e.g. ``rbg``): the
  projected pattern, which the decoder is told about;
- ``decoder.<field>``: any :class:`simbench.decode.DecoderParams` field (phase method, overlay vs
  ``blue`` intensity, voting, neighbour correction, colour normalisation, ...);
- ``sensor.preset``: a sensor preset or TOML file; ``sensor.effects``: a list of
  :data:`simbench.sim.sensor.EFFECTS` switched on over the ``ideal`` model, taken from
  ``sensor.source`` (default ``paper``); ``sensor.<table>.<key>``: one number of the sensor model
  (e.g. ``sensor.camera.dark_noise_e``, ``sensor.ambient.ratio``, ``sensor.projector.lumens``);
- ``scene.name`` (a scene of ``scenes/`` by name, or a scene TOML of one's own by its path),
  ``scene.srgb8`` (repaint every object), ``scene.depth_m``
  (move the scene so its first object's placement - a plane's or box's ``center_m``, a mesh's
  ``translate_m``, its origin - is at this depth), ``scene.tilt_deg`` (the first
  object's rotation about the vertical axis), ``scene.speed_m_s`` and ``scene.motion`` (the first
  object moving ``lateral``-ly or ``axial``-ly at that speed during the exposure:
  :mod:`simbench.sim.motion`), ``scene.spin_deg_s`` (the first object turning at that rate about
  the vertical axis through it, or its scene file's own rotation axis and centre where it gives
  them);
- ``run.spp``, ``run.sampler``, ``run.camera_scale``, ``run.max_depth``.

Execution: a local process pool (``workers``) or a Dask distributed cluster (``scheduler``); each
run is a pure function of its parameters and seeds, so both give identical tables.  Renders go
through the content-hash cache, so a decoder-only axis renders each scene once.  Finished runs
are appended to ``<name>.runs.jsonl``; a restarted sweep skips them.  A failing run is recorded
with its error and the sweep goes on.

The package: :mod:`~simbench.experiments.ablate.spec` (the sweep file and its expansion),
:mod:`~simbench.experiments.ablate.mapping` (parameters -> sensor, scene, decoder),
:mod:`~simbench.experiments.ablate.execute` (runs, workers, run log),
:mod:`~simbench.experiments.ablate.report` (CSV, Markdown, plot).
"""

from simbench.experiments.ablate.execute import WORKER_DIED, run_one, run_sweep
from simbench.experiments.ablate.mapping import check_sweep
from simbench.experiments.ablate.spec import (
    BUILTIN_STUDIES,
    DEFAULTS,
    PARAMETERS,
    STUDIES_DIR,
    Sweep,
    expand,
    load_sweep,
    sweep_from_dict,
)

__all__ = [
    "PARAMETERS",
    "DEFAULTS",
    "Sweep",
    "load_sweep",
    "sweep_from_dict",
    "expand",
    "run_one",
    "run_sweep",
    "check_sweep",
    "WORKER_DIED",
    "BUILTIN_STUDIES",
    "STUDIES_DIR",
]
