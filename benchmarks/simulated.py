"""The recovery's statistics on simulated tracks (forward model + Gaussian
noise, no video): false "sliding" on rolling-from-the-strike tracks per
frame rate and noise, and on sliding tracks the MLE's chi2/dof (weighted
as a lossless and as a lossy codec), the coverage of its 95% intervals and
its RMS error in its own standard errors; the paper method's status counts
and coverage.  Fast (about 0.2 s a track on one core).

Usage: python benchmarks/simulated.py [--null 400] [--sliding 200] [--seed 0]
"""

import argparse
import time
from collections import Counter, defaultdict

import numpy as np


def run(tr, lossless=True):
    from cuespin.recover.api import recover_track
    ok = np.ones(len(tr.t), bool)
    return recover_track(tr.t, tr.xy, ok, np.full(len(tr.t), tr.sigma), tr.params, tr.exposure_s,
                         "all", False, lossless=lossless)


def binom_se(p, n):
    return np.sqrt(max(p * (1 - p), 1e-12) / n)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--null", type=int, default=400)
    ap.add_argument("--sliding", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--seg", action="store_true", help="also the segmentation's F-test (old code)")
    args = ap.parse_args()
    from cuespin.recover.simulate import null_rolling_tracks, sliding_tracks

    cells = defaultdict(list)
    seg_fp = []
    clock = time.perf_counter()
    for tr in null_rolling_tracks(args.null, args.seed):
        out = run(tr)
        m = out["methods"]["mle"]
        cells[(tr.fps, tr.sigma)].append(m["model"] == "full")
        if args.seg:  # the segmentation's own F-test (before issue 11: a second decision)
            from cuespin.fit.segment import segment_track
            from cuespin.physics import rolling_deceleration
            seg = segment_track(tr.t, tr.xy, rolling_deceleration(tr.params.mu_r, tr.params.g), tr.sigma, tr.exposure_s)
            seg_fp.append(bool(seg) and seg.sliding_p < 0.01)
    allv = [v for c in cells.values() for v in c]
    if allv:
        print(f"false 'sliding' (MLE model full) on {len(allv)} rolling-from-the-strike tracks: "
              f"{np.mean(allv):.2%} (+- {binom_se(np.mean(allv), len(allv)):.2%}); nominal 1%")
        for k in sorted(cells):
            print(f"  fps {k[0]:5.0f} sigma {k[1]:.0e} m: {np.mean(cells[k]):6.2%} of {len(cells[k])}")
    if seg_fp:
        print(f"segmentation F-test says sliding on {np.mean(seg_fp):.2%} (nominal 1%)")
    print(f"({time.perf_counter() - clock:.0f} s)")
    rows = []
    for tr in sliding_tracks(args.sliding, args.seed + 1):
        truth = np.r_[tr.shot.v0, tr.shot.w0]
        row = {"fps": tr.fps, "sigma": tr.sigma}
        for codec, lossless in (("lossless", True), ("lossy", False)):
            out = run(tr, lossless)
            m = out["methods"]["mle"]
            row[f"{codec}_status"] = m["status"]
            row[f"{codec}_chi"] = m.get("chi2_per_dof") or np.nan
            if m["status"] == "ok":
                err = np.r_[m["v0"], m["w0"]] - truth
                se = np.r_[m["stderr"]["v0"], m["stderr"]["w0"]]
                row[f"{codec}_z"] = err / se
            p = out["methods"].get("paper", {})
            row[f"{codec}_paper"] = p.get("status")
            if p.get("status") == "ok" and p.get("stderr"):
                err = np.r_[p["v0"], p["w0"]] - truth
                se = np.r_[p["stderr"]["v0"], p["stderr"]["w0"]]
                row[f"{codec}_pz"] = err / se
        rows.append(row)
    for codec in ("lossless", "lossy"):
        chi = np.array([r[f"{codec}_chi"] for r in rows if r[f"{codec}_status"] == "ok"])
        z = np.array([r[f"{codec}_z"] for r in rows if f"{codec}_z" in r])
        st = Counter(r[f"{codec}_status"] for r in rows)
        print(f"{codec} weighting, {len(rows)} sliding tracks: MLE {dict(st)}; chi2/dof median "
              f"{np.median(chi):.3f} (p10 {np.percentile(chi, 10):.2f}, p90 {np.percentile(chi, 90):.2f}); "
              f"coverage {np.mean(np.abs(z) < 1.96):.1%}; RMS z {np.sqrt(np.mean(z**2)):.2f}")
        for s in sorted({r['sigma'] for r in rows}):
            zs = np.array([r[f"{codec}_z"] for r in rows if f"{codec}_z" in r and r["sigma"] == s])
            if len(zs):
                print(f"   sigma {s:.0e}: coverage {np.mean(np.abs(zs) < 1.96):.1%} RMS z {np.sqrt(np.mean(zs**2)):.2f}")
        pst = Counter(r[f"{codec}_paper"] for r in rows)
        pz = np.array([r[f"{codec}_pz"] for r in rows if f"{codec}_pz" in r])
        print(f"   paper: {dict(pst)}" + (f"; coverage of its 95% intervals {np.mean(np.abs(pz) < 1.96):.1%} "
                                          f"over {len(pz)}" if len(pz) else "; no stated errors"))
    print(f"({time.perf_counter() - clock:.0f} s)")


if __name__ == "__main__":
    main()
