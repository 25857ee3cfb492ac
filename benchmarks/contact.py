"""Contact detection on simulated tracks: the threshold's calibration and the
detection error in frames.

    python benchmarks/contact.py calibrate --n 600   # largest change statistic on contact-free tracks
    python benchmarks/contact.py detect --n 300      # frame error of the first contact found

Tracks are the forward model (continued past contacts by
``cuespin.physics.contact``) sampled at the frame times, with Gaussian noise
of a tracker's size (0.005-0.5 px at 500 px/m) and that noise as the stated
error: what ``fit.contact`` sees, without rendering.
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from cuespin.data_gen.sampler import sample_scene
from cuespin.fit.contact import CHANGE_THRESHOLD, find_contact
from cuespin.physics.contact import scene_trajectory
from cuespin.physics.scene import motion_end

NULL_PRESETS = ("random", "case1", "case2", "case3", "case4", "case5", "masse", "leaves_table")
CONTACT_PRESETS = ("cushion", "ball_contact")
MAX_S = 6.0
# Boundaries whose fast statistic is below this keep it (the kink-aware one
# is never larger); well below any threshold worth having.
SCREEN = 15.0


def simulated_track(scene, noise_px: float, rng: np.random.Generator):
    """``(t, xy, stderr_m)`` of a scene's ball, frame by frame, noisy.

    Contact scenes run to rest (capped at 6 s); others until the ball stops
    or its centre leaves the table.
    """
    fps = scene.camera.fps
    traj = scene_trajectory(scene)
    if traj.contacts or scene.render.get("contacts"):
        end = min(traj.t_rest + 0.25, MAX_S)
    else:
        end, left = motion_end(scene.truth, scene.physics, scene.table, fps, MAX_S)
        end = end if left else min(end + 0.25, MAX_S)
    t = np.arange(int(math.floor(end * fps)) + 1) / fps
    sig = noise_px / scene.camera.px_per_m(scene.truth.x0)
    xy = traj.positions(t) + sig * rng.standard_normal((len(t), 2))
    return t, xy, np.full(len(t), sig), traj


def noise_level(rng) -> float:
    """A tracker's centroid error (px), log-uniform 0.005-0.5."""
    return float(np.exp(rng.uniform(np.log(0.005), np.log(0.5))))


def calibrate(n: int, seed: int = 0) -> np.ndarray:
    """Largest change statistic on each of ``n`` contact-free tracks."""
    from cuespin.fit.contact import _moved_index, change_statistic, kink_statistic, window_frames

    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        scene = sample_scene(int(rng.integers(2**31)), NULL_PRESETS[i % len(NULL_PRESETS)])
        t, xy, se, traj = simulated_track(scene, noise_level(rng), rng)
        assert not traj.contacts
        # What find_contact tests: boundaries wholly after the strike, not
        # past a cushion touch it finds first, with the kink-aware statistic.
        c = find_contact(t, xy, np.ones(len(t), bool), se, scene.table, scene.physics.R,
                         threshold=np.inf)
        stop = c.index if c is not None else len(t)
        t, xy, se = t[:stop], xy[:stop], se[:stop]
        b, stat, scale, _, jump = change_statistic(t, xy, se, details=True)
        W = window_frames(t)
        keep = b - W >= _moved_index(xy, se)
        s = kink_statistic(t, xy, se, W, b[keep], stat[keep], jump[keep], scale, SCREEN)
        out.append(float(s.max()) if s.size else 0.0)
    return np.array(out)


def detect(n: int, seed: int = 1, threshold: float = CHANGE_THRESHOLD):
    """Frame error of the first contact found on ``n`` contact tracks.

    Returns rows ``(preset, fps, noise_px, true_index, found_index, kind_true, kind_found)``.
    """
    rng = np.random.default_rng(seed)
    rows = []
    for i in range(n):
        preset = CONTACT_PRESETS[i % 2]
        scene = sample_scene(int(rng.integers(2**31)), preset)
        noise = noise_level(rng)
        t, xy, se, traj = simulated_track(scene, noise, rng)
        first = traj.first_contact
        true_index = int(np.searchsorted(t, first.t))
        balls = np.array([[b["x"], b["y"]] for b in scene.render.get("balls", [])]).reshape(-1, 2)
        c = find_contact(t, xy, np.ones(len(t), bool), se, scene.table, scene.physics.R, balls,
                         threshold=threshold)
        rows.append((preset, scene.camera.fps, noise, true_index,
                     -1 if c is None else c.index, first.kind, "none" if c is None else c.kind,
                     first.t, float("nan") if c is None else c.t))
    return rows


def rendered(n: int, seed: int = 2, fps_choices=(60.0, 120.0, 240.0), codec: str = "MJPG",
             px_per_m: float = 500.0, tail_s: float = 0.5, out=None):
    """Render contact scenes and their contact-free twins, recover both.

    Each scene's video runs to ``tail_s`` after its first contact; its twin
    is the same shot with ``render.contacts`` off (the ball runs on through
    the cushion line, or through the undrawn ball) and the same length.

    Returns rows of dicts: preset, fps, noise, true/found contact frame and
    kind, and the MLE's v0 and w0 errors (m/s, rad/s) with and without the
    contact, with their statuses.
    """
    import dataclasses
    import tempfile
    from pathlib import Path

    from cuespin.pipeline.run import run_recover
    from cuespin.render.video import render_video, video_suffix

    rng = np.random.default_rng(seed)
    out = Path(out or tempfile.mkdtemp(prefix="contact_bench_"))
    rows = []
    for i in range(n):
        preset = CONTACT_PRESETS[i % 2]
        fps = float(rng.choice(fps_choices))
        scene = sample_scene(int(rng.integers(2**31)), preset, fps=fps, px_per_m=px_per_m, codec=codec)
        traj = scene_trajectory(scene)
        first = traj.first_contact
        duration = first.t + tail_s
        scene = dataclasses.replace(scene, render={**scene.render, "duration": duration})
        twin = dataclasses.replace(scene, render={**scene.render, "contacts": False})
        row = {"preset": preset, "fps": fps, "noise": scene.render["noise_sigma"],
               "true_kind": first.kind, "true_t": first.t}
        for name, sc in (("contact", scene), ("twin", twin)):
            video = out / f"{i:03d}_{name}{video_suffix(codec)}"
            truth = render_video(sc, video)
            res = run_recover(video, sc, method="mle")
            m = res["methods"]["mle"]
            tr = sc.truth
            row[f"{name}_status"] = m["status"]
            row[f"{name}_v0_err"] = (float(np.hypot(*(np.array(m["v0"]) - tr.v0)))
                                     if m.get("v0") else float("nan"))
            row[f"{name}_w0_err"] = (float(np.hypot(*(np.array(m["w0"]) - tr.w0)))
                                     if m.get("w0") else float("nan"))
            c = res["track"]["contact"]
            row[f"{name}_contact"] = c
            if name == "contact":
                row["true_index"] = int(np.searchsorted(truth.t, first.t))
                row["found_t"] = c["t"] if c else None
                row["found_kind"] = c["kind"] if c else None
                row["found_index"] = (int(np.searchsorted(truth.t, c["t"] - 1e-12)) if c else None)
            video.unlink()
            Path(str(video.with_suffix("")) + ".truth.csv").unlink()
        rows.append(row)
        print(row, flush=True)
    return rows


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("what", choices=("calibrate", "detect", "rendered"))
    p.add_argument("--n", type=int, default=200)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args(argv)
    if a.what == "calibrate":
        m = calibrate(a.n, a.seed)
        print(f"contact-free tracks: {a.n}; largest statistic: max {m.max():.1f}, "
              f"p99 {np.percentile(m, 99):.1f}, median {np.median(m):.1f}; threshold {CHANGE_THRESHOLD}")
        print(f"false contacts at the threshold: {(m > CHANGE_THRESHOLD).sum()}")
    elif a.what == "rendered":
        rows = rendered(a.n, a.seed)
        import json
        print(json.dumps(rows))
    else:
        rows = detect(a.n, a.seed)
        err = np.array([r[4] - r[3] if r[4] >= 0 else 10**6 for r in rows])
        for kind in ("cushion", "ball"):
            sel = np.array([r[5] == kind for r in rows])
            e = err[sel]
            print(f"{kind}: {sel.sum()} tracks; |frame error| <= 1: {(np.abs(e) <= 1).sum()}, "
                  f"errors {dict(zip(*np.unique(np.clip(e, -9, 9), return_counts=True)))}")
            kinds = [r[6] for r, s in zip(rows, sel) if s]
            print(f"  kinds found: {dict(zip(*np.unique(kinds, return_counts=True)))}")


if __name__ == "__main__":
    main()
