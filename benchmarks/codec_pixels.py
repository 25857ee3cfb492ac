"""A codec's error in pixels under a tilted camera: weighted per frame through
the camera's Jacobian (recover.measurements, ``px_to_m``) against one
variance in table metres for every frame (the weighting before).

Tracks are simulated through a real camera (1.5 m up, tilted 15 degrees:
the local scale varies across the table), with the tracker's stated error
and a larger codec error, both isotropic in pixels, and recovered both ways
as a lossy codec.  Prints, per way, the MLE's coverage of its 95% intervals
and RMS error in its own standard errors (v0, w0), the codec error it
measured (px) and its RMS error in v0 (m/s).

Usage: python benchmarks/codec_pixels.py [--n 40] [--seed 0] [--stated 0.02] [--codec 0.1]
"""

import argparse

import numpy as np


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=40)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--stated", type=float, default=0.02, help="tracker's stated error (px)")
    ap.add_argument("--codec", type=float, default=0.1, help="codec's error (px)")
    args = ap.parse_args()
    from cuespin.data_gen.sampler import sample_shot
    from cuespin.physics import phases
    from cuespin.physics.camera import pinhole_camera
    from cuespin.recover.api import recover_track
    from cuespin.recover.measurements import pixel_to_table, table_covariance
    from cuespin.recover.mle import model_track

    rng = np.random.default_rng(args.seed)
    out = {"pixels (now)": [], "metres (before)": []}
    for _ in range(args.n):
        shot, p = sample_shot(rng, "random")
        ph = phases(shot, p)
        cam = pinhole_camera(height_m=1.5, tilt_deg=15.0, R=p.R, fps=120.0)
        t = np.arange(0.0, min(ph.t2 + 0.3, shot.t0 + 4.0), 1 / 120.0)
        uv = cam.to_pixels(model_track(shot, p, t))
        uv = uv + np.hypot(args.stated, args.codec) * rng.standard_normal(uv.shape)
        xy = cam.to_table(uv)
        cov = table_covariance(cam, xy, np.full((len(t), 2), args.stated))
        ok = np.ones(len(t), bool)
        for key, kw in (("pixels (now)", {"px_to_m": pixel_to_table(cam, xy)}), ("metres (before)", {})):
            m = recover_track(t, xy, ok, cov, p, method="mle", lossless=False, **kw)["methods"]["mle"]
            if m["status"] != "ok":
                continue
            err = np.r_[m["v0"], m["w0"]] - np.r_[shot.v0, shot.w0]
            z = err / np.r_[m["stderr"]["v0"], m["stderr"]["w0"]]
            out[key].append((z, err[:2], m.get("codec_noise_px") or np.nan))
    for key, rows in out.items():
        z = np.array([r[0] for r in rows])
        ev = np.array([r[1] for r in rows])
        c = [r[2] for r in rows if np.isfinite(r[2])]
        print(f"{key:16} {len(rows)} ok: coverage {np.mean(np.abs(z) < 1.96):.1%}, RMS z {np.sqrt(np.mean(z**2)):.2f}, "
              f"RMS v0 error {np.sqrt(np.mean(ev**2)):.2e} m/s, codec measured "
              + (f"{np.median(c):.3f} px (true {args.codec})" if c else "in metres only"))


if __name__ == "__main__":
    main()
