"""What a hand-clicked calibration costs: v0 and w0 errors against corner error.

For each shot (seeded, the sampler's ``random`` mix, at 240 fps through a
tilted pinhole camera 1280 x 720): the ball's true centre at every frame time
is imaged by the true camera, the tracker's per-frame error is added
(Gaussian, ``--track-px`` per axis, the tracker's measured level on sharp
video), and the pixels go back to metres through a camera calibrated from the
table's four corners with every corner coordinate off by Gaussian noise of
``sigma`` px (a click is good to about 1 px).  The maximum-likelihood fit then
states v0, w0 and their standard errors, which are compared with the truth.
Rendering and tracking are left out on purpose: their error is the
``--track-px`` level; what is measured here is the camera's.

Prints, per corner error and per way of fixing the focal length (a lens
calibration ``intrinsics``, or the corners alone), the RMS of the real v0 and
R w0 errors, their RMS in units of the stated standard errors, and the
coverage of the stated 95% intervals.

With ``--auto``: the automatic calibration on drawn frames of the table
(``synthetic_table_frame``) for tilts 0-15 deg, |k1| up to 0.25, no lens
calibration: corner error against the truth, the largest metre error over the
table, and the v0 and R w0 RMS through it beside the exact camera's.

With ``--stated``: the automatic corners' stated error (the edges'
jackknife) against their real error, frame by frame, on drawn tables and on
the renderer's realistic one.

With ``--shaded``: the balls' focal length on the renderer's shaded ball
straight overhead, its light and blur changed one at a time (``--ball-at X,Y``
for the ball, ``--ball-floor`` for ``BALL_SHAPE_FLOOR``).

With ``--focal`` (``--tilts 2,2.5,3``, ``--seeds``, ``--rendered``): the
focal length ``calibrate_frame`` writes at small tilts, its source and its
error against its stated one.

With ``--clicked`` (``--cameras H,T,K1;...``, ``--corner-px 1``, ``--modes
corners,intrinsics``): corners clicked that far off (a new draw per shot),
calibrated as ``calibrate --corners`` does (:func:`calibrate_clicked`: the
bow from the drawn frame's edges, f by the one rule with its still balls,
or the lens known); per camera the real v0 and R w0 errors beside the stated
ones with the calibration's share, their RMS z and the coverage.

With ``--tables`` (``--seed 12000 --n 40``): the automatic corners on random
drawn tables (``calibrate.random_table``) against the edge each names, their
coverage by the stated covariance, and the outline's and the lines' paths
apart (each one's error, their ``PATHS_DISAGREE_Z`` statistic, how near a
band lies inside the lines' noses); and the refusals and the confident
wrong answers (over 1 px and 5 stated errors off).  ``--noise`` redraws
each table at that frame noise, ``--codec jpeg|h264`` (``--quality``,
``--crf``) passes it through a lossy codec.

With ``--diagnose`` (``--height 2 --tilt 0 --k1 -0.25``): the automatic
camera's v0 error split into its parts (corners, k1, focal length), each
camera built from the true values but one.

With ``--auto``, the camera is what ``calibrate_video`` writes for the frame
(:func:`calibrate_frame`: overhead, the focal length from the still balls'
shapes; ``--no-balls`` for the nominal one) and so are the perturbed cameras
(``--no-kappa-camera`` leaves out the one for k1's error, and with the
jackknife's joint moves, each of which moves k1, all of them; ``--corner-sigma``
states the corners' error instead of the jackknife's, one coordinate at a time).
``--frames``: one calibration per shot, each from another noise draw of the
frame, so that a row's coverage is over many frames' corner errors, with a
95% bootstrap interval (shots resampled) per row and pooled;
``--cameras H,T,K1;...`` for other cameras than the table's (which ends
with two at 2-3 degrees of tilt, where the corners' f meets the balls').

Usage: python benchmarks/calibration.py [--n 40] [--seed 0] [--track-px 0.03] [--auto] [--diagnose] [--stated] [--shaded]
    [--tables]
"""

import argparse

import numpy as np

from cuespin.data_gen.sampler import sample_shot
from cuespin.physics.camera import pinhole_camera
from cuespin.physics.motion import phases, positions
from cuespin.physics.scene import Scene, Table
from cuespin.pipeline.calibrate import CalibrationError, calibrate_corners, perturbed_cameras, table_corners
from cuespin.recover.api import recover_track
from cuespin.recover.calibration import add_calibration_error

SIZE = (1280, 720)
FPS = 240.0
# The drawn frames place an edge to 1/4 px (4x supersampling); a roll of the
# camera keeps edges off the pixel grid's axes so that averages out along them.
ROLL_DEG = 1.0


def one(shot, params, true, corners_px, mode, rng, track_px, sigma=0.0, propagate=False):
    """Recover one shot through a camera calibrated from ``corners_px``; return
    (v0 error, R w0 error, v0 stderr, R w0 stderr) as 2-vectors, or None.
    With ``propagate``, the stated errors include the calibration's, from the
    8 cameras of :func:`perturbed_cameras` (the same track refitted through each)."""
    kw = {"intrinsics": true.K, "distortion": true.dist} if mode == "intrinsics" else {}
    try:
        cal = calibrate_corners(corners_px, SIZE, Table(), fps=FPS, **kw)
    except CalibrationError:
        return None
    uv = track_pixels(shot, params, true, rng, track_px)
    cams = perturbed_cameras(corners_px, sigma, SIZE, Table(), fps=FPS, **kw) if propagate and sigma else ()
    r = through(shot, params, cal.camera, *uv, perturbed=cams)
    return None if r is None else r[:4]


def track_pixels(shot, params, true, rng, track_px):
    """The tracked pixels of a shot seen by ``true``: (t, uv), until it stops
    or its centre comes within R of a cushion."""
    table = Table()
    true = Scene(physics=params, camera=true).camera
    ph = phases(shot, params)
    t_end = min(ph.t2 + 0.3, shot.t0 + 3.0)
    t = np.arange(0.0, t_end, 1.0 / FPS)
    xy = positions(shot, params, t, ph)
    inside = table.contains(xy, params.R)
    stop = np.argmin(inside) if not inside.all() else len(t)
    t, xy = t[:stop], xy[:stop]
    return t, true.to_pixels(xy) + rng.normal(0.0, track_px, (len(t), 2)), track_px


def fitted(params, camera, t, uv, track_px, keep=None):
    """The MLE's answer (``recover_track``'s method dict) and the estimate
    (its decisions, its fit's whitened residuals) for the pixels read back
    through ``camera``; ``keep``: an earlier fit's decisions
    (recover.estimate.Decided), kept as ``cuespin recover`` keeps them in its
    refits through the perturbed cameras."""
    cam = Scene(physics=params, camera=camera).camera
    xy_m = cam.to_table(uv)
    cov = cam.cov_to_table(xy_m, np.broadcast_to(np.eye(2) * track_px**2, (len(t), 2, 2)))
    se = np.sqrt(np.stack([cov[:, 0, 0], cov[:, 1, 1]], axis=1))
    out, est = recover_track(t, xy_m, np.ones(len(t), bool), se, params, 0.0, "mle", False, lossless=True,
                             keep=keep, return_estimate=True)
    return out["methods"]["mle"], est


def through(shot, params, camera, t, uv, track_px, perturbed=(), free=False):
    """Pixels read back through ``camera`` and fitted: errors and stated errors
    ``(dv, dw, sv, sw, sv_fit, sw_fit, ar1)`` (2-vectors, m/s; R w0's;
    ``_fit`` the fit's share alone; ``ar1`` the lag-1 correlation of the
    AR(1) errors the fit took, 0: none), or None when the
    fit gave no w0.  With ``perturbed`` (the calibration's cameras) the stated
    errors carry the calibration's share as ``cuespin recover`` adds it
    (recover.calibration.add_calibration_error, each refit keeping this
    fit's decisions; NaN when a refit gave no answer: the share unknown);
    ``free``: each refit re-deciding (the fit's AR(1) model, segmentation,
    ...), as this benchmark did before clicked13 (not what the recovery does:
    measured, docs/measurements.md)."""
    m, est = fitted(params, camera, t, uv, track_px)
    decided = est.decided
    if m["status"] != "ok" or m.get("w0") is None:
        return None
    if perturbed:
        add_calibration_error({"mle": m}, lambda c: {"mle": fitted(params, c, t, uv, track_px,
                                                                    None if free else decided)[0]}, perturbed)
    se = {k: np.nan * np.ones(2) if v is None else np.array(v, dtype=float) for k, v in m["stderr"].items()}
    fit = m.get("stderr_fit") or m["stderr"]
    dv = np.array(m["v0"]) - shot.v0
    dw = params.R * (np.array(m["w0"]) - shot.w0)
    return (dv, dw, se["v0"], params.R * se["w0"], np.array(fit["v0"], float), params.R * np.array(fit["w0"], float),
            decided.ar1)


def joint_z(shot, params, camera, perturbed, t, uv, track_px):
    """z (v0, R w0) of the answer corrected by what the track says about the
    calibration (recover.calibration.track_posterior: one Gauss-Newton step
    on the perturbed cameras' moves under their prior, from the refits'
    whitened residuals), against the fit's error and the calibration's
    remaining one; None when a fit or refit gives no answer."""
    from cuespin.recover.calibration import track_posterior

    def answer(m):
        ok = m["status"] == "ok" and m.get("w0") is not None
        return np.r_[m["v0"], params.R * np.asarray(m["w0"])] if ok else None

    m, est = fitted(params, camera, t, uv, track_px)
    q = answer(m)
    if q is None or est.mle.residuals is None:
        return None
    r = est.mle.residuals.ravel()
    refits = [fitted(params, c, t, uv, track_px, keep=est.decided) for c in perturbed]
    shifts = [answer(mk) for mk, _ in refits]
    if any(a is None for a in shifts) or any(e.mle.residuals is None or e.mle.residuals.size != r.size
                                              for _, e in refits):
        return None
    corr, var = track_posterior(np.array(shifts) - q, [e.mle.residuals.ravel() - r for _, e in refits], r)
    sf = np.r_[m["stderr"]["v0"], params.R * np.asarray(m["stderr"]["w0"])]
    truth = np.r_[shot.v0, params.R * np.asarray(shot.w0)]
    return (q + corr - truth) / np.sqrt(sf**2 + var)


def auto(args):
    """Automatic calibration on drawn frames: corners, metres, v0 against the exact camera."""
    from cuespin.pipeline.calibrate import calibrate_frame, synthetic_table_frame

    print(f"cushions {args.cushion} m; {args.n} shots per camera; tracker error {args.track_px} px")
    print("height tilt    k1 | corner_rms_px edge_rms_px k1_est focal_from | max_m_err | "
          "v0_rms exact / auto (m/s), Rw0_rms exact / auto | n sigma_px cameras | "
          "cover95 (v0, R w0) exact fit-only / auto with the calibration's share, v0 RMS z exact / auto")
    xs, ys = np.meshgrid(np.linspace(0.1, 2.44, 9), np.linspace(0.1, 1.17, 5))
    grid = np.column_stack([xs.ravel(), ys.ravel()])
    cams = [(2.0, 0.0, 0.0), (2.0, 10.0, 0.0), (1.5, 15.0, 0.0), (3.0, 5.0, -0.25),
            (2.0, 10.0, -0.25), (1.5, 15.0, -0.25), (2.0, 12.0, 0.25), (2.0, 0.0, -0.25),
            (2.0, 2.0, 0.0), (2.0, 3.0, -0.25)]       # the last two: where the corners' f meets the balls'
    if args.cameras:
        cams = [tuple(float(v) for v in c.split(",")) for c in args.cameras.split(";")]
    pooled, pooled_cal = [], []

    def calibrated(true, tilt, k1, frame_seed):
        img = synthetic_table_frame(true, seed=int(10 * tilt + 100 * abs(k1)) + 1000 * frame_seed,
                                    cushion_m=args.cushion, pockets=args.cushion > 0)
        # --true-focal: the true focal length given (--focal-px), to tell its share from the rest
        fk = {"focal_px": float(true.K[0, 0])} if args.true_focal else {}
        # what calibrate_video writes for this frame (corners, lens, f, perturbed cameras);
        # --no-balls: the nominal f overhead, as before the balls' f existed
        if args.corner_sigma is not None:
            fk["corner_sigma_px"] = args.corner_sigma
        cal = calibrate_frame(img, Table(), fps=FPS, use_balls=not args.no_balls, **fk)
        pert = cal.perturbed
        kappa = float(cal.camera.dist[0]) / float(cal.camera.K[0, 0]) ** 2
        if args.no_kappa_camera:  # the perturbed cameras as before k1's error was in them
            pert = [c for c in pert if abs(c.dist[0] / c.K[0, 0] ** 2 - kappa) <= 1e-9 * abs(kappa)]
        return cal, pert, kappa

    for height, tilt, k1 in [c for c in cams if not args.overhead or c[1] == 0.0]:
        true = Scene(physics=sample_shot(0)[1], camera=pinhole_camera(
            height_m=height, tilt_deg=tilt, k1=k1, size=SIZE, fps=FPS, roll_deg=ROLL_DEG)).camera
        cal, pert, kappa = calibrated(true, tilt, k1, args.frame_seed)
        sigma, edge_rms = cal.corner_sigma_px, cal.edge_rms_px
        truth = true.project(table_corners(Table()))
        c_rms = float(np.sqrt(np.mean(np.sum((cal.corners_px - truth) ** 2, axis=1))))
        cam = Scene(physics=sample_shot(0)[1], camera=cal.camera).camera
        m_err = float(np.abs(cam.to_table(true.to_pixels(grid)) - grid).max())
        res = {"exact": [], "auto": []}
        f_err, cal_z = [], []
        for i in range(args.n):
            if args.frames and i:
                # --frames: one calibration per shot, each from another noise draw of the frame
                cal, pert, kappa = calibrated(true, tilt, k1, args.frame_seed + i)
            shot, params = sample_shot(args.seed * 1000 + i, "random")
            tr = Scene(physics=params, camera=true).camera
            uv = track_pixels(shot, params, tr, np.random.default_rng(i), args.track_px)
            r = {"exact": through(shot, params, true, *uv),
                 "auto": through(shot, params, cal.camera, *uv, perturbed=pert)}   # the share as the recovery adds it
            if r["exact"] is None or r["auto"] is None or np.isnan(r["auto"][2]).any():
                continue                    # paired: the same shots in both columns
            res["exact"].append(r["exact"][:4])
            dv, dw, sv, sw, sfv, sfw, _ = r["auto"]
            res["auto"].append((dv, dw, sv, sw))
            # the calibration's own error (the answer's move from the exact camera's, the same
            # track) in units of the share it states: the fit's own error left out
            cal_z.append(np.concatenate([(dv - r["exact"][0]) / np.sqrt(sv**2 - sfv**2),
                                         (dw - r["exact"][1]) / np.sqrt(sw**2 - sfw**2)]))
            f_err.append((cal.camera.K[0, 0] / true.K[0, 0] - 1, getattr(cal, "focal_sigma", None) or 0.0))
            if args.frames:     # a line per calibration: the rows' shots pool across runs
                print(f"  frame {args.frame_seed + i} shot {i}: z " + " ".join(
                    f"{v:+.2f}" for v in np.concatenate([dv / sv, dw / sw])) + " share z " + " ".join(
                    f"{v:+.2f}" for v in cal_z[-1]) + f" k1 {kappa * cal.camera.K[0, 0] ** 2:+.5f} f {f_err[-1][0]:+.3%}",
                    flush=True)
        rv = {k: np.sqrt(np.mean([np.sum(r[0] ** 2) / 2 for r in v])) for k, v in res.items()}
        rw = {k: np.sqrt(np.mean([np.sum(r[1] ** 2) / 2 for r in v])) for k, v in res.items()}
        inside = {k: np.array([np.abs(np.concatenate([r[0] / r[2], r[1] / r[3]])) < 1.96 for r in v])
                  for k, v in res.items()}
        cover = {k: v.mean() for k, v in inside.items()}
        zv = {k: np.sqrt(np.mean([np.sum((r[0] / r[2]) ** 2) / 2 for r in v])) for k, v in res.items()}
        fe = np.array(f_err)
        print(f"{height:6.1f} {tilt:4.0f} {k1:+.2f} | {c_rms:13.3f} {edge_rms:11.3f} "
              f"{kappa * cal.camera.K[0, 0] ** 2:+.3f} {cal.focal_source:13s} "
              f"f {fe[:, 0].mean() if args.frames else fe[-1, 0]:+.2%} (stated {fe[:, 1].mean():.1%}) | {m_err:9.1e} | "
              f"{rv['exact']:.2e} / {rv['auto']:.2e} ({rv['auto'] / rv['exact']:.2f}x), "
              f"{rw['exact']:.2e} / {rw['auto']:.2e} | {len(res['auto'])} {sigma:.2f} {len(pert)} | "
              f"{cover['exact']:.0%} / {cover['auto']:.0%}{boot(inside['auto'])}{binom(inside['auto'])}, "
              f"{zv['exact']:.2f} / {zv['auto']:.2f}", flush=True)
        pooled.append(inside["auto"])
        cz = np.array(cal_z)
        pooled_cal.append(np.abs(cz) < 1.96)
        print(f"    the calibration's share alone: (auto - exact) / stated share, RMS {np.sqrt(np.mean(cz**2)):.2f}, "
              f"cover95 {np.mean(np.abs(cz) < 1.96):.0%}{boot(np.abs(cz) < 1.96)}{binom(np.abs(cz) < 1.96)}",
              flush=True)
        if args.frames:
            print(f"    f error per frame (%): {np.round(100 * fe[:, 0], 2).tolist()}; z "
                  f"{np.round(fe[:, 0] / np.where(fe[:, 1] > 0, fe[:, 1], np.nan), 2).tolist()}", flush=True)
    if len(pooled) > 1:
        print(f"pooled over {len(pooled)} rows, {sum(len(p) for p in pooled)} shots: cover "
              f"{np.mean(np.concatenate(pooled)):.1%}{boot(*pooled)}{binom(np.concatenate(pooled))}; the "
              f"calibration's share alone {np.mean(np.concatenate(pooled_cal)):.1%}{boot(*pooled_cal)}"
              f"{binom(np.concatenate(pooled_cal))}")


def boot(*rows, n: int = 2000, seed: int = 0) -> str:
    """A 95% bootstrap interval of the coverage, shots resampled within each row
    (a shot's four components share its calibration and its track, so a shot,
    not a component, is one draw; the rows must not share draws)."""
    rng = np.random.default_rng(seed)
    rows = [np.asarray(r, dtype=float).reshape(len(r), -1) for r in rows if len(r)]
    if not rows:
        return ""
    means = [np.mean(np.concatenate([r[rng.integers(0, len(r), len(r))].ravel() for r in rows])) for _ in range(n)]
    lo, hi = np.percentile(means, [2.5, 97.5])
    return f" [{lo:.0%}, {hi:.0%}]"


def binom(inside) -> str:
    """The 95% binomial (Clopper-Pearson) interval of a coverage over its
    components, as if independent (a shot's four share its track and, with
    one frame a row, every component its calibration: narrower than
    :func:`boot`'s where they are not)."""
    from scipy.stats import binomtest

    x = np.asarray(inside, dtype=bool).ravel()
    if not len(x):
        return ""
    ci = binomtest(int(x.sum()), len(x)).proportion_ci()
    return f" binom, components as if independent [{ci.low:.0%}, {ci.high:.0%}] of {len(x)}"


def stated(args):
    """The automatic corners' stated error (the edges' jackknife, as ``calibrate``
    states it) against their real error, per frame: drawn tables (``--seeds``
    noise seeds per camera) and the renderer's realistic table (texture seeds)."""
    import math
    from dataclasses import replace

    from cuespin.data_gen.sampler import make_scene
    from cuespin.physics.camera import Camera
    from cuespin.physics.motion import Shot
    from cuespin.pipeline.calibrate import detect_corners, matched_corner_errors, synthetic_table_frame
    from cuespin.render.draw import FrameRenderer

    def row(label, img, truth):
        kw = {} if args.pattern_px is None else {"pattern_px": args.pattern_px}
        det = detect_corners(img, robust=not args.no_robust, **kw)
        d = matched_corner_errors(det.corners, truth)[0]
        h, w = img.shape[:2]
        naive = det.edge_rms * math.sqrt(4.0 / ((w + h) / 4.0))     # the scatter over the points' number
        jk = math.sqrt(np.trace(det.corner_cov[:8, :8]) / 8.0)
        real = math.sqrt(np.mean(d**2))
        print(f"{label:32s} edge_rms {det.edge_rms:.3f} | real {real:.3f} scatter/sqrt(n) {naive:.3f} "
              f"jackknife {jk:.3f} | jackknife/real {jk / real:.2f} scatter/real {naive / real:.2f} "
              f"0.2/real {0.2 / real:.1f}", flush=True)

    cams = [(2.0, 0.0, 0.0), (2.0, 10.0, 0.0), (1.5, 15.0, 0.0), (3.0, 5.0, -0.25),
            (2.0, 10.0, -0.25), (1.5, 15.0, -0.25), (2.0, 12.0, 0.25), (2.0, 0.0, -0.25)]
    for height, tilt, k1 in cams:
        true = pinhole_camera(height_m=height, tilt_deg=tilt, k1=k1, size=SIZE, fps=FPS, roll_deg=ROLL_DEG,
                              R=0.028575)
        for sd in range(args.seeds):
            img = synthetic_table_frame(true, seed=int(10 * tilt + 100 * abs(k1)) + 1000 * sd, cushion_m=0.05,
                                        pockets=True)
            row(f"drawn {height} {tilt:g} {k1:+.2f} s{sd}", img, true.project(table_corners(Table())))
    shot, params = sample_shot(100, "random")
    top = Camera(fps=FPS, width=1400, height=756, homography=((500.0, 0, 60.0), (0, -500.0, 695.0), (0, 0, 1.0)))
    rendered = [("top-down H", top)] + [
        (f"{h} {t:g} {k:+.2f}", pinhole_camera(height_m=h, tilt_deg=t, k1=k, size=SIZE, fps=FPS, roll_deg=ROLL_DEG,
                                               margin_m=0.15, R=params.R))
        for h, t, k in [(2.0, 0.0, 0.0), (2.0, 0.0, -0.25), (2.0, 10.0, -0.25), (1.5, 15.0, 0.0), (2.0, 12.0, 0.25)]]
    for label, cam in rendered:
        truth = (cam.project(table_corners(Table())) if cam.is_pinhole
                 else cam.to_pixels(table_corners(Table())[:, :2]))
        for sd in range(min(args.seeds, 2)):
            scene = make_scene(Shot(shot.x0, shot.v0, shot.w0, t0=0.1), params,
                               render={"look": "realistic", "noise_sigma": 2.0, "seed": 1 + sd})
            img = next(iter(FrameRenderer(replace(scene, camera=cam), n_frames=1).frames()))
            row(f"realistic {label} s{sd}", img, truth)


def h264_encode(frames, out, crf: int = 20, fps: int = 30) -> None:
    """BGR uint8 ``frames`` as ONE H.264 stream into ``out`` (a path or a file
    object; MP4): PyAV's libx264, ``crf``, preset medium, yuv420p, as a phone's
    file carries a still table (each frame with its own noise: the encoder
    codes what changed from the key frame)."""
    import av

    with av.open(out, "w", format="mp4") as c:
        s = c.add_stream("libx264", rate=fps)
        s.pix_fmt, s.options = "yuv420p", {"crf": str(crf), "preset": "medium"}
        for k, img in enumerate(frames):
            h, w = img.shape[:2]
            f = np.ascontiguousarray(img[: h - h % 2, : w - w % 2])
            if k == 0:
                s.width, s.height = f.shape[1], f.shape[0]
            for pkt in s.encode(av.VideoFrame.from_ndarray(f, format="bgr24")):
                c.mux(pkt)
        for pkt in s.encode():
            c.mux(pkt)


def through_codec(img, codec: str | None, quality: int = 70, crf: int = 20):
    """``img`` through a lossy codec as a camera's file would carry it: ``jpeg``
    (OpenCV, ``quality``), ``h264`` (:func:`h264_encode`, ``crf``, the frame
    encoded 3 times and the first decoded: the key frame), or None
    (unchanged)."""
    import io

    import cv2

    if codec is None:
        return img
    if codec == "jpeg":
        return cv2.imdecode(cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, quality])[1], cv2.IMREAD_COLOR)
    import av

    buf = io.BytesIO()
    h264_encode([img] * 3, buf, crf)
    buf.seek(0)
    with av.open(buf) as d:
        return next(iter(d.decode(video=0))).to_ndarray(format="bgr24")


def tables(args):
    """The automatic corners on random drawn tables (``calibrate.random_table``, seeds
    ``--seed`` .. ``--seed + --n - 1``): each corner coordinate's error against
    its stated standard error (the detection's covariance), the truth the edge
    it says it found (``noses``: the playing surface; ``felt``: the felt's
    outline); and the two paths apart (the outline's, ``lines="never"``, and
    the cushions' lines, ``"always"``, both ``refuse=False``): each one's RMS
    error and their largest corner difference over their combined stated
    error (``PATHS_DISAGREE_Z``'s statistic)."""
    import math

    from cuespin.pipeline.calibrate import (
        _felt_distance,
        _felt_quad,
        cushion_lines,
        detect_corners,
        matched_corner_errors,
        random_table,
        synthetic_table_frame,
    )

    def matched(det, truth):
        e, idx = matched_corner_errors(det.corners, truth)
        return e.ravel(), det.corner_cov[np.ix_(idx, idx)]

    print("seed height tilt k1 roll | look | auto: edge lines rms_px stated_px inside2sd | outline: edge rms | "
          "lines: edge rms | z | band inside the lines' noses (px)")
    zs, within, e2, v2, shows, refused, wrong = [], [], [], [], [], [], []
    for seed in range(args.seed, args.seed + args.n):
        t = random_table(seed)
        if args.noise is not None:
            t["frame"] = synthetic_table_frame(t["camera"], seed=seed, **dict(t["look"], noise=args.noise))
        t["frame"] = through_codec(t["frame"], args.codec, args.quality, args.crf)
        look = ",".join(f"{k}={v:.3g}" for k, v in t["look"].items())
        try:
            det = detect_corners(t["frame"])
        except CalibrationError as err:
            print(f"{seed} refused: {err}", flush=True)
            refused.append(seed)
            continue
        e, C = matched(det, t[det.edge])
        sd = np.sqrt(np.diag(C))
        within.append(np.abs(e) <= 2.0 * sd)
        # the noses show unless a band inside them is near the cushions' shade (within 0.1 of the felt's)
        lk = t["look"]
        shows.append(abs(lk.get("cushion_shade", 0.0) - lk.get("band_shade", 9.0)) >= 0.1)
        e2.append(e**2)
        v2.append(sd**2)
        if math.sqrt(np.mean(e**2)) > 1.0 and math.sqrt(np.mean(e**2)) > 5.0 * math.sqrt(np.mean(sd**2)):
            wrong.append(seed)      # a confident wrong answer: over 1 px and 5 stated errors off (cushion13)
        paths = {}
        for mode in ("never", "always"):
            try:
                paths[mode] = detect_corners(t["frame"], lines=mode, refuse=False)
            except CalibrationError:
                paths[mode] = None
        cols = []
        for mode in ("never", "always"):
            p = paths[mode]
            cols.append("refused" if p is None else
                        f"{p.edge} {math.sqrt(np.mean(matched(p, t[p.edge])[0] ** 2)):.3f}")
        z = float("nan")
        if all(p is not None for p in paths.values()):
            a, b = paths["never"], paths["always"]
            sig = math.sqrt((np.trace(a.corner_cov[:8, :8]) + np.trace(b.corner_cov[:8, :8])) / 8.0)
            z = float(np.abs(a.corners - b.corners).max() / sig)
            zs.append((seed, z, cols))
        inside = []
        try:
            D, thr = _felt_distance(t["frame"])
            cushion_lines(t["frame"], *_felt_quad(D, thr), D, thr, inside=inside)
        except CalibrationError:
            pass
        crowd = min(inside, default=math.inf)
        print(f"{seed} {t['drawn'][0]:.2f} {t['drawn'][1]:4.1f} {t['drawn'][2]:+.3f} {t['drawn'][3]:+.2f} | {look} | "
              f"{det.edge} {det.lines} {math.sqrt(np.mean(e**2)):.3f} {math.sqrt(np.mean(sd**2)):.3f} "
              f"{int(within[-1].sum())}/8 | {cols[0]} | {cols[1]} | {z:.2f} | {crowd:.1f}", flush=True)
    for label, sel in (("", np.ones(len(within), bool)), (" whose noses show (no band within 0.1 of the cushions' "
                                                           "shade)", np.array(shows))):
        ins, ee, vv = (np.concatenate([a for a, s in zip(x, sel) if s]) for x in (within, e2, v2))
        print(f"{int(sel.sum())} tables{label}: coordinates within 2 stated sd {ins.mean():.3f}; RMS z "
              f"{math.sqrt(np.mean(ee / vv)):.2f}; RMS error / RMS stated {math.sqrt(ee.mean() / vv.mean()):.2f}")
    print(f"refused {len(refused)} {refused}; confident wrong answers (over 1 px and 5 stated errors) {len(wrong)} {wrong}")


def clicked_calibration(corners_px, frame, sigma, **kw):
    """What ``cuespin calibrate --corners`` writes for these corners
    (:func:`calibrate_clicked`, the still balls read in ``frame``)."""
    from cuespin.pipeline.calibrate import calibrate_clicked

    return calibrate_clicked(corners_px, SIZE, Table(), frame=frame, corner_sigma_px=sigma, **kw)


def clicked(args):
    """Corners clicked ``--corner-px`` off (Gaussian per coordinate, a new draw
    per shot, seeded), calibrated as ``calibrate --corners`` does (the focal
    length by the one rule, the drawn frame's still balls; or the lens known,
    ``intrinsics``): per camera (``--cameras H,T,K1;...``), the real v0 and
    R w0 errors beside the stated ones with the calibration's share (the
    same track refitted through the perturbed cameras, keeping the fit's
    decisions, as ``cuespin recover`` does), their RMS z and the
    coverage of the stated 95% intervals with a 95% bootstrap interval."""
    from cuespin.pipeline.calibrate import synthetic_table_frame

    sigma = args.corner_px
    cams = [tuple(float(v) for v in c.split(",")) for c in (args.cameras or "2,2,0;2,3,0;2,10,0;2,2,-0.25;"
                                                             "2,3,-0.25;2,10,-0.25").split(";")]
    print(f"corners {sigma} px off, {args.n} shots per camera (each its own shot, clicks and track noise, seeded "
          f"[{args.seed}, camera, shot]), tracker {args.track_px} px")
    print("height tilt    k1 mode       | n focal_from (f err mean, stated mean) | v0 RMS real / stated (fit-only) "
          "| v0 RMS z, cover95 | R w0 RMS real / stated | R w0 RMS z, cover95 | both cover")
    pooled = {}
    draws = 0
    for cam_idx, (height, tilt, k1) in enumerate(cams):
        true = Scene(physics=sample_shot(0)[1], camera=pinhole_camera(
            height_m=height, tilt_deg=tilt, k1=k1, size=SIZE, fps=FPS, roll_deg=ROLL_DEG)).camera
        frame = synthetic_table_frame(true, seed=int(10 * tilt + 100 * abs(k1)), cushion_m=0.05, pockets=True)
        exact = true.project(table_corners(Table()))
        for mode in args.modes.split(","):
            kw = {"intrinsics": true.K, "distortion": true.dist} if mode == "intrinsics" else {}
            rows, srcs, f_err, failed = [], [], [], 0
            for i in range(args.n):
                # Each (seed, camera, shot) its own shot, clicks and track noise: a shot's four
                # components share one draw, so the draws, not the components, are the sample.
                shot, params = sample_shot(np.random.default_rng([args.seed, cam_idx, i, 1]), "random")
                rng = np.random.default_rng([args.seed, cam_idx, i])
                c = exact + rng.normal(0.0, sigma, exact.shape)
                try:
                    cal = clicked_calibration(c, frame, sigma, fps=FPS, R_nominal=params.R, **kw)
                except CalibrationError as exc:
                    print(f"  shot {i}: refused: {exc}")
                    continue
                tr = Scene(physics=params, camera=true).camera
                uv = track_pixels(shot, params, tr, rng, args.track_px)
                r = through(shot, params, cal.camera, *uv, perturbed=cal.perturbed)
                if r is None:
                    continue
                dv, dw, sv, sw, sf, _, ar1 = r
                if np.isnan(sv).any() or np.isnan(sw).any():   # a refit without an answer: no stated error
                    failed += 1
                    continue
                rows.append((dv, dw, sv, sw, sf))
                srcs.append(cal.focal_source)
                f_err.append((cal.camera.K[0, 0] / true.K[0, 0] - 1, getattr(cal, "focal_sigma", None) or 0.0))
                z = np.concatenate([dv / rows[-1][2], dw / rows[-1][3]])
                print(f"  {height:g},{tilt:g},{k1:+.2f} {mode} shot {i}: f {f_err[-1][0]:+.2%} z "
                      + " ".join(f"{v:+.2f}" for v in z) + f" ar1 {ar1:.2f}", flush=True)
                if args.joint:          # the same draw, the answer corrected by what the track says: its own line
                    zj = joint_z(shot, params, cal.camera, cal.perturbed, *uv)
                    if zj is not None:
                        print(f"  {height:g},{tilt:g},{k1:+.2f} {mode}-joint shot {i}: f {f_err[-1][0]:+.2%} z "
                              + " ".join(f"{v:+.2f}" for v in zj) + f" ar1 {ar1:.2f}", flush=True)
                if args.also_free:      # the same draw, the refits re-deciding (before clicked13): its own line
                    rf = through(shot, params, cal.camera, *uv, perturbed=cal.perturbed, free=True)
                    if not np.isnan(rf[2]).any() and not np.isnan(rf[3]).any():
                        print(f"  {height:g},{tilt:g},{k1:+.2f} {mode}-free shot {i}: f {f_err[-1][0]:+.2%} z "
                              + " ".join(f"{v:+.2f}" for v in np.concatenate([rf[0] / rf[2], rf[1] / rf[3]]))
                              + f" ar1 {rf[6]:.2f}", flush=True)
            if not rows:
                print(f"{height:6.1f} {tilt:4.0f} {k1:+.2f} {mode:10s} | 0")
                continue
            if failed:
                print(f"  {failed} draws without a stated error (a refit through a perturbed camera gave no "
                      "answer: the recovery then states the calibration's share unknown)")
            dv, dw, sv, sw, sf = (np.array([r[k] for r in rows]) for k in range(5))
            zv, zw = dv / sv, dw / sw
            inside = np.abs(np.concatenate([zv, zw], axis=1)) < 1.96
            pooled.setdefault(mode, []).append(inside)
            draws += len(rows)
            fe = np.array(f_err)
            src = max(set(srcs), key=srcs.count)
            rms = lambda a: float(np.sqrt(np.mean(a**2)))  # noqa: E731
            print(f"{height:6.1f} {tilt:4.0f} {k1:+.2f} {mode:10s} | {len(rows)} {src} ({fe[:, 0].mean():+.1%}, "
                  f"{fe[:, 1].mean():.1%}) | {rms(dv):.2e} / {rms(sv):.2e} ({rms(sf):.1e}) | {rms(zv):.2f}, "
                  f"{np.mean(np.abs(zv) < 1.96):.0%}{boot(np.abs(zv) < 1.96)} | {rms(dw):.2e} / {rms(sw):.2e} | "
                  f"{rms(zw):.2f}, {np.mean(np.abs(zw) < 1.96):.0%} | {inside.mean():.0%}{boot(inside)}", flush=True)
    print(f"{draws} independent draws (shot, clicks, track noise), 4 components each")
    for mode, ins in pooled.items():
        print(f"pooled {mode}: {sum(len(x) for x in ins)} draws, cover95 (v0 and R w0) "
              f"{np.concatenate([x.ravel() for x in ins]).mean():.1%}{boot(*ins)} (draws resampled)")


def focal(args):
    """The focal length ``calibrate_frame`` writes at small tilts (``--tilts``,
    2 m, k1 0 and -0.25), its source and its error against its stated one:
    drawn frames (``--seeds`` noise seeds), or with ``--rendered`` the
    renderer's realistic table with a ball at rest at (2.40, 1.15) m under
    the default light and a lamp overhead."""
    import math
    from dataclasses import replace

    from cuespin.data_gen.sampler import make_scene
    from cuespin.physics.motion import Shot
    from cuespin.pipeline.calibrate import calibrate_frame, synthetic_table_frame
    from cuespin.render.draw import FrameRenderer

    shot, params = sample_shot(100, "random")
    zs = []
    for tilt in (float(t) for t in args.tilts.split(",")):
        for k1 in (0.0, -0.25):
            R = params.R if args.rendered else 0.028575    # the drawn balls: a pool ball's
            true = pinhole_camera(height_m=2.0, tilt_deg=tilt, k1=k1, size=SIZE, fps=FPS, roll_deg=ROLL_DEG,
                                  margin_m=0.15 if args.rendered else 0.1, R=R)
            if args.rendered:
                frames = []
                for name, look in (("default", {}), ("lamp", {"light_elevation": 1.55})):
                    scene = make_scene(Shot(np.array([2.40, 1.15]), shot.v0, shot.w0, t0=0.1), params,
                                       render={"look": "realistic", "noise_sigma": 2.0, "seed": 1, **look})
                    frames.append((name, next(iter(FrameRenderer(replace(scene, camera=true), n_frames=1).frames()))))
            else:
                frames = [(f"s{sd}", synthetic_table_frame(true, seed=int(10 * tilt + 100 * abs(k1)) + 1000 * sd,
                                                           cushion_m=0.05, pockets=True)) for sd in range(args.seeds)]
            for label, img in frames:
                cal = calibrate_frame(img, Table(), fps=FPS, R_nominal=R)
                err = cal.camera.K[0, 0] / true.K[0, 0] - 1.0
                zs.append(err / cal.focal_sigma)
                print(f"tilt {tilt:g} k1 {k1:+.2f} {label}: {cal.focal_source:13s} f {err:+.2%} stated "
                      f"{cal.focal_sigma:.2%} z {zs[-1]:+.2f} corner sigma {cal.corner_sigma_px:.3f} px", flush=True)
    z = np.array(zs)
    print(f"{len(z)} frames: f error / stated RMS {math.sqrt(np.mean(z**2)):.2f}, max |.| {np.abs(z).max():.2f}")


def shaded(args):
    """The balls' focal length on the renderer's shaded ball straight overhead
    (2 m, a ball at rest at (2.40, 1.15) m), the look's light and blur changed
    one at a time: the measured shape against the exact outline's, and f."""
    from dataclasses import replace

    import cuespin.pipeline.calibrate as calibrate
    from cuespin.data_gen.sampler import make_scene
    from cuespin.physics.motion import Shot
    from cuespin.pipeline.calibrate import _shape, ball_images, calibrate_frame, detect_corners, signed_area
    from cuespin.render.draw import FrameRenderer

    if args.ball_floor is not None:     # the floor's stated error against the same balls' real one
        calibrate.BALL_SHAPE_FLOOR = args.ball_floor
    shot, params = sample_shot(100, "random")
    pos = np.array([float(v) for v in args.ball_at.split(",")])
    variants = {"default": {}, "no blur": {"psf_sigma": 0.0}, "even light": {"ambient": 1.0, "specular": 0.0},
                "even light, no blur": {"ambient": 1.0, "specular": 0.0, "psf_sigma": 0.0},
                "light overhead": {"light_elevation": 1.55}}
    for k1 in (0.0, -0.25):
        true = pinhole_camera(height_m=2.0, tilt_deg=0.0, k1=k1, size=SIZE, fps=FPS, roll_deg=ROLL_DEG,
                              margin_m=0.15, R=params.R)
        x, y = true.ball_outline(pos, params.R, n=720).T          # the exact outline's area moments
        x1, y1 = np.roll(x, -1), np.roll(y, -1)
        a = x * y1 - x1 * y
        A = a.sum() / 2
        cx, cy = ((x + x1) * a).sum() / (6 * A), ((y + y1) * a).sum() / (6 * A)
        mxx = ((x**2 + x * x1 + x1**2) * a).sum() / (12 * A) - cx**2
        myy = ((y**2 + y * y1 + y1**2) * a).sum() / (12 * A) - cy**2
        mxy = ((x * y1 + 2 * x * y + 2 * x1 * y1 + x1 * y) * a).sum() / (24 * A) - cx * cy
        exact = _shape(np.array([[mxx, mxy], [mxy, myy]]))
        for name, v in variants.items():
            scene = make_scene(Shot(pos, shot.v0, shot.w0, t0=0.1), params,
                               render={"look": "realistic", "noise_sigma": 2.0, "seed": 1, **v})
            img = next(iter(FrameRenderer(replace(scene, camera=true), n_frames=1).frames()))
            cal = calibrate_frame(img, Table(), fps=FPS, R_nominal=params.R)
            det = detect_corners(img)
            scale = np.sqrt(abs(signed_area(det.corners)) / (Table().length * Table().width))
            balls = ball_images(img, det.corners, params.R * scale)
            err = np.round(balls[0].shape - exact, 4).tolist() if balls else None
            print(f"k1 {k1:+.2f} {name:20s} shape error {err} (exact {np.linalg.norm(exact):.3f}) | f from "
                  f"{cal.focal_source} {cal.camera.K[0, 0] / true.K[0, 0] - 1:+.2%}, stated "
                  f"{cal.perturbed[-1].K[0, 0] / cal.camera.K[0, 0] - 1:.2%}", flush=True)


def diagnose(args):
    """Where an automatic camera's v0 error comes from: the same shots through
    cameras built from the true and the found corners, k1 and focal length."""
    from cuespin.pipeline.calibrate import assign_corners, calibrate_frame, detect_corners, synthetic_table_frame

    P = sample_shot(0)[1]
    true = Scene(physics=P, camera=pinhole_camera(height_m=args.height, tilt_deg=args.tilt, k1=args.k1,
                                                  size=SIZE, fps=FPS, roll_deg=ROLL_DEG)).camera
    img = synthetic_table_frame(true, seed=int(10 * args.tilt + 100 * abs(args.k1)), cushion_m=0.05, pockets=True)
    det = detect_corners(img)
    cal = assign_corners(det.corners, SIZE, Table(), kappa=det.kappa, fps=FPS)
    tc = true.project(table_corners(Table()))
    f_true = float(true.K[0, 0])
    k_true = args.k1 / f_true**2
    print(f"{args.height} m, tilt {args.tilt}, k1 {args.k1}: corner error (px) {np.round(cal.corners_px - tc, 3).tolist()}; "
          f"k1 found {det.kappa * f_true**2:+.4f} at the true f {f_true:.1f} px; f written {cal.camera.K[0, 0]:.1f} px "
          f"({cal.focal_source})")
    balls = calibrate_frame(img, Table(), fps=FPS)
    print(f"with the balls' shapes: f {balls.camera.K[0, 0]:.1f} px ({balls.focal_source}, "
          f"{balls.camera.K[0, 0] / f_true - 1:+.2%} off)")
    variants = {
        "found (calibrate, balls' f)": balls.camera,
        "found, f nominal (no balls)": cal.camera,
        "true corners and k1, f as found": calibrate_corners(tc, SIZE, kappa=k_true, fps=FPS).camera,
        "corners and k1 found, true f": calibrate_corners(cal.corners_px, SIZE, kappa=det.kappa, focal_px=f_true,
                                                          fps=FPS).camera,
        "true corners, k1 found, true f": calibrate_corners(tc, SIZE, kappa=det.kappa, focal_px=f_true, fps=FPS).camera,
        "corners found, true k1 and f": calibrate_corners(cal.corners_px, SIZE, kappa=k_true, focal_px=f_true,
                                                          fps=FPS).camera,
    }
    res = {"exact": []} | {k: [] for k in variants}
    for i in range(args.n):
        shot, params = sample_shot(args.seed * 1000 + i, "random")
        uv = track_pixels(shot, params, Scene(physics=params, camera=true).camera, np.random.default_rng(i),
                          args.track_px)
        row = {"exact": through(shot, params, true, *uv)} | {k: through(shot, params, c, *uv)
                                                             for k, c in variants.items()}
        if all(r is not None for r in row.values()):     # paired: shots every camera answers
            for k, r in row.items():
                res[k].append(r[0])
    ex = np.array(res["exact"])
    print(f"{len(ex)} of {args.n} shots answered through every camera")
    for k, v in res.items():
        d = np.array(v)
        print(f"{k:36s} v0 RMS {np.sqrt(np.mean(d**2)):.2e} m/s, ratio {np.sqrt(np.mean(d**2) / np.mean(ex**2)):.2f}, "
              f"RMS difference from the exact camera's {np.sqrt(np.mean((d - ex)**2)):.2e}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=40)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--track-px", type=float, default=0.03)
    ap.add_argument("--tilt", type=float, default=10.0)
    ap.add_argument("--height", type=float, default=2.0)
    ap.add_argument("--auto", action="store_true", help="automatic calibration on drawn frames instead")
    ap.add_argument("--cushion", type=float, default=0.05,
                    help="--auto: cushions this wide (m) in a darker felt, and pockets (0: bare felt)")
    ap.add_argument("--true-focal", action="store_true",
                    help="--auto: give the true focal length (as --focal-px would)")
    ap.add_argument("--overhead", action="store_true", help="--auto: the overhead cameras only")
    ap.add_argument("--no-balls", action="store_true",
                    help="--auto: without the focal length from the balls' shapes (the nominal one overhead)")
    ap.add_argument("--corner-sigma", type=float, default=None, metavar="PX",
                    help="--auto: the corners' stated error (default: calibrate's, the edges' jackknife)")
    ap.add_argument("--frame-seed", type=int, default=0,
                    help="--auto: another draw of each frame's noise (--stated's seeds), the same shots")
    ap.add_argument("--frames", action="store_true",
                    help="--auto: one calibration per shot, each from another noise draw of the frame "
                         "(coverage over many frames' corner errors, not one's)")
    ap.add_argument("--cameras", default=None, metavar="H,T,K1;...",
                    help="--auto: these cameras (height m, tilt deg, k1) instead of the table's")
    ap.add_argument("--no-kappa-camera", action="store_true",
                    help="--auto: without the perturbed camera for k1's error (with the jackknife's joint "
                         "moves, each of which moves k1: without all of them)")
    ap.add_argument("--propagate", action="store_true",
                    help="add the calibration's error (8 perturbed cameras) to the stated errors")
    ap.add_argument("--k1", type=float, default=-0.25, help="--diagnose: the lens's k1")
    ap.add_argument("--diagnose", action="store_true",
                    help="where the automatic camera's v0 error comes from (--height, --tilt, --k1)")
    ap.add_argument("--codec", choices=("jpeg", "h264"), default=None,
                    help="--tables: each frame through this codec (--quality, --crf)")
    ap.add_argument("--quality", type=int, default=70, help="--tables --codec jpeg: JPEG quality")
    ap.add_argument("--crf", type=int, default=20, help="--tables --codec h264: libx264's CRF")
    ap.add_argument("--noise", type=float, default=None,
                    help="--tables: redraw each table at this frame noise (levels) instead of its drawn one")
    ap.add_argument("--tables", action="store_true",
                    help="the automatic corners' errors against their stated ones on random drawn tables")
    ap.add_argument("--stated", action="store_true",
                    help="the automatic corners' stated error against their real one, per frame")
    ap.add_argument("--seeds", type=int, default=3, help="--stated: noise seeds per drawn camera")
    ap.add_argument("--pattern-px", type=float, default=None,
                    help="--stated: the edge locator's fixed-pattern error (px) instead of EDGE_PATTERN_PX "
                         "(0: the jackknife alone, before auto13)")
    ap.add_argument("--no-robust", action="store_true",
                    help="--stated: keep the edge points STRAY_EDGE_Z or more from their line (as before)")
    ap.add_argument("--shaded", action="store_true",
                    help="the balls' focal length on the renderer's shaded ball, light and blur one at a time")
    ap.add_argument("--focal", action="store_true",
                    help="the focal length written at small tilts and its error against its stated one")
    ap.add_argument("--clicked", action="store_true",
                    help="corners clicked --corner-px off, calibrated as calibrate --corners does: real and "
                         "stated v0, w0 errors per camera (--cameras, --modes)")
    ap.add_argument("--corner-px", type=float, default=1.0, help="--clicked: the clicks' error (px per coordinate)")
    ap.add_argument("--joint", action="store_true",
                    help="--clicked: also each draw corrected by what the track says about the camera "
                         "(recover.calibration.track_posterior), on its own line (mode MODE-joint)")
    ap.add_argument("--also-free", action="store_true",
                    help="--clicked: also each draw with the refits re-deciding (the fit's AR(1) model, ...), "
                         "as this benchmark did before clicked13, on its own line (mode MODE-free)")
    ap.add_argument("--modes", default="corners,intrinsics",
                    help="--clicked: corners (the focal length by the rule) and/or intrinsics (the lens known)")
    ap.add_argument("--tilts", default="2,2.5,3", help="--focal: tilts (deg)")
    ap.add_argument("--rendered", action="store_true", help="--focal: on the renderer's realistic table")
    ap.add_argument("--ball-at", default="2.40,1.15", metavar="X,Y", help="--shaded: the ball's table position (m)")
    ap.add_argument("--ball-floor", type=float, default=None, help="--shaded: BALL_SHAPE_FLOOR instead of calibrate's")
    args = ap.parse_args()
    if args.clicked:
        return clicked(args)
    if args.shaded:
        return shaded(args)
    if args.focal:
        return focal(args)
    if args.tables:
        return tables(args)
    if args.stated:
        return stated(args)
    if args.auto:
        return auto(args)
    if args.diagnose:
        return diagnose(args)
    true = pinhole_camera(height_m=args.height, tilt_deg=args.tilt, size=SIZE, fps=FPS)
    exact = true.project(table_corners(Table()))
    print(f"camera: {args.height} m, tilt {args.tilt} deg, f {true.K[0, 0]:.0f} px, {SIZE[0]}x{SIZE[1]}; "
          f"tracker error {args.track_px} px; {args.n} shots")
    print("corner_px  focal       n | v0: rms(m/s) real/stated (rms, robust) cover95 | "
          "R w0: rms(m/s) real/stated (rms, robust) cover95")
    sigmas = (0.5, 1.0) if args.propagate else (0.0, 0.1, 0.5, 1.0, 2.0)
    for sigma in sigmas:
        for mode in ("intrinsics", "corners"):
            rng = np.random.default_rng(args.seed)
            rows = []
            for i in range(args.n):
                shot, params = sample_shot(args.seed * 1000 + i, "random")
                c = exact + rng.normal(0.0, sigma, exact.shape)
                r = one(shot, params, true, c, mode, rng, args.track_px, sigma, args.propagate)
                if r is not None:
                    rows.append(r)
            if not rows:
                print(f"{sigma:9.1f}  {mode:10s}  0")
                continue
            dv, dw, sv, sw = (np.array([r[k] for r in rows]) for k in range(4))
            zv, zw = dv / sv, dw / sw
            # robust: 1.4826 x median |z| (one odd shot does not set it)
            print(f"{sigma:9.1f}  {mode:10s} {len(rows):3d} | {np.sqrt(np.mean(dv**2)):.2e} "
                  f"{np.sqrt(np.mean(zv**2)):6.2f} {1.4826 * np.median(np.abs(zv)):6.2f} "
                  f"{np.mean(np.abs(zv) < 1.96):6.1%} | {np.sqrt(np.mean(dw**2)):.2e} "
                  f"{np.sqrt(np.mean(zw**2)):6.2f} {1.4826 * np.median(np.abs(zw)):6.2f} "
                  f"{np.mean(np.abs(zw) < 1.96):6.1%}")


if __name__ == "__main__":
    main()
