"""The true centre error's correlation between frames on kept H.264 tracks, in time.

    python benchmarks/h264_acf.py --tracks DIR --seed S [--max-seconds 1.5] [--look realistic] [--fit]

Reads the tracks benchmarks/accuracy.py keeps (``--codec H264 --tracks DIR``,
the same seed, look and clip length), rebuilds each shot's scene from the
sampler and its truth (render.draw.FrameRenderer's exposure-averaged
projected centre; no frame drawn) and takes the tracker's centre off it:
per moving frame (after the strike, before the rest; found, with a stated
error, within MAX_ERR_PX of the truth: false centres are another matter)
the error whitened by the tracker's stated covariance, each shot scaled to
unit mean square (the codec's excess included).  Prints, per frame-rate
band, the pooled correlation of errors k frames apart and the same at
fixed times apart; with ``--fit``, the fit of
``rho(dt) = a exp(-dt / tau_long) + b exp(-dt / tau)`` to every band's
lags up to MAX_DT_S at once, weighted by their pair counts, each frame rate's
summed to one: how
recover.mle.INTER_CODEC_ACF was measured (seed 31, realistic, 1.5-s clips).
No shot's mean is taken off (a bias held over the clip is part of what the
stated errors must cover).
"""

from __future__ import annotations

import argparse
import math
import re
from pathlib import Path

import numpy as np
from scipy.optimize import curve_fit

from cuespin.data_gen.sampler import sample_scenes
from cuespin.physics import phases
from cuespin.render.draw import FrameRenderer, ball_motion, render_settings

MAX_ERR_PX = 3.0  # a centre this far off is a false one (cov12's rule), not tracking error
MAX_DT_S = 0.8  # lags fitted: a slide and the first rolling (the 1.5-s clips hold few pairs beyond)
BANDS = ((0, 100), (100, 200), (200, 300), (300, 1000))
LAGS = (1, 2, 3, 5, 10, 20, 40, 80)
TIMES_MS = (4.2, 8.3, 16.7, 33.3, 41.7, 83.3, 166.7)


def truth_uv(scene, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Frame times (s) and the exposure-averaged projected true centres (px) of ``n`` frames."""
    fr = FrameRenderer.__new__(FrameRenderer)  # the truth only: no look, no background
    fr.scene, fr.settings, fr.cam = scene, render_settings(scene), scene.camera
    fr.H, fr.motion = fr.cam.H, ball_motion(scene)
    fr.radius_px = scene.physics.R * math.sqrt(abs(np.linalg.det(fr.cam.jacobian(np.asarray(scene.truth.x0)))))
    fr.similar, fr.n_frames = True, n
    tru = fr._truth()
    return tru.t, tru.uvc


def shot_errors(path: Path, seed: int, i: int, look: str, seconds: float):
    """(fps, whitened errors (n, 2) scaled to unit mean square, valid (n,))."""
    scene = sample_scenes(i + 1, seed, preset=None, look=look)[i]
    scene.render["max_duration"] = seconds
    z = np.load(path)
    cam = scene.camera
    n = len(z["t"])
    t, uvc = truth_uv(scene, n)
    xy = z["xy"]
    good = z["ok"] & np.all(np.isfinite(xy), axis=1)
    uv = np.full((n, 2), np.nan)
    uv[good] = cam.to_pixels(xy[good])
    e = uv - uvc
    cov = np.asarray(z["cov_px"], float)
    if cov.ndim == 2:
        cov = np.einsum("ni,ij->nij", cov**2, np.eye(2))
    ph = phases(scene.truth, scene.physics)
    moving = (t > scene.truth.t0 + 0.5 / cam.fps) & (t < ph.t2 - 0.5 / cam.fps)
    valid = good & moving & np.all(np.isfinite(cov.reshape(n, -1)), axis=1) & (np.hypot(*e.T) < MAX_ERR_PX)
    w = np.zeros((n, 2))
    if valid.sum() < 2:
        return cam.fps, w, valid
    L = np.linalg.cholesky(cov[valid])
    w[valid] = np.linalg.solve(L, e[valid][..., None])[..., 0]
    w /= np.sqrt(np.mean(w[valid] ** 2))
    return cam.fps, w, valid


def lag_sums(w, valid, max_lag: int):
    """Per lag k = 1..max_lag: sum of products of errors k frames apart and the pairs' mean square sum, counts."""
    num, den, cnt = np.zeros(max_lag + 1), np.zeros(max_lag + 1), np.zeros(max_lag + 1)
    for k in range(1, min(max_lag + 1, len(w))):
        pv = valid[k:] & valid[:-k]
        num[k] = np.sum(w[k:][pv] * w[:-k][pv])
        den[k] = 0.5 * np.sum(w[k:][pv] ** 2 + w[:-k][pv] ** 2)
        cnt[k] = 2 * pv.sum()
    return num, den, cnt


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tracks", required=True)
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("--max-seconds", type=float, default=1.5)
    ap.add_argument("--look", default="realistic")
    ap.add_argument("--fit", action="store_true")
    a = ap.parse_args(argv)
    tag = f"s{a.seed}_H264" + ("" if a.look == "plain" else f"_{a.look}") + f"_{a.max_seconds:g}s_"
    files = sorted(Path(a.tracks).glob(tag + "*.npz"), key=lambda f: int(re.findall(r"_(\d+)\.npz$", f.name)[0]))
    per_fps = {}
    for f in files:
        i = int(re.findall(r"_(\d+)\.npz$", f.name)[0])
        fps, w, valid = shot_errors(f, a.seed, i, a.look, a.max_seconds)
        if valid.sum() < 20:
            continue
        s = per_fps.setdefault(fps, [0, 0, 0, 0])
        num, den, cnt = lag_sums(w, valid, int(MAX_DT_S * fps) + 1)
        if isinstance(s[1], int):
            s[1:] = [num, den, cnt]
        else:
            s[1] += num
            s[2] += den
            s[3] += cnt
        s[0] += 1
    print(f"{len(files)} tracks; frame rates {sorted(per_fps)}")
    for lo, hi in BANDS:
        rates = [r for r in per_fps if lo <= r < hi]
        if not rates:
            continue
        shots = sum(per_fps[r][0] for r in rates)
        lag = []
        for k in LAGS:
            num = sum(per_fps[r][1][k] for r in rates if k < len(per_fps[r][1]))
            den = sum(per_fps[r][2][k] for r in rates if k < len(per_fps[r][2]))
            if den > 0:
                lag.append(f"{k}:{num / den:.2f}")
        lag = " ".join(lag)
        tms = []
        for ms in TIMES_MS:
            nums = dens = 0.0
            for r in rates:
                k = int(round(ms * 1e-3 * r))
                if 1 <= k < len(per_fps[r][1]) and abs(k / r - ms * 1e-3) < 0.1 * ms * 1e-3:
                    nums += per_fps[r][1][k]
                    dens += per_fps[r][2][k]
            if dens > 0:
                tms.append(f"{ms:g}ms:{nums / dens:.2f}")
        print(f"{lo}-{hi} fps ({shots} shots): lag(frames) {lag}\n    at times {' '.join(tms)}")
    if a.fit:
        dt, rho, wt = [], [], []
        for r, (_, num, den, cnt) in per_fps.items():
            k = np.flatnonzero(cnt > 0)
            dt += list(k / r)
            rho += list(num[k] / den[k])
            wt += list(cnt[k] / cnt[k].sum())  # each frame rate alike (else 480 fps's pairs rule)
        dt, rho, wt = map(np.asarray, (dt, rho, wt))
        par, _ = curve_fit(lambda d, a_, b, tau, tau_long: a_ * np.exp(-d / tau_long) + b * np.exp(-d / tau),
                           dt, rho, p0=(0.2, 0.3, 0.005, 0.05), sigma=1 / np.sqrt(wt),
                           bounds=([0, 0, 1e-4, 1e-3], [1, 1, 1.0, 10.0]), max_nfev=20000)
        print(f"fit (lags up to {MAX_DT_S} s, {len(dt)} points): a = {par[0]:.3f}, b = {par[1]:.3f}, "
              f"tau = {1e3 * par[2]:.1f} ms, tau_long = {1e3 * par[3]:.0f} ms")
        for lo, hi in BANDS:  # the fit against each band's lag 1 and the correlation at fixed times
            rates = [r for r in per_fps if lo <= r < hi]
            for r in rates:
                _, num, den, cnt = per_fps[r]
                k = np.flatnonzero(cnt > 0)
                model = par[0] * np.exp(-k / r / par[3]) + par[1] * np.exp(-k / r / par[2])
                misfit = np.sum(cnt[k] * (num[k] / den[k] - model)) / np.sum(cnt[k])
                print(f"  {r:g} fps: measured - fit, pair-weighted mean {misfit:+.3f}; "
                      f"lag 1 measured {num[1] / den[1]:.2f}, fit {model[0]:.2f}")


if __name__ == "__main__":
    main()
