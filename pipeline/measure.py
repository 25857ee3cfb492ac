"""Measuring the tracker against truth and the Cramer-Rao bound on rendered video.

Shared by the tests, the benchmarks and the experiments: one definition of
"RMSE over moving frames" and of the bound it is compared with.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cuespin.physics.scene import Scene
from cuespin.render import FrameRenderer, render_video
from cuespin.recover.estimate import one_blas_thread
from cuespin.render.draw import FrameTruth
from cuespin.track.bound import centroid_crb
from cuespin.track.tracker import FIT_BLUR_PX, TrackerConfig
from cuespin.track.video import TrackResult, track_video


@dataclass
class TrackerAccuracy:
    """Per-axis centroid RMSE over moving frames (px) beside the bound (px),
    and the RMS of the errors in the tracker's own stated errors
    (``stated_z``: 1 when its per-frame errors are honest)."""

    result: TrackResult
    truth: FrameTruth
    rmse: float
    crb: float
    stated_z: float = float("nan")

    @property
    def ratio(self) -> float:
        return self.rmse / self.crb


def tracker_accuracy(scene: Scene, video: Path, refine: str = "fit", n_eval: int = 12,
                     settle_s: float = 0.02) -> TrackerAccuracy:
    """Render ``scene`` to ``video``, track it, and compare with truth and the bound.

    Frames count from ``settle_s`` after the strike (the strike frame itself
    holds a half-still, half-moving ball that no disc model describes).  The
    bound is averaged (RMS) over ``n_eval`` of those frames, with the blur as
    a nuisance wherever the tracker fits it.
    """
    truth = render_video(scene, video)
    res = track_video(video, scene, TrackerConfig(refine=refine))
    r = FrameRenderer(scene)
    moving = np.flatnonzero(res.ok & (truth.t > scene.truth.t0 + settle_s))
    err = res.uv[moving] - truth.uv[moving]
    s = r.settings
    bounds = []
    for k in moving[np.linspace(0, len(moving) - 1, n_eval).astype(int)]:
        nodes = r._uv_nodes[k]
        # The tracker's blur estimate is the path over the exposure.
        blur_len = np.hypot(*(nodes[-1] - nodes[0])) * (1 + 1 / max(len(nodes) - 1, 1))
        bounds.append(centroid_crb(nodes, r.radius_px, s["ball_grey"], r.background,
                                   s["noise_sigma"], blur_len > FIT_BLUR_PX))
    with np.errstate(invalid="ignore", divide="ignore"):
        z = err / res.stderr_px[moving]  # NaN with refine="moments", which states none
    return TrackerAccuracy(result=res, truth=truth, rmse=float(np.sqrt(np.mean(err**2))),
                           crb=float(np.sqrt(np.mean(np.square(bounds)))),
                           stated_z=float(np.sqrt(np.mean(z**2))))


@one_blas_thread  # its (m, m) Cholesky on one BLAS thread, as the recovery's own products (recover.estimate)
def mle_bound(scene: Scene, track, mle: dict | None = None, independent: bool = False, ar1: float | None = None,
              acf=None):
    """Cramer-Rao covariance of ``(x0, t0, v0[, w0])`` at the scene's truth.

    The inverse Fisher information of the maximum-likelihood fit's model
    (its Jacobian at the truth) for the measurements it used
    (recover.measurements): pass the fit's own
    :class:`~cuespin.recover.measurements.Measurements` as ``track``
    (``recover_track(..., return_estimate=True)`` gives them), or a
    TrackResult and the fit's JSON ``mle``, from which they are rebuilt
    the same way (strike window at its ``t0``, the rest after its ``t2``
    shared for a lossy codec, its ``codec_noise_px`` added through the
    camera, or ``codec_noise_m`` when it has none); nothing is
    segmented again.  Under the error model the fit used: its AR(1)
    correlation ``ar1`` (default the JSON's ``mle["ar1"]``; 0 when neither
    gives one); with ``acf`` (an inter-frame codec's correlation in time,
    recover.mle.INTER_CODEC_ACF) the frames' errors correlated as the fit's
    covariance takes them (recover.mle.crb_covariance).  With ``independent``, the tracker's errors with every
    frame its own, independent measurement, the bound a lossy codec's
    shared errors put out of reach (a reference).

    Returns
    -------
    (cov, rolling) : (ndarray, bool)
        ``rolling`` when the shot rolls from the strike (w0 then follows
        from v0, and ``cov`` is 5 x 5).

    Raises
    ------
    numpy.linalg.LinAlgError
        When the information matrix is singular.
    """
    from cuespin.physics import contact_velocity
    from cuespin.recover.measurements import (Measurements, build_measurements, pixel_to_table, stated_frames,
                                              still_look_applies, table_covariance)
    from cuespin.recover.mle import crb_covariance

    truth, p, cam = scene.truth, scene.physics, scene.camera
    rolling = bool(np.hypot(*contact_velocity(np.array(truth.v0), np.array(truth.w0), p.R)) < 1e-9)
    if isinstance(track, Measurements):
        meas = track
        if independent:
            meas = build_measurements(meas.t, meas.xy, meas.cov)
    else:
        cov = table_covariance(cam, track.xy, track.cov_px)
        ok = track.ok & stated_frames(cov)  # the frames recover_track fits
        t, xy, cov = track.t[ok], track.xy[ok], cov[ok]
        mle = mle or {}
        if independent or mle.get("t0") is None:
            meas = build_measurements(t, xy, cov)
        else:
            in_px = mle.get("codec_noise_px") is not None
            c = (mle["codec_noise_px"] if in_px else mle.get("codec_noise_m")) or 0.0
            meas = build_measurements(t, xy, cov, t0=mle["t0"], t_rest=mle.get("t2"),
                                      exposure_s=cam.exposure_s, frame_dt=1.0 / cam.fps,
                                      shared_rest=not getattr(track, "independent_errors", track.lossless),
                                      look_rest=bool(track.lossless) and not getattr(track, "independent_errors",
                                                                                     track.lossless),
                                      look_factor=float(getattr(track, "look_factor", 1.0)),
                                      still_look=still_look_applies(getattr(track, "look_shaded", False), track.lossless,
                                                                 getattr(track, "inter_frame", False)),
                                      px_to_m=pixel_to_table(cam, xy) if in_px else None,
                                      clear_s=mle.get("cue_clear_s") or 0.0,
                                      cue=None if getattr(track, "foreign", None) is None
                                      else np.asarray(track.foreign, dtype=bool)[ok],
                                      # under the AR(1) model the fit kept a lossless rest frame by frame
                                      group_rest=not mle.get("ar1"),
                                      rest_scale=mle.get("rest_scale") or 1.0,
                                      rest_scale_dof=mle.get("rest_scale_dof") or float("inf"),
                                      ).with_codec(np.sign(c) * c * c)
    if ar1 is None:
        ar1 = (mle or {}).get("ar1") or 0.0
    return crb_covariance(truth, p, meas, cam.exposure_s, rolling=rolling,
                          ar1=0.0 if independent else float(ar1), acf=None if independent else acf), rolling


@dataclass
class AnswerBound:
    """The Cramer-Rao bound of the model an answer was given with, at the
    parameters of that model nearest the truth.

    Attributes
    ----------
    model : str
        The answer's model: ``"rolling"`` (rolling from the strike; its
        bound covers v0 alone, w0 following from it) or ``"full"`` (free
        slip: v0 and w0).
    centre : ndarray, shape (4,)
        That model's ``(v0 (m/s), w0 (rad/s))`` nearest the truth: the
        truth itself when the model holds it, else (a rolling answer on a
        shot that slid, unseen) the rolling fit to the truth's exact path
        at the answer's own measurements and weights: where the answer
        tends as the errors shrink.
    bias : ndarray, shape (4,)
        ``centre - truth`` (m/s, rad/s): what assuming the answer's model
        costs however small the errors (zero when the model holds the truth).
    cov : ndarray or None
        The bound, Cramer-Rao covariance of ``(x0, t0, v0[, w0])`` at
        ``centre`` (m, s, m/s, rad/s); None when there is none.
    reason : str
        Why there is no bound ("" when there is one).
    """

    model: str
    centre: np.ndarray
    bias: np.ndarray
    cov: np.ndarray | None = None
    reason: str = ""

    @property
    def components(self) -> list:
        """Indices into ``(v0x, v0y, w0x, w0y)`` the bound covers."""
        return [0, 1] if self.model == "rolling" else [0, 1, 2, 3]

    @property
    def sd(self) -> np.ndarray:
        """The bound's standard deviations of the covered components (m/s, rad/s)."""
        return np.sqrt(np.diag(self.cov)[[c + 3 for c in self.components]])

    def z(self, answer) -> np.ndarray:
        """The answer's error about ``centre`` in bound units, over
        ``(v0x, v0y, w0x, w0y)`` (NaN where the bound covers none)."""
        out = np.full(4, np.nan)
        c = self.components
        out[c] = (np.asarray(answer, float)[c] - self.centre[c]) / self.sd
        return out

    def bias_z(self) -> np.ndarray:
        """``bias`` in bound units (NaN where the bound covers none)."""
        out = np.full(4, np.nan)
        out[self.components] = self.bias[self.components] / self.sd
        return out


def rms_z(z) -> float:
    """RMS error / bound (or / stated error): the root mean square of
    errors in those units, ``z`` (any shape), over its finite entries (NaN:
    a component the bound does not cover, :meth:`AnswerBound.z`; infinite:
    an answer without stated errors, which the caller counts apart); NaN
    when there are none.  The one definition for an answer (its covered
    components) and for a set of answers (every covered component of every
    answer pooled: a free-slip answer's four, a rolling answer's two v0
    components), used by benchmarks/accuracy.py's per-shot columns, its
    summary and its intervals alike."""
    a = np.asarray(z, dtype=float)
    a = a[np.isfinite(a)]
    return float(np.sqrt(np.mean(a * a))) if a.size else float("nan")


@one_blas_thread  # as mle_bound
def answer_bound(scene: Scene, meas, model: str, ar1: float = 0.0, acf=None, independent: bool = False,
                 fit_friction: bool = False) -> AnswerBound:
    """The Cramer-Rao bound of the model an answer was given with
    (``model``: the MLE's JSON ``model``, ``"rolling"`` or ``"full"``), for
    the measurements it used (``meas``, recover.measurements) under the
    error model the fit took (``ar1``, ``acf``: as :func:`mle_bound`;
    ``independent``: every frame its own measurement, a reference).

    An efficient estimator's error about the point its model tends to
    reaches this bound: a rolling answer is compared with the rolling
    model's bound at the rolling parameters nearest the truth
    (:class:`AnswerBound` ``centre``), and what assuming no slip costs
    when the truth slid unseen is its ``bias``, stated apart.  (The free
    slip's bound at a truth that slid only before the first measured
    frame, mle_bound's before, is singular by form, held37's 38/8 NaN and
    38/36's 10^4-times-too-large bound: it is the bound of an estimator
    the answer was not given by.)

    No bound, with ``reason``: a free-slip answer on a truth rolling from
    the strike, or one whose slide ends before the first measured moving
    frame's exposure (the v0 and w0 columns then combine to zero, as
    recover.mle._deficient_by_form's cases), or one that stops as its
    slide ends (the sampler's case2: the truth on the model's kink, where
    central differences straddle it; MJPG seed 39 shot 5's w0 "bound" came
    out 25,000 times its error); a rolling fit to the exact
    path that fails; an information matrix singular or rank deficient to
    round-off (recover.mle.RANK_DEFICIENT_EIG, the fit's own rule); a
    covered variance not positive.  Never raises for those: the caller
    reports such shots apart.
    """
    from dataclasses import replace

    from cuespin.physics import contact_velocity, phases
    from cuespin.recover.measurements import build_measurements
    from cuespin.recover.mle import (_rank_deficient, crb_jacobian, first_measured_after, fit_model,
                                     info_inverse, model_track)

    truth, p, cam = scene.truth, scene.physics, scene.camera
    exposure = cam.exposure_s
    truth_vw = np.r_[truth.v0, truth.w0].astype(float)
    none = AnswerBound(model=model, centre=truth_vw, bias=np.zeros(4))
    if independent:
        meas = build_measurements(meas.t, meas.xy, meas.cov)
    truth_rolls = bool(np.hypot(*contact_velocity(np.array(truth.v0), np.array(truth.w0), p.R)) < 1e-9)
    rolling = model == "rolling"
    shot = truth
    if not rolling:
        if truth_rolls:
            return replace(none, reason="free slip answered, the truth rolls from the strike: free slip's "
                                        "information is singular at zero slip")
        first = first_measured_after(meas, float(truth.t0))
        ph = phases(truth, p)
        if float(np.hypot(*ph.v1)) < 1e-9:
            return replace(none, reason="free slip answered, the truth stops as its slide ends (no rolling): "
                                        "the model has a kink there, its derivatives and bound are not defined")
        if ph.t1 <= first - 0.5 * exposure:
            return replace(none, reason=f"free slip answered, the truth's slide ends before the first "
                                        f"measured moving frame ({first - truth.t0:.4f} s after the "
                                        f"strike): its v0 and w0 not determined by these frames")
    elif not truth_rolls:
        # The rolling answer's limit: the rolling fit to the exact path.
        exact = replace(meas, xy=model_track(truth, p, meas.t, exposure))
        try:
            f = fit_model(exact, p, (truth.x0, truth.t0, truth.v0, truth.w0), exposure, True,
                          fit_friction=fit_friction, ar1=ar1)
        except (ValueError, np.linalg.LinAlgError) as e:
            return replace(none, reason=f"the rolling fit to the exact path failed: {e}")
        if not f.converged:
            return replace(none, reason=f"the rolling fit to the exact path did not converge: {f.message}")
        shot = f.shot
    centre = np.r_[shot.v0, shot.w0].astype(float)
    out = AnswerBound(model=model, centre=centre, bias=centre - truth_vw)
    try:
        J = crb_jacobian(shot, p, meas, exposure, rolling=rolling, ar1=ar1, acf=acf)
        if _rank_deficient(J):
            return replace(out, reason="the information is rank deficient to round-off")
        cov = info_inverse(J)
    except np.linalg.LinAlgError:
        return replace(out, reason="the information is singular")
    var = np.diag(cov)[[c + 3 for c in out.components]]
    if not np.all(np.isfinite(var) & (var > 0)):
        return replace(out, reason="a variance of the bound is not positive")
    return replace(out, cov=cov)
