"""Both recoveries from one track, as the JSON object of CONVENTIONS.md.

Pure: arrays and dataclasses in, a plain dict out (numbers that could not be
determined are None, never NaN).  No exception escapes: anything unexpected
becomes a ``failed`` method with its reason.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np

from cuespin.fit.conics import classify_path
from cuespin.fit.segment import noise_from_track, segment_track
from cuespin.physics.motion import BallParams, Shot
from cuespin.physics.parabola import sliding_parabola
from cuespin.recover.mle import fit_mle, initial_guess
from cuespin.recover.paper import CONSISTENCY_SIGMAS, PaperResult, recover_line, recover_parabola

METHODS = ("paper", "mle", "all")
# The segmentation's p-value for "no sliding" below which the MLE's own
# rolling-from-the-strike fit is not worth running: its likelihood ratio
# would be astronomically past the 1% point.
OBVIOUS_SLIDING_P = 1e-12


def _num(x):
    if x is None:
        return None
    if isinstance(x, (list, tuple, np.ndarray)):
        return [_num(v) for v in np.asarray(x, dtype=float).tolist()]
    x = float(x)
    return x if math.isfinite(x) else None


def track_noise(stderr_m, xy):
    """Per-frame position noise (m): the tracker's standard errors, or, when it
    gave none (moments refinement), the spread the track itself shows."""
    se = np.asarray(stderr_m, dtype=float)
    if se.ndim == 2:
        se = np.sqrt(np.mean(se**2, axis=1))
    if np.isfinite(se).sum() >= max(8, 0.5 * len(se)):
        fill = np.nanmedian(se)
        return np.where(np.isfinite(se), se, fill)
    return np.full(len(xy), noise_from_track(xy))


def run_paper(seg, xy, params: BallParams, sigma: float, frame_dt: float) -> PaperResult:
    """The paper's method on a segmented track: parabola or line by the test of
    ``fit.conics``, with the status and reason CONVENTIONS.md asks for.

    ``xy`` are the track's points (m) that ``seg`` indexes."""
    if not seg:
        return PaperResult("failed", f"the track could not be segmented: {seg.reason}")
    if not np.isfinite(seg.t1):
        return PaperResult("degenerate", "sliding had not ended when the track did: x1, and so "
                           "the paper's method, is not determined", x0=seg.x0)
    # x1 is itself estimated (to about a frame's travel), so eq. 37 and the line's
    # forward check are held to that, not to the pixel noise alone.
    tol = CONSISTENCY_SIGMAS * sigma + np.hypot(*seg.v1) * frame_dt
    slide_pts = None
    if seg.t1 > seg.t0 and seg.slide is not None and len(seg.slide) >= 5:
        slide_pts = seg.slide
    start = None
    if slide_pts is not None:
        x0, t0, v0, w0 = initial_guess(seg, params)
        try:
            start = sliding_parabola(x0, v0, w0, params)
        except ValueError:
            start = None
    if slide_pts is not None:
        shape = classify_path(xy[seg.slide], start)
        if shape.curved:
            res = recover_parabola(shape.parabola.parabola, seg.x0, seg.x1, params, tol)
            return res
        why_line = (f"the sliding path is straight within the noise (F-test for curvature: "
                    f"p = {shape.p_value:.2g} >= 0.01)")
    else:
        why_line = "no sliding seen (rolling from the strike)" if seg.t1 <= seg.t0 else \
            "sliding too short to fit a parabola (fewer than 5 frames)"
    if seg.x2 is None:
        return PaperResult("degenerate", f"{why_line}, and no rest point is in view: the paper's "
                           "line method needs x2", "line", x0=seg.x0, x1=seg.x1)
    heading = seg.v0 / np.hypot(*seg.v0) if np.hypot(*seg.v0) > 0 else None
    return recover_line(seg.x0, seg.x1, seg.x2, params, tol, heading)


def rest_weighting(t, sig, seg, frame_dt):
    """Standard errors with each rest group counted as one measurement.

    For a lossy codec the frames of a resting ball are the same image, so
    they share its compression error (measured: a common offset of ~1.6
    times the per-frame error for MJPG): ``n`` rest frames then carry one
    frame's information, not ``n``.  Scales their errors by ``sqrt(n)``.
    """
    sig = np.array(sig, dtype=float)
    if not seg:
        return sig
    groups = [t < seg.t0 - 0.5 * frame_dt]
    if seg.t2 is not None:
        groups.append(t > seg.t2 + 0.5 * frame_dt)
    for g in groups:
        if g.sum() > 1:
            sig[g] *= np.sqrt(g.sum())
    return sig


def strike_exclusion(t, sig, seg, exposure_s, frame_dt):
    """Leave out the frames whose exposure holds the strike.

    Their image is a ball at rest for part of the exposure and streaking for
    the rest, which neither the tracker's disc nor its straight streak
    describes, so their centres are biased, and that bias, at the one place
    where slip and v0 are told apart, can pass for slip (paper case 4 fitted
    with free slip, v0 off by percents).  Errors there are set 1e6 times
    larger.
    """
    sig = np.array(sig, dtype=float)
    if not seg or exposure_s <= 0:
        return sig
    half = 0.5 * exposure_s + 0.25 * frame_dt  # margin for the strike time's own error
    sig[np.abs(t - seg.t0) < half] *= 1e6
    return sig


# A codec's measured share may lower the tracker's stated errors (see
# codec_noise) to no less than this fraction of them.
MIN_NOISE_FRACTION = 0.5


def with_codec_error(sig, codec_m: float):
    """Per-frame errors (m) with the codec's measured share ``codec_m`` (m,
    signed as :func:`codec_noise` returns it) added in quadrature."""
    sig = np.asarray(sig, dtype=float)
    var = sig**2 + np.sign(codec_m) * codec_m**2
    return np.sqrt(np.maximum(var, (MIN_NOISE_FRACTION * sig) ** 2))


def mle_noise(t, sig, seg, exposure_s: float, frame_dt: float, lossless: bool, codec_m: float = 0.0):
    """The per-frame errors (m) the maximum-likelihood fit weights by.

    The tracker's errors with, for a lossy codec, its own error ``codec_m``
    (per axis, m; see :func:`codec_noise`) added in quadrature and each rest
    counted once (:func:`rest_weighting`); the strike's frames left out
    (:func:`strike_exclusion`).  The Cramer-Rao bound of the same
    measurements uses the same errors (pipeline.measure.mle_bound).
    """
    sig = np.asarray(sig, dtype=float)
    if not lossless:
        sig = rest_weighting(t, with_codec_error(sig, codec_m), seg, frame_dt)
    return strike_exclusion(t, sig, seg, exposure_s, frame_dt)


def codec_noise(residuals, sig_fit, sig_frame, n_par: int) -> float:
    """Per-axis error (m) a lossy codec adds beyond the tracker's stated one.

    Measured from a fit's residuals over the frames weighted as single
    measurements (moving, not at the strike): the variance in excess of the
    stated one, with the fit's degrees of freedom.  Signed: negative when
    the residuals are smaller than stated, as with MJPG at low noise, whose
    error is in the residuals the tracker's per-frame errors come from
    but moves the centre less than independent pixel noise would (measured:
    the tracker's stated errors 1.2-1.4 times its real ones below noise 1,
    on sharp and blurred video).

    Parameters
    ----------
    residuals : ndarray, shape (n, 2)
        Normalised residuals of the fit (residual / ``sig_fit``).
    sig_fit, sig_frame : ndarray, shape (n,)
        Errors the fit weighted by, and the tracker's per-frame errors (m).
    n_par : int
        Parameters fitted.

    Returns
    -------
    float
        ``sign(excess) * sqrt(|excess|)`` (m); 0 when too few frames.
    """
    r = np.asarray(residuals, dtype=float)
    single = np.isclose(sig_fit, sig_frame)
    n = int(single.sum())
    if r.shape[0] != len(sig_fit) or 2 * n <= n_par + 2:
        return 0.0
    r2 = np.sum((r[single] * sig_fit[single, None]) ** 2)
    s2 = 2.0 * np.sum(sig_frame[single] ** 2)
    excess = (r2 - s2 * (1.0 - n_par / (2.0 * n))) / (2 * n - n_par)
    return float(np.sign(excess) * np.sqrt(abs(excess)))


def recover_track(t, xy, ok, stderr_m, params: BallParams, exposure_s: float = 0.0,
                  method: str = "all", fit_friction: bool = False, lossless: bool = True) -> dict:
    """v0 and w0 from a track, by the paper's method and/or maximum likelihood.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Frame times (s).
    xy : ndarray, shape (n, 2)
        Ball centre (m); rows where ``ok`` is False are ignored.
    ok : ndarray of bool, shape (n,)
    stderr_m : ndarray, shape (n,) or (n, 2)
        Per-axis standard error of each centre (m); NaN where unknown.
    params : BallParams
    exposure_s : float
        Exposure (s), for the maximum-likelihood model.
    method : str
        ``paper``, ``mle`` or ``all``.
    fit_friction : bool
        Estimate mu_s and mu_r in the maximum-likelihood fit.
    lossless : bool
        The video's codec is lossless; otherwise resting frames count as one
        measurement per rest (see :func:`rest_weighting`).

    Returns
    -------
    dict
        ``{"methods": {...}, "best": ..., "timing_s": {"fit": s, "recover": s}}``
        with each method's fields as CONVENTIONS.md gives them.
    """
    t = np.asarray(t, dtype=float)
    xy = np.asarray(xy, dtype=float)
    ok = np.asarray(ok, dtype=bool) & np.all(np.isfinite(xy), axis=1)
    tt, xx = t[ok], xy[ok]
    sig = track_noise(np.asarray(stderr_m, dtype=float)[ok], xx) if ok.any() else np.zeros(0)
    sigma = float(np.median(sig)) if len(sig) else float("nan")
    frame_dt = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    clock = time.perf_counter()
    try:
        seg = segment_track(tt, xx, 5.0 / 7.0 * params.mu_r * params.g, sigma, exposure_s)
    except Exception as exc:  # never let a fit crash the answer
        from cuespin.fit.segment import Segments
        seg = Segments(False, f"segmentation failed: {exc.__class__.__name__}: {exc}")
    t_fit = time.perf_counter() - clock
    methods = {}
    clock = time.perf_counter()
    paper = None
    if method in METHODS:  # the MLE starts from the paper's answer when it has one
        try:
            paper = run_paper(seg, xx, params, sigma, frame_dt)
        except Exception as exc:
            paper = PaperResult("failed", f"internal error: {exc.__class__.__name__}: {exc}")
    if method in ("paper", "all"):
        methods["paper"] = paper_dict(paper, seg, params)
    if method in ("mle", "all"):
        sig_mle = mle_noise(tt, sig, seg, exposure_s, frame_dt, lossless)
        # The fit is made twice.  The strike's frames are left out around the
        # segmentation's t0, which can miss by most of a frame (60 fps): the
        # frame it then keeps, half still and half moving, passed for slip
        # (measured: v0 1.6% off at 9 stated errors).  And a lossy codec's
        # error is not in the tracker's.  So a first fit places the strike
        # and measures the codec's error from its residuals; the fit, slip
        # test included, is made again with the strike's frames left out
        # around its t0 and the codec's error in the weights.
        first = _run_mle(tt, xx, sig_mle, params, seg, paper, exposure_s, fit_friction)
        mle, codec_m = first, 0.0
        if first.status != "failed" and first.t0 is not None:
            if not lossless and first.residuals is not None:
                codec_m = codec_noise(first.residuals, sig_mle, sig, len(first.names))
            sig_again = mle_noise(tt, sig, replace(seg, t0=first.t0), exposure_s, frame_dt, lossless,
                                  codec_m)
            if not np.array_equal(sig_again, sig_mle):
                mle = _run_mle(tt, xx, sig_again, params, seg, paper, exposure_s, fit_friction,
                               first=first)
        methods["mle"] = mle_dict(mle)
        methods["mle"]["codec_noise_m"] = _num(codec_m)
    t_rec = time.perf_counter() - clock
    best = next((m for m in ("mle", "paper") if methods.get(m, {}).get("status") == "ok"), None)
    if best is None:
        best = next(iter(methods)) if methods else None
    return {"methods": methods, "best": best, "timing_s": {"fit": t_fit, "recover": t_rec},
            "sigma_m": _num(sigma)}


def _run_mle(t, xy, sig, params, seg, paper, exposure_s, fit_friction, first=None):
    """The maximum-likelihood fit from the best start at hand: ``first``'s
    answer (an earlier fit), the paper's, then the segmentation's guess."""
    from cuespin.recover.mle import MLEResult
    if not seg:
        return MLEResult("failed", f"no starting point: {seg.reason}")
    try:
        starts = [initial_guess(seg, params)]
        if paper is not None and paper.status == "ok":
            starts.insert(0, (seg.x0, seg.t0, paper.v0, paper.w0))
        if first is not None and first.status == "ok" and first.model == "full":
            starts.insert(0, (first.x0, first.t0, first.v0, first.w0))
        best = None
        for start in starts:  # the segmentation's guess when the paper's start fails
            res = fit_mle(t, xy, sig, params, start, exposure_s, fit_friction,
                          sliding_ended=bool(np.isfinite(seg.t1)),
                          sliding_obvious=bool(seg.sliding_p < OBVIOUS_SLIDING_P))
            if best is None or (best.status == "failed" and res.status != "failed"):
                best = res
            if best.status != "failed":
                break
        return best
    except Exception as exc:
        return MLEResult("failed", f"internal error: {exc.__class__.__name__}: {exc}")


def paper_dict(p: PaperResult, seg, params: BallParams) -> dict:
    """The paper method's JSON fields (CONVENTIONS.md)."""
    from cuespin.physics.motion import phases
    out = {"status": p.status, "reason": p.reason, "trajectory": p.trajectory or None,
           "v0": _num(p.v0), "w0": _num(p.w0), "x0": _num(p.x0 if p.x0 is not None else getattr(seg, "x0", None)),
           "t0": _num(seg.t0) if seg else None, "x1": None, "t1": None, "x2": None, "t2": None,
           "solutions": [{"v0": _num(s["v0"]), "w0": _num(s["w0"])} for s in p.solutions]}
    if p.status == "ok" and seg:
        # Where and when the recovered shot ends sliding and stops (eq. 10-19).
        ph = phases(Shot(seg.x0, p.v0, p.w0, seg.t0), params)
        out.update(x1=_num(ph.x1), t1=_num(ph.t1), x2=_num(ph.x2), t2=_num(ph.t2))
    elif seg:
        out.update(x1=_num(seg.x1) if np.isfinite(seg.t1) else None, t1=_num(seg.t1),
                   x2=_num(seg.x2), t2=_num(seg.t2))
    return out


def mle_dict(m) -> dict:
    """The maximum-likelihood fit's JSON fields (CONVENTIONS.md)."""
    out = {"status": m.status, "reason": m.reason, "model": m.model or None,
           "v0": _num(m.v0), "w0": _num(m.w0),
           "stderr": {k: _num(v) for k, v in m.stderr.items()},
           "x0": _num(m.x0), "t0": _num(m.t0), "t1": _num(m.t1), "t2": _num(m.t2),
           "slip_lr": _num(m.slip_lr), "chi2_per_dof": _num(m.chi2 / m.dof) if m.dof else None}
    if m.mu_s is not None:
        out.update(mu_s=_num(m.mu_s), mu_r=_num(m.mu_r))
    return out
