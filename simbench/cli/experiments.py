"""``simbench demo``, ``reproduce``, ``crosstalk``, ``ablate`` and ``bench``: the experiments."""

from __future__ import annotations

import json
import sys
import time
from dataclasses import replace
from pathlib import Path


from simbench.seeds import DEFAULT_SEED
from simbench.cli.options import (
    SEED,
    add_cache_options,
    add_render_options,
    float_in,
    int_in,
    registered_systems,
    render_settings,
)


def _cmd_demo(args) -> int:
    from simbench.experiments.demo import DEFAULT_SCENES, demo_config, run_demo
    from simbench.sim.mitsuba_dict import DEFAULT_SAMPLER
    from simbench.variant import select_variant

    spp, sampler = render_settings(args)
    select_variant(args.variant)
    cfg = demo_config(spp=spp, sampler=sampler, seed=args.seed, sensor=args.camera)
    scenes = tuple(args.scenes) if args.scenes else DEFAULT_SCENES
    cache_dir = None if args.no_cache else args.cache
    # what was asked, for "Made by" (the defaults left out: `simbench demo --out results/demo` is make reproduce's)
    given = [
        ("--spp", args.spp),
        ("--sampler", args.sampler if args.sampler != DEFAULT_SAMPLER else None),
        ("--seed", args.seed if args.seed != DEFAULT_SEED else None),
        ("--sensor", args.camera if args.camera != "minimal" else None),
        ("--scenes", " ".join(args.scenes) if args.scenes else None),
        ("--variant", args.variant),
    ]
    command = " ".join([f"simbench demo --out {args.out}"] + [f"{k} {v}" for k, v in given if v is not None])
    run_demo(
        args.out,
        config=cfg,
        scenes=scenes,
        cache_dir=cache_dir,
        progress=lambda s: print(s, flush=True),
        command=command,
    )
    print(f"wrote {args.out}/summary.md, metrics.json, provenance.json and one figure per scene")
    return 0


def _cmd_reproduce(args) -> int:
    from simbench.experiments.common import RunConfig
    from simbench.sim.sensor import get_sensor
    from simbench.experiments.reproduce import (
        check_targets,
        check_threshold_names,
        THRESHOLD_RUN_SETTINGS,
        check_run_settings,
        check_thresholds,
        earlier_run,
        kept_thresholds,
        load_thresholds,
        reproduce,
        same_values,
        write_thresholds,
    )
    from simbench.variant import select_variant

    # everything a user can get wrong is checked before the first render
    check_targets(args.targets)
    if args.margin is not None and not args.write_thresholds:
        raise ValueError("--margin applies to --write-thresholds (the margin of the thresholds it writes)")
    margin = 0.25 if args.margin is None else args.margin
    if args.check:
        check_threshold_names(load_thresholds(args.check), args.targets, path=args.check, quick=args.quick)
    if args.write_thresholds:
        from simbench.io import check_output_file

        check_output_file(args.write_thresholds, what="--write-thresholds")
        kept_thresholds(args.write_thresholds, args.targets, margin=margin, quick=args.quick)
    if args.camera is not None:
        get_sensor(args.camera)
    overrides = {
        k: v
        for k, v in (
            ("seed", args.seed),
            ("spp", args.spp),
            ("fig9_repeats", args.repeats),
            ("sensor", args.camera),
            ("sampler", args.sampler),
        )
        if v is not None
    }
    config = RunConfig.preset(quick=args.quick, **overrides)  # checks spp against the sampler
    if args.decoder:
        from simbench.decode import robust_params, with_assignments

        # both decoders: the colour-robust one's own settings first, the assignments on top (a
        # decoder developer's audit, 2026-11-30: `--decoder crease_doubt=false` reached the paper's
        # decoder only, and the hard scenes' robust columns came out the same bits without a word)
        config = replace(
            config,
            decoder=with_assignments(config.decoder, args.decoder),
            robust_decoder=with_assignments(robust_params(config.decoder), args.decoder),
        )
    settings = {k: getattr(config, k) for k in THRESHOLD_RUN_SETTINGS}
    if args.check:
        check_run_settings(args.check, settings)  # before the run: thresholds of like runs only
    if args.write_thresholds and kept_thresholds(args.write_thresholds, args.targets, margin=margin, quick=args.quick):
        check_run_settings(args.write_thresholds, settings)  # the entries it keeps are of like runs
    out = args.out or ("results/quick" if args.quick else "results")
    from simbench.io import check_output_folder

    check_output_folder(out, what="--out")  # before the run, not after it (a decoder developer's audit)
    # the committed metrics a check compares with, read before the run may write over them
    earlier = earlier_run(Path(args.check).with_name("metrics.json")) if args.check else None
    select_variant(args.variant)
    # the command as typed (`simbench ...` or `python -m simbench ...`); called from Python, what
    # the options make of it (--quick among them: a thresholds file records its runs' resolution)
    command = (
        "simbench " + " ".join(sys.argv[1:])
        if sys.argv[1:2] == ["reproduce"]
        else "simbench reproduce " + " ".join(args.targets) + (" --quick" if args.quick else "")
    )
    metrics = reproduce(
        args.targets,
        config=config,
        out_dir=out,
        cache_dir=None if args.no_cache else args.cache,
        progress=lambda s: print(s, flush=True),
        command=command,
        workers=args.workers,
        scheduler=args.scheduler,
    )
    if args.write_thresholds:
        path = write_thresholds(
            args.write_thresholds,
            metrics,
            margin=margin,
            command=command,
            targets=args.targets,
            quick=args.quick,
            settings=settings,
        )
        print(f"wrote thresholds {path}")
    if args.check:
        failures = check_thresholds(metrics, args.check, targets=args.targets)
        if failures:
            for f in failures:
                print(f"simbench: regression: {f}", file=sys.stderr)
            print(f"simbench: {len(failures)} metric(s) worse than {args.check}", file=sys.stderr)
            if Path(args.check).with_name("metrics.json").exists():
                print(same_values(metrics, earlier), file=sys.stderr)
            return 1
        print(f"all metrics within {args.check}")
        if Path(args.check).with_name("metrics.json").exists():
            print(same_values(metrics, earlier))
    return 0


def _cmd_crosstalk(args) -> int:
    from simbench.experiments.table1 import PAPER_TABLE1
    from simbench.io import atomic_write_text
    from simbench.experiments.crosstalk import crosstalk_report

    if args.out:  # before the report is printed (a folder given failed only after it)
        from simbench.io import check_output_file

        check_output_file(args.out, what="--out")
    text = crosstalk_report({name: srgb for name, (srgb, _) in PAPER_TABLE1.items()})
    print(text)
    if args.out:
        atomic_write_text(
            args.out,
            text.replace(
                "# Projector-to-camera crosstalk matrices",
                f"# Projector-to-camera crosstalk matrices\n\nMade by `simbench crosstalk --out {args.out}`.",
                1,
            ),
        )
        print(f"wrote {args.out}")
    return 0


def _cmd_ablate(args) -> int:
    from simbench.experiments.ablate import BUILTIN_STUDIES, check_sweep, load_sweep, run_sweep
    from simbench.io import check_output_folder
    from simbench.variant import select_variant

    if args.scheduler is not None and args.workers > 1:  # before --fresh forgets a run log
        raise ValueError("--workers and --scheduler: choose one (the cluster's workers run the sweep)")
    if "builtin" in args.sweep:
        named = sorted({n for n in args.sweep if n in BUILTIN_STUDIES})
        if named or args.sweep.count("builtin") > 1:
            raise ValueError(
                f"'builtin' runs every built-in study ({', '.join(named) or 'builtin'} among them, named again): "
                "give 'builtin' or the studies"
            )
    names = [m for n in args.sweep for m in (BUILTIN_STUDIES if n == "builtin" else [n])]
    check_output_folder(args.out, what="--out")
    if not args.no_cache and args.cache is not None and Path(args.cache).exists():
        # (a third new user's audit: a --cache that is a file, or a folder of other files, failed every
        # run - a table of n/a, exit 0 - where render refuses it at once)
        from simbench.cache import check_cache_folder

        check_cache_folder(args.cache)
    sweeps = [load_sweep(n) for n in names]  # every file checked before any run starts
    for sweep in sweeps:
        check_sweep(sweep)  # and every run's values
    seen: dict[str, str] = {}
    for n, sweep in zip(names, sweeps):
        if sweep.name in seen:  # their tables, plots and run log would be one file each
            raise ValueError(
                f"{seen[sweep.name]} and {n} are both the study {sweep.name!r} (named by its `name` key, else by the "
                f"file's stem): their files in {args.out} would overwrite each other; rename one, or run them into "
                "other --out folders"
            )
        seen[sweep.name] = n
    select_variant(args.variant)
    command = (
        "simbench ablate " + " ".join(sys.argv[2:])
        if sys.argv[1:2] == ["ablate"]
        else "simbench ablate " + " ".join(args.sweep)
    )
    from simbench.io import claim_output

    # one sweep command at a time into a folder (a third new user's audit: two runs of one study into
    # one --out each did all its runs, and its run log held every run twice)
    with claim_output(args.out):
        failures = 0
        for sweep in sweeps:
            t0 = time.perf_counter()
            if args.fresh:
                (Path(args.out) / f"{sweep.name}.runs.jsonl").unlink(missing_ok=True)
            rows = run_sweep(
                sweep,
                out_dir=args.out,
                cache_dir=None if args.no_cache else args.cache,
                workers=args.workers,
                scheduler=args.scheduler,
                variant=args.variant,
                progress=lambda s: print(s, flush=True),
                command=command,
            )
            failed = sum(1 for r in rows if r["error"])
            failures += failed
            print(
                f"ablation {sweep.name}: {len(rows)} runs ({failed} failed) in {time.perf_counter() - t0:.0f} s -> "
                f"{args.out}/{sweep.name}.csv, .md, .png, .pdf"
            )
    if failures:  # the tables are written, their failed rows n/a; a script must not read that as done
        print(
            f"simbench: {failures} run(s) failed (their errors are in the tables and the run logs; a rerun "
            "retries them)",
            file=sys.stderr,
        )
        return 1
    return 0


def _cmd_bench(args) -> int:
    from simbench.experiments.bench import run_decode_benchmark, stage_table

    if args.stages:
        return _bench_stages(args)
    rig = None
    if args.rig is not None:
        from simbench.rig import load_rig

        rig = load_rig(args.rig)
    if args.max_ratio is not None and not args.robust:
        raise ValueError("--max-ratio applies to --robust (the colour-robust decoder against the paper's)")
    res = run_decode_benchmark(
        repeats=args.repeats,
        device=args.device,
        scene=args.scene,
        rig=rig,
        mode=args.mode,
        robust=args.robust,
        baseline=args.max_ratio is not None,
        decoder=tuple(args.decoder or ()),
    )
    setup = ", ".join(
        [res["scene"]]
        + ([f"rig {args.rig}"] if rig is not None else [])
        + ([f"{args.mode} mode"] if args.mode else [])
        + (["colour-robust decoder"] if args.robust else [])
        + ([f"decoder {' '.join(args.decoder)}"] if args.decoder else [])
    )
    threads = f"{res['threads']} thread" + ("s" if res["threads"] != 1 else "")
    print(
        json.dumps(res, indent=2)
        if args.json
        else f"{res['device']} decode of one {res['size_wh'][0]}x{res['size_wh'][1]} capture ({setup}): median "
        f"{res['median_ms']:.1f} ms, "
        f"min {res['min_ms']:.1f} ms over {res['repeats']} runs ({threads})"
        + (
            f"; {res['ratio']:.2f}x the paper decoder's median {res['baseline_median_ms']:.1f} ms, timed alongside"
            if "ratio" in res
            else ""
        )
    )
    if res["stages_ms"] and not args.json:
        print("per stage, mean per decode (row bands run in parallel threads, so the sum exceeds the wall time):")
        print(stage_table(res["stages_ms"]))
    # a failed check is exit 1, as reproduce --check's regressions: 2 is bad input
    if args.max_ms is not None and res["median_ms"] > args.max_ms:
        print(
            f"simbench: regression: decode median {res['median_ms']:.1f} ms exceeds --max-ms {args.max_ms}",
            file=sys.stderr,
        )
        return 1
    if args.max_ratio is not None and res["ratio"] > args.max_ratio:
        print(
            f"simbench: regression: the colour-robust decoder's median is {res['ratio']:.2f}x the paper decoder's, "
            f"over --max-ratio {args.max_ratio}",
            file=sys.stderr,
        )
        return 1
    return 0


def _bench_stages(args) -> int:
    """``bench --robust --stages``: the colour-robust decoder timed whole and with each stage off."""
    from simbench.experiments.bench import run_stage_benchmark

    if not args.robust:
        raise ValueError("--stages times the colour-robust decoder's stages: give --robust")
    clash = [
        flag
        for flag, given in (
            ("--rig", args.rig is not None),
            ("--mode", args.mode is not None),
            ("--decoder", bool(args.decoder)),
            ("--max-ms", args.max_ms is not None),
            ("--max-ratio", args.max_ratio is not None),
        )
        if given
    ]
    if clash:
        raise ValueError(f"--stages times the variants of simbench.experiments.robust_stages alone, not with {clash}")
    res = run_stage_benchmark(repeats=args.repeats, scene=args.scene, device=args.device)
    if args.json:
        print(json.dumps(res, indent=2))
        return 0
    w, h = res["size_wh"]
    print(
        f"colour-robust decoder of one {w}x{h} capture ({res['scene']}, triangulation), whole and with each stage "
        f"off (simbench.experiments.robust_stages), the decoders taking turns: over {res['repeats']} rounds "
        f"({res['threads']} threads), the median and the saving against the whole decoder in the same round "
        "(median, interquartile range)"
    )
    named = {"none": "none (the whole decoder)", "paper": "the paper's decoder (every stage)"}
    names = [named.get(r["stage_off"], r["stage_off"]) for r in res["rows"]]
    width = max(map(len, names))
    print(f"{'stage off':<{width}}  {'median ms':>9}  {'saved ms':>8}  {'IQR':>13}")
    unresolved = False
    for name, r in zip(names, res["rows"]):
        q1, q3 = r["saved_iqr_ms"]
        mark = "  not resolved" if r["stage_off"] != "none" and q1 <= 0.0 <= q3 else ""
        unresolved |= bool(mark)
        print(f"{name:<{width}}  {r['median_ms']:9.1f}  {r['saved_ms']:8.1f}  {q1:6.1f}..{q3:5.1f}{mark}")
    if unresolved:
        print(
            "not resolved: the saving's interquartile range holds 0 - more rounds (--repeats) or a quieter machine "
            "tell it from noise"
        )
    return 0


def add_parsers(sub, kw: dict) -> None:
    """Add this module's commands to the command line's subparsers."""
    from simbench.systems import DEFAULT_SYSTEM

    s = sub.add_parser("demo", help="render, decode and score the pipeline scenes into a results folder", **kw)
    s.add_argument("--out", default="results/demo", help="output folder")
    add_render_options(s)
    add_cache_options(s)
    s.add_argument("--seed", type=SEED, default=DEFAULT_SEED, help="base seed")
    s.add_argument(
        "--sensor",
        "--camera",
        dest="camera",
        default="minimal",
        help="sensor model: preset (ideal, minimal, paper, paper_sim) or TOML file",
    )
    s.add_argument("--scenes", nargs="+", help="scene names in scenes/ (default: the four pipeline scenes)")
    s.add_argument("--variant", default=None, help="Mitsuba variant (default: the fastest this machine runs)")
    s.set_defaults(fn=_cmd_demo)

    s = sub.add_parser("reproduce", help="regenerate the paper's Table 1, Table 3, Fig. 9 and figures", **kw)
    s.add_argument(
        "targets",
        nargs="*",
        default=["all"],
        # listed here, not imported (every command would pay the experiments' imports, ~45 ms);
        # tests/test_cli.py checks the list against simbench.experiments.reproduce.TARGETS
        help="table1, table3, fig9, figures, budget, render_noise, flatness, motion, hard_scenes, robust_stages or all "
        "(default: every target but hard_scenes and robust_stages: ~42-60 min from an empty cache on 2 cores, "
        "README.md's measurements)",
    )
    s.add_argument("--quick", action="store_true", help="640x480, 4 spp, 3 recordings per depth (the CI benchmark)")
    s.add_argument("--out", default=None, help="output folder (default: results, or results/quick with --quick)")
    add_cache_options(s, "render cache folder")
    s.add_argument("--seed", type=SEED, default=None, help=f"base seed (default {DEFAULT_SEED})")
    add_render_options(s, quick_spp=4)
    s.add_argument(
        "--repeats",
        type=int_in(1, 1000),
        default=None,
        help="recordings per Fig. 9 depth (default: 10, 3 with --quick)",
    )
    s.add_argument(
        "--sensor",
        "--camera",
        dest="camera",
        default=None,
        help="sensor model: preset (ideal, minimal, paper, paper_sim) or TOML file (default: paper)",
    )
    s.add_argument(
        "--decoder",
        nargs="*",
        metavar="NAME=VALUE",
        help="decoder parameter overrides, e.g. sigma_periods=0.4, for both decoders: the paper's, and the "
        "colour-robust one on top of its own settings (both recorded in the provenance)",
    )
    s.add_argument(
        "--check", help="thresholds TOML: exit 1 when a metric is worse (one of the other resolution is refused)"
    )
    s.add_argument(
        "--write-thresholds",
        help="write a thresholds TOML from this run's metrics (an existing file keeps its other targets' entries; it "
        "must be of this run's resolution and margin)",
    )
    s.add_argument(
        "--margin",
        type=float_in(lo=0.0, hi=10.0),
        default=None,
        help="relative margin for --write-thresholds (default 0.25)",
    )
    s.add_argument(
        "--workers",
        type=int_in(1, 64),
        default=1,
        help=(
            "worker processes, one task each at a time - a part of a target: a board of table1, a depth of fig9, a "
            "scene of hard_scenes, ... - (same outputs as 1; not with --scheduler)"
        ),
    )
    s.add_argument(
        "--scheduler",
        default=None,
        help=(
            "Dask distributed scheduler address (tcp://host:8786): run the targets on its workers instead (give "
            "--cache a path every worker sees; the files come back here)"
        ),
    )
    s.add_argument("--variant", default=None, help="Mitsuba variant (default: the fastest this machine runs)")
    s.set_defaults(fn=_cmd_reproduce)

    s = sub.add_parser(
        "crosstalk",
        help="print the projector-to-camera crosstalk matrices of white and the paper's seven colours",
        **kw,
    )
    s.add_argument("--out", help="also write them as Markdown here")
    s.set_defaults(fn=_cmd_crosstalk)

    s = sub.add_parser(
        "ablate",
        help="run ablation sweeps (TOML files or built-in study names; 'builtin' = all built-in studies)",
        **kw,
    )
    s.add_argument(
        "sweep",
        nargs="+",
        help="sweep TOML file(s) and built-in study name(s); 'builtin' (beside files, not beside its own studies) = "
        "every built-in study",
    )
    s.add_argument("--out", default="results/ablations", help="output folder")
    s.add_argument("--workers", type=int_in(1, 256), default=1, help="local worker processes (not with --scheduler)")
    s.add_argument("--fresh", action="store_true", help="forget finished runs (the run log) and redo every run")
    s.add_argument(
        "--scheduler", default=None, help="Dask distributed scheduler address (tcp://host:8786): run there instead"
    )
    add_cache_options(s, "render cache folder")
    s.add_argument("--variant", default=None, help="Mitsuba variant (default: the fastest this machine runs)")
    s.set_defaults(fn=_cmd_ablate)

    s = sub.add_parser("bench", help="benchmark a decoder at its native resolution (the paper's: 1280x960)", **kw)
    s.add_argument(
        "--system",
        "--device",
        dest="device",
        default=DEFAULT_SYSTEM,
        choices=registered_systems(),
        help="whose decoder",
    )
    s.add_argument(
        "--scene",
        default="plane",
        choices=["plane", "shadow"],
        help="colour-fringe decoder: a fully lit plane, or with a projector shadow (the path real scenes take)",
    )
    s.add_argument(
        "--rig",
        default=None,
        help="colour-fringe decoder: decode with this rig (TOML, e.g. from simbench calibrate; the capture is made "
        "with the paper's rig), its lens distortion included",
    )
    s.add_argument(
        "--mode",
        default=None,
        choices=["reference", "calibrated"],
        help="colour-fringe decoder: reference-plane matching or triangulation with the rig (default: the decoder's)",
    )
    s.add_argument(
        "--robust",
        action="store_true",
        help="colour-fringe decoder: time our colour-robust decoder (with its calibration frames) instead of the "
        "paper's",
    )
    s.add_argument(
        "--decoder",
        nargs="*",
        metavar="NAME=VALUE",
        help="colour-fringe decoder: time a variant, e.g. phase_method=ftp (on top of the colour-robust decoder's own "
        "settings with --robust; the paper decoder timed alongside stays the paper's)",
    )
    s.add_argument("--repeats", type=int_in(1, 100000), default=20, help="timed decodes (after one warm-up)")
    s.add_argument(
        "--max-ms", type=float_in(lo=0.0, lo_open=True), default=None, help="fail when the median exceeds this"
    )
    s.add_argument(
        "--max-ratio",
        type=float_in(lo=0.0, lo_open=True),
        default=None,
        help="with --robust: time the paper decoder alongside and fail when the colour-robust decoder's median "
        "exceeds this multiple of its median (a guard the machine's speed does not move)",
    )
    s.add_argument(
        "--stages",
        action="store_true",
        help="with --robust: time the colour-robust decoder whole, with each of its stages off (the variants of "
        "`simbench reproduce robust_stages`) and the paper's decoder, taking turns; --repeats rounds",
    )
    s.add_argument("--json", action="store_true", help="print the timings as JSON")
    s.set_defaults(fn=_cmd_bench)
