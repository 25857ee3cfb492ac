"""Are the maximum-likelihood fit's standard errors honest on H.264?

    python benchmarks/h264_honesty.py --n 12 --seed 1

Renders the same shots (120 fps, 250 px/m, noise 3, no blur, at most 3 s;
presets case3, random, masse in turn) in MJPG and H.264 (libx264, CRF 20),
tracks each once and recovers it twice: with the codec's error treated as
independent between moving frames (``inter_frame`` off: what every codec
got before) and as the tracker reports the codec (H.264: shared between
neighbouring frames, recover.mle.codec_sandwich).  Printed per codec and
treatment, over the shots answered ``ok``: coverage of the 95% intervals of
v0 and w0's four components, and the RMS error in units of the stated
standard errors (1 when honest).

The codec error's correlation (recover.mle.INTER_CODEC_ACF) is measured by
benchmarks/h264_acf.py (this script's former ``--acf`` measured it in
frames, the codec's share only, before h264cov: git history).
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
from pathlib import Path

import numpy as np

from cuespin.data_gen.sampler import sample_scene
from cuespin.pipeline.run import run_recover, track_covariance_m
from cuespin.recover.api import recover_track
from cuespin.render.video import render_video

PRESETS = ("case3", "random", "masse")


def shot_scene(seed: int, i: int, codec: str):
    """The i-th benchmark shot's scene in ``codec``."""
    scene = sample_scene(seed, PRESETS[i % 3], fps=120.0, px_per_m=250.0, noise=3.0, blur=False, codec=codec)
    return dataclasses.replace(scene, render={**scene.render, "max_duration": 3.0})


def z_scores(m: dict, truth) -> np.ndarray:
    """(v0x, v0y, w0x, w0y) errors in units of the stated errors; NaN unless ``ok``."""
    if m["status"] != "ok":
        return np.full(4, np.nan)
    return np.concatenate([(np.array(m[k]) - np.array(getattr(truth, k))) / np.array(m["stderr"][k])
                           for k in ("v0", "w0")])


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=12)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--out", default=None, help="folder for the videos (default: a new temporary one)")
    a = p.parse_args(argv)
    out = Path(a.out or tempfile.mkdtemp(prefix="h264_honesty_"))
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(a.seed)
    seeds = [int(rng.integers(2**31)) for _ in range(a.n)]
    z = {}
    for i, s in enumerate(seeds):
        for codec, ext in (("MJPG", "avi"), ("H264", "mp4")):
            scene = shot_scene(s, i, codec)
            video = out / f"{i:03d}.{ext}"
            if not video.exists():
                render_video(scene, video)
            res, tr = run_recover(video, scene, method="mle", return_track=True)
            z.setdefault((codec, tr.inter_frame), []).append(z_scores(res["methods"]["mle"], scene.truth))
            if tr.inter_frame:  # the same track, the codec's error taken as independent
                cam = tr.camera or scene.camera
                n = len(tr.t) if res["track"].get("contact") is None else int(np.sum(tr.t < res["track"]["contact"]["t"]))
                other = recover_track(tr.t[:n], tr.xy[:n], tr.ok[:n], track_covariance_m(tr, cam)[:n], scene.physics,
                                      cam.exposure_s, "mle", lossless=tr.lossless, inter_frame=False)
                z.setdefault((codec, False), []).append(z_scores(other["methods"]["mle"], scene.truth))
            print(i, codec, res["methods"]["mle"]["status"], np.round(z[(codec, tr.inter_frame)][-1], 2), flush=True)
    print(f"\n{'codec':6} {'inter-frame model':18} {'ok':>5} {'coverage 95%':>13} {'RMS z v0':>9} {'RMS z w0':>9}")
    for (codec, inter), rows in sorted(z.items()):
        r = np.array(rows)
        ok = np.isfinite(r).all(axis=1)
        rk = r[ok]
        cover = np.mean(np.abs(rk) < 1.959964) if ok.any() else float("nan")
        print(f"{codec:6} {'on' if inter else 'off':18} {ok.sum():>2}/{len(r):<2} {100 * cover:>12.1f}% "
              f"{np.sqrt(np.mean(rk[:, :2] ** 2)):>9.2f} {np.sqrt(np.mean(rk[:, 2:] ** 2)):>9.2f}")


if __name__ == "__main__":
    main()
