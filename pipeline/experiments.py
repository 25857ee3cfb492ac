"""Experiments: accuracy against noise and against speed, and where methods break.

A *trial* is one shot rendered to a video (plain look, the given sensor
noise, frame rate, pixels per metre and codec), tracked and recovered by
both methods, and scored against the truth: a row of ``trials.csv`` with
the relative errors of v0 and R w0, the MLE's Cramer-Rao bound for the same
measurements, each method's status and the timings.  The video runs from
frame 0 (the ball at rest for the shot's lead-in ``t0``) to the end of
sliding plus ``ROLL_S`` of rolling (or the stop, or the ball leaving the
table); the noise and stability trials film only the part of the table the
ball crosses (:func:`path_camera`: the same pixels as the whole-table view,
a smaller frame), the speed-accuracy trials the whole table, so that their
times are a user's.

Each experiment renders, tracks and recovers many scenes (in worker
processes), appends every trial to ``trials.csv`` as it ends (a rerun
resumes: only missing trials run) and draws PNG charts:

* ``noise``: errors of v0 and w0 for each method against noise sigma, frame
  rate, pixels per metre and codec (one factor at a time from a base of
  sigma 5, 240 fps, 500 px/m, MJPG), with the MLE's Cramer-Rao bound.
* ``speed-accuracy``: time per video against error for the choices that
  trade one for the other (tracker refinement, resolution, frame rate,
  paper vs MLE), Pareto front marked.
* ``stability``: a map over the spin's direction relative to v0 and its
  magnitude, colouring each method's error and failure rate; each cell is
  labelled with its sliding time.
"""

from __future__ import annotations

import csv
import math
import os
import tempfile
import time
from contextlib import nullcontext
from pathlib import Path

import numpy as np

EXPERIMENTS = ("noise", "speed-accuracy", "stability")
# Shots per setting: 20 gives a median and an interquartile range that a
# different seed does not reorder (3 did: issue 13).
DEFAULT_N = 20
BASE = {"noise": 5.0, "fps": 240.0, "px_per_m": 500.0, "codec": "MJPG", "refine": "fit",
        "view": "path"}
MAX_SECONDS = 3.0
# Rolling filmed after the sliding ends (s): the roll line both methods need
# (the paper's eq. 17-19 and the MLE's rolling segment) at 30+ frames even at
# 60 fps; filming on to the stop (up to MAX_SECONDS) cost 3-5x the frames.
ROLL_S = 0.5
# Felt kept around the ball's path in a "path" view (m).  The tracker learns
# the felt and the noise from the whole frame: with 24 px (about 2 ball radii
# at 500 px/m) the path filled so much of the frame that the noise read 26.5
# grey levels for 20 and no ball was found in a sigma-20 video the
# whole-table view tracks; 0.13 m read 21.4, 0.26 m 19.8 (measured).
PAD_M = 0.25
# The grid the cut is aligned to (MJPG's 16 px macroblocks).
CROP_ALIGN = 16


def shot_pool(n: int, seed: int):
    """``n`` shots whose sliding ends in view and which stay on the table for a
    while after: the shots both methods can in principle answer."""
    from cuespin.data_gen.sampler import sample_shot
    from cuespin.physics import phases, positions
    from cuespin.physics.scene import Table

    rng = np.random.default_rng(seed)
    table = Table()
    out = []
    while len(out) < n:
        shot, p = sample_shot(rng, "random")
        speed = np.hypot(*shot.v0)
        if not 0.4 <= speed <= 2.5:
            continue
        ph = phases(shot, p)
        t = np.linspace(shot.t0, min(ph.t2, ph.t1 + 0.5), 50)
        if ph.t1 - shot.t0 < 0.03 or not table.contains(positions(shot, p, t), margin=p.R).all():
            continue
        out.append((shot, p))
    return out


def path_camera(shot, p, fps: float, px_per_m: float, end: float, pad_m: float = PAD_M):
    """The conventions' top-down camera cut down to the part of the table the
    ball crosses until ``end`` (s), plus ``pad_m`` (m) of felt beyond its outline.

    The cut falls on :data:`CROP_ALIGN` pixel multiples of the whole-table
    view, so every pixel keeps its place on the codec's block grid and its
    metres: the ball's image is the whole-table render's, only the frame
    (and so the time to encode and decode it) is smaller.
    """
    from dataclasses import replace

    from cuespin.physics import positions
    from cuespin.physics.camera import default_camera

    cam = default_camera(fps=fps, px_per_m=px_per_m)
    t = np.linspace(shot.t0, max(end, shot.t0), 200)
    xy = np.vstack([np.asarray(shot.x0, dtype=float)[None], positions(shot, p, t)])
    uv = np.asarray(cam.to_pixels(xy))
    r = (p.R + pad_m) * px_per_m
    a = CROP_ALIGN
    c0 = max(0, int(math.floor((uv[:, 0].min() - r) / a)) * a)
    c1 = min(cam.width, int(math.ceil((uv[:, 0].max() + r) / a)) * a)
    r0 = max(0, int(math.floor((uv[:, 1].min() - r) / a)) * a)
    r1 = min(cam.height, int(math.ceil((uv[:, 1].max() + r) / a)) * a)
    H = np.array(cam.homography, dtype=float)
    H[0, 2] -= c0
    H[1, 2] -= r0
    return replace(cam, width=c1 - c0, height=r1 - r0, homography=tuple(map(tuple, H)))


def trial(spec: dict) -> dict:
    """Render, track and recover one scene; errors, the MLE bound and timings.

    ``spec`` holds the shot (``x0 v0 w0 t0`` and friction) and the settings
    (``noise fps px_per_m codec refine view``) plus labels copied to the row.
    The video runs from frame 0 (the ball at rest, ``t0`` lead-in) to the
    end of sliding plus :data:`ROLL_S` of rolling (or to the stop, or off
    the table); ``view`` "path" films the part of the table the ball
    crosses (:func:`path_camera`), "table" the whole table.
    """
    from dataclasses import replace

    from cuespin.data_gen.sampler import make_scene
    from cuespin.pipeline.run import run_recover
    from cuespin.physics import BallParams, Shot
    from cuespin.pipeline.measure import mle_bound
    from cuespin.render import render_video, truth_path, video_length
    from cuespin.track.tracker import TrackerConfig

    shot = Shot(spec["x0"], spec["v0"], spec["w0"], spec["t0"])
    p = BallParams(mu_s=spec["mu_s"], mu_r=spec["mu_r"])
    end = min(MAX_SECONDS, shot.t0 + float(spec["t1"]) + ROLL_S)
    scene = make_scene(shot, p, fps=spec["fps"], px_per_m=spec["px_per_m"],
                       render={"noise_sigma": spec["noise"], "codec": spec["codec"],
                               "max_duration": end, "seed": spec.get("seed", 0)})
    if spec.get("view", "table") == "path":
        scene = replace(scene, camera=path_camera(shot, p, spec["fps"], spec["px_per_m"], end))
    row = {k: v for k, v in spec.items() if k not in ("x0", "v0", "w0")}
    row.update(frames=video_length(scene), width=scene.camera.width, height=scene.camera.height)
    fd, name = tempfile.mkstemp(suffix=".avi")
    os.close(fd)
    try:
        clock = time.perf_counter()
        render_video(scene, name)
        row["t_render"] = time.perf_counter() - clock
        clock = time.perf_counter()
        out, tr = run_recover(name, scene, return_track=True,
                              config=TrackerConfig(refine=spec["refine"], threaded=False))
        row["t_total"] = time.perf_counter() - clock
    except Exception as exc:  # an experiment records failures, it does not stop
        row.update(status_paper="failed", status_mle="failed", reason=str(exc))
        return row
    finally:  # the video and the truth sidecar render_video writes beside it
        Path(name).unlink(missing_ok=True)
        truth_path(name).unlink(missing_ok=True)
    v0, w0 = np.array(shot.v0), np.array(shot.w0)
    speed = np.hypot(*v0)
    row.update(t_track=out["timing_s"]["track"], t_fit=out["timing_s"]["fit"],
               t_recover=out["timing_s"]["recover"], t1=float(spec["t1"]))
    for m, d in out["methods"].items():
        row[f"status_{m}"] = d["status"]
        row[f"err_v0_{m}"] = np.hypot(*(np.array(d["v0"]) - v0)) / speed if d["v0"] else math.nan
        row[f"err_rw0_{m}"] = p.R * np.hypot(*(np.array(d["w0"]) - w0)) / speed if d["w0"] else math.nan
    # The bound for the same measurements as the fit's (pipeline.measure).
    try:
        cov, rolling = mle_bound(scene, tr, out["methods"].get("mle"))
        row["crb_v0"] = float(np.sqrt(cov[3, 3] + cov[4, 4]) / speed)
        row["crb_rw0"] = float(p.R * np.sqrt(cov[5, 5] + cov[6, 6]) / speed) if not rolling else row["crb_v0"]
    except (np.linalg.LinAlgError, IndexError, ValueError):  # singular, or no frame tracked
        row["crb_v0"] = row["crb_rw0"] = math.nan
    return row


def _spec(shot, p, i, **settings):
    from cuespin.physics import phases
    s = dict(BASE)
    s.update(settings)
    s.update(x0=shot.x0, v0=shot.v0, w0=shot.w0, t0=shot.t0, mu_s=p.mu_s, mu_r=p.mu_r, shot=i,
             t1=phases(shot, p).t1 - shot.t0, seed=i)
    return s


def specs_noise(n, seed, quick=False):
    pool = shot_pool(n, seed)
    factors = {"noise": [0.0, 2.0, 5.0, 10.0, 20.0], "fps": [60.0, 120.0, 240.0, 480.0],
               "px_per_m": [250.0, 375.0, 500.0], "codec": ["MJPG", "FFV1"]}
    if quick:
        # A smoke test: two noise levels and the other codec (500 px/m is the base).
        factors = {"noise": [2.0, 10.0], "codec": ["FFV1"]}
    # The base setting is run once (as noise 5.0): the other factors' base
    # levels are the same videos (same shots, seeds and settings).
    return [_spec(shot, p, i, factor=f, level=str(v), **{f: v})
            for f, values in factors.items() for v in values if f == "noise" or v != BASE[f]
            for i, (shot, p) in enumerate(pool)]


def specs_speed(n, seed, quick=False):
    pool = shot_pool(n, seed)
    grid = [(r, s, f) for r in ("fit", "moments") for s in (250.0, 500.0) for f in (120.0, 240.0)]
    if quick:
        grid = grid[:2]
    # The whole table in view: the time per video is a user's.
    return [_spec(shot, p, i, refine=r, px_per_m=s, fps=f, view="table", config=f"{r}, {s:.0f} px/m, {f:.0f} fps")
            for r, s, f in grid for i, (shot, p) in enumerate(pool)]


STABILITY_ANGLES = (0, 45, 90, 225, 270)   # deg; the mirror images of the rest (docstring)
STABILITY_MAGS = (0.25, 1.0, 2.5)          # R|w0|/|v0|


def specs_stability(n, seed, quick=False):
    """Spin direction (relative to v0) x spin magnitude R|w0|/|v0|, n shots per cell.

    Mirroring a shot in the vertical plane through v0 turns the spin's
    direction a into 180 - a (w0 is an axial vector), so 135, 180 and 315
    degrees repeat 45, 0 and 225 and are left out (the 1,080 trials of 20
    shots a point must fit an hour on 2 shared cores).
    """
    from cuespin.physics import BallParams, Shot
    angles = np.array(STABILITY_ANGLES) if not quick else np.array([0, 90])
    mags = STABILITY_MAGS if not quick else [1.5]
    rng = np.random.default_rng(seed)
    out = []
    for a in angles:
        for k in mags:
            for j in range(n):
                head = rng.uniform(-0.3, 0.3)
                d = np.array([np.cos(head), np.sin(head)])
                speed = 1.0
                ang = head + np.radians(a)
                w0 = k * speed / 0.028575 * np.array([np.cos(ang), np.sin(ang)])
                shot = Shot((0.45, 0.55 + rng.uniform(-0.1, 0.1)), speed * d, w0, t0=0.2)
                p = BallParams(mu_s=0.2, mu_r=0.015)
                out.append(_spec(shot, p, len(out), angle=float(a), mag=float(k)))
    return out


SPECS = {"noise": specs_noise, "speed-accuracy": specs_speed, "stability": specs_stability}


def trial_id(spec: dict) -> str:
    """A trial's stable name: its experiment's settings and its shot's index
    (the same for the same ``--n`` and ``--seed``); keys the resume."""
    keys = [k for k in ("factor", "level", "config", "angle", "mag") if k in spec]
    return " ".join(f"{k}={spec[k]}" for k in keys) + f" shot={spec['shot']}"


# Columns a trial writes besides its spec's (fixed so that rows can be appended
# to one CSV as they finish, whatever a trial answered).
RESULT_COLUMNS = ("t_total", "t_track", "t_fit", "t_recover", "t_render", "frames", "width", "height",
                  *(f"{c}_{m}" for m in ("paper", "mle") for c in ("status", "err_v0", "err_rw0")),
                  "crb_v0", "crb_rw0", "reason")
# Read back as text (the rest are numbers; an empty cell is NaN).
TEXT_COLUMNS = {"trial_id", "factor", "level", "config", "codec", "refine", "view", "reason",
                "status_paper", "status_mle"}


def _columns(specs) -> list[str]:
    keys = dict.fromkeys(["trial_id"])
    for s in specs:
        keys.update(dict.fromkeys(k for k in s if k not in ("x0", "v0", "w0")))
    keys.update(dict.fromkeys(RESULT_COLUMNS))
    return list(keys)


def _parse(row: dict) -> dict:
    out = {}
    for k, v in row.items():
        if k in TEXT_COLUMNS or k is None:
            out[k] = v
        else:
            try:
                out[k] = float(v) if v not in ("", None) else math.nan
            except ValueError:
                out[k] = v
    return out


def read_trials(path: Path) -> list[dict]:
    """The finished trials of ``trials.csv`` (numbers as floats), without a
    last row that a cut-short run left half written."""
    if not Path(path).exists():
        return []
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    return [_parse(r) for r in rows if r.get("trial_id") and r.get("status_mle")]


def _check_run(out: Path, meta: dict) -> None:
    """Refuse to mix trials of another run (other name, n, seed or grid) into ``out``."""
    import json

    path = out / "run.json"
    if path.exists():
        old = json.loads(path.read_text())
        if old != meta:
            diff = ", ".join(f"{k} {old.get(k)} (now {v})" for k, v in meta.items() if old.get(k) != v)
            raise ValueError(f"{out} holds another run ({diff}): use another --out or the same settings")
    else:
        path.write_text(json.dumps(meta) + "\n")


class _Progress:
    """done/total, seconds per trial and ETA on stderr: a live bar on a
    terminal (tqdm), otherwise a line every 5% and a last one."""

    def __init__(self, name, total, initial, enabled=True):
        import sys

        from tqdm import tqdm

        self.name, self.total, self.initial, self.done = name, total, initial, initial
        self.enabled, self.start, self.stream = enabled, time.monotonic(), sys.stderr
        self.tty = enabled and self.stream.isatty()
        self.bar = tqdm(total=total, initial=initial, desc=name, unit="trial", dynamic_ncols=True,
                        disable=not self.tty)
        self.every = max(1, (total - initial) // 20)

    def line(self):
        ran = self.done - self.initial
        head = f"{self.name}: {self.done}/{self.total} trials ({self.initial} from an earlier run)"
        if not ran:
            return head
        per = (time.monotonic() - self.start) / ran
        eta = per * (self.total - self.done)
        return head + f", {per:.1f} s/trial" + (f", ETA {eta / 60:.1f} min" if self.done < self.total else "")

    def update(self):
        self.done += 1
        self.bar.update(1)
        self.printed = self.enabled and not self.tty and (self.done - self.initial) % self.every == 0
        if self.printed:
            print(self.line(), file=self.stream, flush=True)

    def close(self):
        self.bar.close()
        if self.enabled and not getattr(self, "printed", False):
            print(self.line(), file=self.stream, flush=True)


def run_experiment(name: str, out: Path, n: int, seed: int, workers: int | None = None,
                   quick: bool = False, progress=True, max_trials: int | None = None) -> Path:
    """Run an experiment: ``out/trials.csv`` and ``out/*.png``; returns the CSV path.

    Each trial's row is appended to ``trials.csv`` (and flushed) as it ends;
    a rerun into the same ``out`` with the same ``n``, ``seed`` and grid runs
    only the trials the file lacks (keyed by :func:`trial_id`) and draws the
    charts from every row.  ``max_trials`` stops after that many new trials
    (the charts are then drawn from what is done).
    """
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    specs = SPECS[name](n, seed, quick)
    for s in specs:
        s["trial_id"] = trial_id(s)
    assert len({s["trial_id"] for s in specs}) == len(specs), "trial ids must be unique"
    _check_run(out, {"experiment": name, "n": n, "seed": seed, "quick": bool(quick), "trials": len(specs)})
    path = out / "trials.csv"
    cols = _columns(specs)
    rows = read_trials(path)
    wanted = {s["trial_id"] for s in specs}
    rows = [r for r in rows if r["trial_id"] in wanted]
    done = {r["trial_id"] for r in rows}
    # Rewrite what is kept (drops a half-written last line), then append.
    tmp = path.with_suffix(".tmp")
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=cols, extrasaction="ignore")
        w.writeheader()
        w.writerows([{k: _cell(r.get(k)) for k in cols} for r in rows])
    os.replace(tmp, path)
    # Round-robin over the settings (every setting's first shot, then every
    # second...): a run cut short leaves every point with about as many shots.
    rank, seen = [], {}
    for s in specs:
        group = s["trial_id"].rsplit(" shot=", 1)[0]
        seen[group] = seen.get(group, -1) + 1
        rank.append(seen[group])
    order = sorted(range(len(specs)), key=lambda i: rank[i])
    todo = [specs[i] for i in order if specs[i]["trial_id"] not in done][:max_trials]
    bar = _Progress(name, len(specs), len(done), enabled=progress)
    workers = workers or os.cpu_count() or 1
    with open(path, "a", newline="") as f, (ProcessPoolExecutor(max_workers=workers, initializer=_warm)
                                             if todo else nullcontext()) as pool:
        w = csv.DictWriter(f, fieldnames=cols, extrasaction="ignore")
        # A few trials in flight per worker: a cut loses little, the workers never wait.
        pending, pending_spec, it = set(), {}, iter(todo)

        def submit(spec):
            fut = pool.submit(trial, spec)
            pending.add(fut)
            pending_spec[fut] = spec

        for s in it:
            submit(s)
            if len(pending) >= 2 * workers:
                break
        while pending:
            finished, pending = wait(pending, return_when=FIRST_COMPLETED)
            for fut in finished:
                try:
                    row = fut.result()
                except BrokenProcessPool:  # a killed worker: rerun to resume, record nothing
                    raise
                except Exception as exc:  # a crash in a trial is that trial's failure, not the run's
                    spec = pending_spec.pop(fut)
                    row = {k: v for k, v in spec.items() if k not in ("x0", "v0", "w0")}
                    row.update(status_paper="failed", status_mle="failed", reason=f"{type(exc).__name__}: {exc}")
                else:
                    pending_spec.pop(fut)
                w.writerow({k: _cell(row.get(k)) for k in cols})
                f.flush()
                rows.append(row)
                bar.update()
                nxt = next(it, None)
                if nxt is not None:
                    submit(nxt)
    bar.close()
    rows = read_trials(path)  # every row as the charts of a resumed run see them
    CHARTS[name](rows, out)
    return path


def _warm():
    """Import a worker's modules before its first trial, so that the first
    trial's ``t_total`` times the trial, not the imports (about 2 s)."""
    import scipy.stats  # noqa: F401  (fit.decide's import, the largest)

    import cuespin.pipeline.measure  # noqa: F401
    import cuespin.pipeline.run  # noqa: F401
    import cuespin.recover.api  # noqa: F401


def _cell(v):
    if isinstance(v, float) and not math.isfinite(v):
        return ""
    if isinstance(v, (tuple, list)):
        return " ".join(str(x) for x in v)
    return v


# -- charts ---------------------------------------------------------------------------

def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _save(fig, path, dpi=100):
    """The figure as a 256-colour PNG: charts of flat colours and text lose
    nothing visible and stay under ~150 KB for the README (RGB was 140-170 KB)."""
    import io

    from PIL import Image

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    buf.seek(0)
    Image.open(buf).convert("RGB").quantize(colors=256).save(path, optimize=True)


def _values(rows, key):
    v = [r.get(key, math.nan) for r in rows]
    return np.array([x for x in v if isinstance(x, (int, float)) and np.isfinite(x)], dtype=float)


def _median(rows, key):
    v = _values(rows, key)
    return float(np.median(v)) if v.size else math.nan


def _quartiles(rows, key):
    """(25th percentile, median, 75th percentile, n) of a column's finite values."""
    v = _values(rows, key)
    if not v.size:
        return math.nan, math.nan, math.nan, 0
    q1, q2, q3 = np.percentile(v, [25, 50, 75])
    return float(q1), float(q2), float(q3), int(v.size)


STYLE = {"paper": dict(color="tab:orange", marker="s"), "mle": dict(color="tab:blue", marker="o"),
         "crb": dict(color="k", ls="--", marker="")}
NAMES = {"paper": "paper", "mle": "MLE", "crb": "Cramer-Rao bound (MLE)"}


def chart_noise(rows, out):
    """Median error per level with its interquartile band, per method, and the bound.

    Numeric factors are lines over their values; the codec is a category
    (points with interquartile bars, never joined).  Each point's ``n`` is
    the number of shots answered ``ok`` it summarises.
    """
    plt = _plt()
    factors = ["noise", "fps", "px_per_m", "codec"]
    xlabels = {"noise": "image noise sigma (grey levels)", "fps": "frame rate (fps)",
               "px_per_m": "resolution (px per m)", "codec": "codec (category)"}
    fig, axes = plt.subplots(2, 4, figsize=(16, 7.5), sharey="row")
    for j, f in enumerate(factors):
        sub = [r for r in rows if r.get("factor") == f]
        if f != "noise" and not any(r["level"] == str(BASE[f]) for r in sub):
            # The base videos, run once as noise 5.0 (specs_noise), are every factor's base level.
            sub += [dict(r, factor=f, level=str(BASE[f])) for r in rows
                    if r.get("factor") == "noise" and r.get("level") == str(BASE["noise"])]
        if not sub:
            continue
        levels = sorted({r["level"] for r in sub}, key=lambda s: (float(s) if _isnum(s) else s))
        categorical = not all(_isnum(lv) for lv in levels)
        xs = np.arange(len(levels), dtype=float) if categorical else np.array([float(lv) for lv in levels])
        for i, (qty, lab) in enumerate((("v0", "|dv0| / |v0|"), ("rw0", "R |dw0| / |v0|"))):
            ax = axes[i, j]
            for k, m in enumerate(("paper", "mle", "crb")):
                stats = []
                for lv in levels:
                    cell = [r for r in sub if r["level"] == lv]
                    if m == "crb":
                        stats.append(_quartiles(cell, f"crb_{qty}"))
                    else:
                        stats.append(_quartiles([r for r in cell if r.get(f"status_{m}") == "ok"], f"err_{qty}_{m}"))
                q1, q2, q3, n = (np.array(c) for c in zip(*stats))
                st = STYLE[m]
                if categorical:
                    dx = (k - 1) * 0.12
                    ax.errorbar(xs + dx, q2, yerr=[q2 - q1, q3 - q2], fmt=st["marker"] or "_", color=st["color"],
                                capsize=4, ms=6 if st["marker"] else 14, label=NAMES[m])
                else:
                    ax.plot(xs, q2, color=st["color"], marker=st["marker"], ls=st.get("ls", "-"), label=NAMES[m])
                    ax.fill_between(xs, q1, q3, color=st["color"], alpha=0.15 if m != "crb" else 0.08, lw=0)
                if m != "crb":
                    for x, y, nn in zip(xs + ((k - 1) * 0.12 if categorical else 0), q2, n):
                        if np.isfinite(y):
                            ax.annotate(f"{nn}", (x, y), fontsize=8, color=st["color"], xytext=(4, 4 if m == "mle"
                                        else -11), textcoords="offset points")
            ax.set_yscale("log")
            if categorical:
                ax.set_xticks(xs, levels)
                ax.set_xlim(-0.6, len(levels) - 0.4)
            ax.set_xlabel(xlabels[f])
            if j == 0:
                ax.set_ylabel(f"relative error {lab}")
            ax.grid(True, which="both", alpha=0.3)
            if not categorical:
                ax.margins(x=0.08)  # room for the counts beside the last points
    # Below the panels: inside one it hid a point.
    handles, names = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, [f"{x} (median; band/bars: 25-75%)" if "bound" not in x else x for x in names],
               loc="lower center", ncol=3, fontsize=10, frameon=False)
    n_shots = len({r.get("shot") for r in rows})
    fig.suptitle("Recovery error against image noise, frame rate, resolution and codec, one factor at a time from "
                 f"the base (sigma 5, 240 fps, 500 px/m, MJPG)\n{n_shots} shots per level; numbers beside the "
                 "points: shots answered ok (the bound: over all shots)", fontsize=11)
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    _save(fig, out / "noise.png")
    plt.close(fig)


def _isnum(s):
    try:
        float(s)
        return True
    except (TypeError, ValueError):
        return False


def pareto(points):
    """Indices of points (time, error) that no other point beats on both."""
    idx = []
    for i, (t, e) in enumerate(points):
        if not any((t2 <= t and e2 <= e) and (t2 < t or e2 < e) for j, (t2, e2) in enumerate(points) if j != i):
            idx.append(i)
    return idx


def chart_speed(rows, out):
    """Median time against median error per setting and method, with interquartile bars
    on both axes; the Pareto front of the medians.  Points carry their setting's number,
    listed beside the plot with the shots each method answered ok."""
    plt = _plt()
    pts, labels, bars = [], [], []
    cfgs = sorted({r["config"] for r in rows if "config" in r})
    listing = []
    for c_i, cfg in enumerate(cfgs, 1):
        sub = [r for r in rows if r.get("config") == cfg]
        t1, t2, t3, _ = _quartiles(sub, "t_total")
        counts = []
        for m in ("paper", "mle"):
            ok = [r for r in sub if r.get(f"status_{m}") == "ok"]
            e1, e2, e3, n = _quartiles(ok, f"err_v0_{m}")
            counts.append(f"{n}/{len(sub)}")
            if np.isfinite(e2):
                pts.append((t2, e2))
                bars.append(((t2 - t1, t3 - t2), (e2 - e1, e3 - e2)))
                labels.append((m, c_i))
        listing.append(f"{c_i}  {cfg}\n     ok: paper {counts[0]}, MLE {counts[1]}")
    front = set(pareto(pts))
    fig, (ax, side) = plt.subplots(1, 2, figsize=(11, 6), gridspec_kw={"width_ratios": [3, 1]})
    for i, ((t, e), (m, c_i), (xb, yb)) in enumerate(zip(pts, labels, bars)):
        st = STYLE[m]
        ax.errorbar([t], [e], xerr=[[xb[0]], [xb[1]]], yerr=[[yb[0]], [yb[1]]], fmt=st["marker"], color=st["color"],
                    ms=9 if i in front else 6, mec="k" if i in front else st["color"], capsize=2, lw=0.8, alpha=0.9)
        ax.annotate(str(c_i), (t, e), fontsize=9, fontweight="bold", xytext=(6, 4), textcoords="offset points",
                    color=st["color"])
    fp = sorted(pts[i] for i in front)
    ax.plot([p[0] for p in fp], [p[1] for p in fp], "k-", lw=1, label="Pareto front (medians)")
    for m in ("paper", "mle"):
        ax.errorbar([], [], fmt=STYLE[m]["marker"], color=STYLE[m]["color"], label=NAMES[m])
    ax.set_xscale("log")
    ax.xaxis.set_major_formatter(plt.FuncFormatter(lambda v, _: f"{v:g}"))
    ax.xaxis.set_minor_formatter(plt.FuncFormatter(lambda v, _: f"{v:g}" if f"{v:g}"[0] in "25" else ""))
    ax.set_yscale("log")
    ax.set_xlabel("time per video: track + fit + recover (s); median, bars 25-75%")
    ax.set_ylabel("|dv0| / |v0| over answers ok; median, bars 25-75%")
    n_shots = len({r.get("shot") for r in rows})
    ax.set_title(f"Speed against accuracy, {n_shots} shots a setting (numbers: settings, listed right)", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="upper right", fontsize=9)
    side.axis("off")
    side.text(0, 1, "settings (refinement, resolution,\nframe rate; whole table in view)\n\n" + "\n".join(listing),
              va="top", ha="left", fontsize=8.5, family="monospace", transform=side.transAxes)
    fig.tight_layout()
    _save(fig, out / "speed_accuracy.png")
    plt.close(fig)


def chart_stability(rows, out):
    """Per spin direction and magnitude: each method's median error of w0 over its ok
    answers (cells with none hatched, in the legend) and the share not ok, with the
    counts and the sliding time written in each cell."""
    plt = _plt()
    from matplotlib.patches import Patch

    angles = sorted({r["angle"] for r in rows})
    mags = sorted({r["mag"] for r in rows})
    fig, axes = plt.subplots(2, 2, figsize=(15, 8.5))
    for j, m in enumerate(("paper", "mle")):
        err = np.full((len(mags), len(angles)), np.nan)
        fail = np.zeros_like(err)
        counts = np.zeros(err.shape, dtype=int)
        totals = np.zeros(err.shape, dtype=int)
        t1 = np.zeros_like(err)
        for a_i, a in enumerate(angles):
            for k_i, k in enumerate(mags):
                cell = [r for r in rows if r["angle"] == a and r["mag"] == k]
                ok = [r for r in cell if r.get(f"status_{m}") == "ok"]
                err[k_i, a_i] = _median(ok, f"err_rw0_{m}")
                counts[k_i, a_i], totals[k_i, a_i] = len(ok), len(cell)
                fail[k_i, a_i] = 1 - len(ok) / max(len(cell), 1)
                t1[k_i, a_i] = _median(cell, "t1")
        ax = axes[0, j]
        ax.set_facecolor("0.85")
        # Hatched underneath: shows only where the image is blank (no ok answer).
        ax.add_patch(plt.Rectangle((-0.5, -0.5), len(angles), len(mags), fill=False, hatch="//", color="0.55", lw=0,
                                   zorder=0))
        im = ax.imshow(np.log10(err), origin="lower", cmap="viridis", aspect="auto", vmin=-5, vmax=0, zorder=1)
        fig.colorbar(im, ax=ax, label="log10 median R|dw0|/|v0| over answers ok")
        ax2 = axes[1, j]
        im2 = ax2.imshow(fail, origin="lower", cmap="Reds", aspect="auto", vmin=0, vmax=1)
        fig.colorbar(im2, ax=ax2, label="share not ok (degenerate, ambiguous, failed)")
        for a_i in range(len(angles)):
            for k_i in range(len(mags)):
                e = err[k_i, a_i]
                if np.isfinite(e):
                    light = np.log10(e) > -2.0  # viridis is light at its top
                    ax.text(a_i, k_i, f"{e:.0e}\nn={counts[k_i, a_i]}", ha="center", va="center", fontsize=10,
                            color="k" if light else "w", zorder=2)
                else:
                    ax.text(a_i, k_i, f"no ok\n0/{totals[k_i, a_i]}", ha="center", va="center", fontsize=10,
                            color="k", zorder=2)
                f = fail[k_i, a_i]
                ax2.text(a_i, k_i, f"{totals[k_i, a_i] - counts[k_i, a_i]}/{totals[k_i, a_i]}\n"
                         f"{t1[k_i, a_i] * 1000:.0f} ms", ha="center", va="center", fontsize=10,
                         color="w" if f > 0.6 else "k")
        for a in (ax, ax2):
            a.set_xticks(range(len(angles)), [f"{x:.0f}" for x in angles])
            a.set_yticks(range(len(mags)), [f"{x:g}" for x in mags])
            a.set_xlabel("spin direction relative to v0 (deg)")
            a.set_ylabel("spin magnitude R|w0|/|v0|")
        ax.set_title(f"{NAMES[m]}: error of w0 (cells: median, n answers ok)")
        ax2.set_title(f"{NAMES[m]}: share not ok (cells: not ok / shots, sliding time)")
    fig.legend(handles=[Patch(facecolor="0.85", hatch="//", edgecolor="0.55", label="no ok answer in the cell")],
               loc="upper left", fontsize=9, framealpha=0.9)
    fig.suptitle("Where each method breaks: 90/270 deg = pure top/back spin (straight sliding), 0 deg = side spin "
                 f"(curved); {len({r.get('shot') for r in rows}) // max(len(angles) * len(mags), 1)} shots a cell"
                 "\n135, 180 and 315 deg are the mirror images of 45, 0 and 225 deg (not run)", fontsize=11)
    fig.tight_layout()
    _save(fig, out / "stability.png")
    plt.close(fig)


CHARTS = {"noise": chart_noise, "speed-accuracy": chart_speed, "stability": chart_stability}
