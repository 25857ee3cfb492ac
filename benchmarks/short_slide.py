"""Coverage of the maximum-likelihood fit's intervals against how many
measured frames the sliding phase spans (recover.mle.MIN_SLIDING_FRAMES).

Shots rolling from the strike (the sampler's case 4) given a slip that
lasts 0.2-8 frames (|u0| = 7/2 mu_s g tau1, eq. 10, in a random
direction), simulated with recover.simulate (60-240 fps, noise 2e-5-6e-4
m, half with an exposure), recovered; prints per model and number of
sliding frames the coverage of the 95% intervals of v0 and w0 and their
RMS error in stated errors.

Sliding frames are counted as recover.mle counts them: the single-frame
measurements (strike window left out) between the fitted t0 and t1.
``--min-frames`` sets recover.mle.MIN_SLIDING_FRAMES for the run (1: every
slip answered, to measure the curve the threshold comes from).

Usage: python benchmarks/short_slide.py [--n 360] [--seed 5] [--min-frames 1]
"""

import argparse

import numpy as np


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=360)
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--min-frames", type=int, default=None)
    args = ap.parse_args()
    if args.min_frames is not None:
        import cuespin.recover.mle as mle_module
        mle_module.MIN_SLIDING_FRAMES = args.min_frames
    from cuespin.data_gen.sampler import sample_shot
    from cuespin.physics.motion import Shot, phases, z_cross
    from cuespin.recover.estimate import estimate
    from cuespin.recover.simulate import simulate_track
    rng = np.random.default_rng(args.seed)
    rows, other = {}, {}
    for i in range(args.n):
        fps = (60.0, 120.0, 240.0)[i % 3]
        sigma = (2e-5, 1e-4, 6e-4)[(i // 3) % 3]
        shot, p = sample_shot(rng, "case4")
        tau1 = float(rng.uniform(0.2, 8.0)) / fps
        ang = rng.uniform(0, 2 * np.pi)
        u0 = 3.5 * p.mu_s * p.g * tau1 * np.array([np.cos(ang), np.sin(ang)])
        v0 = np.asarray(shot.v0, float)
        s = Shot(x0=shot.x0, v0=v0, w0=z_cross(v0 - u0) / p.R, t0=shot.t0)
        exposure = float(rng.uniform(0.3, 1.0) / fps) if rng.random() < 0.5 else 0.0
        tr = simulate_track(s, p, fps, sigma, rng, exposure)
        est = estimate(tr.t, tr.xy, np.full(len(tr.t), sigma), p, exposure, run_paper=False)
        m = est.mle
        if m is None or m.status != "ok":
            key = m.status if m is not None else "failed"
            other[key] = other.get(key, 0) + 1
            continue
        ph = phases(s, p)
        meas = est.meas
        t_m = meas.t_used[meas.single[meas.group[meas.used]]]
        n = 0 if m.model == "rolling" else int(np.sum((t_m > m.t0) & (t_m < m.t1)))
        z = np.r_[m.v0 - v0, m.w0 - s.w0] / np.r_[m.stderr["v0"], m.stderr["w0"]]
        rows.setdefault((m.model, n), []).append((z, (ph.t1 - s.t0) * fps))
    print("model    sliding frames  shots  coverage  RMS z  true sliding (frames)")
    for (model, n), v in sorted(rows.items()):
        z = np.concatenate([r[0] for r in v])
        k = [r[1] for r in v]
        print(f"{model:8} {n:14d} {len(v):6d} {np.mean(np.abs(z) < 1.96):9.1%} {np.sqrt(np.mean(z**2)):6.2f}  "
              f"{min(k):.1f}-{max(k):.1f}")
    print("other answers:", other)


if __name__ == "__main__":
    main()
