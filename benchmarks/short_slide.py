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

A rolling answer's errors include the slip it cannot exclude
(recover.mle.unseen_slip); the table gives its coverage and RMS with that
share ("after") and without it ("before", the errors of the rolling fit
alone), and for the shots answered rolling the slip's displacement
1/2 mu_s g tau1^2 in position errors (what recover.mle.UNSEEN_SLIP_SIGMAS
must reach when sliding outlasts the first frame).  ``--null N`` also
recovers N true rolling-from-the-strike shots (recover.simulate.
null_rolling_tracks) and prints how much the unseen slip widens their
errors and how many stay ``ok``.

Usage: python benchmarks/short_slide.py [--n 360] [--seed 5] [--min-frames 1] [--null 120]
"""

import argparse

import numpy as np


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=360)
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--min-frames", type=int, default=None)
    ap.add_argument("--null", type=int, default=0)
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
        t_m = meas.t_single
        n = 0 if m.model == "rolling" else int(np.sum((t_m > m.t0) & (t_m < m.t1)))
        err = np.r_[m.v0 - v0, m.w0 - s.w0]
        se = np.r_[m.stderr["v0"], m.stderr["w0"]]
        se0, disp = before(m, p), 0.0
        if m.model == "rolling":
            tau1 = ph.t1 - s.t0
            disp = 0.5 * p.mu_s * p.g * tau1**2 / sigma
        rows.setdefault((m.model, n), []).append((err / se, err / se0, (ph.t1 - s.t0) * fps, disp))
    print("model    sliding frames  shots  coverage before  after  RMS z before  after  "
          "true sliding (frames)  max displacement (errors)")
    for (model, n), v in sorted(rows.items()):
        z = np.concatenate([r[0] for r in v])
        z0 = np.concatenate([r[1] for r in v])
        k = [r[2] for r in v]
        print(f"{model:8} {n:14d} {len(v):6d} {np.mean(np.abs(z0) < 1.96):16.1%} {np.mean(np.abs(z) < 1.96):6.1%} "
              f"{np.sqrt(np.mean(z0**2)):13.2f} {np.sqrt(np.mean(z**2)):6.2f}  {min(k):9.1f}-{max(k):.1f}"
              f"{max(r[3] for r in v):20.1f}")
    print("other answers:", other)
    if args.null:
        null_widening(args.null, args.seed)


def before(m, p):
    """The stated errors of (v0, w0) without the unseen slip's share."""
    s2 = (m.unseen_slip / 1.959964) ** 2
    return np.sqrt(np.maximum(np.r_[m.stderr["v0"] ** 2 - s2, m.stderr["w0"] ** 2 - (2.5 / p.R) ** 2 * s2],
                              0.0))


def null_widening(n, seed):
    """Recover ``n`` rolling-from-the-strike shots; print the widening."""
    from cuespin.recover.estimate import estimate
    from cuespin.recover.simulate import null_rolling_tracks
    ratio, cover0, cover, status, rel = [], [], [], {}, []
    for tr in null_rolling_tracks(n, seed, fps_grid=(60.0, 120.0, 240.0)):
        est = estimate(tr.t, tr.xy, np.full(len(tr.t), tr.sigma), tr.params, tr.exposure_s, run_paper=False)
        m = est.mle
        key = (m.status, m.model) if m is not None else ("failed", "")
        status[key] = status.get(key, 0) + 1
        if m is None or m.status != "ok" or m.model != "rolling":
            continue
        se0 = before(m, tr.params)
        se = np.r_[m.stderr["v0"], m.stderr["w0"]]
        err = np.r_[m.v0 - tr.shot.v0, m.w0 - tr.shot.w0]
        ratio.append(np.max(se[:2] / se0[:2]))
        cover0.append(np.abs(err / se0) < 1.96)
        cover.append(np.abs(err / se) < 1.96)
        rel.append(m.unseen_slip / float(np.hypot(*tr.shot.v0)))
    ratio, rel = np.array(ratio), np.array(rel)
    print(f"true rolling shots: {n}, answers {status}")
    print(f"  v0 error widened by x{np.median(ratio):.1f} median (x{ratio.min():.1f}-{ratio.max():.1f}); "
          f"unseen slip / |v0|: median {np.median(rel):.3f}, max {rel.max():.3f}")
    print(f"  coverage before {np.mean(cover0):.1%}, after {np.mean(cover):.1%}")


if __name__ == "__main__":
    main()
