"""Both recoveries from one track: segmentation, the decisions, the
maximum-likelihood fit and the paper's method, in that order.

The measurements (recover.measurements) are built once per pass and shared
with the bound; every yes/no question is put once to fit.decide.  Pure:
arrays in, dataclasses out (recover.api turns them into the JSON object).
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, field

import numpy as np
from threadpoolctl import ThreadpoolController

from cuespin.fit.decide import (PAPER_FIT_TAU_Z, Decision, autocorrelated, slip_in_one_measurement, sliding_ended,
                               sliding_seen, sliding_times_differ, strike_in_view, t1_in_view)
from cuespin.fit.segment import Segments, correlated_end_F, segment_track
from cuespin.physics.motion import BallParams, phases, rolling_deceleration, z_cross
from cuespin.recover.measurements import (CUE_CLEAR_FRAMES, MAX_CODEC_NOISE_RATIO, MAX_STEP_R, Measurements,
                                          as_covariance, build_measurements, codec_excess, codec_noise_ratio,
                                          cue_clear_s, fill_covariance, moving_scale, still_look_applies,
                                          touched_run_s, track_step)
from cuespin.recover.mle import (MAX_AR1, CodecCorrelation, MLEResult, ModelFit, ar1_from_residuals,
                                 correlated_codec_var, time_whitener,
                                 fit_model, fit_models, initial_guess, lag1_autocorrelation, model_track, result,
                                 slip_lr, slip_lr_without_largest, with_profile_interval)
from cuespin.recover.paper import (PaperResult, paper_from_segments, ran_into_rest, sliding_time, sliding_time_stderr,
                                   with_unseen_slip)
from cuespin.recover.slope import rolling_slope

# The first fit's strike time is used to place the strike's window only
# when within this many frames of the segmentation's (the segmentation
# finds it to a fraction of a frame: README; further off, the first fit
# is lost and its t0 is not trusted).
MAX_T0_SHIFT_FRAMES = 3.0
# Errors a fit may raise on a track it cannot describe: reported as the
# fit's failure, never raised.
FIT_ERRORS = (ValueError, np.linalg.LinAlgError, FloatingPointError)


@dataclass(frozen=True)
class Decided:
    """What one recovery decided about a track, for a refit of the same
    track through another camera to keep (recover.calibration): the
    calibration's share must measure the camera alone, not a model that a
    perturbed camera tips the other way (sliding or rolling, the path's
    shape, the paper's root).

    ``sliding_seen`` (None: the fit did not run), ``sliding_ended``,
    ``segments`` (``sliding``, ``unended`` or ``rolling``: the segmentation
    chosen), ``curved`` (the paper's path; None: not asked), ``strike_seen``,
    ``frames`` (the strike's and the rest's frames, fit.segment), ``t0``
    (the strike window's centre, s), ``codec_var`` (as
    :attr:`Estimate.codec_var`), ``start`` (the chosen fit's ``(x0, t0,
    v0, w0)``, to start from), ``paper`` (the paper's ``(v0, w0)`` or None),
    ``ar1`` (the AR(1) error model's lag-1 correlation; 0: none) and
    ``breaks`` (the chosen segmentation's ``(t0, t1)``, ``t1`` inf when its
    sliding runs to the end of the motion: the refit's segmentation is
    searched from them and keeps their kind, fit.segment.segment_track),
    ``hac`` (the residuals' autocorrelation answered by a HAC sandwich:
    decided once, on the first fit; never on top of the AR(1) model),
    ``verdicts`` (the chosen fit's status rules' answers,
    :attr:`recover.mle.MLEResult.verdicts`), ``stop_apart`` (the paper's
    case 2 question, :attr:`recover.paper.PaperResult.stop_apart`) and
    ``clear_s`` (the time after ``t0`` whose frames the cue's tip may touch,
    left out: recover.measurements.cue_clear_s), ``rest_scale`` (the first
    fit's chi2/dof over the moving frames and its degrees of freedom, which
    a lossless rest's scatter is judged against:
    recover.measurements.moving_scale), ``sliding_times_agree`` (the
    paper's sliding time against the fit's, :func:`sliding_times_agree`;
    None: not asked), ``slip_gap`` (a rolling answer's gap to the free-slip
    fit where the slip was neither seen nor excluded, recover.mle.result's
    ``slip_gap``: the refit states it too).
    """

    sliding_seen: bool | None
    sliding_ended: bool
    segments: str
    curved: bool | None
    strike_seen: bool
    frames: tuple
    t0: float
    codec_var: float
    start: tuple | None = None
    paper: tuple | None = None
    ar1: float = 0.0
    breaks: tuple | None = None
    hac: bool = False
    verdicts: dict | None = None
    stop_apart: bool | None = None
    clear_s: float = 0.0
    rest_scale: tuple = (1.0, float("inf"))
    sliding_times_agree: bool | None = None
    slip_gap: tuple | None = None


@dataclass(frozen=True)
class Estimate:
    """Everything the recovery found in one track.

    ``seg`` is the segmentation the decisions chose (rolling from the
    strike, or sliding that ended in view or not); ``meas`` the
    measurements the maximum-likelihood fit used (for its bound);
    ``codec_var`` the codec's per-axis error variance (signed; px^2 when
    the track came with ``px_to_m``, else m^2) measured from the first
    fit's residuals; ``decisions`` name each Decision taken.
    """

    seg: Segments
    paper: PaperResult | None
    mle: MLEResult | None
    meas: Measurements | None = None
    codec_var: float = 0.0
    decisions: dict = field(default_factory=dict)
    timing_s: dict = field(default_factory=dict)
    decided: Decided | None = None


def _first_fit(meas, params, starts, exposure_s, fit_friction) -> ModelFit | None:
    """The free-slip fit of least chi-square among those from ``starts``
    that run and converge.  Not the first that converges: a sliding
    segment of a few frames can start it at ten times the speed (a
    rolling shot whose first moving frames lie off the path: 16.9 m/s for
    1.7), and it then converges far from the shot, and the codec's share
    measured from its residuals (3-73 px on 5 of 24 realistic rolling
    renders) made every answer's errors meaningless."""
    best = None
    for start in starts:
        try:
            fit = fit_model(meas, params, start, exposure_s, False, fit_friction)
        except FIT_ERRORS:
            continue
        if fit.converged and (best is None or fit.chi2 < best.chi2):
            best = fit
    return best


# The recovery's BLAS (and OpenMP) run on one thread, inside the call only
# (threadpoolctl restores the caller's limits on return; the tracker's numba
# and OpenCV threads are its own and not touched).  Measured (docs/
# measurements.md, fitspeed and blas1): its matrices are small (at most a few
# hundred rows: (360, 360) @ (360, 14) takes 0.12 ms CPU on one thread, 2.7 ms
# on two at load ~5), so OpenBLAS's second thread mostly waits for a core:
# recovery CPU on held37's 80 realistic H.264 tracks 2.86-3.48 s on one thread
# against 4.82-5.35 s on the default two, wall about a third.  And the answers
# depended on the thread count (18 of those 80 tracks differed, two degenerate
# fits materially: 37/25 v0's stated error inf against 509 m/s, 37/26 t1
# 8.93 s against 2.26 s); on one thread they are the same on any machine.
RECOVERY_BLAS_THREADS = 1


@functools.cache
def _thread_pools() -> ThreadpoolController:
    """The BLAS and OpenMP libraries loaded when first asked (numpy's and
    scipy's OpenBLAS are, by this module's imports; with OpenCV imported, its
    own OpenBLAS too, idle during the recovery); found once, because finding
    them takes ~0.9 ms a call against ~0.01 ms to set their limits."""
    return ThreadpoolController()


def one_blas_thread(f):
    """Run ``f`` with BLAS and OpenMP limited to RECOVERY_BLAS_THREADS
    threads, the caller's limits restored on return; ``f.__wrapped__`` is
    the unlimited function (for measuring the difference)."""
    @functools.wraps(f)
    def limited(*args, **kwargs):
        with _thread_pools().limit(limits=RECOVERY_BLAS_THREADS):
            return f(*args, **kwargs)
    return limited


@one_blas_thread
def estimate(t, xy, cov, params: BallParams, exposure_s: float = 0.0, lossless: bool = True,
             fit_friction: bool = False, run_paper: bool = True, inter_frame: bool = False,
             px_to_m=None, keep: Decided | None = None, ar1_floor: float = 0.0,
             touched=None, independent: bool | None = None, look_factor: float = 1.0,
             foreign=None, shaded: bool = False) -> Estimate:
    """Segment, decide and fit one track.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Times (s) of the frames where the ball was found.
    xy : ndarray, shape (n, 2)
        Centres (m).
    cov : ndarray, shape (n, 2, 2), (n, 2) or (n,)
        Per-frame covariance (m^2) or per-axis standard errors (m); NaN
        where unknown.
    params : BallParams
    exposure_s : float
        Exposure (s).
    lossless : bool
        The codec is lossless; otherwise the codec's own error is measured
        from the residuals (and, with an intra-frame codec, shared by frames
        that show the ball at one place: recover.mle.still_codec_sandwich).
    independent : bool, optional
        Each frame's error is its own (track.video's
        ``TrackResult.independent_errors``); otherwise a still ball's frames
        share one error (one measurement a rest, the paper's rests no better
        than one frame): a lossy codec's, or a look the tracker's model
        misses (a shaded ball, on a lossless codec too).  Default
        ``lossless``.
    look_factor : float
        The factor the tracker put on every frame's covariance for the
        look (``TrackResult.look_factor``); on a lossless codec with
        ``independent`` False it is taken off the rests' frames
        (:func:`cuespin.recover.measurements.build_measurements`).
    shaded : bool
        The tracker shaded the ball's look (``TrackResult.look_shaded``): on
        a lossy intra-frame codec (MJPG) each rest's mean has the still
        look's own error (``build_measurements(still_look=)``).
    fit_friction : bool
        Estimate mu_s and mu_r in the maximum-likelihood fit.
    run_paper : bool
        Run the paper's method as well.
    inter_frame : bool
        The lossy codec predicts frames from other frames (H.264): its
        error is shared between neighbouring frames, and the standard
        errors follow its measured correlation (recover.mle.codec_sandwich).
    px_to_m : ndarray, shape (n, 2, 2), optional
        Metres per pixel at each frame (recover.measurements.pixel_to_table):
        a codec's error is one variance in the image, carried to the table
        through it; without it (simulated tracks) one variance in m^2.
    keep : Decided, optional
        An earlier recovery's decisions on the same frames (its
        ``Estimate.decided``), kept instead of made again: the refits of the
        calibration's share (recover.calibration) change the camera only.
    touched : ndarray of bool, shape (n,), optional
        Frames the tracker flags (``TrackResult.touched``: something beside
        the ball, the cue; or the ball leaving the spot it rested on): the
        first frames after the strike (recover.measurements.cue_clear_s), and
        the whole run of flagged frames from the first after the strike on,
        its holes spanning up to ``TOUCHED_GAP_S`` bridged
        (recover.measurements.touched_run_s), are left out only when that run
        is found or a frame within ``CUE_CLEAR_FRAMES`` of the strike is
        flagged.  Without it (simulated tracks, a shot with no cue
        in view) none are: leaving them out of a cue-less shot cost free-slip
        answers their coverage (short_slide.py, seeds 8-9: 91.9% -> 83.9%).
    foreign : ndarray of bool, shape (n,), optional
        The flags of ``touched`` that are the cue's or another object's
        (``TrackResult.foreign``), apart from the rest spot's: a run holding
        one of these may start up to ``TOUCHED_GAP_S`` after the first frame
        after the strike (recover.measurements.touched_run_s).
        Without it every run must start at that frame.
    ar1_floor : float
        Lag-1 correlation of the AR(1) error model the track states (the
        tracker's measure, track.misfit.error_ar1; 0: independent).  When
        positive the fit is under AR(1) errors of at least this correlation
        whatever the residuals' test says: a correlated error costs a
        velocity about (1 + rho) / (1 - rho) in variance, which a scaled
        covariance alone does not state (41% coverage measured at rho 0.9);
        the decision ``autocorrelated`` is then yes, stated by the track.

    Returns
    -------
    Estimate
    """
    t = np.asarray(t, dtype=float)
    xy = np.asarray(xy, dtype=float)
    cov = fill_covariance(as_covariance(cov, len(t)), xy) if len(t) else np.zeros((0, 2, 2))
    sigma = float(np.median(np.sqrt(0.5 * (cov[:, 0, 0] + cov[:, 1, 1])))) if len(t) else float("nan")
    frame_dt = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    clock = time.perf_counter()
    seg = segment_track(t, xy, rolling_deceleration(params.mu_r, params.g), sigma, exposure_s,
                        frames=keep.frames if keep is not None else None,
                        breaks=keep.breaks if keep is not None else None)
    t_fit = time.perf_counter() - clock
    clock = time.perf_counter()
    if not seg:
        fail = f"the track could not be segmented: {seg.reason}"
        return Estimate(seg, PaperResult("failed", fail), MLEResult("failed", f"no starting point: {seg.reason}"),
                        timing_s={"fit": t_fit, "recover": time.perf_counter() - clock})
    independent = lossless if independent is None else bool(independent)
    # First pass (free slip, which nests rolling): place the strike and, for
    # a lossy codec, measure the codec's error from the residuals.  The
    # segmentation's t0 can miss by most of a frame at 60 fps, and the frame
    # it then keeps, half still and half moving, passed for slip (measured:
    # v0 1.6% off at 9 stated errors).
    # The frames after the strike whose ball the cue's tip still touches are
    # left out too, for the time the ball takes to clear it at the speed the
    # segmentation and then the first fit give (recover.measurements.CUE_CLEAR_R).
    # A lossless rest's scatter is judged against the moving frames' own
    # scale of their stated errors, measured by the first fit.
    def measure(t0, clear_s, group_rest=True, scale=(1.0, float("inf"))):
        return build_measurements(t, xy, cov, t0=t0, t_rest=seg.t2, exposure_s=exposure_s,
                                  frame_dt=frame_dt, shared_rest=not independent, px_to_m=px_to_m, clear_s=clear_s,
                                  group_rest=group_rest, rest_scale=scale[0], rest_scale_dof=scale[1],
                                  look_rest=lossless and not independent, look_factor=look_factor,
                                  still_look=still_look_applies(shaded, lossless, inter_frame), cue=foreign,
                                  touched=touched)

    if keep is not None:
        codec = CodecCorrelation(keep.codec_var, frame_dt) if inter_frame and not lossless else None
        return _refit(keep, seg, t, xy, cov, params, exposure_s, fit_friction, run_paper, lossless, sigma,
                      frame_dt, measure, codec, t_fit, clock, independent)
    starts = [initial_guess(s, params) for s in (seg, seg.unended, seg.rolling) if s is not None]

    def cue_window(speed, t0):
        if touched is None or not np.isfinite(t0):
            return 0.0
        # The run reached from t0 counts as the cue's as well: a first fit's
        # t0 placed most of a frame early put the run's first flagged frame
        # outside `near`, and the window, found from the segmentation's t0,
        # fell to nothing (docs/measurements.md, slip11: seed 43 shot 17).
        run = touched_run_s(t, touched, t0, exposure_s, frame_dt, foreign)
        near = np.abs(t - t0) <= (CUE_CLEAR_FRAMES + 0.5) * frame_dt
        if run <= 0 and not np.any(touched[near]):
            return 0.0
        return max(cue_clear_s(speed, params.R, frame_dt), run)

    clear_s = cue_window(np.hypot(*starts[0][2]), seg.t0) if starts else 0.0
    meas1 = measure(seg.t0, clear_s)
    first = _first_fit(meas1, params, starts, exposure_s, fit_friction)
    codec_var, t0, scale = 0.0, seg.t0, (1.0, float("inf"))
    if first is not None:
        if independent:
            scale = moving_scale(meas1, first.residuals, len(first.x))
        if not lossless and inter_frame:
            # Not below 0: the stated errors are the floor.  A negative
            # estimate says the first fit's residuals are smaller than the
            # stated errors allow, which is what a fit that absorbed a shared
            # step does: realistic seed 36 shot 5 (H.264, the track 1.22 px
            # off after the strike, 0.30 before) measured -0.046 px^2, the
            # stated errors shrunk and z 5.75 (docs/measurements.md,
            # h264new, chroma36).  The time correlation, not this variance,
            # carries the tracker's shared error (h264cov).
            codec_var = max(correlated_codec_var(first, meas1), 0.0)
        elif not lossless:
            codec_var = codec_excess(meas1, first.residuals, len(first.x))
        if abs(first.shot.t0 - seg.t0) < MAX_T0_SHIFT_FRAMES * frame_dt:
            t0 = first.shot.t0
            clear_s = cue_window(np.hypot(*first.shot.v0), t0)
    meas = measure(t0, clear_s, scale=scale).with_codec(codec_var)
    codec = CodecCorrelation(codec_var, frame_dt) if inter_frame and not lossless else None
    # An intra-frame lossy codec (MJPG): its error is shared by frames that
    # show the ball at nearly the same place (recover.mle.still_codec_sandwich).
    still = not lossless and not inter_frame
    decisions: dict[str, Decision] = {}
    mle = None
    hac = False  # no HAC sandwich: not autocorrelated, or the AR(1) model took it in
    # The errors' correlation in time, when they share it (an inter-frame
    # codec's, or AR(1) residuals): "sliding ended" is asked under it
    # (fit.segment.correlated_end_F), else a slide outlasting the track,
    # bent by its last frames' drift, reads as ended (docs/measurements.md,
    # gross13 class A, endf13).
    end_rho = None  # the AR(1) errors' lag-1 correlation, when the residuals show one

    def end_F():  # None: independent errors, the segmentation's own end_F
        if codec is None and end_rho is None:
            return None
        whiten = time_whitener(codec.acf) if codec is not None else time_whitener(rho=end_rho, frame_dt=frame_dt)
        return correlated_end_F(seg, t, xy, whiten)
    try:
        start = (first.shot.x0, first.shot.t0, first.shot.v0, first.shot.w0) if first else starts[0]
        full, roll = fit_models(meas, params, start, exposure_s, fit_friction,
                                initial_guess(seg.rolling, params), acf=None if codec is None else codec.acf)
        if codec is None:
            # Residuals correlated along the track (a lossy codec at low
            # noise): both models again under AR(1) errors of that lag-1
            # correlation, so their likelihood ratio and covariance hold.
            # A correlation the track states is used by construction, the
            # residuals' if larger.
            rho, z = lag1_autocorrelation(meas, full.residuals)
            decisions["autocorrelated"] = autocorrelated(rho, z, stated=ar1_floor > 0)
            if decisions["autocorrelated"]:
                # The residuals' lag-1 autocorrelation lies below the errors'
                # (the fit takes up their slowly varying part): the errors'
                # is the one that would show as much in these residuals.
                rho = ar1_from_residuals(meas, full, rho)
                if independent:  # the AR(1) model carries a lossless rest's correlation itself
                    meas = measure(t0, clear_s, group_rest=False, scale=scale).with_codec(codec_var)
                full, roll = fit_models(meas, params, (full.shot.x0, full.shot.t0, full.shot.v0, full.shot.w0),
                                        exposure_s, fit_friction,
                                        (roll.shot.x0, roll.shot.t0, roll.shot.v0, roll.shot.w0),
                                        ar1=max(rho, ar1_floor))
                end_rho = float(np.clip(max(rho, ar1_floor), 0.0, MAX_AR1))  # as fit_model takes it
        # An inter-frame codec: the whole error's correlation in time states
        # the errors (recover.mle.codec_sandwich), whatever codec variance the
        # first fit measured (a negative one too: the tracker's own error is
        # shared between neighbouring frames as much; docs/measurements.md
        # h264cov), so no HAC question is asked.
    except FIT_ERRORS as exc:
        mle = MLEResult("failed", f"the fit did not run: {exc}")
    gap = None
    if mle is None:
        lr = slip_lr(full, roll, meas, codec, hac)
        decisions["sliding_seen"] = sliding_seen(lr, slip_lr_without_largest(full, roll, lr))
        if decisions["sliding_seen"]:
            decisions["sliding_ended"] = sliding_ended(
                seg, t, phases(full.shot, full.params).t1, friction_known=not fit_friction,
                end_F=end_F())
            mle = with_profile_interval(result(full, meas, lr, decisions["sliding_ended"].yes, codec, still, hac),
                                        full, meas, exposure_s)
        else:
            # A ratio over its threshold on one measurement's share alone
            # (fit.decide.sliding_seen) leaves a slip the track may show: the
            # rolling fit's stated errors hold the slip it cannot exclude
            # (recover.mle.unseen_slip) and the gap to the free-slip fit that
            # the ratio alone would have answered with (neither excluded);
            # the paper's rolling segments' hold neither (paper_verdicts).
            in_one = slip_in_one_measurement(decisions["sliding_seen"], lr)
            gap = (np.concatenate([np.subtract(full.shot.v0, roll.shot.v0), np.subtract(full.shot.w0, roll.shot.w0)])
                   if in_one else None)
            mle = result(roll, meas, lr, True, codec, still, hac,
                         verdicts={"slip_in_one_measurement": in_one}, slip_gap=gap)
    else:
        decisions["sliding_ended"] = sliding_ended(seg, t, end_F=end_F())
    chosen = seg
    if "sliding_seen" in decisions and not decisions["sliding_seen"]:
        chosen = seg.rolling
    elif seg.unended is not None and not (decisions["sliding_ended"]
                                          and t1_in_view(seg.t1, t if seg.t2 is None else t[t <= seg.t2])):
        # Still sliding at the end, or (the ball seen at rest) sliding ran
        # into the rest (case 2): the segmentation's "unended" fit, which
        # then puts t1 where the sliding velocity vanishes (eq. 29).
        chosen = seg.unended
    paper, shape, agree = None, None, None
    strike_seen = strike_in_view(t, chosen.t0, touched, meas.xy, meas.cov)
    if run_paper:
        # The paper's errors are propagated from the same per-frame noise the
        # fit weights by: the tracker's, with the codec's measured share.
        paper_sigma = math.sqrt(sigma**2 + max(meas.codec_m2(codec_var), 0.0))

        def paper_of(s):
            return paper_from_segments(s, t, xy, params, paper_sigma, frame_dt, strike_seen, independent,
                                       meas=meas, noise=mle_noise(mle, codec))
        paper = paper_of(chosen)
        # Where the fit on the frames the recovery trusts (the cue's touched
        # run left out) refuses (paper_verdicts: trusted_frames_refuse), the
        # paper's answer is degenerate though its segmentation took the run's
        # frames.  paper32's answer from a second recovery on every frame in
        # its place (right on 32/22 and 71/0, in sample) found nothing to
        # answer on 80 held-out realistic H.264 shots (seeds 34 and 36:
        # paper ok with the fit not, 0 of 80), so it is not kept (fixpaper).
        if chosen is seg and seg.unended is not None and ran_into_rest(seg.unended):
            # Where sliding ended, at the segmentation's breakpoint or (case
            # 2) in the rest: the breakpoint's answer when its sliding time
            # (eq. 10) is the fit's, else the slide into the rest, decided
            # once here (realistic H.264 32/16: the breakpoint 0.13 s early
            # on the codec's excursion, its answer's sliding time z -4.3
            # from the fit's; case 2's answer within 0.6 stated errors;
            # paper32).  The slide into the rest's answer is then held to
            # the fit like any other, not chosen for agreeing.
            # The breakpoint's line answer refused because its sliding speed
            # does not roll to the rest (eq. 19; recover.paper.rolling_speed_z)
            # leaves the same two readings: sliding did not end at x1, so the
            # segmentation's other one, the slide into the rest, is taken
            # (realistic H.264 36/38: the rest found 66 ms early, the line's
            # answer 7.7 stated errors off; case 2's 0.68; docs/measurements.md,
            # p38, v1chk).
            if paper.rolling_speed is not None:
                decisions["rolling_speed_differs"] = paper.rolling_speed
            decisions["breakpoint_differs"] = sliding_times_differ(sliding_time_z(paper, mle, params))
            if decisions["breakpoint_differs"] or decisions.get("rolling_speed_differs"):
                chosen = seg.unended
                paper = paper_of(chosen)
        shape = paper.trajectory == "parabola" if paper.trajectory else None
        agree = sliding_times_agree(paper, mle, params)
        paper = paper_verdicts(paper, mle, chosen is seg.rolling, params, agree)
    seen = decisions.get("sliding_seen")
    fit = None if seen is None else (full if seen else roll)
    decided = Decided(
        sliding_seen=None if seen is None else bool(seen), sliding_ended=bool(decisions.get("sliding_ended", True)),
        segments="rolling" if chosen is seg.rolling else "unended" if chosen is seg.unended else "sliding",
        curved=shape, strike_seen=strike_seen, frames=(seg.k_move, seg.rest_k), t0=t0, codec_var=codec_var,
        start=None if fit is None else (fit.shot.x0, fit.shot.t0, fit.shot.v0, fit.shot.w0),
        paper=(paper.v0, paper.w0) if paper is not None and paper.status == "ok" else None,
        ar1=0.0 if fit is None else fit.ar1,
        breaks=(chosen.t0, float("inf") if runs_to_end(chosen) else chosen.t1) if chosen else None,
        hac=hac, verdicts=dict(mle.verdicts) or None, stop_apart=None if paper is None else paper.stop_apart,
        clear_s=clear_s, rest_scale=scale, sliding_times_agree=agree,
        slip_gap=None if gap is None else tuple(float(g) for g in gap))
    paper, mle = unexplained(paper, mle, meas, codec_var, sigma,
                             lambda: rolling_fit(t, xy, cov, meas.px_to_m, params, mle, chosen, exposure_s, frame_dt, sigma,
                                                 acf=None if codec is None else codec.acf),
                             step=step_r(meas, fit, exposure_s, mle))
    return Estimate(chosen, paper, mle, meas, codec_var, decisions,
                    {"fit": t_fit, "recover": time.perf_counter() - clock}, decided)


def _refit(keep: Decided, seg, t, xy, cov, params, exposure_s, fit_friction, run_paper, lossless, sigma,
           frame_dt, measure, codec, t_fit, clock, independent: bool) -> Estimate:
    """:func:`estimate` keeping an earlier recovery's decisions (``keep``):
    the same model fitted from the earlier answer, the same segmentation,
    path shape and root for the paper's method."""
    nan = float("nan")
    chosen = kept_segments(seg, keep)
    meas = measure(keep.t0, keep.clear_s, group_rest=not keep.ar1, scale=keep.rest_scale).with_codec(keep.codec_var)
    decisions = {"sliding_ended": Decision(keep.sliding_ended, nan, nan)}
    mle, fit = None, None
    if keep.sliding_seen is None or keep.start is None:
        mle = MLEResult("failed", "the fit did not run on the first camera")
    else:
        decisions["sliding_seen"] = Decision(keep.sliding_seen, nan, nan)
        rolling = not keep.sliding_seen
        try:
            fit = fit_model(meas, params, keep.start, exposure_s, rolling, fit_friction, keep.ar1,
                            None if codec is None else codec.acf)
            mle = result(fit, meas, nan, keep.sliding_ended or rolling, codec, not lossless and codec is None,
                         keep.hac, keep.verdicts, slip_gap=keep.slip_gap if rolling else None)
        except FIT_ERRORS as exc:
            mle = MLEResult("failed", f"the fit did not run: {exc}")
    paper = None
    if run_paper and seg and chosen is None:
        paper = PaperResult("failed", f"the segmentation kept from the first camera ({keep.segments}) is not "
                            "found through this camera")
    elif run_paper and seg:
        paper_sigma = math.sqrt(sigma**2 + max(meas.codec_m2(keep.codec_var), 0.0))
        paper = paper_from_segments(chosen, t, xy, params, paper_sigma, frame_dt, keep.strike_seen, independent,
                                    curved=keep.curved, near=keep.paper, apart=keep.stop_apart, meas=meas,
                                    noise=mle_noise(mle, codec))
        paper = paper_verdicts(paper, mle, keep.segments == "rolling", params, keep.sliding_times_agree)
    paper, mle = unexplained(paper, mle, meas, keep.codec_var, sigma,
                             # the tracker's stated cov, as in estimate: rolling_slope measures the codec's
                             # share itself (meas.cov already holds it; review 12b: ratios went negative)
                             lambda: rolling_fit(t, xy, cov, px_to_m=meas.px_to_m, params=params, mle=mle,
                                                 seg=chosen or seg, exposure_s=exposure_s, frame_dt=frame_dt,
                                                 sigma=sigma, acf=None if codec is None else codec.acf),
                             step=step_r(meas, fit, exposure_s, mle))
    return Estimate(chosen or seg, paper, mle, meas, keep.codec_var, decisions,
                    {"fit": t_fit, "recover": time.perf_counter() - clock}, keep)


def paper_verdicts(paper, mle, rolling: bool, params: BallParams, agree: bool | None = None):
    """The paper's answer ``paper``, or ``degenerate`` with the fit's reason
    where the fit's verdicts (recover.mle.result, asked of the frames the
    recovery trusts) say the frames cannot know what the paper's answer
    rests on.  From the rolling segments (``rolling``): a slide hidden by
    the cue's window (sample_shot(1, "case5") at 60 fps, the window 1.1
    times the bound: 29% off, answered ok) or outlasting every frame seen
    is not excluded (``slide_hidden``, ``slide_outlasts``).  Any segments:
    v0 not determined, the strike not in view, or the slide seen in too few
    frames, by the frames left after the cue's touched run
    (:func:`trusted_frames_refuse`): the paper's
    segmentation takes x0 and the slide's start from all frames, those
    touched by the cue too (realistic H.264 seed 32 shot 0: the cue's run
    frames 31-57, the segmentation's t1 26 ms early, v0 19% off at 10 of its
    stated errors; docs/measurements.md, paper11).  Any segments: a slide
    through every frame not excluded by the fit (``slide_ends`` False).
    Then ``failed`` when the answer's sliding time disagrees with the fit's
    (:func:`sliding_times_agree`; ``agree`` False, an earlier answer of it on
    the same track kept by a refit; None: asked here)."""
    if paper is None or paper.status != "ok" or mle is None:
        return paper
    v = mle.verdicts or {}
    if rolling and (v.get("slide_hidden") or v.get("slide_outlasts")):
        return PaperResult("degenerate", mle.reason)
    if rolling and v.get("slip_in_one_measurement"):
        # A slip seen in one measurement alone is not told from its error
        # (fit.decide.sliding_seen), nor excluded: the rolling segments'
        # answer holds none (short_slide_shot(5, 148) of tests/
        # test_recover.py, a 0.70-frame slip at 60 fps: ratio 28.2, 8.8
        # without its largest share; the paper's rolling answer 0.015 m/s off
        # at 2,000 of its stated errors, the fit's 0.86; docs/measurements.md, slip2).
        return PaperResult("degenerate", "the slip ratio passes its threshold on one measurement alone: a slip "
                           "the track may show is neither seen nor excluded, and the paper's rolling "
                           "segments hold none")
    if rolling and mle.status == "failed":
        # No rolling fit to bound the slip the track cannot exclude (the fit
        # failed): the rolling segments' answer would state x0's and x2's
        # errors alone (late review of papshort).
        return PaperResult("degenerate", "the rolling segments' answer holds no slip, and without the fit's rolling "
                           f"answer the slip the track cannot exclude is not bounded ({mle.reason})")
    if rolling and getattr(mle, "model", "") == "rolling":
        # The rolling segments' answer (case 4, x1 at x0) holds no slip;
        # the track cannot exclude one up to the fit's unseen slip, whose
        # errors the fit's rolling answer states and the paper's now too
        # (recover.paper.with_unseen_slip; docs/measurements.md, papshort).
        paper = with_unseen_slip(paper, float(mle.unseen_slip or 0.0), params)
    if v.get("slide_ends") is False:
        # The fit's end of sliding does not exclude a slide through every
        # frame (recover.mle.result's slide_ends, asked of the free-slip
        # model whatever segments the paper took): x1, and so the paper's
        # answer, rests on an end of sliding the track does not show
        # (realistic H.264 37/31: the true slide ends 0.07 s after the last
        # fitted frame, the paper's x1 16 cm off, w0 9.9 stated errors off and
        # given as best; of the 20 paper answers ok on seeds 37/38 the one so
        # refused; held37).
        return PaperResult("degenerate", mle.reason)
    if v.get("sliding_ended") is False:
        # The fit's slide outlasts the track (recover.mle.result): a rest the
        # segmentation found, and case 2's slide into it, is a slow moment of
        # a slide going on (realistic MJPG 49/48, 240 fps: a spin-reversed
        # slide of 1.9 s, the segmentation's rest at 1.43 s, the track ending
        # at 1.50 s; case 2's answer ok with w0 1,573 stated errors off;
        # docs/measurements.md, papshort).
        return PaperResult("degenerate", mle.reason)
    if trusted_frames_refuse(mle):
        return PaperResult("degenerate", mle.reason)
    if agree is None:
        agree = sliding_times_agree(paper, mle, params)
    if agree is False:
        tau_f, se_f = fit_sliding_time(mle, params)
        z = sliding_time_z(paper, mle, params)
        why = (f"the answer slides {sliding_time(paper.v0, paper.w0, params):.3f} s (eq. 10) where "
               f"the maximum-likelihood fit measures {tau_f:.3f} s (standard error {se_f * 1e3:.1f} ms): "
               f"{abs(z):.1f} of their errors apart (more than {PAPER_FIT_TAU_Z:g}), so the segmentation's "
               "end of sliding, x1, is not where the track's sliding ends"
               if np.isfinite(z) else "the answer's sliding time disagrees with the maximum-likelihood fit's")
        return PaperResult("failed", why, paper.trajectory, x0=paper.x0, x1=paper.x1, x2=paper.x2)
    return paper


def trusted_frames_refuse(mle) -> bool:
    """The fit's verdicts on the frames the recovery trusts say v0 is not
    determined, the strike not in view, or the slide seen in fewer than
    ``MIN_SLIDING_FRAMES`` of them (``v0_determined``, ``strike_seen``,
    ``sliding_frames``: recover.mle.result).  The last joined when a
    simulated slide covered by the cue's touched run (tests/
    test_paper_sliding_time.py, track 4) ended the fit, on another
    machine's numpy/BLAS build, where v0 is determined but the slide is
    seen in 2 trusted frames: the paper's segmentation had taken the
    touched frames for that slide."""
    v = mle.verdicts or {}
    return (v.get("v0_determined") is False or v.get("strike_seen") is False
            or v.get("sliding_frames") is False)


def sliding_times_agree(paper, mle, params: BallParams) -> bool | None:
    """The paper's answer's sliding time (eq. 10) within
    :data:`~cuespin.fit.decide.PAPER_FIT_TAU_Z` errors of the
    maximum-likelihood fit's (:func:`sliding_time_z`,
    fit.decide.sliding_times_differ); None when not asked (either not
    ``ok``, or without a slide or errors)."""
    z = sliding_time_z(paper, mle, params)
    return None if not np.isfinite(z) else not sliding_times_differ(z)


def fit_sliding_time(mle, params: BallParams) -> tuple[float, float]:
    """The maximum-likelihood answer's sliding time ``t1 - t0`` (s, eq. 10)
    and its standard error (s) by the delta method on the fit's stated
    covariance (:attr:`recover.mle.MLEResult.cov`, ``v0``, ``w0`` and, when
    fitted, ``mu_s``); NaNs unless the fit answered ``ok`` with slip fitted."""
    nan = (float("nan"), float("nan"))
    if mle is None or mle.status != "ok" or mle.model != "full" or mle.cov is None or mle.t1 is None:
        return nan
    names = list(mle.names)
    mu_s = mle.mu_s if mle.mu_s is not None else params.mu_s
    fitted = BallParams(R=params.R, mu_s=mu_s, mu_r=params.mu_r, g=params.g)
    tau = sliding_time(mle.v0, mle.w0, fitted)
    C = np.asarray(mle.cov, float)
    idx = [names.index(k) for k in ("v0x", "v0y", "w0x", "w0y")]
    var = sliding_time_stderr(mle.v0, mle.w0, C[np.ix_(idx, idx)], fitted) ** 2
    if "mu_s" in names:  # tau = 2 |u0| / (7 mu_s g): d tau / d mu_s = -tau / mu_s, and its terms with v0, w0
        k = names.index("mu_s")
        u0 = np.asarray(mle.v0, float) + params.R * z_cross(np.asarray(mle.w0, float))
        u_hat = u0 / max(float(np.hypot(*u0)), 1e-300)
        g = np.zeros(len(names))
        g[idx] = 2.0 / (7.0 * mu_s * params.g) * np.r_[u_hat, params.R * np.array([u_hat[1], -u_hat[0]])]
        g[k] = -tau / mu_s
        var = float(g @ C @ g)
    return tau, float(np.sqrt(max(var, 0.0)))


def sliding_time_z(paper, mle, params: BallParams) -> float:
    """The paper's answer's sliding time (eq. 10) against the
    maximum-likelihood answer's (:func:`fit_sliding_time`), in the two
    stated errors added in quadrature: ``(tau_paper - tau_fit) / sqrt(se_paper^2
    + se_fit^2)``.  Both are measured by the same frames, so this is not
    the difference's error: its spread on right answers is measured
    (fit.decide.PAPER_FIT_TAU_Z: sd 1.09 under H.264's shared error, tails
    heavier than the normal's).  NaN unless both answered ``ok`` with a
    slide and both state the errors."""
    if paper is None or paper.status != "ok" or paper.cov is None:
        return float("nan")
    tau_f, se_f = fit_sliding_time(mle, params)
    tau_p = sliding_time(paper.v0, paper.w0, params)
    se_p = sliding_time_stderr(paper.v0, paper.w0, paper.cov, params)
    if not (np.isfinite(tau_f) and np.isfinite(se_p) and se_f + se_p > 0):
        return float("nan")
    return float((tau_p - tau_f) / np.hypot(se_p, se_f))


def step_r(meas: Measurements, fit: ModelFit | None, exposure_s: float, mle) -> float:
    """The chosen fit's largest step along the track
    (recover.measurements.track_step) in ball radii; 0 without a fit that
    ran (``mle`` failed)."""
    if fit is None or mle is None or mle.status == "failed" or meas is None:
        return 0.0
    return track_step(meas, model_track(fit.shot, fit.params, meas.t_used, exposure_s)) / fit.params.R


def unexplained(paper, mle, meas: Measurements, codec_var: float, sigma: float, rolling=None, step: float = 0.0):
    """Both methods' answers refused (``failed``) when the codec noise the
    recovery had to add to explain the track is over
    :data:`MAX_CODEC_NOISE_RATIO` times the tracker's stated error
    (recover.measurements.codec_noise_ratio): the model then does not
    explain the track, and the codec term hides the misfit from chi2.  Both
    methods weight by that noise (the paper's errors through
    ``paper_sigma``), so one decision answers both.  ``rolling``, called
    only then, gives the rolling phase's fit with a slope
    (:func:`rolling_fit`): when a slope explains the track
    (:attr:`recover.slope.SlopeFit.explains`) the reason names it.  Refused
    too when the track steps (``step``, :func:`step_r`, over
    :data:`~cuespin.recover.measurements.MAX_STEP_R` ball radii): the
    frames either side are not one ball's (the codec guard's reason first
    when both apply).  Returns ``(paper, mle)``,
    unchanged otherwise."""
    ratio = codec_noise_ratio(meas, codec_var, sigma)
    if ratio > MAX_CODEC_NOISE_RATIO:  # its reason first: a slope, friction or collision names the cause
        slope = rolling() if rolling is not None else None
        if slope is not None and slope.explains:
            why = f"the model does not explain the track: {slope.reason()}"
        else:
            why = (f"the model does not explain the track: the fit needed {ratio:.0f} times the tracker's stated "
                   f"error as codec noise (at most {MAX_CODEC_NOISE_RATIO:.0f} on correct answers): a wrong "
                   "friction (mu_r; --fit-friction or the cloth's value), a table not level, or a collision")
    elif step > MAX_STEP_R:
        why = (f"the track steps: the fit misses the frames either side of one point by {step:.1f} ball radii "
               f"apart (at most {MAX_STEP_R:.0f} on correct answers): they are not the same ball's centre "
               "(the cue's tip or another ball taken for it), or a collision")
    else:
        return paper, mle
    if mle is not None and mle.status != "failed":
        mle = MLEResult("failed", why, chi2=mle.chi2, dof=mle.dof)
    if paper is not None and paper.status != "failed":
        paper = PaperResult("failed", why)
    return paper, mle


def rolling_fit(t, xy, cov, px_to_m, params: BallParams, mle, seg, exposure_s: float, frame_dt: float, sigma: float,
                acf=None):
    """The rolling phase's fit with a slope (recover.slope.rolling_slope):
    the frames from a frame after the fit's end of sliding (``mle.t1``, else
    the segmentation's) to the segmentation's rest, under the friction the
    fit used; None when neither places the end of sliding.  ``acf``: an
    inter-frame codec's correlation in time (the recovery's
    CodecCorrelation.acf), None otherwise."""
    t1 = getattr(mle, "t1", None)
    if t1 is None or not np.isfinite(t1):
        t1 = getattr(seg, "t1", float("nan"))
    if not np.isfinite(t1):
        return None
    t2 = getattr(seg, "t2", None)
    t2 = float("inf") if t2 is None or not np.isfinite(t2) else t2
    sel = (t > t1 + 0.5 * exposure_s + frame_dt) & (t < t2 - 0.5 * exposure_s)
    mu_r = getattr(mle, "mu_r", None) or params.mu_r
    pm = None if px_to_m is None else np.asarray(px_to_m)[sel]
    return rolling_slope(t[sel], xy[sel], cov[sel], rolling_deceleration(mu_r, params.g), sigma, pm, params.g, acf=acf)


def mle_noise(mle, codec: CodecCorrelation | None = None) -> tuple[float, float, tuple | None]:
    """The maximum-likelihood fit's error model for the paper's inputs
    (recover.measurements.linear_covariance): ``(ar1, scale, acf)``, its
    errors' lag-1 correlation, the factor its own errors carry (``max(1,
    chi2/dof)``, or the track's shared scale when larger:
    recover.mle.MLEResult.error_scale; the paper's inputs are measured by
    the same drifting frames) and an inter-frame codec's correlation in time (``codec``'s
    ``acf``, as the fit's codec_sandwich states its errors; None without
    one).  The codec's correlation holds whatever the fit answered: it is
    the measurements' model, not the fit's finding.  (Before, the paper's
    errors took H.264's frames as independent: its 95% intervals covered
    81.2% on realistic H.264, RMS 8.8 stated errors; docs/measurements.md,
    paper11.)"""
    acf = None if codec is None else codec.acf
    if mle is None or mle.status != "ok":
        return 0.0, 1.0, acf
    ar1 = float(getattr(mle, "ar1", 0.0) or 0.0)
    chi2 = getattr(mle, "chi2", float("nan")) / max(getattr(mle, "dof", 0), 1)
    scale = max(1.0, chi2) if np.isfinite(chi2) else 1.0
    factor = float(getattr(mle, "error_scale", 1.0))
    return (ar1 if np.isfinite(ar1) else 0.0), (max(scale, factor) if np.isfinite(factor) else scale), acf


def runs_to_end(seg) -> bool:
    """The segmentation's sliding lasts to the end of the motion: still
    sliding when the track ends (``t1`` inf), or running into the rest
    (case 2, recover.paper.ran_into_rest)."""
    return bool(not np.isfinite(seg.t1) or ran_into_rest(seg))


def kept_segments(seg, keep: Decided):
    """The refit's segmentation of the kind ``keep`` chose: rolling from the
    strike, sliding to the end of the motion, or a breakpoint in view
    (searched from ``keep.breaks``); None when this camera's segmentation
    has none of that kind (never another kind in its place)."""
    if keep.segments == "rolling":
        return seg.rolling
    if keep.breaks is None:  # an older Decided: by its label
        return {"unended": seg.unended}.get(keep.segments, seg) or seg
    to_end = not np.isfinite(keep.breaks[1])
    for s in (seg, seg.unended):
        if s is not None and runs_to_end(s) == to_end:
            return s
    return None
