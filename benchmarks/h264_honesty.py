"""Are the maximum-likelihood fit's standard errors honest on H.264?

    python benchmarks/h264_honesty.py --n 12 --seed 1 [--acf]

Renders the same shots (120 fps, 250 px/m, noise 3, no blur, at most 3 s;
presets case3, random, masse in turn) in MJPG and H.264 (libx264, CRF 20),
tracks each once and recovers it twice: with the codec's error treated as
independent between moving frames (``inter_frame`` off: what every codec
got before) and as the tracker reports the codec (H.264: shared between
neighbouring frames, recover.mle.codec_sandwich).  Printed per codec and
treatment, over the shots answered ``ok``: coverage of the 95% intervals of
v0 and w0's four components, and the RMS error in units of the stated
standard errors (1 when honest).

``--acf`` also prints the H.264 codec error's correlation between frames
k apart, pooled over the shots' moving frames (truth sidecar's projected
centres against the tracker's, the tracker's stated variance taken off),
and its fit ``a exp(-k / tau_long) + b exp(-k / tau)`` (lags 1-200 weighted by
their pair counts): how recover.mle.INTER_CODEC_ACF was measured before
h264cov (``--seed 0 --n 12``; in frames, the codec's share only).  It is now
the whole error's correlation in time: benchmarks/h264_acf.py.
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
from pathlib import Path

import numpy as np
from scipy.optimize import curve_fit

from cuespin.data_gen.sampler import sample_scene
from cuespin.pipeline.run import run_recover, track_covariance_m
from cuespin.recover.api import recover_track
from cuespin.render.video import read_truth_csv, render_video, truth_path

PRESETS = ("case3", "random", "masse")
MAX_LAG = 200


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


def codec_lags(tr, video):
    """Sums of products of the centre's error (px) k = 0..MAX_LAG frames apart
    over moving frames, their counts, and the stated variance's sum."""
    tru = read_truth_csv(truth_path(video))
    uvt = np.stack([tru["uc_px"], tru["vc_px"]], 1)
    e = tr.uv - uvt
    idx = np.flatnonzero(tr.ok)
    mov = np.zeros(len(e), bool)
    mov[idx[1:]] = np.hypot(*np.diff(uvt[idx], axis=0).T) > 1e-6
    num, cnt = np.zeros(MAX_LAG + 1), np.zeros(MAX_LAG + 1)
    for k in range(min(MAX_LAG + 1, len(e))):
        both = mov[k:] & mov[:len(mov) - k]
        num[k] = np.sum(e[k:][both] * e[:len(e) - k][both])
        cnt[k] = 2 * both.sum()
    return num, cnt, float(np.sum(tr.stderr_px[mov] ** 2))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=12)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--acf", action="store_true")
    p.add_argument("--lags-out", default=None, help="also save the lag sums (npz) for pooling runs")
    p.add_argument("--out", default=None, help="folder for the videos (default: a new temporary one)")
    a = p.parse_args(argv)
    out = Path(a.out or tempfile.mkdtemp(prefix="h264_honesty_"))
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(a.seed)
    seeds = [int(rng.integers(2**31)) for _ in range(a.n)]
    z = {}
    lags = [np.zeros(MAX_LAG + 1), np.zeros(MAX_LAG + 1), 0.0]
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
                if a.acf:
                    num, cnt, st = codec_lags(tr, video)
                    lags[0] += num
                    lags[1] += cnt
                    lags[2] += st
            print(i, codec, res["methods"]["mle"]["status"], np.round(z[(codec, tr.inter_frame)][-1], 2), flush=True)
    print(f"\n{'codec':6} {'inter-frame model':18} {'ok':>5} {'coverage 95%':>13} {'RMS z v0':>9} {'RMS z w0':>9}")
    for (codec, inter), rows in sorted(z.items()):
        r = np.array(rows)
        ok = np.isfinite(r).all(axis=1)
        rk = r[ok]
        cover = np.mean(np.abs(rk) < 1.959964) if ok.any() else float("nan")
        print(f"{codec:6} {'on' if inter else 'off':18} {ok.sum():>2}/{len(r):<2} {100 * cover:>12.1f}% "
              f"{np.sqrt(np.mean(rk[:, :2] ** 2)):>9.2f} {np.sqrt(np.mean(rk[:, 2:] ** 2)):>9.2f}")
    if a.acf and lags[1][0] > 0:
        if a.lags_out:
            np.savez(a.lags_out, num=lags[0], cnt=lags[1], stated=lags[2])
        c = lags[0] / lags[1]
        codec_var = c[0] - lags[2] / lags[1][0]
        rho = c[1:] / codec_var
        k = np.arange(1, MAX_LAG + 1)
        par, _ = curve_fit(lambda k, a_, b, tau, tau_long: a_ * np.exp(-k / tau_long) + b * np.exp(-k / tau),
                           k, rho, p0=(0.2, 0.1, 7.0, 100.0), sigma=1 / np.sqrt(np.maximum(lags[1][1:], 1)),
                           bounds=([0, 0, 1, 1], [1, 1, 1e3, 1e4]), max_nfev=20000)
        print(f"\nH.264 error variance {c[0]:.3g} px^2, stated {c[0] - codec_var:.3g}; codec's correlation at lags "
              f"1, 10, 40, 100, 200: {np.round(rho[[0, 9, 39, 99, 199]], 3)}; "
              f"fit a = {par[0]:.3f}, b = {par[1]:.3f}, tau = {par[2]:.1f}, tau_long = {par[3]:.0f} frames")

if __name__ == "__main__":
    main()
