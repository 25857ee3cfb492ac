"""Recovery accuracy over generated shots: the paper's method beside the MLE.

For N generated shots (default 200; the sampler's mix of presets), render,
track and recover, then print per method: the median and 95th-percentile
errors of v0 (relative) and of R w0 (relative to |v0|) over shots answered
``ok``, the share answered ``ok`` (and the other statuses); for the MLE, the
RMS of its errors in units of the Cramer-Rao bound computed from the same
model's Jacobian at the truth with the per-frame errors the fit weights by
(recover.measurements: the measurements the fit used, the codec's own
error measured from the residuals included), the coverage of its reported
95% intervals (all shots, and below and above noise 0.5) and its chi2/dof;
for the paper's method, the coverage of its stated errors.  Speed: fit plus both recoveries as
a fraction of decoding the same video (target <= 0.1).  Videos are capped at
6 s; shots run in worker processes.

``--look realistic`` renders the sampler's realistic look (colour,
shading, highlights, markings turning with the spin, rails, resting balls,
a cue; the tracker's look factor, track.misfit, then scales its stated
errors); ``--preset case4`` makes every shot roll from the strike and adds
the share of them answered with free slip (issue 10: at most 2%).

``--camera tilted`` draws every shot through the sampler's real camera
(1.5-3 m up, tilted 0-15 degrees, barrel distortion k1 down to -0.25);
``--disc`` then tracks with one disc at the image centre's scale (the
tracker before the ball's local outline, for comparison).

Usage: python benchmarks/accuracy.py [--n 200] [--seed 0] [--workers 2] [--csv out.csv] [--codec FFV1 or H264]
                                     [--tracks DIR]   (keep tracks; a rerun refits them in seconds)
                                     [--camera tilted] [--disc] [--look realistic] [--preset case4]
       python benchmarks/accuracy.py --summarize out.csv
"""

import argparse
import csv
import functools
import inspect
import tempfile
from multiprocessing import Pool
from pathlib import Path
from types import SimpleNamespace


import numpy as np

MAX_SECONDS = 6.0
# The answer's components whose 95% intervals are counted (each its own
# marginal interval, estimate +/- 1.96 of the JSON's stated error).
COMPONENTS = ("v0x", "v0y", "w0x", "w0y")


@functools.lru_cache(maxsize=1)
def code_version() -> str:
    """A hash of the sources that make a track (track/ and render/): a cached
    track made by other code is stale for tracking questions (it still serves
    fit/ and recover/ ones) and is counted as such in the summary."""
    import hashlib

    import cuespin.render
    import cuespin.track

    h = hashlib.sha1()
    for pkg in (cuespin.render, cuespin.track):
        for f in sorted(Path(pkg.__file__).parent.glob("*.py")):
            h.update(f.name.encode() + f.read_bytes())
    return h.hexdigest()[:12]


def one_shot(args):
    """One shot's row (:func:`_one_shot`; None: not kept, with --only-cached),
    or, where rendering, tracking or recovering it raises, a row saying so:
    both methods' status ``error`` and the exception's text and place in
    ``error`` (every other row's is empty).  A worker's exception killed
    the pool and a long run with it (seed 48 shot 5, realistic case4 MJPG:
    the tracker's ``negative dimensions not allowed``); a row keeps the run
    going and the shot counted."""
    try:
        row = _one_shot(args)
    except Exception as e:  # any: the run goes on, the row says what it was
        import traceback

        where = traceback.extract_tb(e.__traceback__)[-1]
        i, codec, camera, preset = args[0], args[3], args[7], args[10]
        return {"i": i, "preset": preset, "codec": codec, "camera": camera, "paper_status": "error",
                "mle_status": "error", "mle_model": "",
                "error": f"{type(e).__name__}: {e} ({Path(where.filename).name}:{where.lineno})"}
    if row is not None:
        row["error"] = ""
    return row


def _one_shot(args):
    i, seed, tmp, codec, tracks, only_cached, noise_max, camera, disc, look, preset = args[:11]
    max_seconds = args[11] if len(args) > 11 else MAX_SECONDS
    try:
        from cuespin.data_gen.sampler import scene_at
    except ImportError:  # an older data_gen/, for before/after tables
        from cuespin.data_gen.sampler import sample_scenes

        def scene_at(i, seed, preset=None, **kwargs):
            return sample_scenes(i + 1, seed, preset=preset, **kwargs)[i]
    from cuespin.physics import phases
    from cuespin.pipeline.measure import answer_bound, rms_z
    from cuespin.recover.api import recover_track
    from cuespin.recover.measurements import table_covariance
    try:
        from cuespin.recover.measurements import pixel_to_table
    except ImportError:  # an older recover/
        def pixel_to_table(cam, xy):
            return None
    from cuespin.render import render_settings, render_video
    from cuespin.render.video import video_suffix
    from cuespin.track.misfit import error_ar1
    from cuespin.track.tracker import TrackerConfig
    from cuespin.track.video import decode_seconds, track_video

    if disc:
        from cuespin.track import video as video_module
        from cuespin.track.tracker import BallTracker

        class DiscTracker(BallTracker):  # no camera: the disc everywhere
            def __init__(self, *a, **kw):
                kw.pop("camera", None)
                super().__init__(*a, **kw)

        video_module.BallTracker = DiscTracker
    scene = scene_at(i, seed, preset=preset, camera=camera, look=look)
    scene.render["max_duration"] = max_seconds
    if codec:
        scene.render["codec"] = codec
    if noise_max is not None:  # the same shots at low noise: uniform in [0, noise_max), seeded by shot
        scene.render["noise_sigma"] = float(np.random.default_rng([seed, i]).uniform(0.0, noise_max))
    cam = scene.camera
    # A track cache (--tracks DIR): the render, decode and track of a shot are
    # kept, so a change to fit/ or recover/ is re-measured in seconds.
    tag = ("" if noise_max is None else f"_lt{noise_max:g}") + ("" if camera == "topdown" else f"_{camera}") \
        + ("_disc" if disc else "") + ("" if look == "plain" else f"_{look}") + (f"_{preset}" if preset else "") \
        + ("" if max_seconds == MAX_SECONDS else f"_{max_seconds:g}s")
    cached = Path(tracks) / f"s{seed}_{codec or 'scene'}{tag}_{i}.npz" if tracks else None
    if only_cached and not (cached is not None and cached.exists()):
        return None
    if cached is not None and cached.exists():
        z = np.load(cached)
        # Tracks kept before TrackResult.look_shaded: a realistic look was
        # tracked shaded (every realistic track kept since states it).
        shaded = bool(z["shaded"]) if "shaded" in z else look == "realistic"
        independent = bool(z["independent"]) if "independent" in z else bool(z["lossless"])
        tr = SimpleNamespace(t=z["t"], xy=z["xy"], ok=z["ok"], cov_px=z["cov_px"], lossless=bool(z["lossless"]),
                             inter_frame=bool(z["inter_frame"]),
                             independent_errors=independent and not shaded,
                             look_shaded=shaded,
                             look_factor=float(z["look_factor"]) if "look_factor" in z else 1.0,
                             look_rho=float(z["look_rho"]) if "look_rho" in z else 0.0)
        tr.foreign = z["foreign"] if "foreign" in z else None  # kept before the tracker told the cue's flags apart
        if "touched" in z:
            tr.touched = z["touched"]
        else:  # kept before the tracker flagged frames: those leaving the rest, from the centres
            from cuespin.track.video import leaving_rest
            uv = np.full_like(tr.xy, np.nan)
            good = tr.ok & np.all(np.isfinite(tr.xy), axis=1)
            uv[good] = cam.to_pixels(tr.xy[good])
            # the ball's radius at the image centre's scale, as track_video takes it
            centre = cam.to_table([[cam.width / 2, cam.height / 2]])[0]
            tr.touched = leaving_rest(uv, good, scene.physics.R * cam.px_per_m(centre))
        n, t_decode = int(z["frames"]), float(z["t_decode"])
        stale = str(z["code"]) != code_version() if "code" in z else True
    else:
        # .mp4 for H264 (PyAV's libx264 at the scene's render.crf), else .avi
        video = Path(tmp) / f"shot_{i}{video_suffix(str(render_settings(scene)['codec']))}"
        render_video(scene, video)
        t_decode, n = decode_seconds(video)
        tr = track_video(video, scene, TrackerConfig())
        video.unlink()
        stale = False
        if cached is not None:
            np.savez(cached, t=tr.t, xy=tr.xy, ok=tr.ok, cov_px=tr.cov_px, lossless=tr.lossless,
                     inter_frame=tr.inter_frame, frames=n, t_decode=t_decode, code=code_version(),
                     independent=getattr(tr, "independent_errors", tr.lossless),
                     shaded=getattr(tr, "look_shaded", False),
                     look_factor=getattr(tr, "look_factor", 1.0), look_rho=getattr(tr, "look_rho", 0.0),
                     touched=getattr(tr, "touched", None) if getattr(tr, "touched", None) is not None
                     else np.zeros(len(tr.t), bool),
                     foreign=getattr(tr, "foreign", None) if getattr(tr, "foreign", None) is not None
                     else np.zeros(len(tr.t), bool))
    # The analysis ends at the first contact, cut as the user's path cuts it
    # (pipeline.run.contact_cut): the benchmark measures what the user gets.
    from cuespin.pipeline.run import contact_cut

    contact, n_fit = contact_cut(tr, scene, cam)
    for key in ("t", "xy", "ok", "cov_px", "stderr_px", "uv", "touched", "foreign"):
        if getattr(tr, key, None) is not None:
            setattr(tr, key, np.asarray(getattr(tr, key))[:n_fit])
    # As pipeline.run.run_recover does, keeping the fit's own measurements
    # for the bound.
    kw = {"px_to_m": pixel_to_table(cam, tr.xy)}
    if "ar1_floor" in inspect.signature(recover_track).parameters:
        kw["ar1_floor"] = error_ar1(getattr(tr, "look_factor", 1.0), getattr(tr, "look_rho", 0.0))
    if "touched" in inspect.signature(recover_track).parameters:
        kw["touched"] = getattr(tr, "touched", None)
    if "foreign" in inspect.signature(recover_track).parameters:
        kw["foreign"] = getattr(tr, "foreign", None)
    if "look_factor" in inspect.signature(recover_track).parameters:
        kw["look_factor"] = float(getattr(tr, "look_factor", 1.0))
    if "shaded" in inspect.signature(recover_track).parameters:
        kw["shaded"] = bool(getattr(tr, "look_shaded", False))
    lossless = getattr(tr, "independent_errors", tr.lossless)
    if "independent" in inspect.signature(recover_track).parameters:  # the codec apart from the errors' sharing
        kw["independent"], lossless = lossless, bool(tr.lossless)
    if "px_to_m" not in inspect.signature(recover_track).parameters:  # an older recover/, for before/after tables
        kw = {}
    out, est = recover_track(tr.t, tr.xy, tr.ok, table_covariance(cam, tr.xy, tr.cov_px), scene.physics,
                             cam.exposure_s, "all", False, lossless=lossless,
                             return_estimate=True,
                             inter_frame=tr.inter_frame, **kw)
    truth, p = scene.truth, scene.physics
    v0, w0 = np.array(truth.v0), np.array(truth.w0)
    speed = np.hypot(*v0)
    row = {"i": i, "stale": stale, "preset": scene.render.get("preset"),
           "look_factor": float(getattr(tr, "look_factor", 1.0)),
           "fps": cam.fps, "codec": scene.render.get("codec"),
           "camera": camera, "height_m": float(cam.centre[2]) if cam.is_pinhole else np.nan,
           "noise": scene.render.get("noise_sigma"), "frames": n, "t_decode": t_decode,
           "frames_fitted": n_fit, "contact": "" if contact is None else contact.kind,
           "t_fit": out["timing_s"]["fit"], "t_recover": out["timing_s"]["recover"],
           "t1_true": phases(truth, p).t1 - truth.t0}
    truth_vw = np.r_[v0, w0]
    for m, d in out["methods"].items():
        row[f"{m}_status"] = d["status"]
        row[f"{m}_ev"] = np.hypot(*(np.array(d["v0"]) - v0)) / speed if d["v0"] else np.nan
        row[f"{m}_ew"] = p.R * np.hypot(*(np.array(d["w0"]) - w0)) / speed if d["w0"] else np.nan
        row[f"{m}_z"] = row[f"{m}_cover"] = np.nan
        row.update({f"{m}_z_{name}": np.nan for name in COMPONENTS})
        se = d.get("stderr") or {}
        if d["status"] == "ok" and se.get("v0") and se.get("w0"):
            err = np.r_[d["v0"], d["w0"]] - truth_vw
            z = err / np.r_[se["v0"], se["w0"]]
            row[f"{m}_z"] = float(np.sqrt(np.mean(z**2)))
            row[f"{m}_cover"] = float(np.mean(np.abs(z) < 1.96))
            for k, name in enumerate(COMPONENTS):  # per component, for intervals over shots (summarize)
                row[f"{m}_z_{name}"] = float(z[k])
        elif d["status"] == "ok":
            # An ok without stated errors states none: a miss in every
            # component (z infinite), counted, never left out (held37: two
            # paper answers so, 29% and 12% off, left out of its coverage).
            row[f"{m}_z"], row[f"{m}_cover"] = np.inf, 0.0
            row.update({f"{m}_z_{name}": np.inf for name in COMPONENTS})
    mle = out["methods"]["mle"]
    row["mle_model"] = mle.get("model") or ""
    row["mle_v0_z"] = np.nan  # |v0 error| in its stated errors (the worse axis)
    if mle["status"] == "ok" and (mle.get("stderr") or {}).get("v0"):
        row["mle_v0_z"] = float(np.max(np.abs((np.array(mle["v0"]) - v0) / np.array(mle["stderr"]["v0"]))))
    row["mle_crb_z"] = row["mle_crb_z_indep"] = row["mle_crb_z_truth"] = row["mle_bias_z"] = np.nan
    row["mle_bias_v0"] = row["t_unseen"] = row["t_allowance"] = np.nan
    row["mle_bound_fail"] = ""
    row.update({f"mle_crb{i}_{name}": np.nan for name in COMPONENTS for i in ("", "i")})
    row["chi2_per_dof"] = row["codec_noise_px"] = row["hac"] = row["rho1"] = row["ar1"] = np.nan
    if mle["status"] == "ok":
        err = np.r_[mle["v0"], mle["w0"]] - truth_vw
        row["chi2_per_dof"] = mle.get("chi2_per_dof")
        row["hac"], row["rho1"] = float(bool(mle.get("hac"))), mle.get("rho1")
        row["ar1"] = mle.get("ar1", np.nan)
        row["codec_noise_px"] = mle.get("codec_noise_px", np.nan)
        # The bound of the model the answer was given with, at that model's
        # parameters nearest the truth (pipeline.measure.answer_bound): a
        # rolling answer against the rolling model's bound, what assuming
        # no slip costs on a truth that slid unseen (its bias) stated
        # apart; a shot without a bound says why and is counted apart
        # (held37: 38/8's NaN and 38/36's 4e-5 came from the free slip's
        # bound, singular there, and were averaged silently).
        from cuespin.recover.mle import INTER_CODEC_ACF, first_measured_after
        ar1 = float(getattr(est.mle, "ar1", 0.0) or 0.0)
        # An inter-frame codec: its frames' errors correlated in time as the
        # fit's covariance takes them (recover.mle.INTER_CODEC_ACF).
        acf = INTER_CODEC_ACF if tr.inter_frame and not tr.lossless and not ar1 else None
        model = "rolling" if mle.get("model") == "rolling" else "full"
        for key, indep in (("mle_crb_z_indep", True), ("mle_crb_z", False)):
            b = answer_bound(scene, est.meas, model, ar1=0.0 if indep else ar1, acf=None if indep else acf,
                             independent=indep)
            if b.cov is None:
                if not indep:
                    row["mle_bound_fail"] = b.reason
                continue
            zc = b.z(err + truth_vw)
            row[key] = rms_z(zc)
            # per component (NaN for w0 on a rolling answer: its bound is v0's), pooled by bound_summary
            # and intervals; mle_crbi_*: every frame independent (the reference)
            for k, name in enumerate(COMPONENTS):
                row[f"mle_crb{'i' if indep else ''}_{name}"] = float(zc[k])
            if not indep:
                bz = b.bias_z()
                row["mle_bias_z"] = rms_z(bz)
                # the whole error (bias with it) in the same bound, for reference
                row["mle_crb_z_truth"] = rms_z(zc + bz)
        if model == "rolling":
            # The unseen slide's size: the truth's sliding time beside the
            # time after the strike with no measured moving frame, and the
            # answer's allowance for it (recover.mle.unseen_slip, as time).
            # (b: the loop's last, the fit's own measurements; its centre and bias stand without a bound)
            row["mle_bias_v0"] = float(np.hypot(*b.bias[:2]) / speed)
            row["t_unseen"] = float(first_measured_after(est.meas, float(truth.t0)) - truth.t0)
            row["t_allowance"] = float((mle.get("unseen_slip") or 0.0) / (p.mu_s * p.g))
    return row


# The components' intra-shot correlation coverage_interval assumes at
# least (the data's when larger, shot_icc): measured 0.11-0.46 (median
# 0.33) on h264cov's realistic H.264 accuracy sets (seeds 31-33, 9-52 ok
# shots each) and 0.14-0.33 on review 13's simulated shots (boot.py).
# With 0.2 those simulated intervals held the truth 94.4-97.5% at 10-40
# shots (two seeds); with 0.46 96.4-98.7% (wider than needed); the shot
# bootstrap before 87.3-99.5% (docs/measurements.md "rev13s").
SHOT_ICC_FLOOR = 0.2


def wilson(k: float, n: float, z: float = 1.959964):
    """Wilson score interval (95%) of a proportion k / n."""
    p, d = k / n, 1.0 + z * z / n
    c, h = (p + z * z / (2 * n)) / d, z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return c - h, c + h


def shot_icc(hit) -> float:
    """The intra-shot correlation of ``hit`` (shots, components) of bool:
    the one-way ANOVA estimator ``(MSB - MSW) / (MSB + (c - 1) MSW)`` over
    shots of ``c`` components each; NaN when every component is alike."""
    y = np.asarray(hit, float)
    m, c = y.shape
    share, p = y.mean(axis=1), y.mean()
    msb = c * float(np.sum((share - p) ** 2)) / max(m - 1, 1)
    msw = float(np.sum((y - share[:, None]) ** 2)) / (m * (c - 1))
    d = msb + (c - 1) * msw
    return (msb - msw) / d if d > 0 else float("nan")


def coverage_interval(hit):
    """95% interval of the share of components covered, ``hit`` (shots,
    components) of bool: Wilson's interval over the components counted as
    ``shots * components / deff`` independent trials, the design effect
    ``deff = 1 + (components - 1) icc`` of the components' correlation
    within a shot (a shot's v0 and w0 errors are strongly correlated, so
    its components are not independent trials: Wilson over all
    components was too narrow, docs/measurements.md "stats12b").  ``icc``
    is the data's (:func:`shot_icc`) and at least :data:`SHOT_ICC_FLOOR`:
    one estimated from a few misses is noisy, and every component covered
    gives none; the floor keeps the interval with a miss from being
    narrower than with none (the shot bootstrap's was)."""
    hit = np.asarray(hit, bool)
    m, c = hit.shape
    icc = shot_icc(hit) if m > 1 and c > 1 else float("nan")
    icc = SHOT_ICC_FLOOR if not np.isfinite(icc) else min(max(icc, SHOT_ICC_FLOOR), 1.0)
    n_eff = m * c / (1.0 + (c - 1) * icc)
    return wilson(float(hit.mean()) * n_eff, n_eff)


def intervals(rows, n_boot: int = 4000, seed: int = 0, m: str = "mle"):
    """The MLE's (``m``; the paper's method: ``paper``, without the bound)
    coverage, RMS error in stated errors and RMS error / bound
    per noise band, with 95% intervals: coverage counts each component of
    v0 and w0 (each its own interval, estimate +/- 1.96 stated errors):
    Wilson's with the shots' design effect (:func:`coverage_interval`);
    the RMS intervals resample shots (a cluster bootstrap, percentile
    interval, ``n_boot`` draws): a shot's components are not independent
    trials."""
    from cuespin.pipeline.measure import rms_z

    rng = np.random.default_rng(seed)
    print(f"\n{'MLE' if m == 'mle' else m} with 95% intervals (components of v0, w0; coverage: Wilson with "
          "the shots' design effect; RMS: bootstrap over shots)")
    # Free slip apart: a rolling answer's errors hold the bound of a slip too
    # short to see (recover.mle.unseen_slip), not a standard error, so its
    # components sit near 0 stated errors and pull the RMS of "all" down.
    # The paper's method has no free slip / rolling choice: that band is the MLE's.
    bands = (("all", lambda r: True), ("noise < 0.5", lambda r: r["noise"] < 0.5),
             ("noise >= 0.5", lambda r: r["noise"] >= 0.5))
    if m == "mle":
        bands += (("free slip answers", lambda r: r.get("mle_model") == "full"),
                  ("rolling answers", lambda r: r.get("mle_model") == "rolling"))
    for band, sel in bands:
        ok = [r for r in rows if r[f"{m}_status"] == "ok" and sel(r) and f"{m}_z_{COMPONENTS[0]}" in r
              and not np.isnan(float(r[f"{m}_z_{COMPONENTS[0]}"]))]
        if len(ok) < 2:
            continue
        Z = np.array([[r[f"{m}_z_{c}"] for c in COMPONENTS] for r in ok], float)
        # ok answers without stated errors (z infinite): misses in the
        # coverage, out of the RMS (which they have none of), and said.
        bare = int(np.sum(~np.all(np.isfinite(Z), axis=1)))
        K = np.array([[r.get(f"mle_crb_{c}", np.nan) if m == "mle" else np.nan for c in COMPONENTS] for r in ok],
                     float)
        hit = np.abs(Z) < 1.959964
        k, n = int(hit.sum()), Z.size
        idx = rng.integers(0, len(ok), (n_boot, len(ok)))
        # over the components a draw holds (none: NaN, out of the percentiles)
        boot = {name: np.nanpercentile([rms_z(A[i]) for i in idx], [2.5, 97.5]) for name, A in (("rms", Z), ("crb", K))
                if name != "crb" or m == "mle"}
        lo, hi = coverage_interval(hit)
        print(f"  {band}: {len(ok)} ok" + (f" ({bare} without stated errors: missed)" if bare else "")
              + f"; coverage {k}/{n} = {k / n:.1%} (95% {lo:.1%}-{hi:.1%}, "
              f"design effect of the shots); RMS / stated error "
              f"{rms_z(Z):.2f} ({boot['rms'][0]:.2f}-{boot['rms'][1]:.2f})"
              + (f"; RMS / bound {rms_z(K):.2f} ({boot['crb'][0]:.2f}-{boot['crb'][1]:.2f}); "
                 f"chi2/dof median {np.nanmedian([r['chi2_per_dof'] for r in ok]):.2f}" if m == "mle" else ""))


def bound_fail(r) -> str:
    """Why a row has no bound ("" when it has one; a CSV's empty cell reads NaN)."""
    v = r.get("mle_bound_fail", "")
    return "" if v is None or (isinstance(v, float) and np.isnan(v)) else str(v)


def bound_summary(ok):
    """RMS error / Cramer-Rao bound of the MLE's ok answers, each against
    the bound of the model it answered with (pipeline.measure.answer_bound):
    all, free slip and rolling answers apart; a rolling answer's error about
    the rolling model's parameters nearest the truth, the bias of assuming
    no slip (the truth sliding unseen) stated apart; the shots without a
    bound listed with why, never averaged in.  Pooled over the answers'
    components (pipeline.measure.rms_z, as :func:`intervals`); per shot,
    each answer's own RMS."""
    from cuespin.pipeline.measure import rms_z

    for key, comp, what in (("mle_crb_z", "mle_crb_", "the fit's own measurements (recover.measurements; on "
                                                    "inter-frame video correlated in time as the fit's covariance "
                                                    "takes them)"),
                            ("mle_crb_z_indep", "mle_crbi_", "tracker's errors, every frame independent (reference)")):
        for band, sel in (("all", lambda r: True), ("free slip answers", lambda r: r.get("mle_model") == "full"),
                          ("rolling answers", lambda r: r.get("mle_model") == "rolling")):
            rows = [r for r in ok if sel(r) and np.isfinite(r[key])]
            crb_z = np.array([r[key] for r in rows])
            if len(crb_z):
                pooled = rms_z([[r.get(comp + c, np.nan) for c in COMPONENTS] for r in rows])
                print(f"{'' if band == 'all' else '  '}MLE: RMS error / Cramer-Rao bound of the answer's model, "
                      f"{band}, with {what} (v0, w0 components; rolling: v0; {len(crb_z)} shots): "
                      f"{pooled:.2f}; per shot median {np.median(crb_z):.2f}, "
                      f"p90 {np.percentile(crb_z, 90):.2f} (target <= 1.1)")
            if band == "all" and key == "mle_crb_z":
                print("  (a rolling answer's error about the rolling parameters nearest the truth: its model's "
                      "bias on a truth that slid unseen apart, below)")
    roll = [r for r in ok if r.get("mle_model") == "rolling" and np.isfinite(r.get("mle_bias_v0", np.nan))]
    slid = [r for r in roll if r["t1_true"] > 0]
    if roll:
        print(f"  rolling answers: {len(roll) - len(slid)} on a truth rolling from the strike (no bias), "
              f"{len(slid)} on a truth that slid")
    if slid:
        roll = slid
        print(f"  rolling answers' bias of assuming no slip ({len(roll)}; per shot: |bias of v0| / |v0|, "
              "bias in the rolling bound, the truth's sliding time, the answer's unseen-slide allowance "
              "(recover.mle.unseen_slip), the time to the first measured moving frame, error / stated):")
        for r in roll:
            print(f"    shot {int(r['i'])}: {r['mle_bias_v0']:.1%}, {r['mle_bias_z']:.1f} bounds; slide "
                  f"{1e3 * r['t1_true']:.1f} ms, allowance {1e3 * r['t_allowance']:.1f} ms"
                  f"{' (shorter)' if r['t_allowance'] < r['t1_true'] else ''}, first frame "
                  f"{1e3 * r['t_unseen']:.1f} ms; error / stated {r['mle_z']:.2f}, / bound "
                  f"{r['mle_crb_z']:.2f} (about the truth {r['mle_crb_z_truth']:.1f})")
    failed = [r for r in ok if bound_fail(r)]
    if failed:
        print(f"  no bound on {len(failed)} ok answers (left out of the RMS / bound above):")
        for r in failed:
            print(f"    shot {int(r['i'])} ({r.get('mle_model')}): {bound_fail(r)}")


def pct(x, q):
    x = np.asarray([v for v in x if np.isfinite(v)])
    return float(np.percentile(x, q)) if len(x) else float("nan")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--csv", default=None, help="write every shot's row here")
    ap.add_argument("--codec", default=None, help="render every shot with this FourCC or H264 (libx264 at "
                    "the scene's render.crf, default 20; default: the scene's codec, MJPG)")
    ap.add_argument("--tracks", default=None, help="keep each shot's track in this folder and reuse it on a "
                    "rerun (same seed and codec): a change to fit/ or recover/ is re-measured without rendering")
    ap.add_argument("--only-cached", action="store_true", help="with --tracks: refit only the shots "
                    "whose track is kept (no rendering)")
    ap.add_argument("--noise-max", type=float, default=None, help="render each shot at a noise drawn "
                    "uniformly below this (grey levels; e.g. 0.5 for the low-noise band)")
    ap.add_argument("--camera", choices=("topdown", "tilted"), default="topdown",
                    help="the sampler's camera (tilted: 1.5-3 m, 0-15 deg, k1 -0.25 to 0)")
    ap.add_argument("--disc", action="store_true",
                    help="track with the image centre's disc, not the ball's local outline (comparison)")
    ap.add_argument("--look", choices=("plain", "realistic"), default="plain",
                    help="the sampler's look (realistic: colour, shading, highlights, markings, rails, a cue)")
    ap.add_argument("--preset", default=None, help="the sampler's preset for every shot (e.g. case4: rolling "
                    "from the strike); default its mix")
    ap.add_argument("--max-seconds", type=float, default=MAX_SECONDS, help="cap each video at this "
                    "length (s; short clips: the strike and the first rolling, for a rate over many shots)")
    ap.add_argument("--summarize", default=None, help="only print the tables of a CSV written before "
                    "(a run cut short keeps its finished rows); several, comma-separated, are pooled")
    args = ap.parse_args()
    if args.summarize:
        import pandas as pd
        # Several CSVs (comma-separated: seeds of one band) pooled; shot
        # numbers made unique per file for the tables' order.
        rows = []
        for k, path in enumerate(args.summarize.split(",")):
            rows += [dict(r, i=r["i"] + 100000 * k) for r in pd.read_csv(path).to_dict("records")]
        summarize(rows, args.seed)
        refuse_if_none_answered(rows)
        return
    from tqdm import tqdm
    rows = []
    out = None
    waiting = []  # rows of shots that raised (fewer columns), until a whole row names the columns
    if args.tracks:
        Path(args.tracks).mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp, Pool(args.workers) as pool:
        # Rows are written as shots finish, so a run cut short keeps them.
        jobs = [(i, args.seed, tmp, args.codec, args.tracks, args.only_cached, args.noise_max,
                 args.camera, args.disc, args.look, args.preset, args.max_seconds) for i in range(args.n)]
        for row in tqdm(pool.imap_unordered(one_shot, jobs),
                        total=args.n, desc="shots", disable=None):
            if row is None:
                continue
            rows.append(row)
            if args.csv:
                waiting.append(row)
                if out is None and not row["error"]:
                    out = open(args.csv, "w", newline="")
                    w = csv.DictWriter(out, fieldnames=sorted(row), restval="nan")
                    w.writeheader()
                if out is not None:
                    w.writerows(waiting)
                    waiting = []
                    out.flush()
    if waiting:  # every shot raised: their own columns
        out = open(args.csv, "w", newline="")
        w = csv.DictWriter(out, fieldnames=sorted(waiting[0]))
        w.writeheader()
        w.writerows(waiting)
    if out is not None:
        out.close()
    summarize(rows, args.seed)
    refuse_if_none_answered(rows)


def raised(row) -> bool:
    """Did the shot's render, track or recovery raise (one_shot's ``error``
    row; a CSV read back holds "nan" for the others' empty text)?"""
    return str(row.get("error", "") or "") not in ("", "nan")


def refuse_if_none_answered(rows) -> None:
    """Exit non-zero, saying why, when no shot gave an answer (every one
    raised, or none ran): the tables then measure nothing, and a run that
    exits 0 reads as a measurement (crash48 kept a raised shot as a row, so
    a run whose every shot raises finished with 0)."""
    if any(not raised(r) for r in rows):
        return
    first = next((f"; the first: shot {r['i']}, {r['error']}" for r in sorted(rows, key=lambda r: r["i"])), "")
    raise SystemExit(f"accuracy.py: no shot gave an answer ({len(rows)} run, all raised{first})")


def summarize(rows, seed=0):
    """Print the tables for finished rows (also: python -c 'from accuracy import ...' on a CSV)."""
    from cuespin.pipeline.measure import rms_z
    rows = sorted(rows, key=lambda r: r["i"])
    n = len(rows)
    print(f"\n{n} shots (seed {seed}); errors over shots answered ok")
    # Shots whose render, track or recovery raised (one_shot): counted as
    # status "error" in the shares below and each named here; the look
    # factors and speeds are the other shots'.
    done = [r for r in rows if not raised(r)]
    for r in rows:
        if raised(r):
            print(f"shot {r['i']} raised: {r['error']}")
    stale = sum(str(r.get("stale", "")) in ("True", "1", "1.0") for r in rows)
    if stale:
        print(f"{stale} of {n} tracks were kept by other tracker/renderer code (track/, render/): "
              "their tracking is not this code's; the fits and recoveries are")
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
    bound_summary(ok)
    chi = np.array([r["chi2_per_dof"] for r in ok if np.isfinite(r["chi2_per_dof"])])
    if len(chi):
        print(f"MLE: chi2/dof of the fits answered ok: median {np.median(chi):.2f} (target 0.9-1.1), "
              f"p10 {np.percentile(chi, 10):.2f}, p90 {np.percentile(chi, 90):.2f}, max {chi.max():.1f}; "
              f"a sandwich (HAC; on H.264 the codec's own) widened the errors on "
              f"{np.nanmean([r['hac'] for r in ok]):.0%}, the AR(1) model on "
              f"{np.mean([bool(r.get('ar1', 0) or 0) and np.isfinite(r.get('ar1', 0)) for r in ok]):.0%}; "
              f"the residuals' lag-1 autocorrelation median {np.nanmedian([r.get('rho1', np.nan) for r in ok]):.2f}")
    for m, target in (("mle", "93-97%"), ("paper", "90-97%")):
        for band, sel in (("all", lambda r: True), ("noise < 0.5", lambda r: r["noise"] < 0.5),
                          ("noise >= 0.5", lambda r: r["noise"] >= 0.5)):
            zs = [r for r in rows if r[f"{m}_status"] == "ok" and not np.isnan(float(r[f"{m}_z"])) and sel(r)]
            if zs:
                fin = [r[f"{m}_z"] for r in zs if np.isfinite(r[f"{m}_z"])]
                bare = len(zs) - len(fin)
                print(f"{m}: {band}: coverage of 95% intervals {np.mean([r[f'{m}_cover'] for r in zs]):.1%} "
                      f"(target {target}; {bare} ok without stated errors counted as missed); RMS error / own "
                      f"stderr {rms_z(fin):.2f} (target 0.9-1.1); "
                      f"{len(zs)} shots")
    intervals(rows)
    intervals(rows, m="paper")
    rolling = [r for r in rows if r.get("preset") == "case4" and r["mle_status"] == "ok"]
    if rolling:
        slip = [r for r in rolling if r.get("mle_model") == "full"]
        far = [r for r in slip if not r["mle_v0_z"] <= 3.0]
        print(f"rolling from the strike (case4, {len(rolling)} answered ok): free slip chosen in {len(slip)} "
              f"({len(slip) / len(rolling):.1%}; target <= 2%), {len(far)} of them with v0 beyond 3 stated errors")
        # Every answer that names a model (degenerate ones too): free slip
        # chosen at all, with the binomial (Clopper-Pearson) 95% interval.
        from scipy.stats import binomtest
        named = [r for r in rows if r.get("preset") == "case4" and str(r.get("mle_model") or "") not in ("", "nan")]
        k = sum(str(r.get("mle_model")) == "full" for r in named)
        if named:
            ci = binomtest(k, len(named)).proportion_ci()
            print(f"  any status naming a model ({len(named)}): free slip {k} ({k / len(named):.1%}, "
                  f"Clopper-Pearson 95% {ci.low:.1%}-{ci.high:.1%})")
    factors = [r["look_factor"] for r in done if np.isfinite(r.get("look_factor", np.nan))]
    if factors and max(factors) > 1:
        print(f"tracker's look factor (track.misfit): median {np.median(factors):.2f}, "
              f"> 1 on {np.mean(np.array(factors) > 1):.0%} of the shots")
    ratio = [(r["t_fit"] + r["t_recover"]) / r["t_decode"] for r in done]
    print(f"speed: (fit + both recoveries) / decode: median {pct(ratio, 50):.3f}, "
          f"p95 {pct(ratio, 95):.3f} (target <= 0.1)")


if __name__ == "__main__":
    main()
