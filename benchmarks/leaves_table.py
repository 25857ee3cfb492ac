"""Rolling answers on shots seen briefly: the ball leaves the table while it may still slide.

Generated tracks (recover.simulate.leaves_table_tracks: the sampler's fast
shots at a near cushion, cut where the ball reaches it, 0.1-0.3 s after the
strike; 60-480 fps, per-axis noise 2e-5-6e-4 m, independent errors),
recovered by recover.estimate as tests/test_unseen_slip.py does.  Per noise
level: answers ``ok`` as rolling from the strike, of them w0 outside its 95%
interval and more than 10 stated errors off, and answers refused by
recover.mle's ``slide_outlasts`` verdict (a slide lasting through every frame
seen would stay within UNSEEN_SLIP_SIGMAS errors of a rolling path).
``--rolling`` recovers the same shots rolling from the strike (v0 kept): the
refusals there are the rule's cost on answers that were right.
``--before`` sets recover.mle.SLIDE_THROUGH_TAU to 0 (the rule off).

Usage: python benchmarks/leaves_table.py [--n 240] [--seed 31] [--rolling] [--before]
"""

import argparse
from collections import defaultdict

import numpy as np


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=240)
    ap.add_argument("--seed", type=int, default=31)
    ap.add_argument("--rolling", action="store_true")
    ap.add_argument("--before", action="store_true")
    args = ap.parse_args()
    import cuespin.recover.mle as mle_module
    if args.before:
        mle_module.SLIDE_THROUGH_TAU = 0.0
    from cuespin.physics import phases
    from cuespin.recover.estimate import estimate
    from cuespin.recover.simulate import leaves_table_tracks
    cells = defaultdict(lambda: defaultdict(int))
    for tr in leaves_table_tracks(args.n, args.seed, preset="case4" if args.rolling else "leaves_table"):
        m = estimate(tr.t, tr.xy, np.full(len(tr.t), tr.sigma), tr.params, tr.exposure_s, run_paper=False).mle
        outlasts = phases(tr.shot, tr.params).t1 > tr.t[-1]
        for key in (f"{tr.sigma:g}", "all"):
            c = cells[key]
            c["n"] += 1
            c["slide outlasts the track"] += bool(outlasts)
            c[m.status] += 1
            if m.verdicts.get("slide_outlasts"):
                c["refused: slide_outlasts"] += 1
            if m.status == "ok" and m.model == "rolling":
                c["ok rolling"] += 1
                z = np.abs(np.r_[m.v0 - tr.shot.v0, m.w0 - tr.shot.w0]) / np.r_[m.stderr["v0"], m.stderr["w0"]]
                c["ok rolling, missed (|z| > 1.96)"] += bool(np.any(z > 1.959964))
                c["ok rolling, gross (|z| > 10)"] += bool(np.any(z > 10))
    keys = ["n", "slide outlasts the track", "ok", "degenerate", "failed", "refused: slide_outlasts", "ok rolling",
            "ok rolling, missed (|z| > 1.96)", "ok rolling, gross (|z| > 10)"]
    print("| noise (m) | " + " | ".join(keys) + " |\n|" + "---|" * (len(keys) + 1))
    for cell in sorted(cells, key=lambda k: (k == "all", k)):
        print(f"| {cell} | " + " | ".join(str(cells[cell][k]) for k in keys) + " |")


if __name__ == "__main__":
    main()
