"""MLE accuracy at a variable frame rate against the same shots at a constant one.

    python benchmarks/vfr.py --n 10

Each shot is rendered to H.264 twice, with ``render.vfr_jitter`` 0 and 0.03
(same scene, same noise seed), tracked (the tracker stamps frames with the
file's presentation times) and recovered; printed: v0 and w0 errors in units
of the fit's stated standard errors, RMS over the shots, for each.
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
from pathlib import Path

import numpy as np

from cuespin.data_gen.sampler import sample_scene
from cuespin.pipeline.run import run_recover
from cuespin.render.video import render_video


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=10)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--jitter", type=float, default=0.03)
    a = p.parse_args(argv)
    out = Path(tempfile.mkdtemp(prefix="vfr_bench_"))
    rng = np.random.default_rng(a.seed)
    z = {0.0: [], a.jitter: []}
    for i in range(a.n):
        scene = sample_scene(int(rng.integers(2**31)), ("case3", "random", "masse")[i % 3], fps=120.0,
                             px_per_m=250.0, noise=3.0, blur=False, codec="H264")
        scene = dataclasses.replace(scene, render={**scene.render, "max_duration": 3.0})
        for j in z:
            sc = dataclasses.replace(scene, render={**scene.render, "vfr_jitter": j})
            video = out / f"{i:03d}_{j}.mp4"
            render_video(sc, video)
            m = run_recover(video, sc, method="mle")["methods"]["mle"]
            if m["status"] == "ok":
                e = [(np.array(m[k]) - np.array(getattr(sc.truth, k))) / np.array(m["stderr"][k])
                     for k in ("v0", "w0")]
                z[j].append(np.concatenate(e))
            else:
                z[j].append(np.full(4, np.nan))
            print(i, j, m["status"], z[j][-1].round(2), flush=True)
    both = np.all([np.isfinite(np.array(rows)).all(axis=1) for rows in z.values()], axis=0)
    for j, rows in z.items():
        r = np.array(rows)
        ok = np.isfinite(r).all(axis=1)
        print(f"jitter {j}: {ok.sum()}/{len(r)} ok; RMS error / stated error, v0 {np.sqrt(np.mean(r[ok, :2]**2)):.2f}, "
              f"w0 {np.sqrt(np.mean(r[ok, 2:]**2)):.2f}; coverage of 95% intervals {np.mean(np.abs(r[ok]) < 1.96):.1%}; "
              f"the {both.sum()} shots ok at both rates: v0 {np.sqrt(np.mean(r[both, :2]**2)):.2f}, "
              f"w0 {np.sqrt(np.mean(r[both, 2:]**2)):.2f}")


if __name__ == "__main__":
    main()
