"""Moving scenes (issue 37): depth error against object speed, for every system with a time model.
Writes ``motion.md``, ``motion.csv``, ``motion.png``, ``.pdf`` and ``motion.provenance.json``.

The paper's case for a single-shot pattern is dynamic scenes (Sec. 1).  Here an object of two
scenes - the white board of ``scenes/motion_board.toml`` (before a wall) and the plaster bust of
``scenes/bust.toml`` - moves at a constant speed, sideways (+x) or towards the camera (-z), from
0 to 1 m/s, and each system records it with its own time model (:mod:`simbench.sim.motion`): the
paper's sensor one exposure of its global-shutter camera (decoded by the paper's decoder and by
the colour-robust one), 4-step phase shifting + Gray code 12 frames at the slower of the camera's
60 frames/s and the exposure, the Kinect one 1/30 s exposure per row of its rolling shutter (rows
63.5 us apart: :func:`simbench.systems.kinect.row_windows_s`), the ToF camera its four samples one
after another (:func:`simbench.systems.tof.tap_windows_s`).  Scored against the truth at
mid-capture over the moving object's lit pixels off the edge band (MAE and completeness), each
recording with the same seeds at every speed (common random numbers: the speed is the only
difference).  That region cannot see depth a system smears beyond the object's mid-capture
outline (onto the wall it passes, or between the two), so every decoded pixel of the image is
judged too, against every depth its pixel's truth takes during the capture
(``wrong_share_image``: :func:`capture_truths`), and its wrong pixels told apart by where motion
changed what they recorded (:func:`motion_classes`).

Budget (stated, not hidden): the experiment renders at a quarter of the camera's resolution
(:data:`CAMERA_SCALE`) with 64 samples a pixel in every capture (:data:`SPP`), since a blurred
capture takes one render per time slice (63 slices at 1 m/s on this camera); quick runs move the
board only, at 0, 0.03 and 0.3 m/s.  Phase shifting, twelve such captures, runs
only up to :data:`MULTI_SHOT_MAX_SPEED_M_S`: its sequence lasts ~0.33 s, so at that speed the
object has moved 32 mm during it; faster rows are "not run", not zero.  The competitors record
at their own cameras' resolution (the Kinect's 640x480, the ToF's 176x144).
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING

import numpy as np

from simbench.experiments.common import RunConfig, Session, Split, markdown_table, score, table_text
from simbench.metrics import edge_band, wrong_pixels
from simbench.report import figure_files, figure_formats
from simbench.sim.motion import Motion
from simbench.sim.timeline import image_speed_px_s, scene_at
from simbench.sim.truth import ground_truth

if TYPE_CHECKING:
    from simbench.systems import Recording

__all__ = [
    "SPEEDS_M_S",
    "QUICK_SPEEDS_M_S",
    "DIRECTIONS",
    "SCENES",
    "QUICK_SCENES",
    "SPLIT",
    "run_motion",
    "measure_motion",
    "write_motion",
    "motion_parts",
    "holds_up_to",
    "capture_truths",
    "capture_states",
    "motion_classes",
]

SPEEDS_M_S = (0.0, 0.003, 0.01, 0.03, 0.1, 0.3, 1.0)
QUICK_SPEEDS_M_S = (0.0, 0.03, 0.3)
# unit directions in the camera frame (x right, z forward): sideways, and towards the camera
DIRECTIONS = {"lateral": (1.0, 0.0, 0.0), "axial": (0.0, 0.0, -1.0)}
# scene file -> the object that moves
SCENES = {"motion_board": "board", "bust": "bust"}
QUICK_SCENES = ("motion_board",)
# a quarter of the camera's resolution (5.4 px a fringe period; an eighth, 2.7 px, does not decode)
CAMERA_SCALE = 0.25
# every capture's sample budget, static or moving: 64 multijittered samples a pixel still, the
# same 64 spread over the time slices when moving (63 slices at 1 m/s: one each), so that render
# noise is the same at every speed and the speed is the only difference
SPP = 64
SAMPLER = "multijitter"
MULTI_SHOT_MAX_SPEED_M_S = 0.1
# the rows: (system, decoder); the decoders of the paper's sensor read the same capture
# the competitors, recorded and decoded their devices' way
COMPETITORS = ("kinect", "tof")
ROWS = (("proposed", "paper"), ("proposed", "robust"), ("phase_shift", ""), *((c, "") for c in COMPETITORS))
# a system "holds" at a speed while its MAE stays within this factor of its static MAE
HOLD_FACTOR = 2.0
WRONG_M = 0.005  # a decoded depth this far from the truth is wrong (the hard scenes' measure)
# the truth over a capture is sampled at instants this far apart in image motion (any point of the
# moving object moves at most this many camera pixels from one to the next: a depth edge is then
# seen on both sides, and a slope of up to 10 mm a pixel changes the depth by < 5 mm between two)
SWEEP_STEP_PX = 0.5
MAX_SWEEP_INSTANTS = 257
# the whole image's wrong shares: all, and where motion changed the pixel's surface or its light
# (motion_classes)
WRONG_IMAGE = ("wrong_share_image", "wrong_share_image_moved", "wrong_share_image_shadowed")


def _label(system: str, decoder: str) -> str:
    if decoder:
        return {"paper": "paper's decoder", "robust": "colour-robust decoder"}[decoder]
    return {"phase_shift": "4-step phase shifting", "kinect": "Kinect v1 (simulated)", "tof": "SR4000-like ToF"}[system]


def holds_up_to(speeds: list[float], mae_mm: list[float], *, factor: float = HOLD_FACTOR) -> float:
    """The largest speed of the grid up to which the MAE stays within ``factor`` times the
    static one (speed 0) at every speed; NaN without a static MAE."""
    static = dict(zip(speeds, mae_mm)).get(0.0, math.nan)
    if not math.isfinite(static):
        return math.nan
    held = 0.0
    for s, m in sorted(zip(speeds, mae_mm)):
        if not (math.isfinite(m) and m <= factor * static):
            break
        held = s
    return held


def _moving(raw, name: str, velocity: tuple[float, float, float]):
    objects = tuple(
        dataclasses.replace(o, motion=Motion(velocity_m_s=velocity)) if o.name == name and any(velocity) else o
        for o in raw.objects
    )
    return dataclasses.replace(raw, objects=objects)


def _motion_session(session: Session) -> Session:
    """``session`` at the study's camera scale and sample budget (same cache, seeds, sensor)."""
    cfg = session.config
    sub = session.fork(
        session.sensor, config=dataclasses.replace(cfg, camera_scale=CAMERA_SCALE, spp=SPP, sampler=SAMPLER)
    )
    if not sub.sensor.is_physical:
        raise ValueError("the motion experiment needs the physical (emva) camera model (its exposure time)")
    return sub


def _grid(config: RunConfig) -> tuple[tuple[float, ...], dict]:
    return (QUICK_SPEEDS_M_S, {k: SCENES[k] for k in QUICK_SCENES}) if config.quick else (SPEEDS_M_S, SCENES)


# a capture's systems in three parts: phase shifting's moving sequence is most of a capture's time
# (up to ~5 min of one worker for the bust at 0.1 m/s), so it runs beside the others on a pool
GROUPS = ("proposed", "phase_shift", "competitors")


def motion_parts(config: RunConfig) -> list[str]:
    """The study's parts, ``scene/direction/speed/group``: every scene, direction and speed, its
    systems in :data:`GROUPS` (the proposed sensor, phase shifting, the competitors)."""
    speeds, scenes = _grid(config)
    return [f"{s}/{d}/{v:g}/{g}" for s in scenes for d in DIRECTIONS for v in speeds for g in GROUPS]


def motion_cost(part: str) -> float:
    """A part's rank for a pool: its speed (a faster object takes more time slices to render),
    phase shifting's twelve frames counted twelve times where it runs."""
    _, _, speed_text, group = part.split("/")
    speed = float(speed_text)
    if group == "phase_shift":
        return 12.0 * speed if speed <= MULTI_SHOT_MAX_SPEED_M_S else 0.0
    return speed


def measure_motion(session: Session, part: str) -> dict:
    """One scene moving in one direction at one speed, recorded and scored by one group of
    systems: its rows, metrics and the systems' capture times (plain data)."""
    scene_name, direction, speed_text, group = part.split("/")
    speed = float(speed_text)
    sub = _motion_session(session)
    moving = SCENES[scene_name]
    scene = _moving(sub.raw_scene(scene_name), moving, tuple(speed * u for u in DIRECTIONS[direction]))
    metrics, timing = {}, {}
    # the same seeds at every speed and direction (common random numbers)
    rows = _row_set(
        sub,
        scene,
        moving,
        f"motion/{scene_name}",
        f"motion/{scene_name}/{direction}/{speed_text}",
        speed,
        metrics,
        timing,
        scale=CAMERA_SCALE,
        group=group,
    )
    for r in rows:
        r.update(scene=scene_name, direction=direction)
    return {"rows": rows, "metrics": metrics, "timing": timing}


def write_motion(session: Session, measured: list[dict]) -> dict:
    """The study's files from :func:`measure_motion`'s results (in :func:`motion_parts`' order)."""
    speeds, scenes = _grid(session.config)
    sub = _motion_session(session)
    rows = [r for m in measured for r in m["rows"]]
    metrics = {k: v for m in measured for k, v in m["metrics"].items()}
    timing = {k: v for m in measured for k, v in m["timing"].items()}
    summary = _summary(rows)
    for (scene_name, direction, row), held in summary.items():
        metrics[f"motion/{scene_name}/{direction}/{row}/holds_up_to_m_s"] = held
    cols = [
        "scene",
        "direction",
        "speed_m_s",
        "system",
        "decoder",
        "row",
        "gt_mae_mm",
        "completeness",
        "wrong_share",
        *WRONG_IMAGE,
        "capture_s",
        "image_motion_px",
        "pixels",
        "note",
    ]
    files = {
        "motion.csv": table_text(rows, cols),
        "motion.md": _markdown(session, sub, rows, summary, timing, speeds, scenes),
        **figure_files("motion", _figure(rows, scenes, note=sub.config.figure_note())),
    }
    session.write_results(
        "motion",
        files,
        extra={
            "camera_scale": CAMERA_SCALE,
            "speeds_m_s": list(speeds),
            "multi_shot_max_speed_m_s": MULTI_SHOT_MAX_SPEED_M_S,
        },
    )
    return metrics


# each capture a part (the run's workers take them side by side, the fastest object first)
SPLIT = Split("motion", motion_parts, measure_motion, write_motion, cost=motion_cost)


def run_motion(session: Session) -> dict:
    """Every part of :func:`motion_parts` measured, then the files written (:class:`Split`)."""
    return SPLIT.run(session)


def _region(rec, moving_id: int, band_px: int) -> np.ndarray:
    gt = rec.gt
    region = gt.lit & np.isfinite(gt.depth_m) & (gt.object_id == moving_id)
    if band_px > 0:
        region &= ~edge_band(gt.depth_m, object_id=gt.object_id, band_px=band_px)
    return region


def capture_states(rec: "Recording", window_s: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """The truth over ``rec``'s capture (``window_s``: its system's ``capture_window_s``): the
    moving scene posed at K evenly spaced instants from the capture's start to its end, K such
    that no point moves more than :data:`SWEEP_STEP_PX` camera pixels between two (at most
    :data:`MAX_SWEEP_INSTANTS`); a static scene's one truth (K = 1).

    Returns
    -------
    depth_m : ndarray, shape (K, H, W), float32
        The truth's depth at each instant (NaN where it sees nothing).  A depth any of them takes
        at a pixel is one the pixel saw during the capture: judged against them, a blurred pixel is
        wrong only if it is far from everything it saw (lenient where a rolling shutter's row saw
        less than the whole capture: the Kinect's rows are judged against the frame's window).
    lit : ndarray, shape (K, H, W), bool
        Whether the projector lit each pixel at each instant (``GroundTruth.lit``: seen, in the
        projector's frustum, not in its shadow, on the surface's side facing both).
    """
    if rec.gt.motion_px is None:
        return rec.gt.depth_m[None], rec.gt.lit[None]
    scene = rec.scene
    t0, t1 = window_s
    # evenly spaced instants: the fastest in-view motion sets their count (timeline.slice_count)
    reach = image_speed_px_s(scene, scene.rig.camera, t0, t1) * (t1 - t0)
    n = int(min(MAX_SWEEP_INSTANTS, max(2, math.ceil(reach / SWEEP_STEP_PX) + 1)))
    pinhole = dataclasses.replace(scene, camera_lens=None)  # the truth is at the pinhole's pixel centres
    depth, lit = [], []
    for t in np.linspace(t0, t1, n):  # (two maps an instant kept, not K whole truths)
        gt = ground_truth(scene_at(pinhole, float(t)))
        depth.append(gt.depth_m)
        lit.append(gt.lit)
    return np.stack(depth), np.stack(lit)


def capture_truths(rec: "Recording", window_s: tuple[float, float]) -> np.ndarray:
    """The depth of :func:`capture_states`, shape (K, H, W), float32."""
    return capture_states(rec, window_s)[0]


def motion_classes(depth_m: np.ndarray, lit: np.ndarray, *, wrong_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Where motion changed what a pixel recorded during a capture.

    Parameters
    ----------
    depth_m, lit : ndarray, shape (K, H, W), float32 and bool
        The truth over the capture (:func:`capture_states`).
    wrong_m : float
        The depth change (m) that counts as another surface.

    Returns
    -------
    moved : ndarray, shape (H, W), bool
        Pixels whose surface changed under them: a depth span over ``wrong_m``, or seen at some
        instants only (depth smeared across a moving outline - a pixel counts once the outline
        crosses its centre -, or along a motion towards the camera).
    shadowed : ndarray, shape (H, W), bool
        Of the others, pixels the projector lit at some instants only: a shadow's border crossed
        a surface whose depth stayed within ``wrong_m`` (a fringe cut off part of the time).
        Neither class holds a pixel never seen, never lit, or of a static scene (K = 1).
    """
    seen = np.isfinite(depth_m)
    span = np.where(seen, depth_m, -np.inf).max(axis=0) - np.where(seen, depth_m, np.inf).min(axis=0)
    moved = (seen.any(axis=0) & ~seen.all(axis=0)) | (seen.all(axis=0) & (span > wrong_m))
    shadowed = ~moved & lit.any(axis=0) & ~lit.all(axis=0)
    return moved, shadowed


def _wrong_shares_image(depth_m: np.ndarray, states: tuple[np.ndarray, np.ndarray]) -> dict[str, float]:
    """Shares of every decoded pixel of the image more than 5 mm from every truth of ``states``
    (:func:`capture_states`), :data:`WRONG_IMAGE`: all of them, and those of :func:`motion_classes`'
    two classes; NaN where nothing is decoded."""
    n = int(np.isfinite(depth_m).sum())
    if not n:
        return dict.fromkeys(WRONG_IMAGE, math.nan)
    wrong = wrong_pixels(depth_m, states[0], wrong_m=WRONG_M)
    moved, shadowed = motion_classes(*states, wrong_m=WRONG_M)
    return dict(zip(WRONG_IMAGE, (float(np.count_nonzero(wrong & m) / n) for m in (wrong, moved, shadowed))))


def _wrong_share(depth_m: np.ndarray, rec, region: np.ndarray) -> float:
    """Share of the decoded pixels of ``region`` more than 5 mm from the truth."""
    d = np.asarray(depth_m, np.float64)
    ok = region & np.isfinite(d)
    if not ok.any():
        return math.nan
    return float(np.mean(np.abs(d[ok] - rec.gt.depth_m[ok]) > WRONG_M))


def _row_set(
    sub: Session,
    scene,
    moving: str,
    label: str,
    key: str,
    speed: float,
    metrics: dict,
    timing: dict,
    *,
    scale: float,
    group: str,
):
    """The rows of ``group`` of :data:`GROUPS` for one moving scene."""
    cfg = sub.config
    moving_id = [o.name for o in scene.objects].index(moving)
    rows = []
    prepared = sub.prepare(scene)
    # the run's edge band is for its own camera scale: the same angle at this one
    band = max(1, int(round(cfg.edge_band_px * scale / cfg.camera_scale)))
    if group == "proposed":
        window = sub.proposed.capture_window_s(prepared)
        timing["proposed"] = window[1] - window[0]
        cap = sub.capture(prepared, label)[0]
        region = _region(cap, moving_id, band)
        motion_px = float(np.abs(cap.gt.motion_px).max()) if cap.gt.motion_px is not None else 0.0
        states = capture_states(cap, window)
        for decoder in ("paper", "robust"):
            params = cfg.decoder if decoder == "paper" else cfg.robust()
            result = sub.decode(cap, params, mode="calibrated")
            sc = score(cap, result, params.period_px, region=region)
            sc["wrong_share"] = _wrong_share(result.depth_m, cap, region)
            sc.update(_wrong_shares_image(result.depth_m, states))
            rows.append(_row("proposed", decoder, speed, sc, window, motion_px, int(region.sum()), ""))
    if group == "phase_shift":
        rows += _phase_shift_rows(sub, scene, moving_id, label, speed, band, timing)
    if group == "competitors":
        rows += _competitor_rows(sub, scene, moving_id, label, speed, band, prepared.rig.camera.focal_px, timing)
    for r in rows:
        for m in ("gt_mae_mm", "completeness", "wrong_share", *WRONG_IMAGE):
            metrics[f"{key}/{r['row']}/{m}"] = r[m]
    return rows


def _phase_shift_rows(sub: Session, scene, moving_id: int, label: str, speed: float, band: int, timing: dict) -> list:
    rows = []
    ps = sub.system("phase_shift")
    ps_prepared = ps.prepare(scene)
    ps_window = ps.capture_window_s(ps_prepared)
    timing["phase_shift"] = ps_window[1] - ps_window[0]
    timing["phase_shift_period"] = ps.frame_period_s(ps_prepared)
    if speed <= MULTI_SHOT_MAX_SPEED_M_S:
        rec, depth = sub.acquire("phase_shift", scene, label)[0]
        region_ps = _region(rec, moving_id, band)
        sc = score(rec, depth, ps.info().period_px, region=region_ps)
        sc["wrong_share"] = _wrong_share(depth.depth_m, rec, region_ps)
        sc.update(_wrong_shares_image(depth.depth_m, capture_states(rec, ps_window)))
        mpx = float(np.abs(rec.gt.motion_px).max()) if rec.gt.motion_px is not None else 0.0
        rows.append(_row("phase_shift", "", speed, sc, ps_window, mpx, int(region_ps.sum()), ""))
    else:
        travel_mm = speed * (ps_window[1] - ps_window[0]) * 1e3
        rows.append(
            _row(
                "phase_shift",
                "",
                speed,
                None,
                ps_window,
                math.nan,
                0,
                f"not run: the object moves {travel_mm:.0f} mm during the {ps_window[1] - ps_window[0]:.2f} s sequence",
            )
        )
    return rows


def _competitor_rows(
    sub: Session, scene, moving_id: int, label: str, speed: float, band: int, main_focal: float, timing: dict
) -> list:
    rows = []
    for name in COMPETITORS:  # each at its own camera's resolution
        rec, depth = sub.acquire(name, scene, label)[0]
        band_own = max(1, int(round(band * rec.scene.rig.camera.focal_px / main_focal)))  # the same angle
        region_own = _region(rec, moving_id, band_own)
        sc = score(rec, depth, None, region=region_own)
        sc["wrong_share"] = _wrong_share(depth.depth_m, rec, region_own)
        mpx = float(np.abs(rec.gt.motion_px).max()) if rec.gt.motion_px is not None else 0.0
        own_window = sub.system(name).capture_window_s(rec.scene)
        sc.update(_wrong_shares_image(depth.depth_m, capture_states(rec, own_window)))
        timing[name] = own_window[1] - own_window[0]
        rows.append(_row(name, "", speed, sc, own_window, mpx, int(region_own.sum()), ""))
    return rows


def _row(system: str, decoder: str, speed: float, sc: dict | None, window, motion_px: float, pixels: int, note: str):
    nan = math.nan
    return {
        "speed_m_s": speed,
        "system": system,
        "decoder": decoder,
        "row": f"{system}_{decoder}" if decoder else system,
        "gt_mae_mm": nan if sc is None else float(sc["gt_mae_mm"]),
        "completeness": nan if sc is None else float(sc["completeness"]),
        "wrong_share": nan if sc is None else float(sc["wrong_share"]),
        **{m: nan if sc is None else float(sc[m]) for m in WRONG_IMAGE},
        "capture_s": float(window[1] - window[0]),
        "image_motion_px": motion_px,
        "pixels": pixels,
        "note": note,
    }


def _summary(rows: list[dict]) -> dict:
    groups: dict = {}
    for r in rows:
        groups.setdefault((r["scene"], r["direction"], r["row"]), []).append(r)
    return {k: holds_up_to([r["speed_m_s"] for r in rs], [r["gt_mae_mm"] for r in rs]) for k, rs in groups.items()}


def _markdown(session: Session, sub: Session, rows, summary, timing, speeds, scenes) -> str:
    cfg = session.config
    cam = sub.scene("motion_board").rig.camera
    lines = [
        "# Moving scenes: depth error against object speed",
        "",
        f"Made by `{session.command}` ({cam.width_px}x{cam.height_px} camera: "
        f"{CAMERA_SCALE:g} of the sensor's resolution, sensor model `{cfg.sensor}`, {SPP} samples a pixel in every "
        f"capture - {SAMPLER} when still, spread over the time slices when moving -, base seed {cfg.seed}, "
        f"variant `{session.variant}`).",
        "",
        "Time models: the paper's sensor records one exposure of its global-shutter camera, "
        f"{timing['proposed'] * 1e3:.1f} ms (the auto exposure on the white board); 4-step phase shifting + Gray code "
        f"records 12 frames, one every {timing['phase_shift_period'] * 1e3:.1f} ms (the exposure, or the Flea3's "
        f"60 frames/s if that is slower), {timing['phase_shift']:.3f} s in all; the Kinect's rolling-shutter IR camera "
        "exposes each row for 1/30 s (an assumption: no published value), the rows "
        f"{sub.system('kinect').model.row_time_s * 1e6:.1f} us apart top to bottom (MT9M001 data sheet), "
        f"{timing['kinect'] * 1e3:.1f} ms from the first row's start to the last row's end; the SR4000-like ToF "
        "camera takes its "
        f"four correlation samples one after another over its {timing['tof'] * 1e3:.1f} ms integration (an "
        "assumption, as PMD cameras do). Motion blur is the radiance integrated "
        "over "
        "each exposure (time slices, each point moving at most 0.25 px per slice); the truth is the scene at "
        "mid-capture. Scored over the moving object's lit pixels off the edge band: MAE against the truth, "
        "completeness, share of decoded pixels > 5 mm wrong. That region cannot see depth smeared beyond the "
        "object's mid-capture outline, so every decoded pixel of the image is judged as well, against every depth "
        f"the truth takes at that pixel during the capture (the scene posed at instants <= {SWEEP_STEP_PX:g} px of "
        "motion apart; the Kinect's rows against the whole frame's window, lenient): wrong if more than 5 mm from "
        "all of them, or decoded where the truth sees nothing. "
        f"Phase shifting runs up to {MULTI_SHOT_MAX_SPEED_M_S:g} m/s (rows above: not run, with the distance the "
        "object "
        "travels during its sequence).",
        "",
        f"**Holds up to** (the fastest speed of the grid at which the MAE is still within {HOLD_FACTOR:g}x the static "
        "MAE, at every speed up to it):",
        "",
    ]
    hdr = ["scene", "motion", *[_label(s, d) for s, d in ROWS]]
    body = []
    for scene_name in scenes:
        for direction in DIRECTIONS:
            cells = []
            for s, d in ROWS:
                held = summary.get((scene_name, direction, f"{s}_{d}" if d else s), math.nan)
                top = max(
                    r["speed_m_s"]
                    for r in rows
                    if r["scene"] == scene_name and r["direction"] == direction and r["system"] == s and not r["note"]
                )
                if not math.isfinite(held):
                    cells.append("-")
                elif held == top:  # held at every speed it was recorded at: a lower bound
                    cells.append(f">= {held * 1e3:g} mm/s (all run)")
                else:
                    cells.append(f"{held * 1e3:g} mm/s")
            body.append([scene_name, direction, *cells])
    lines += markdown_table(hdr, body)
    lines += ["", "MAE (mm) / completeness by speed:", ""]
    hdr = ["scene", "motion", "speed (m/s)", *[_label(s, d) for s, d in ROWS]]
    lines += markdown_table(
        hdr, _by_speed(rows, scenes, speeds, lambda r: f"{r['gt_mae_mm']:.3f} / {100 * r['completeness']:.1f} %")
    )
    lines += [
        "",
        "Wrong depth (> 5 mm), % of the decoded pixels: of the object's (the region above) / of the whole image's "
        "(against every truth during the capture). The static row is each system's floor at this camera's "
        "resolution (its depth edges, and its noise: the competitors' alone passes 5 mm on part of the wall); what "
        "motion adds is the rise above it, which the object's region does not see (the next table says where it "
        "lies). The whole image's measure is lenient where a pixel saw a range of depths (an axial motion, a long "
        "sequence): any depth in it is right there; the object's MAE is not.",
        "",
    ]
    lines += markdown_table(
        hdr,
        _by_speed(rows, scenes, speeds, lambda r: f"{_percent(r['wrong_share'])} / {_percent(r['wrong_share_image'])}"),
    )
    lines += [
        "",
        "Where the whole image's wrong pixels lie, % of the decoded pixels: where the surface under the pixel moved "
        "during the capture (its depth changed by more than 5 mm, or it came into or out of view: depth smeared "
        "across a moving outline, or along a motion towards the camera) / where its depth stayed within 5 mm but a "
        "shadow's border crossed it (the projector's light cut off part of the time: a fringe that fades within "
        "the capture) / elsewhere (the static floor above, and what lies beyond those pixels; "
        "`simbench.experiments.motion.motion_classes`). A pixel counts as moved once a moving outline crosses its "
        "centre, so from the speed at which an outline first crosses a column of pixel centres the "
        "static floor's own wrong pixels along it pass into the first class; the Kinect's rows are classed over the "
        "whole frame's window, about twice a row's exposure, so its first two classes are as lenient.",
        "",
    ]
    lines += markdown_table(hdr, _by_speed(rows, scenes, speeds, _where_wrong))
    return "\n".join(lines) + "\n"


def _where_wrong(r: dict) -> str:
    moved, shadowed = r["wrong_share_image_moved"], r["wrong_share_image_shadowed"]
    # (the classes are disjoint subsets of the wrong pixels: a difference under 0 is float rounding)
    elsewhere = max(0.0, r["wrong_share_image"] - moved - shadowed)
    return f"{_percent(moved)} / {_percent(shadowed)} / {_percent(elsewhere)}"


def _by_speed(rows: list[dict], scenes, speeds, cell) -> list[list[str]]:
    """A table body: a row per scene, direction and speed, a column per system of :data:`ROWS`,
    each cell ``cell(row)`` ("not run" where the system did not run)."""
    body = []
    for scene_name in scenes:
        for direction in DIRECTIONS:
            for speed in speeds:
                cells = []
                for s, d in ROWS:
                    row = _find(rows, scene_name, direction, speed, s, d)
                    cells.append("not run" if row["note"] else cell(row))
                body.append([scene_name, direction, f"{speed:g}", *cells])
    return body


def _find(rows: list[dict], scene_name: str, direction: str, speed: float, system: str, decoder: str) -> dict:
    return next(
        r
        for r in rows
        if r["scene"] == scene_name
        and r["direction"] == direction
        and r["speed_m_s"] == speed
        and r["system"] == system
        and r["decoder"] == decoder
    )


def _percent(share: float) -> str:
    return "-" if not math.isfinite(share) else f"{100 * share:.2f} %"


# the figure's level for a wrong share of 0 (a log axis): under one pixel of the study's 320x240
# (0.0013 %), so that every share measured shows as it is
WRONG_FLOOR_PERCENT = 0.001
# speed 0 on the log speed axis: the still capture, drawn apart (an open marker, not joined to the
# moving ones: on the line it read as a measurement at 0.3 mm/s - a figure audit, 2026-11-30)
STILL_AT_M_S = 3e-4
_DIRECTION_WORDS = {"lateral": "sideways", "axial": "towards the camera"}


def _figure(rows: list[dict], scenes: dict, *, note: str = "") -> dict[str, bytes]:
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    from simbench.report import panel_row

    panels = [(s, d) for s in scenes for d in DIRECTIONS]
    plt, fig, axes = panel_row(len(panels), width=3.6, rows=2)
    # a colour and a marker each (not colour alone: red and green told two systems apart)
    colours = {
        "proposed_paper": ("tab:blue", "o"),
        "proposed_robust": ("tab:green", "s"),
        "phase_shift": ("tab:red", "^"),
        "kinect": ("tab:orange", "D"),
        "tof": ("tab:purple", "v"),
    }
    for col, (scene_name, direction) in enumerate(panels):
        ax, ax_wrong = axes[0, col], axes[1, col]
        for s, d in ROWS:
            name = f"{s}_{d}" if d else s
            rs = [r for r in rows if r["scene"] == scene_name and r["direction"] == direction and r["row"] == name]
            rs = [r for r in rs if math.isfinite(r["gt_mae_mm"])]
            if not rs:
                continue
            colour, marker = colours[name]
            label = _label(s, d)
            if any(r.get("note") for r in rows if r["row"] == name):
                # (phase shifting: not run where the object moves too far during its sequence)
                label += (
                    f" (run up to {max(r['speed_m_s'] for r in rows if r['row'] == name and not r.get('note')):g} m/s)"
                )
            still = [r for r in rs if r["speed_m_s"] == 0]
            moving = [r for r in rs if r["speed_m_s"] > 0]
            # percent; none wrong drawn at WRONG_FLOOR_PERCENT
            wrong = lambda rr: [max(100 * r["wrong_share_image"], WRONG_FLOOR_PERCENT) for r in rr]  # noqa: E731
            speeds = [r["speed_m_s"] for r in moving]
            ax.plot(speeds, [r["gt_mae_mm"] for r in moving], "-", marker=marker, ms=4, color=colour, label=label)
            ax_wrong.plot(speeds, wrong(moving), "-", marker=marker, ms=4, color=colour)
            if still:
                kw = dict(marker=marker, ms=5, mfc="none", color=colour, ls="none")
                ax.plot([STILL_AT_M_S], [still[0]["gt_mae_mm"]], **kw)
                ax_wrong.plot([STILL_AT_M_S], wrong(still[:1]), **kw)
                ax.axhline(HOLD_FACTOR * still[0]["gt_mae_mm"], color=colour, ls=":", lw=0.8)
        ax.set_yscale("log")
        # plain numbers at 1, 2 and 5 of each decade (the default labelled a short range's minor ticks
        # as 4 x 10^0)
        ax.yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
        ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        ax.yaxis.set_minor_formatter(NullFormatter())
        ax.set_title(f"{scene_name}, {_DIRECTION_WORDS.get(direction, direction)} ({direction})")
        ax_wrong.set_yscale("log")
        ax_wrong.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        if any(r["wrong_share_image"] == 0 for r in rows if r["scene"] == scene_name and r["direction"] == direction):
            ax_wrong.set_ylim(bottom=WRONG_FLOOR_PERCENT * 0.8)  # (the level a share of 0 is drawn at)
        ax_wrong.set_xlabel("speed (m/s)")
        for a in (ax, ax_wrong):
            a.set_xscale("log")
            a.grid(True, which="both", alpha=0.3)
            a.axvline(STILL_AT_M_S * 2, color="0.6", lw=0.6)  # the still capture's column, set apart
    axes[0, 0].set_ylabel(f"object's MAE (mm)\ndotted: {HOLD_FACTOR:g}x static")
    axes[1, 0].set_ylabel(f"wrong (> 5 mm), % of the image's\ndecoded pixels ({WRONG_FLOOR_PERCENT:g}: none)")
    # below the panels: inside the first one it covered the phase-shifting curve
    handles, labels = axes[0, 0].get_legend_handles_labels()
    from matplotlib.lines import Line2D

    handles.append(Line2D([], [], marker="o", mfc="none", color="0.3", ls="none"))
    labels.append("open: still (speed 0), left of the grey line")
    fig.legend(handles, labels, loc="outside lower center", ncol=len(labels), fontsize=8, frameon=False)
    fig.suptitle(f"Moving scenes: depth error against the object's speed{note}", fontsize=10)
    return figure_formats(fig, dpi=110)
