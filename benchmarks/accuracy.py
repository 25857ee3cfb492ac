"""Recovery accuracy over generated shots: the paper's method beside the MLE.

For N generated shots (default 200; the sampler's mix of presets), render,
track and recover, then print per method: the median and 95th-percentile
errors of v0 (relative) and of R w0 (relative to |v0|) over shots answered
``ok``, the share answered ``ok`` (and the other statuses); for the MLE, the
RMS of its errors in units of the Cramer-Rao bound computed from the same
model's Jacobian at the truth with the per-frame errors the fit weights by
(recover.api.mle_noise, which includes the codec's own error measured
from the residuals), and the coverage of its reported 95% intervals.  Speed: fit plus both recoveries as
a fraction of decoding the same video (target <= 0.1).  Videos are capped at
6 s; shots run in worker processes.

Usage: python benchmarks/accuracy.py [--n 200] [--seed 0] [--workers 2] [--csv out.csv] [--codec FFV1]
"""

import argparse
import csv
import tempfile
import time
from multiprocessing import Pool
from pathlib import Path


import numpy as np

MAX_SECONDS = 6.0


def one_shot(args):
    i, seed, tmp, codec = args
    from cuespin.data_gen.sampler import sample_scenes
    from cuespin.physics import phases
    from cuespin.pipeline.run import run_recover
    from cuespin.render import render_video
    from cuespin.track.video import open_video

    scene = sample_scenes(i + 1, seed)[i]
    scene.render["max_duration"] = MAX_SECONDS
    if codec:
        scene.render["codec"] = codec
    video = Path(tmp) / f"shot_{i}.avi"
    render_video(scene, video)
    cap = open_video(video)
    t = time.perf_counter()
    n = 0
    while cap.read()[0]:
        n += 1
    t_decode = time.perf_counter() - t
    cap.release()
    out, tr = run_recover(video, scene, return_track=True)
    video.unlink()
    truth, p = scene.truth, scene.physics
    v0, w0 = np.array(truth.v0), np.array(truth.w0)
    speed = np.hypot(*v0)
    row = {"i": i, "preset": scene.render.get("preset"), "fps": scene.camera.fps,
           "noise": scene.render.get("noise_sigma"), "frames": n, "t_decode": t_decode,
           "t_fit": out["timing_s"]["fit"], "t_recover": out["timing_s"]["recover"],
           "t1_true": phases(truth, p).t1 - truth.t0}
    for m, d in out["methods"].items():
        row[f"{m}_status"] = d["status"]
        row[f"{m}_ev"] = np.hypot(*(np.array(d["v0"]) - v0)) / speed if d["v0"] else np.nan
        row[f"{m}_ew"] = p.R * np.hypot(*(np.array(d["w0"]) - w0)) / speed if d["w0"] else np.nan
    mle = out["methods"]["mle"]
    row["mle_z"] = row["mle_cover"] = row["mle_crb_z"] = row["mle_crb_z_meas"] = row["mle_crb_z_indep"] = np.nan
    row["chi2_per_dof"] = row["codec_noise_px"] = np.nan
    if mle["status"] == "ok":
        est = np.r_[mle["v0"], mle["w0"]]
        se = np.r_[mle["stderr"]["v0"], mle["stderr"]["w0"]]
        err = est - np.r_[v0, w0]
        row["mle_z"] = float(np.sqrt(np.mean((err / se) ** 2)))
        row["mle_cover"] = float(np.mean(np.abs(err) < 1.96 * se))
        # The bound for the same measurements (pipeline.measure.mle_bound),
        # and for reference the one with every frame independent.
        from cuespin.pipeline.measure import mle_bound
        cam = scene.camera
        centre = cam.to_table([[cam.width / 2, cam.height / 2]])[0]
        scale = np.sqrt(max(mle.get("chi2_per_dof") or 1.0, 1.0))
        try:
            for key, indep in (("mle_crb_z_indep", True), ("mle_crb_z", False)):
                cov, rolling = mle_bound(scene, tr, mle, independent=indep)
                idx = [3, 4] if rolling else [3, 4, 5, 6]
                e = err[:2] if rolling else err
                crb = np.sqrt(np.diag(cov)[idx])
                row[key] = float(np.sqrt(np.mean((e / crb) ** 2)))
            row["mle_crb_z_meas"] = row["mle_crb_z"] / scale
            row["chi2_per_dof"] = mle.get("chi2_per_dof")
            row["codec_noise_px"] = (mle.get("codec_noise_m") or 0.0) * cam.px_per_m(centre)
        except np.linalg.LinAlgError:  # the bound is a diagnostic; never lose the row
            pass
    return row


def pct(x, q):
    x = np.asarray([v for v in x if np.isfinite(v)])
    return float(np.percentile(x, q)) if len(x) else float("nan")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--csv", default=None, help="write every shot's row here")
    ap.add_argument("--codec", default=None, help="render every shot with this FourCC (default: the scene's, MJPG)")
    args = ap.parse_args()
    from tqdm import tqdm
    with tempfile.TemporaryDirectory() as tmp, Pool(args.workers) as pool:
        rows = list(tqdm(pool.imap_unordered(one_shot, [(i, args.seed, tmp, args.codec) for i in range(args.n)]),
                         total=args.n, desc="shots", disable=None))
    rows.sort(key=lambda r: r["i"])
    if args.csv:
        with open(args.csv, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=sorted({k for r in rows for k in r}))
            w.writeheader()
            w.writerows(rows)
    n = len(rows)
    print(f"\n{n} shots (seed {args.seed}); errors over shots answered ok")
    print(f"{'method':6} {'ok':>5} {'v0 med':>9} {'v0 p95':>9} {'Rw0 med':>9} {'Rw0 p95':>9}  other statuses")
    for m in ("paper", "mle"):
        ok = [r for r in rows if r[f"{m}_status"] == "ok"]
        other = {}
        for r in rows:
            if r[f"{m}_status"] != "ok":
                other[r[f"{m}_status"]] = other.get(r[f"{m}_status"], 0) + 1
        print(f"{m:6} {len(ok) / n:5.0%} {pct([r[f'{m}_ev'] for r in ok], 50):9.2e} "
              f"{pct([r[f'{m}_ev'] for r in ok], 95):9.2e} {pct([r[f'{m}_ew'] for r in ok], 50):9.2e} "
              f"{pct([r[f'{m}_ew'] for r in ok], 95):9.2e}  {other}")
    ok = [r for r in rows if r["mle_status"] == "ok"]
    for key, what in (("mle_crb_z_meas", "errors the fit weights by, at the scale the residuals measure"),
                      ("mle_crb_z", "errors the fit weights by, as the tracker states them"),
                      ("mle_crb_z_indep", "tracker's errors, every frame independent (reference)")):
        crb_z = np.array([r[key] for r in ok if np.isfinite(r[key])])
        print(f"\nMLE: RMS error / Cramer-Rao bound with the {what} (v0, w0 components, {len(crb_z)} shots): "
              f"{np.sqrt(np.mean(np.square(crb_z))):.2f}; per shot median {np.median(crb_z):.2f}, "
              f"p90 {np.percentile(crb_z, 90):.2f} (target <= 1.3)")
    chi = np.array([r["chi2_per_dof"] for r in ok if np.isfinite(r["chi2_per_dof"])])
    if len(chi):
        print(f"MLE: chi2/dof of the fits answered ok: median {np.median(chi):.2f}, max {chi.max():.1f}")
    print(f"MLE: RMS error / its own stderr: {np.sqrt(np.nanmean(np.square([r['mle_z'] for r in ok]))):.2f}; "
          f"coverage of 95% intervals: {np.nanmean([r['mle_cover'] for r in ok]):.1%} (target 90-97%)")
    ratio = [(r["t_fit"] + r["t_recover"]) / r["t_decode"] for r in rows]
    print(f"speed: (fit + both recoveries) / decode: median {np.median(ratio):.3f}, "
          f"p95 {np.percentile(ratio, 95):.3f} (target <= 0.1)")


if __name__ == "__main__":
    main()
