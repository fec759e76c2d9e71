"""A sweep's results as files: one row per run (CSV), a Markdown table of means per
parameter set and a plot."""

from __future__ import annotations

import hashlib
import logging
import math
from pathlib import Path

import numpy as np

from simbench.experiments.ablate.spec import (
    DEFAULTS,
    EDGE_BAND_PX,
    METRICS,
    REF_METRICS,
    Sweep,
)
from simbench.io import json_bytes, write_files

log = logging.getLogger(__name__)

__all__ = ["sweep_rows", "write_sweep"]


def sweep_rows(sweep: Sweep, runs: list[dict], done: dict) -> list[dict]:
    axis_names = [k for k, _ in sweep.axes]
    rows = []
    for r in runs:
        rec = done.get(r["key"], {})
        row = {"run": r["run"], "repeat": r["repeat"], **{k: _fmt(r["params"].get(k)) for k in axis_names}}
        for k in METRICS + REF_METRICS:
            row[k] = rec.get(k, float("nan"))
        row.update(
            seed=r["seed"],
            render_seed=rec.get("render_seed", ""),
            noise_seed=rec.get("noise_seed", ""),
            placement_seed=rec.get("placement_seed", ""),
            error=rec.get("error", "not run"),
            warnings=" | ".join(rec.get("warnings", ())),
        )
        rows.append(row)
    return rows


def _fmt(v) -> str:
    if isinstance(v, (list, tuple)):
        return "+".join(map(str, v)) if v else "none"
    if isinstance(v, bool):
        return "on" if v else "off"
    return str(v)


def write_sweep(sweep: Sweep, rows: list[dict], runs: list[dict], done: dict, out: Path, command: str) -> None:
    from simbench.experiments.common import git_state
    from simbench.report import table_text
    from simbench.sim.keys import versions

    axis_names = [k for k, _ in sweep.axes]
    cols = [
        "run",
        "repeat",
        *axis_names,
        *METRICS,
        *REF_METRICS,
        "seed",
        "render_seed",
        "noise_seed",
        "placement_seed",
        "error",
        "warnings",
    ]
    timing_rows = [{"run": r["run"], **done.get(r["key"], {}).get("timing", {})} for r in runs]
    # the set is made first and written all or nothing: an interrupt while the plot is drawn (or
    # a full disk) leaves the previous set whole, never a table of this run beside another's
    # provenance
    files = {
        out / f"{sweep.name}.csv": table_text(rows, cols).encode("utf-8"),
        out / f"{sweep.name}.timings.csv": table_text(
            timing_rows, ["run", "setup_s", "render_record_s", "decode_s"]
        ).encode("utf-8"),
        out / f"{sweep.name}.md": _markdown(sweep, rows, command).encode("utf-8"),
        **{out / f"{sweep.name}.{fmt}": data for fmt, data in _plot(sweep, rows).items()},
    }
    base = {k: _fmt(v) for k, v in {**DEFAULTS, **sweep.base}.items()}
    files[out / f"{sweep.name}.provenance.json"] = json_bytes(
        {
            "command": command,
            "sweep_file": sweep.path,
            "sweep": {
                "name": sweep.name,
                "base": base,
                "axes": [[k, [_fmt(v) for v in vs]] for k, vs in sweep.axes],
                "combine": sweep.combine,
                "repeats": sweep.repeats,
                "seed": sweep.seed,
            },
            # the Mitsuba variant(s) the runs were made with ("unknown": a run logged before it was kept)
            "variant": sorted(
                {str(done.get(r["key"], {}).get("variant", "unknown")) for r in runs if r["key"] in done}
            ),
            "versions": versions(),
            **git_state(),
            # the code that made the runs (a resume reuses only the runs of its own code)
            "code": sorted({str(done.get(r["key"], {}).get("code", "unknown")) for r in runs if r["key"] in done}),
            "files": {p.name: hashlib.sha256(data).hexdigest() for p, data in files.items()},
        }
    )
    write_files(files)


def _groups(sweep: Sweep, rows: list[dict]) -> list[tuple[tuple, list[dict]]]:
    axis_names = [k for k, _ in sweep.axes]
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault(tuple(r[k] for k in axis_names), []).append(r)
    return list(groups.items())


def _mean(rows: list[dict], key: str) -> float:
    vals = [r[key] for r in rows if not r["error"] and isinstance(r[key], float) and math.isfinite(r[key])]
    return float(np.mean(vals)) if vals else float("nan")


def _cell(value: float, spec: str) -> str:
    # NaN (a plane fit of a scene that is not a plane, an error over no decoded pixel) would print
    # as "nan" in a table meant for a paper
    return spec.format(value) if math.isfinite(value) else "n/a"


def _markdown(sweep: Sweep, rows: list[dict], command: str) -> str:
    from simbench.experiments.common import markdown_table

    axis_names = [k for k, _ in sweep.axes]
    base = {**DEFAULTS, **sweep.base}
    lines = [
        f"# Ablation: {sweep.name}",
        "",
        sweep.description,
        "",
        f"Made by `{command}` (sweep `{sweep.path}`; {sweep.combine} over {', '.join(axis_names)}; {sweep.repeats} "
        f"repetition(s) "
        f"with the same seeds in every parameter set, base seed {sweep.seed}). Every run with its seeds: "
        f"`{sweep.name}.csv`; "
        f"timings: `{sweep.name}.timings.csv`; plot: `{sweep.name}.png`.",
        "",
        "Fixed: " + ", ".join(f"`{k}` = {_fmt(v)}" for k, v in sorted(base.items()) if k not in axis_names) + ".",
        "",
        "Every object of the scene is placed with the run's placement tolerance (seeded, independent of the reference "
        "plane; `run.placement_depth_mm`, `run.placement_tilt_deg`). Decoded by triangulation with the rig (paper Eq. "
        "15; "
        "the first columns) and against the separately captured reference plane (Sec. 5.4; `ref. plane` columns). "
        "`n/a`: not measured in any repetition - a plane fit where the scene over the decoded pixels is not a "
        "plane (`simbench.metrics.PLANAR_TRUTH_RMS_MM`), an error where no pixel decoded, any metric where every "
        "repetition failed (`errors`).",
        "",
        "Mean over repetitions (failed runs left out; `errors` counts them):",
        "",
    ]
    body = []
    for combo, group in _groups(sweep, rows):
        errs = sum(1 for r in group if r["error"])
        body.append(
            [
                *combo,
                *(
                    _cell(_mean(group, k), "{:.4g}")
                    for k in ("plane_mae_mm", "gt_mae_mm", "gt_rmse_mm", "gt_p95_mm", "edge5_mae_mm")
                ),
                _cell(100 * _mean(group, "outlier_share"), "{:.3f} %"),
                _cell(100 * _mean(group, "completeness"), "{:.2f} %"),
                _cell(_mean(group, "stripe_order_errors"), "{:.0f}"),
                *(_cell(_mean(group, k), "{:.4g}") for k in ("ref_plane_mae_mm", "ref_gt_mae_mm")),
                _cell(100 * _mean(group, "ref_completeness"), "{:.2f} %"),
                str(errs),
            ]
        )
    header = [
        *axis_names,
        "plane fit (mm)",
        "GT MAE (mm)",
        "GT RMSE (mm)",
        "GT p95 (mm)",
        f"MAE off edges (mm, {EDGE_BAND_PX} px)",
        "outliers (> 5 mm)",
        "completeness",
        "stripe-order errors",
        "ref. plane: plane fit (mm)",
        "ref. plane: GT MAE (mm)",
        "ref. plane: completeness",
        "errors",
    ]
    lines += markdown_table(header, body)
    failures = sorted({r["error"] for r in rows if r["error"]})
    if failures:
        lines += ["", "Errors:", ""] + [f"- {e}" for e in failures]
    told: dict[str, list[str]] = {}
    for combo, group in _groups(sweep, rows):
        for w in dict.fromkeys(w for r in group for w in r.get("warnings", "").split(" | ") if w):
            told.setdefault(w, []).append(", ".join(f"{k} = {v}" for k, v in zip(axis_names, combo)))
    if told:
        lines += [
            "",
            "Warnings (the decoder's checks of the pattern on the rig, as `simbench decode` gives them - in a sweep "
            "its options are `pattern.period_px`, `pattern.order` and `decoder.depth_range_m` -, and what the "
            "recording shows, as `simbench.record` warns of it: an object no pixel sees, lit surface beyond the "
            "working range, a clipped or dark capture):",
            "",
        ]
        lines += [f"- {', '.join(f'`{c}`' for c in combos)}: {w}" for w, combos in told.items()]
    return "\n".join(lines) + "\n"


def plot_series(sweep: Sweep, rows: list[dict]) -> tuple[list, list[tuple[str, np.ndarray, np.ndarray, np.ndarray]]]:
    """The plot's x values and its lines: (label, mean, min, max of ``sweep.plot_metric`` over the
    repetitions at each x), one line per combination of the other axes' values (grid sweeps) - and
    one line for combinations whose values are the same to the last bit, labelled with all of them
    (drawn apart, a factor that changes nothing left one line on top of the others, in the last
    one's colour, under a legend of as many entries: the design_choices study's eight were two)."""
    axis_names = [k for k, _ in sweep.axes]
    x_name = axis_names[0]
    x_vals = list(dict.fromkeys(r[x_name] for r in rows))
    series_names = axis_names[1:] if sweep.combine == "grid" else []
    series = list(dict.fromkeys(tuple(r[k] for k in series_names) for r in rows))
    same_values: dict[bytes, list[tuple]] = {}  # a line's values -> the combinations that have exactly them
    values = {}
    for s in series:
        means, lo, hi = [], [], []
        for xv in x_vals:
            vals = [
                r[sweep.plot_metric]
                for r in rows
                if r[x_name] == xv
                and tuple(r[k] for k in series_names) == s
                and not r["error"]
                and math.isfinite(r[sweep.plot_metric])
            ]
            means.append(np.mean(vals) if vals else np.nan)
            lo.append(np.min(vals) if vals else np.nan)
            hi.append(np.max(vals) if vals else np.nan)
        values[s] = tuple(np.array(v, np.float64) for v in (means, lo, hi))
        same_values.setdefault(np.stack(values[s]).tobytes(), []).append(s)
    short = [k.split(".")[-1] for k in series_names]
    lines = []
    for same in same_values.values():
        sets = [list(dict.fromkeys(s[i] for s in same)) for i in range(len(series_names))]
        if len(same) == math.prod(len(v) for v in sets):
            # every combination of the factors' values: each factor's values once
            label = ", ".join(f"{k}={'|'.join(map(str, v))}" for k, v in zip(short, sets))
        else:
            label = "; ".join(", ".join(f"{k}={v}" for k, v in zip(short, s)) for s in same)
        label = label or sweep.plot_metric
        if len(same) > 1:
            label += f" ({len(same)} sets, the same values)"
        lines.append((label, *values[same[0]]))
    return x_vals, lines


# what each metric is, in words, and the factor it is drawn with (shares as %)
_METRIC_WORDS = {
    "plane_mae_mm": ("plane-fit residual, mean absolute (mm)", 1.0),
    "gt_mae_mm": ("depth error against ground truth, MAE (mm)", 1.0),
    "gt_rmse_mm": ("depth error against ground truth, RMSE (mm)", 1.0),
    "gt_p95_mm": ("depth error, 95th percentile (mm)", 1.0),
    "outlier_share": ("pixels more than 5 mm off (%)", 100.0),
    "edge5_mae_mm": (f"MAE off a {EDGE_BAND_PX}-px band at depth edges (mm)", 1.0),
    "completeness": ("completeness (% of the lit pixels)", 100.0),
    "stripe_order_errors": ("stripe-order errors (pixels)", 1.0),
    "stripe_order_error_rate": ("stripe-order errors (% of the decoded pixels)", 100.0),
}


def metric_words(metric: str) -> tuple[str, float]:
    """(an axis label in words with its unit, the factor the values are drawn with) of a sweep's
    metric: triangulated with the rig (paper Eq. 15) or, ``ref_*``, against the reference plane."""
    ref = metric.startswith("ref_")
    words, factor = _METRIC_WORDS[metric[4:] if ref else metric]
    return f"{words}, {'reference plane' if ref else 'triangulation'}", factor


def axis_words(name: str) -> str:
    """A sweep axis in words (its description, :data:`PARAMETERS`) with its key, for a plot."""
    from simbench.experiments.ablate.spec import PARAMETERS

    described = PARAMETERS.get(name, "")
    if described.startswith("DecoderParams."):
        # the field's own description in DecoderParams' docstring (a new user's audit: decoder axes
        # were labelled by their bare key, where docs/ablations.md promises words)
        described = _decoder_field_words(described.split(".", 1)[1])
    if not described:
        return name
    return f"{_first_clause(described)} [{name}]"


def _first_clause(text: str) -> str:
    """``text`` up to its first ':', ';' or sentence end outside brackets (a review: "speed (m/s;
    ...)" lost its bracket's end)."""
    depth, cut = 0, len(text)
    for i, ch in enumerate(text):
        depth += (ch == "(") - (ch == ")")
        if depth == 0 and (ch in ":;" or text.startswith(". ", i)):
            cut = i
            break
    return text[:cut].rstrip().rstrip(".")


# a decoder field's words on a plot axis: at most this many characters, brackets dropped beyond it
_DECODER_WORDS_MAX = 60


def _decoder_field_words(field: str) -> str:
    """The first clause of ``field``'s description in :class:`DecoderParams`' docstring, its reST
    markup removed (``x`` -> x, :func:`a.b` -> b); "" where the docstring has none."""
    import inspect
    import re

    from simbench.decode.params import DecoderParams

    doc = inspect.cleandoc(DecoderParams.__doc__ or "")
    # (a line may name several fields: "dark_level, saturation_level : float")
    m = re.search(rf"^(?:\w+, )*{re.escape(field)}(?:, \w+)* : [^\n]*\n((?:    [^\n]*\n?)+)", doc, re.M)
    if m is None:
        return ""
    text = " ".join(line.strip() for line in m.group(1).splitlines())
    text = re.sub(r":[a-z]+:`~?(?:[\w.]+\.)?([\w]+)`", r"\1", text).replace("``", "")
    first = _first_clause(text)
    if len(first) > _DECODER_WORDS_MAX:
        first = re.sub(r"\s*\([^()]*\)", "", first)
    if len(first) > _DECODER_WORDS_MAX:  # (the rest is in DecoderParams' docstring)
        first = first[: first.rfind(" ", 0, _DECODER_WORDS_MAX)].rstrip(",;") + " \u2026"
    return first


def _plot(sweep: Sweep, rows: list[dict]) -> dict[str, bytes]:
    import textwrap

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x_name = sweep.axes[0][0]
    x_vals, lines = plot_series(sweep, rows)
    ylabel, factor = metric_words(sweep.plot_metric)
    fig, ax = plt.subplots(figsize=(6.4, 4.2), constrained_layout=True)
    numeric = all(_is_number(v) for v in x_vals)
    pos = np.array([float(v) for v in x_vals] if numeric else list(range(len(x_vals))), np.float64)
    # values of a category are not joined by lines (there is nothing between two boards), and the
    # series are set a little apart so that their bars stay visible (a figure audit, 2026-11-30)
    dodge = 0.0 if numeric else min(0.08, 0.6 / max(1, len(lines)))
    for i, (label, means, lo, hi) in enumerate(lines):
        # each line its own marker and dash, the later ones' markers smaller, so that lines close
        # together stay told apart (and not by colour alone)
        style = dict(marker="osD^v<>p"[i % 8], ls=("-", "--", "-.", ":")[i % 4] if numeric else "none")
        m, a, b = (factor * v for v in (means, lo, hi))
        at = pos + dodge * (i - (len(lines) - 1) / 2)
        ax.errorbar(at, m, yerr=[m - a, b - m], capsize=3, label=label, ms=max(3.0, 7.0 - 0.5 * i), **style)
    if not numeric:
        ax.set_xticks(pos, x_vals, rotation=20, ha="right", rotation_mode="anchor", fontsize=8)
    elif len(x_vals) <= 8 and all(float(v).is_integer() for v in x_vals):
        ax.set_xticks(pos, [str(int(float(v))) for v in x_vals])
    ax.set_xlabel(textwrap.fill(axis_words(x_name), 80), fontsize=9)
    ax.set_ylabel(textwrap.fill(ylabel, 45), fontsize=9)
    ax.margins(y=0.08)
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    if len(lines) > 3:  # (beside the data a long legend hid it: the voting study's eight entries)
        fig.legend(loc="outside lower center", ncol=math.ceil(len(lines) / 6), fontsize=7)
        fig.set_figheight(4.2 + 0.13 * min(len(lines), 6))
    elif len(lines) > 1 or (lines and lines[0][0] != sweep.plot_metric):
        ax.legend(fontsize=7)
    described = sweep.description.rstrip()
    described += "" if not described or described.endswith(".") else "."
    caption = f"ablation {sweep.name}: {described} Bars: min to max over {sweep.repeats} repetition(s).".replace(
        ":  ", ": "
    )
    ax.set_title(textwrap.fill(caption, 90), fontsize=8)
    from simbench.report import figure_formats

    return figure_formats(fig, dpi=100)


def _is_number(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False
