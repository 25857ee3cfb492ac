"""Both recoveries from one track, as the JSON object of CONVENTIONS.md.

An adapter only: recover.estimate does the work (segmentation, decisions,
fits); this turns its dataclasses into a plain dict (numbers that could not
be determined are None, never NaN).
"""

from __future__ import annotations

import math

import numpy as np

from cuespin.physics.motion import BallParams, Shot, phases
from cuespin.recover.estimate import Estimate, estimate
from cuespin.recover.measurements import stated_frames

METHODS = ("paper", "mle", "all")


def _num(x):
    if x is None:
        return None
    if isinstance(x, (list, tuple, np.ndarray)):
        return [_num(v) for v in np.asarray(x, dtype=float).tolist()]
    x = float(x)
    return x if math.isfinite(x) else None


def recover_track(t, xy, ok, stderr_m, params: BallParams, exposure_s: float = 0.0,
                  method: str = "all", fit_friction: bool = False, lossless: bool = True,
                  return_estimate: bool = False, inter_frame: bool = False, px_to_m=None, keep=None,
                  ar1_floor: float = 0.0, touched=None, independent: bool | None = None,
                  look_factor: float = 1.0, foreign=None, shaded: bool = False, uncalibrated: str = ""):
    """v0 and w0 from a track, by the paper's method and/or maximum likelihood.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Frame times (s).
    xy : ndarray, shape (n, 2)
        Ball centre (m); rows where ``ok`` is False are ignored.
    ok : ndarray of bool, shape (n,)
    stderr_m : ndarray, shape (n, 2, 2), (n, 2) or (n,)
        Each centre's covariance in table metres (m^2; from the tracker's
        pixel covariance by ``scene.camera.cov_to_table``), or its per-axis
        standard error (m); NaN where unknown.
    params : BallParams
    exposure_s : float
        Exposure (s), for the maximum-likelihood model.
    method : str
        ``paper``, ``mle`` or ``all``.
    fit_friction : bool
        Estimate mu_s and mu_r in the maximum-likelihood fit.
    lossless : bool
        The video's codec is lossless; otherwise the codec's error is
        measured from the residuals.
    independent : bool, optional
        Each frame's error is its own (``TrackResult.independent_errors``);
        otherwise a resting ball's frames are one measurement per rest (a
        lossy codec, or a shaded look the tracker's model misses).  Default
        ``lossless``.
    look_factor : float
        ``TrackResult.look_factor``, on every frame's stated error: taken
        off the rests' frames where they share the look's error.
    shaded : bool
        ``TrackResult.look_shaded``: on a lossy codec each rest's mean is
        stated at least one frame's stated covariance, the codec's error at
        a still ball's place (recover.measurements.rest_floor_covariance).
    inter_frame : bool
        The lossy codec predicts frames from others (H.264): its error is
        shared between neighbouring frames (recover.mle.codec_sandwich).
    px_to_m : ndarray, shape (n, 2, 2), optional
        Metres per pixel at each frame (``recover.measurements.pixel_to_table``
        of the scene's camera): a lossy codec's own error is measured in
        pixels and carried to the table through it, as the tracker's is;
        without it, in metres (tracks with no camera).
    keep : Decided, optional
        An earlier recovery's decisions on the same track
        (``Estimate.decided``, from ``return_estimate``), kept by this one: a
        refit through another camera (recover.calibration).
    ar1_floor : float
        Lag-1 correlation of the AR(1) error model the track states (the
        tracker's ``TrackResult.error_ar1``; 0: independent): the fit is then under
        AR(1) errors of at least this correlation (recover.estimate.estimate).
    touched : ndarray of bool, shape (n,), optional
        Frames the tracker flags (``TrackResult.touched``: something beside
        the ball, or the ball leaving its rest): the first frames after the
        strike are left out only when such frames lie at the strike
        (recover.estimate.estimate); without it none are.
    foreign : ndarray of bool, shape (n,), optional
        The flags of ``touched`` that are the cue's (``TrackResult.foreign``:
        the fit saw foreign pixels), apart from the rest spot's: a run that
        starts with them may start a frame or two after the strike
        (recover.measurements.touched_run_s).
    uncalibrated : str
        Why the track's stated errors are not calibrated
        (``TrackResult.warning``: 4:1:1 / 4:1:0 chroma, measured error /
        stated 0.4-3.7, fix411), or "": every answer is then ``degenerate``
        with that reason, its numbers kept, and ``best`` None
        (:func:`uncalibrated_answers`).
    return_estimate : bool
        Also return the :class:`~cuespin.recover.estimate.Estimate` (its
        measurements give the bound: pipeline.measure.mle_bound).

    Returns
    -------
    dict
        ``{"methods": {...}, "best": ..., "timing_s": {"fit": s, "recover": s}, "sigma_m": m}``
        with each method's fields as CONVENTIONS.md gives them; ``best`` is
        None when no method answered ``ok``.
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(METHODS)}, not {method!r}")
    t = np.asarray(t, dtype=float)
    xy = np.asarray(xy, dtype=float)
    # A frame without a stated error is no measurement: left out, as one without a centre.
    ok = np.asarray(ok, dtype=bool) & np.all(np.isfinite(xy), axis=1) & np.isfinite(t) & stated_frames(stderr_m)
    cov = np.asarray(stderr_m, dtype=float)[ok]
    est = estimate(t[ok], xy[ok], cov, params, exposure_s, lossless, fit_friction,
                   run_paper=method in ("paper", "all"), inter_frame=inter_frame,
                   px_to_m=None if px_to_m is None else np.asarray(px_to_m, dtype=float)[ok], keep=keep,
                   ar1_floor=ar1_floor, touched=None if touched is None else np.asarray(touched, bool)[ok],
                   independent=independent, look_factor=look_factor, shaded=shaded,
                   foreign=None if foreign is None else np.asarray(foreign, bool)[ok])
    methods = {}
    if method in ("paper", "all"):
        methods["paper"] = paper_dict(est, params)
    if method in ("mle", "all"):
        methods["mle"] = mle_dict(est)
    if uncalibrated:
        uncalibrated_answers(methods, uncalibrated)
    best = next((m for m in ("mle", "paper") if methods.get(m, {}).get("status") == "ok"), None)
    sigma = None
    if est.meas is not None and len(est.meas.cov):
        sigma = _num(np.median(np.sqrt(0.5 * np.trace(est.meas.cov, axis1=1, axis2=2))))
    out = {"methods": methods, "best": best, "timing_s": dict(est.timing_s), "sigma_m": sigma,
           "decisions": {k: {"yes": d.yes, "statistic": _num(d.statistic), "threshold": _num(d.threshold),
                             "level": d.level} for k, d in est.decisions.items()}}
    return (out, est) if return_estimate else out


def uncalibrated_answers(methods: dict, why: str) -> None:
    """Every ``ok`` answer of ``methods`` made ``degenerate`` with the
    reason ``why`` (the track's stated errors are not calibrated), in
    place; its numbers kept.  Its stated errors, and the decisions made on
    them (the slip test, the end of sliding, the paper's checks), are off
    by an unknown factor: 4:1:1 / 4:1:0 tracks' measured error / stated
    0.4-3.7 per axis, realistic 1.9-4.95 (fix411), which moves a chi-square
    statistic by up to ~25 times, so an ``ok`` would be a confident answer
    with no honest error (review of fix411, MUST-FIX)."""
    for m in methods.values():
        if m.get("status") == "ok":
            m["status"] = "degenerate"
            m["reason"] = f"the answer is shown, but {why}"


def paper_dict(est: Estimate, params: BallParams) -> dict:
    """The paper method's JSON fields (CONVENTIONS.md)."""
    p, seg = est.paper, est.seg
    out = {"status": p.status, "reason": p.reason, "trajectory": p.trajectory or None,
           "v0": _num(p.v0), "w0": _num(p.w0), "x0": _num(p.x0 if p.x0 is not None else getattr(seg, "x0", None)),
           "t0": _num(seg.t0) if seg else None, "x1": None, "t1": None, "x2": None, "t2": None,
           "stderr": {k: _num(v) for k, v in p.stderr.items()} if p.stderr else None,
           "solutions": [{"v0": _num(s["v0"]), "w0": _num(s["w0"])} for s in p.solutions]}
    if p.status == "ok" and seg:
        # Where and when the recovered shot ends sliding and stops (eq. 10-19).
        ph = phases(Shot(seg.x0, p.v0, p.w0, seg.t0), params)
        out.update(x1=_num(ph.x1), t1=_num(ph.t1), x2=_num(ph.x2), t2=_num(ph.t2))
    elif seg:
        # A breakpoint held on the slide's deceleration bound is not a measured
        # t1 (fit.segment.SLIDE_DECEL_RATIO): neither it nor x1 is reported.
        held = seg.t1_bound
        out.update(x1=_num(seg.x1) if np.isfinite(seg.t1) and not held else None,
                   t1=None if held else _num(seg.t1),
                   x2=_num(seg.x2), t2=_num(seg.t2))
    return out


def mle_dict(est: Estimate) -> dict:
    """The maximum-likelihood fit's JSON fields (CONVENTIONS.md)."""
    m = est.mle
    # The codec's error: measured in pixels when the track came with its
    # camera (then also in metres at the median frame), else in metres.
    in_px = est.meas is not None and est.meas.px_to_m is not None
    c_m2 = est.meas.codec_m2(est.codec_var) if est.meas is not None else est.codec_var
    out = {"status": m.status, "reason": m.reason, "model": m.model or None,
           "v0": _num(m.v0), "w0": _num(m.w0),
           "stderr": {k: _num(v) for k, v in m.stderr.items()},
           "x0": _num(m.x0), "t0": _num(m.t0), "t1": _num(m.t1), "t2": _num(m.t2),
           "slip_lr": _num(m.slip_lr),
           "unseen_slip": _num(m.unseen_slip) if m.model == "rolling" else None,
           # The free-slip fit's (v0, w0) less the rolling answer's, stated in
           # its errors where the slip was neither seen nor excluded.
           "slip_gap": (_num(np.asarray(est.decided.slip_gap)) if est.decided is not None
                        and est.decided.slip_gap is not None and m.model == "rolling" else None),
           "chi2_per_dof": _num(m.chi2 / m.dof) if m.dof else None,
           "dof": _num(round(float(m.dof), 1)) if m.dof else None, "hac": bool(m.hac), "rho1": _num(m.rho1),
           "ar1": _num(m.ar1),
           # The frames after t0 left out while the cue's tip may touch the
           # ball (recover.measurements.cue_clear_s): the bound leaves out
           # the same frames.
           "cue_clear_s": _num(est.decided.clear_s) if est.decided is not None else None,
           # The moving frames' chi2/dof (and its dof) a lossless rest's
           # scatter was judged against (recover.measurements.moving_scale):
           # the bound judges it the same.
           "rest_scale": _num(est.decided.rest_scale[0]) if est.decided is not None else None,
           "rest_scale_dof": _num(est.decided.rest_scale[1]) if est.decided is not None else None,
           "codec_noise_m": _num(math.copysign(math.sqrt(abs(c_m2)), c_m2)),
           "codec_noise_px": None if not in_px else _num(math.copysign(math.sqrt(abs(est.codec_var)),
                                                                         est.codec_var))}
    if m.mu_s is not None or m.mu_r is not None:
        out.update(mu_s=_num(m.mu_s), mu_r=_num(m.mu_r))
    return out
