"""Strike, sliding/rolling breakpoint and rest from a time-stamped track.

The path is fitted with the piecewise-quadratic kinematics the paper
predicts: at rest at ``x0`` before ``t0``; a constant, free acceleration
``a_s`` while sliding (eq. 9: ``-mu_s g u_hat``, so mu_s need not be known)
until ``t1``; the rolling deceleration ``(5/7) mu_r g`` along ``-v1_hat``
(eq. 18) after; position and velocity continuous.  Rolling's acceleration
must be the known one: left free, a "rolling" phase can impersonate sliding.
For fixed ``(t0, t1)`` the model is linear in ``(x0, v0, a_s)`` once the
direction of ``v1`` is known (taken from a first solve), so the breakpoints
are found by profiling the least-squares cost: a coarse scan, then a
refinement to a fraction of a frame.  ``t1`` may lie beyond the track: the
ball left the view still sliding.
The rest at the end, when in view, is where the ball stays within noise of
its last position.  Pure functions of arrays.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cuespin.fit.decide import T1_END_MARGIN_FRAMES

# Consecutive end frames within this many sigma of the final position are at rest.
REST_SIGMAS = 5.0
MIN_REST_FRAMES = 5
# Refits of a slide that runs into the rest (case 2) with the frames up to
# its fitted stop (fit.segment._finish).
CASE2_REFITS = 2
# The rest's frames must show no drift: the fitted velocity over them within
# this many standard errors of zero (two axes: 3.5 leaves a resting ball
# called moving about 0.2% of the time, chi^2(2) > 12.25).
REST_DRIFT_Z = 3.5
# A rest must last this long (s): at 480 fps a ball rolling at 5 cm/s stays
# within 5 sigma (1e-4 m) of its last position for 5 frames (10 ms), and 5
# frames cannot show its drift (recover.simulate tracks cut while rolling).
MIN_REST_S = 0.05
# Frames of motion needed before any fit is attempted.
MIN_MOVING_FRAMES = 6
# The strike is the first of this many consecutive frames away from the start.
MOVE_CONFIRM_FRAMES = 3
# The sliding fit's slide (t1 after t0, ended in view or running on) is a
# slide only where its fitted acceleration is a slide's: |a_s| (eq. 9:
# mu_s g) at least this many times the rolling deceleration (eq. 18: (5/7)
# mu_r g).  Left free, a_s equal to rolling's makes "sliding" up to any t1
# the same path as rolling, the profile over t1 is flat there, and its
# minimum fell seconds into the rolling on short slides
# (benchmarks/short_slide.py's draws with the rest in view, seeds 5 and 6,
# 300 shots: 23 breakpoints more than 10 frames off, 14 of them 25-2155
# frames, |a_s| equal to the rolling deceleration to 1e-4; with the rule 4,
# at most 18 frames; docs/measurements.md, seg11).  The sampler's friction
# (mu_s 0.1-0.3, mu_r 0.005-0.02) puts the true ratio at 7 or more; 5
# leaves the slide's estimated a_s 30% below that.  2.5 was tried: 4 of the
# first 138 of those shots more than 10 frames off (12-27), its minimum
# held on the rule's boundary, against 1 with 5.  Sliding and case-2 tracks
# (recover.simulate, 120 each): every breakpoint the same as without it.
SLIDE_DECEL_RATIO = 5.0
# The rule decides the breakpoint when the best one's |a_s| sits on its
# bound (the search's minimum held against it): the data preferred a slower
# slide, so the slide's end is not identified (Segments.t1_bound), not a
# measured t1.  A minimum held there lies within 1e-3 of the bound (the
# search refines to 1e-3 frame); a free one at 1.015 or more of it
# (short_slide's draws seeds 5, 6, short_slip_tracks seeds 41, 42,
# null_rolling_tracks seed 7: 810 tracks; docs/measurements.md, seg12).
SLIDE_BOUND_REL = 0.01


@dataclass(frozen=True)
class Segments:
    """Phases found in a track; falsy when it could not be segmented.

    Times in s, positions in m, velocities in m/s, accelerations in m/s^2.
    This is the fit with a sliding phase at its best breakpoints; the
    questions "is sliding seen at all?" and "did it end in view?" are
    decided elsewhere (fit.decide) and answered by choosing among the
    alternatives kept here: ``rolling`` (rolling from the strike, ``t1 ==
    t0``) and ``unended`` (still sliding when the track ended, ``t1`` inf);
    ``end_F`` is the F statistic of the breakpoint found against
    ``unended`` (1 and ``end_dof`` degrees of freedom; 0 when the best fit is
    already unended).  ``t2``/``x2`` are None when no rest is in view; ``t1``
    is ``inf`` (and ``x1``, ``v1`` extrapolated to the last frame) when the
    ball was still sliding when the track ended.  ``slide`` and ``roll``
    index the frames of each phase; ``sigma`` is the position noise (m) the
    fit's residuals show; ``k_move`` the first frame seen moving and
    ``rest_k`` the first frame of the final rest (None: no rest in view).
    ``t1_bound`` is True when the breakpoint is held on the sliding
    deceleration's bound (:data:`SLIDE_DECEL_RATIO`): the slide's end is
    then not identified (a slide too short to show its deceleration, or a
    cloth whose mu_s g is under that many times the rolling deceleration),
    and ``t1`` is where the bound put it, not a measurement.
    ``geometry_cov`` holds the covariances (m^2, 2x2) of ``x0``, ``x1``,
    their cross term and ``x2`` (keys ``x0``, ``x1``, ``x0x1``, ``x2``), with
    every frame's error independent at ``sigma``; and, for their covariance
    under the track's own errors (recover.paper.geometry_covariance: a lossy
    codec's still frames share theirs), the estimates' weights: ``x0 =
    sum_k w[k, 0] xy[frames_k]`` (``v0``, ``a_slide``: columns 1 and 2),
    ``x1`` likewise by ``w1`` (plus the breakpoints' shares ``x1_t1``,
    ``x0_t0`` and ``x0x1_t``), and
    ``x2`` the mean of ``xy[rest]``.  Where the fit's profile does not
    curve about the breakpoints those shares are zero: their errors are not
    measured there (:func:`_geometry_cov`; docs/measurements.md, gapcov: on
    a slide into the rest the paper's answers then cover less).
    """

    ok: bool
    reason: str
    t0: float = float("nan")
    x0: np.ndarray | None = None
    t1: float = float("nan")
    x1: np.ndarray | None = None
    v0: np.ndarray | None = None
    v1: np.ndarray | None = None
    a_slide: np.ndarray | None = None
    a_roll: np.ndarray | None = None
    t2: float | None = None
    x2: np.ndarray | None = None
    slide: np.ndarray | None = None
    roll: np.ndarray | None = None
    sigma: float = float("nan")
    t_last: float = float("nan")
    residuals: np.ndarray | None = None
    end_F: float = 0.0
    end_dof: int = 1
    k_move: int = 0
    rest_k: int | None = None
    geometry_cov: dict | None = None
    rolling: "Segments | None" = None
    unended: "Segments | None" = None
    t1_bound: bool = False

    def __bool__(self):
        return self.ok


def _path_basis(t, t0s, t1s):
    """The fixed-breakpoint path's basis (eq. 18's sliding-then-rolling
    form) at times ``t`` (n,) for breakpoints ``t0s``, ``t1s`` (K,): the
    time since the strike ``tau`` (K, n), the sliding time ``tau1`` (K, 1),
    the sliding acceleration's coefficient ``c2 = ts^2 / 2 + tau1 tr`` and
    the rolling one's ``tr^2 / 2`` (K, n), ``ts`` the time sliding, ``tr``
    rolling."""
    tau = np.maximum(t[None, :] - t0s[:, None], 0.0)   # (K, n)
    tau1 = np.maximum(t1s - t0s, 0.0)[:, None]         # (K, 1)
    ts = np.minimum(tau, tau1)
    tr = tau - ts                                      # time rolling
    return tau, tau1, 0.5 * ts**2 + tau1 * tr, 0.5 * tr**2


def _solve_many(t, xy, t0s, t1s, decel):
    """Least squares for fixed breakpoints, for many ``(t0, t1)`` at once.

    For fixed ``(t0, t1)`` the path is linear in ``x0, v0, a_s`` (per axis):
    ``x = x0 + v0 tau + a_s (ts^2/2 + tau1 tr) + a_r tr^2/2`` with ``tau`` the
    time since ``t0``, ``ts`` its part before ``t1`` and ``tr`` after; the
    rolling acceleration ``a_r`` is ``decel`` along ``-v1`` (eq. 18), its
    direction taken from a first solve.  Normal equations, batched over the
    pairs (``t0s`` and ``t1s`` broadcast to one shape (K,)): this is the
    inner loop of the search.  A sliding phase of zero length (case 4:
    rolling from the strike) drops the sliding term.

    Returns the sums of squared residuals, shape (K,), the coefficients
    ``[x0, v0, a_s, a_r]``, shape (K, 4, 2), and the residuals (K, n, 2).
    """
    t0s, t1s = np.broadcast_arrays(np.atleast_1d(np.asarray(t0s, dtype=float)),
                                   np.atleast_1d(np.asarray(t1s, dtype=float)))
    tau, tau1, c2, roll = _path_basis(t, t0s, t1s)
    K, n = c2.shape
    AtA = np.empty((K, 3, 3))
    AtA[:, 0, 0] = n
    AtA[:, 0, 1] = AtA[:, 1, 0] = tau.sum(axis=1)
    AtA[:, 1, 1] = np.einsum("kn,kn->k", tau, tau)
    AtA[:, 0, 2] = AtA[:, 2, 0] = c2.sum(axis=1)
    AtA[:, 1, 2] = AtA[:, 2, 1] = np.einsum("kn,kn->k", c2, tau)
    AtA[:, 2, 2] = np.einsum("kn,kn->k", c2, c2)
    no_slide = tau1[:, 0] < 1e-9
    AtA[no_slide, 2, :] = AtA[no_slide, :, 2] = 0.0
    AtA[no_slide, 2, 2] = 1.0
    Atxy = np.empty((K, 3, 2))
    Atxy[:, 0] = xy.sum(axis=0)
    Atxy[:, 1] = tau @ xy
    Atxy[:, 2] = c2 @ xy
    Atroll = np.stack([roll.sum(axis=1), np.einsum("kn,kn->k", roll, tau),
                       np.einsum("kn,kn->k", roll, c2)], axis=1)
    Atroll[no_slide, 2] = 0.0
    Atxy[no_slide, 2] = 0.0
    a_r = np.zeros((K, 2))
    for _ in range(2):  # the direction of v1 from the previous solve
        rhs = Atxy - Atroll[:, :, None] * a_r[:, None, :]
        try:
            coef = np.linalg.solve(AtA, rhs)
        except np.linalg.LinAlgError:
            coef = np.stack([np.linalg.lstsq(M, r, rcond=None)[0] for M, r in zip(AtA, rhs)])
        v1 = coef[:, 1] + coef[:, 2] * tau1
        speed = np.hypot(v1[:, 0], v1[:, 1])[:, None]
        a_r = np.where(speed > 0, -decel * v1 / np.where(speed > 0, speed, 1.0), 0.0)
    # The path x0 + v0 tau + a_s c2 + a_r roll and its residuals, an axis at
    # a time: (K, n) arrays, not (K, n, 2) ones broadcast from (K, 1, 2)
    # (4 times slower: this was most of the search's time), the same
    # operations in the same order, so the same numbers.
    res = np.empty((K, n, 2))
    model, term = np.empty((K, n)), np.empty((K, n))
    for d in (0, 1):  # in place, the same operations in the same order
        np.multiply(tau, coef[:, 1, d, None], out=term)
        np.add(coef[:, 0, d, None], term, out=model)
        np.multiply(c2, coef[:, 2, d, None], out=term)
        model += term
        np.multiply(roll, a_r[:, d, None], out=term)
        model += term
        np.subtract(xy[None, :, d], model, out=res[:, :, d])
    flat = res.reshape(K, 2 * n)
    sse = np.einsum("kj,kj->k", flat, flat)
    return sse, np.concatenate([coef, a_r[:, None, :]], axis=1), res


def _solve(t, xy, t0, t1, decel):
    """:func:`_solve_many` for one pair: (SSE, coefficients (4, 2), residuals (n, 2))."""
    sse, coef, res = _solve_many(t, xy, t0, t1, decel)
    return float(sse[0]), coef[0], res[0]


def _zoom(cost_many, t0, t1, h0, h1, tol, points=7, shrink=3.0, max_rounds=40):
    """Minimise ``cost_many(t0s, t1s)`` by a grid around ``(t0, t1)`` that
    re-centres on its best point and shrinks until finer than ``tol``.

    The profile has kinks wherever a frame changes phase, which stall
    derivative-free simplex and bracketing methods; a grid steps over them,
    and each round is one batched evaluation.  ``h1 = 0`` searches ``t0``
    alone with ``t1 = t0`` (rolling from the strike).  Returns
    ``(t0, t1, cost)``.
    """
    u = np.linspace(-1.0, 1.0, points)
    best = float("inf")
    for _ in range(max_rounds):
        if h1 > 0:
            g0, g1 = np.meshgrid(t0 + h0 * u, t1 + h1 * u, indexing="ij")
            g0, g1 = g0.ravel(), g1.ravel()
        else:
            g0 = t0 + h0 * u
            g1 = g0
        c = cost_many(g0, g1)
        k = int(np.argmin(c))
        moved = c[k] < best
        if moved:
            best, t0, t1 = float(c[k]), float(g0[k]), float(g1[k])
        i0, i1 = divmod(k, points) if h1 > 0 else (k, 1)
        inside = 0 < i0 < points - 1 and 0 < i1 < points - 1
        if inside or not moved:  # the minimum is held in the box: look closer
            h0, h1 = h0 / shrink, h1 / shrink
        if h0 < tol and h1 < tol:
            break
    return t0, t1, best


def find_rest_end(t, xy, sigma):
    """Index of the first frame of the final rest, or None if the ball is
    still moving (or gone) at the end."""
    n = len(t)
    if n < MIN_REST_FRAMES:
        return None
    end = np.median(xy[-MIN_REST_FRAMES:], axis=0)
    near = np.hypot(*(xy - end).T) < REST_SIGMAS * sigma
    if not near[-MIN_REST_FRAMES:].all():
        return None
    k = n - 1
    # One frame alone beyond REST_SIGMAS does not end the rest: against the
    # median of the last frames (itself noisy) a still frame lies that far
    # about once in 10^4, and a rest of hundreds of frames (480 fps) then
    # ended there, 58-85 frames after the stop, in about one case-2 track
    # in a hundred; the slide's quadratic fitted through those still frames
    # put its stop 6-40 of its errors past the rest (calibrate_tests.py
    # --which case2).  Two in a row do; a ball creeping to its stop is cut
    # from the rest by the drift test below.
    while k > 0 and (near[k - 1] or (k > 1 and near[k - 2])):
        k -= 1
    # A ball still rolling slowly stays within noise of its last position for
    # a few frames at a high frame rate, and a stopping ball creeps into its
    # rest: the rest is the frames from the end that show no drift (their
    # fitted velocity within REST_DRIFT_Z standard errors of zero), moving
    # the window's start on while they do, and lasting MIN_REST_S.
    def drifts(k):
        tt = t[k:] - t[k:].mean()
        ss = max(float(tt @ tt), 1e-300)
        slope = (tt @ (xy[k:] - xy[k:].mean(axis=0))) / ss
        return np.hypot(*slope) * np.sqrt(ss) / sigma > REST_DRIFT_Z

    step = max(1, (n - k) // 20)  # small steps: frames past the stop in the fit would misfit it
    while n - k >= 2 * MIN_REST_FRAMES and drifts(k):
        k += step
    if n - k < MIN_REST_FRAMES or t[-1] - t[k] < MIN_REST_S or drifts(k):
        return None
    return k


def noise_from_track(xy) -> float:
    """Per-axis position noise (m) from second differences of consecutive
    positions: motion contributes ``a dt^2``, tiny at video rates, so the
    robust spread of second differences is ``sqrt(6)`` times the noise."""
    xy = np.asarray(xy, dtype=float)
    d2 = xy[2:] - 2 * xy[1:-1] + xy[:-2]
    if len(d2) < 3:
        return float("nan")
    mad = np.median(np.abs(d2 - np.median(d2, axis=0)), axis=0) * 1.4826
    return float(np.sqrt(np.mean(mad**2)) / np.sqrt(6.0))


def segment_track(t, xy, decel: float, sigma: float | None = None,
                  exposure_s: float = 0.0, frames: tuple | None = None,
                  breaks: tuple | None = None) -> Segments:
    """Find the strike, the end of sliding and the rest in a track.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Frame times (s) of the frames where the ball was found.
    xy : ndarray, shape (n, 2)
        Ball centre (m) in those frames.
    decel : float
        Rolling deceleration ``(5/7) mu_r g`` (m/s^2), eq. 16.
    sigma : float, optional
        Per-axis position noise (m); estimated from the track when absent.
    exposure_s : float
        Exposure (s).  Frames whose exposure may hold the strike are left out
        of the fit: a half-still, half-streaking ball has a biased centre,
        and that bias near the strike would pass for a sliding phase.
    frames : tuple, optional
        ``(k_move, rest_k)`` of an earlier segmentation of the same frames
        (its Segments' fields): the first moving frame and the rest's first
        frame are kept instead of found again (a refit of the same track
        through another camera, recover.calibration).
    breaks : tuple, optional
        ``(t0, t1)`` (s) of an earlier segmentation of the same frames whose
        kind is kept: the breakpoints are refined from there, and a
        breakpoint in view (``t1`` finite and after ``t0``) stays in view,
        so a refit through another camera gets the same kind of answer (a
        sliding phase that ends, or one that runs to the end: ``t1`` inf).

    Returns
    -------
    Segments
        Never raises for bad data: ``ok`` False with a reason instead.
    """
    t = np.asarray(t, dtype=float)
    xy = np.asarray(xy, dtype=float)
    good = np.all(np.isfinite(xy), axis=1) & np.isfinite(t)
    t, xy = t[good], xy[good]
    if len(t) < MIN_MOVING_FRAMES + 2:
        return Segments(False, f"only {len(t)} frames with the ball found")
    if sigma is None or not np.isfinite(sigma) or sigma <= 0:
        sigma = noise_from_track(xy)
    sigma = max(float(sigma), 1e-7)
    # Rest is judged against the scatter the track shows, when larger than
    # the stated noise: a lossy codec's error scatters a still ball's centre
    # by several stated errors (measured: 3x for MJPG at sigma 2).
    still = max(sigma, noise_from_track(xy) if len(xy) > 4 else 0.0)
    # Motion starts where the ball leaves its first position by more than
    # noise and stays away: one outlying still frame is not a strike.
    start = np.median(xy[:3], axis=0)
    away = np.hypot(*(xy - start).T) > REST_SIGMAS * still
    stays = np.convolve(away, np.ones(MOVE_CONFIRM_FRAMES, int), "valid") == MOVE_CONFIRM_FRAMES
    if away.sum() < MIN_MOVING_FRAMES or not stays.any():
        return Segments(False, "the ball does not move in the track")
    k_move = int(np.argmax(stays))
    rest_k = find_rest_end(t, xy, still)
    if frames is not None:
        k_move, rest_k = int(frames[0]), None if frames[1] is None else int(frames[1])
    k_end = rest_k if rest_k is not None else len(t)
    if k_end - k_move < MIN_MOVING_FRAMES:
        # A rest given (``frames``) before the motion's start counts none
        # (held52's 52/32 read "only -32 frames": a false contact at the strike).
        return Segments(False, f"only {max(k_end - k_move, 0)} frames of motion before the final rest or the "
                        "track's end")
    # Fit from a few rest frames before the motion up to the final rest.
    lo = max(k_move - 8, 0)
    tf, xf = t[lo:k_end + (1 if rest_k is not None else 0)], xy[lo:k_end + (1 if rest_k is not None else 0)]
    dt = float(np.median(np.diff(t)))
    if exposure_s > 0:  # the strike lies between the last still frame and the first moving one
        t_strike_lo, t_strike_hi = t[k_move] - dt, t[k_move]
        keep = (tf < t_strike_lo - 0.5 * exposure_s) | (tf > t_strike_hi + 0.5 * exposure_s) | \
            (tf == t[k_move - 1] if k_move > 0 else False)
        keep &= ~((tf > t_strike_lo) & (tf < t_strike_hi + 0.5 * exposure_s))
        if keep.sum() >= MIN_MOVING_FRAMES + 4:
            tf, xf = tf[keep], xf[keep]
    # Extrapolate the first two moving frames' distances back to zero.
    d1, d2 = (np.hypot(*(xy[k] - start)) for k in (k_move, min(k_move + 1, len(t) - 1)))
    speed = (d2 - d1) / dt if d2 > d1 else 0.0
    back = d1 / speed if speed > 0 else dt
    t0_guess = t[k_move] - float(np.clip(back, 0.0, dt if k_move > 0 else 10 * dt))

    def cost_any(t0s, t1s):
        t0s, t1s = np.broadcast_arrays(np.asarray(t0s, dtype=float), np.asarray(t1s, dtype=float))
        c, coef, _ = _solve_many(tf, xf, t0s, np.minimum(t1s, beyond), decel)
        return np.where(t1s < t0s, np.inf, c), coef

    def cost_many(t0s, t1s):
        # The one breakpoint rule: the sliding fit's slide (t1 > t0, ended in
        # view or not) decelerates as a slide does, not as rolling does.
        c, coef = cost_any(t0s, t1s)
        slide = np.asarray(t1s) - np.asarray(t0s) > 1e-9
        return np.where(slide & (np.hypot(*coef[:, 2].T) < SLIDE_DECEL_RATIO * decel), np.inf, c)

    # A t1 past the last frame means "still sliding when the track ends".
    beyond = tf[-1] + dt
    # Coarse scan of t1 at the t0 guess, then joint refinement.
    # Sliding is usually short (0.05-0.3 s): every frame of the first 0.4 s
    # after the strike is a candidate, sparser beyond.
    after = tf[tf > t0_guess]
    near = after[after < t0_guess + 0.4]
    far = after[after >= t0_guess + 0.4]
    cands = np.concatenate([[t0_guess], near[:: max(1, len(near) // 100)],
                            far[:: max(1, len(far) // 40)], [beyond]])
    costs = cost_many(t0_guess, cands)
    k = int(np.argmin(costs))
    t1_guess = float(cands[k])
    gap = max(np.diff(cands[max(k - 1, 0):k + 2]).max(initial=0.0), 2 * dt)
    cost_main = cost_many
    if breaks is not None and breaks[1] > breaks[0]:
        # The kept kind: from the kept breakpoints, a breakpoint in view held
        # before the end (else "still sliding at the end", t1 beyond).
        t0_guess, gap = float(breaks[0]), 2 * dt
        t1_guess = float(breaks[1]) if np.isfinite(breaks[1]) else beyond
        if np.isfinite(breaks[1]):  # in view as fit.decide.t1_in_view has it
            last = tf[-1] - T1_END_MARGIN_FRAMES * dt

            def cost_main(t0s, t1s):
                return np.where(np.asarray(t1s) > last, np.inf, cost_many(t0s, t1s))
            t1_guess = min(t1_guess, last)
    # Joint refinement to a thousandth of a frame (the maximum-likelihood fit
    # refines both times further with the full model).
    t0, t1, best_sse = _zoom(cost_main, t0_guess, t1_guess, dt, gap, 1e-3 * dt)
    t_roll, _, _ = _zoom(cost_many, t0, t0, 3 * dt, 0.0, 1e-2 * dt)
    dof = max(2 * len(tf) - 8, 1)
    end_F, t_un = 0.0, t0
    if t1 < beyond:
        # "Still sliding at the end" at its own best strike time (a breakpoint
        # fit may have moved t0 to suit its kink).
        def cost_unended(t0s, _t1s):  # the alternative as it is, decided in fit.decide
            return cost_any(t0s, np.full(np.shape(t0s), beyond))[0]

        t_un, _, sse_un = _zoom(cost_unended, t0, t0, dt, 0.0, 1e-3 * dt)
        end_F = max(sse_un - best_sse, 0.0) / max(best_sse / dof, 1e-300)

    def finish(t0, t1, **extra):
        return _finish(t, xy, tf, xf, t0, t1, beyond, decel, rest_k, k_end, k_move, dof, **extra)

    # The search's slide (ended in view or not) held on the rule's bound.
    _, coef = cost_any(np.array([t0]), np.array([t1]))
    t1_bound = bool(t1 > t0 and np.hypot(*coef[0, 2]) < SLIDE_DECEL_RATIO * decel * (1 + SLIDE_BOUND_REL))
    return finish(t0, t1, end_F=end_F, end_dof=dof, rolling=finish(t_roll, t_roll),
                  unended=finish(t_un, beyond) if t1 < beyond else None, t1_bound=t1_bound)


def _finish(t, xy, tf, xf, t0, t1, beyond, decel, rest_k, k_end, k_move, dof, **extra) -> Segments:
    """The Segments of the fit with breakpoints ``(t0, t1)`` (``t1 >=
    beyond``: still sliding at the end of the track)."""
    sse, coef, res = _solve(tf, xf, t0, t1, decel)
    x0, v0, a_s, a_r = coef
    tau1 = min(t1, beyond) - t0
    v1 = v0 + a_s * tau1
    x1 = x0 + v0 * tau1 + 0.5 * a_s * tau1**2
    if t1 >= beyond:
        t1 = float("inf")  # sliding had not ended when the track did
    slide = np.flatnonzero((t >= t0) & (t < t1))
    roll = np.flatnonzero((t >= t1) & (t < (t[k_end] if rest_k is not None else np.inf)))
    t2 = x2 = None
    case2 = rest_k is not None and not np.isfinite(t1)
    if case2:
        # Sliding ran into the rest (case 2, eq. 29): both end when the
        # sliding velocity v0 + a_s tau is smallest.
        # Not clipped at the rest's first frame: a stopping ball creeps
        # within noise of its rest for a frame or two, so the rest is found
        # that early, and x1 there sat 9-30 of its errors short of the rest
        # on simulated case-2 tracks (benchmarks/calibrate_tests.py --which case2).
        # The frames from the rest's first one to the stop, where the ball
        # still creeps, belong to the slide: fitted with it (twice, as the
        # stop moves), x1 is no longer extrapolated past the fitted frames
        # (on simulated 480-fps case-2 tracks by 9 frames in median, which
        # put |x1 - x2| up to 33 times chi^2(2)'s 1% point in its errors).
        for _ in range(CASE2_REFITS):
            tau_stop = -float(v0 @ a_s) / max(float(a_s @ a_s), 1e-300)
            more = (t > tf[-1]) & (t <= t0 + tau_stop)
            if not more.any():
                break
            tf, xf = np.r_[tf, t[more]], np.r_[xf, xy[more]]
            beyond = tf[-1] + float(np.median(np.diff(tf)))
            sse, coef, res = _solve(tf, xf, t0, beyond, decel)
            x0, v0, a_s, a_r = coef
        tau_stop = -float(v0 @ a_s) / max(float(a_s @ a_s), 1e-300)
        t1 = float(min(max(t0 + tau_stop, t0), t[-1]))
        tau1 = t1 - t0
        v1 = np.zeros(2)
        x1 = x0 + v0 * tau1 + 0.5 * a_s * tau1**2
    # The rest's frames: those from its first frame on, but in case 2 not
    # the ones before the fitted stop, where the ball still creeps within
    # the rest's noise (the rest is found 1-13 frames, median 4, before the
    # true stop on simulated case-2 tracks, and their mean sat 1.1 of its
    # errors short of the rest along the path: calibrate_tests.py --which case2).
    rest = None
    if rest_k is not None:
        rest = np.arange(rest_k, len(xy))
        after = rest[t[rest] >= t1]
        if case2 and len(after) >= MIN_REST_FRAMES:
            rest = after
    geometry_cov = _geometry_cov(tf, xf, t0, min(t1, beyond), beyond, decel, v1,
                                 sse / dof, None if rest is None else len(rest), v0)
    # The estimates' weights on the track's frames, for a covariance under
    # another error model than independent frames at ``sse / dof``
    # (recover.paper.geometry_covariance: a lossy codec's rests share errors).
    geometry_cov["frames"] = np.searchsorted(t, tf)
    geometry_cov["rest"] = rest
    if rest_k is not None:
        x2 = np.mean(xy[rest], axis=0)
        # The rolling deceleration is along -v1: v = 0 when |v1| = |a_r| (t - t1).
        ar = np.hypot(*a_r)
        t2 = t1 + (np.hypot(*v1) / ar if ar > 0 else 0.0)
        t2 = float(min(max(t2, t1), t[rest_k]))
    return Segments(True, "", t0=t0, x0=x0, t1=t1, x1=x1, v0=v0, v1=v1, a_slide=a_s, a_roll=a_r,
                    t2=t2, x2=x2, slide=slide, roll=roll,
                    sigma=float(np.sqrt(sse / dof)), t_last=float(t[k_end - 1]), residuals=res,
                    k_move=k_move, rest_k=rest_k, geometry_cov=geometry_cov, **extra)


def _geometry_cov(tf, xf, t0, t1, beyond, decel, v1, s2, n_rest, v0=None):
    """Covariances of the fitted ``x0``, ``x1`` (and ``x2``, the mean of
    ``n_rest`` frames) with per-axis variance ``s2`` (m^2).

    For fixed breakpoints the fit is linear in ``(x0, v0, a_s)``, so
    ``x0`` and ``x1 = x0 + v0 tau1 + a_s tau1^2 / 2`` have covariance
    ``s2 c^T (A^T A)^-1 c``; the breakpoint's own error moves ``x1`` along
    ``v1``, with ``var(t1) = 2 s2 / (d^2 SSE / d t1^2)`` from the profile's
    curvature a frame either side (kept apart as ``x1_t1``); the strike
    time's likewise moves ``x0`` along ``v0`` (``x0_t0``, and the two
    breakpoints' shared term ``x0x1_t``).  ``w`` holds
    the coefficients' ``(x0, v0, a_s)`` weights on the fitted frames,
    ``A (A^T A)^-1`` (shape (n, 3); ``x0 = sum_i w[i, 0] xf_i``), and ``w1``
    x1's, ``A (A^T A)^-1 c1``, for their covariance under other errors;
    ``wv1`` likewise the sliding velocity's at the breakpoint, ``v1 = v0 +
    a_s tau1`` (m/s per m), and ``x1v1_t`` the breakpoints' share of
    ``(x1, v1, t1)``'s covariance (5 x 5; m, m/s, s), the path refitted as
    they move.
    """
    tau = np.maximum(tf - t0, 0.0)
    tau1 = max(t1 - t0, 0.0)
    ts = np.minimum(tau, tau1)
    cols = [np.ones_like(tau), tau] + ([0.5 * ts**2 + tau1 * (tau - ts)] if tau1 > 0 else [])
    A = np.stack(cols, axis=1)
    M = np.linalg.pinv(A.T @ A)
    c0 = np.zeros(len(cols))
    c0[0] = 1.0
    c1 = np.r_[1.0, tau1, 0.5 * tau1**2][:len(cols)]
    I2 = np.eye(2)
    cv1 = np.r_[0.0, 1.0, tau1][:len(cols)]  # v1 = v0 + a_s tau1
    out = {"x0": s2 * float(c0 @ M @ c0) * I2, "x1": s2 * float(c1 @ M @ c1) * I2,
           "x0x1": s2 * float(c0 @ M @ c1) * I2, "x2": None,
           "w": A @ M, "w1": A @ (M @ c1), "wv1": A @ (M @ cv1), "x1_t1": np.zeros((2, 2)),
           "x0_t0": np.zeros((2, 2)), "x0x1_t": np.zeros((2, 2)),
           "x1v1_t": np.zeros((5, 5))}
    if 0 < tau1 and t1 < beyond:
        # The Hessian of the profile over (t0, t1), a frame either side: t1's
        # marginal variance, with t0 free too (they trade off).
        h = float(np.median(np.diff(tf)))
        g0, g1 = np.meshgrid([-h, 0.0, h], [-h, 0.0, h], indexing="ij")
        S, coef, _ = _solve_many(tf, xf, t0 + g0.ravel(), t1 + g1.ravel(), decel)
        S = S.reshape(3, 3)
        H = np.array([[S[2, 1] - 2 * S[1, 1] + S[0, 1], (S[2, 2] - S[2, 0] - S[0, 2] + S[0, 0]) / 4],
                      [0.0, S[1, 2] - 2 * S[1, 1] + S[1, 0]]]) / h**2
        H[1, 0] = H[0, 1]
        if np.linalg.det(H) > 0 and H[0, 0] > 0:
            Ht = 2 * s2 * np.linalg.inv(H)  # covariance of (t0, t1)
            out["x1_t1"] = Ht[1, 1] * np.outer(v1, v1)
            # (x1, v1, t1) along the profile (the path refitted at each
            # breakpoint), central differences over (t0, t1): their share of
            # the breakpoints' errors, J Ht J^T (recover.paper.rolling_speed_z).
            # (x1 along v1 and v1 along a_s, the path held, read |v1| against
            # eq. 19's rolling speed 9 times too loose: docs/measurements.md, v1chk.)
            tau1s = (t1 + g1.ravel()) - (t0 + g0.ravel())
            x1s = coef[:, 0] + coef[:, 1] * tau1s[:, None] + 0.5 * coef[:, 2] * tau1s[:, None] ** 2
            v1s = coef[:, 1] + coef[:, 2] * tau1s[:, None]
            q = np.concatenate([x1s, v1s, (t1 + g1.ravel())[:, None]], axis=1).reshape(3, 3, 5)
            J = np.stack([(q[2, 1] - q[0, 1]) / (2 * h), (q[1, 2] - q[1, 0]) / (2 * h)], axis=1)
            out["x1v1_t"] = J @ Ht @ J.T
            out["x1"] = out["x1"] + out["x1_t1"]
            if v0 is not None:
                # x0 is the fitted path at t0: t0's error moves it along v0.
                # (Left out, x0's mean squared error in stated errors per
                # axis was 3.30 on sliding_tracks(60, 1)'s answers; 0.92 with it.)
                out["x0_t0"] = Ht[0, 0] * np.outer(v0, v0)
                out["x0x1_t"] = Ht[0, 1] * np.outer(v0, v1)
                out["x0"] = out["x0"] + out["x0_t0"]
                out["x0x1"] = out["x0x1"] + out["x0x1_t"]
    elif tau1 == 0 and v0 is not None and len(tf) > 1:
        # Rolling from the strike (case 4, t1 = t0, x1 = x0): the strike
        # time's error moves x0 (and x1 with it) along v0, var(t0) = 2 s2 /
        # (d^2 SSE / d t0^2) along the profile with t1 held at t0, a frame
        # either side.  (Left out, the paper's case-4 answers on 60 shots
        # to rest, the review of pap37's case4_rest.py, read x0 up to 6.5
        # of its stated errors off along the path, and their errors covered
        # 72.9% of 192 components.)
        h = float(np.median(np.diff(tf)))
        g = np.array([-h, 0.0, h])
        S, _, _ = _solve_many(tf, xf, t0 + g, t0 + g, decel)
        d2 = float(S[2] - 2 * S[1] + S[0]) / h**2
        # Not curved (d2 <= 0): the profile does not hold t0 a frame either
        # side, and t0's share is left out, not guessed.  Measured where that happens: never on 360 simulated
        # case-4 tracks with their strike in view (rolls_to_rest_tracks,
        # seed 5's 60, seed 6's 300) nor on held37's 40 realistic H.264; on 2 of
        # 30 case-4 tracks cut to begin 0.5-1 frame after the strike, where
        # nothing before the strike holds x0 and the paper refuses it ("the
        # strike is not in view"; tests/test_fit.py pins both).
        if d2 > 0:
            share = 2 * s2 / d2 * np.outer(v0, v0)
            out["x0_t0"], out["x1_t1"], out["x0x1_t"] = share, share.copy(), share.copy()
            for k in ("x0", "x1", "x0x1"):
                out[k] = out[k] + share
    if n_rest:
        out["x2"] = s2 / n_rest * I2
    return out


def correlated_end_F(seg: Segments, t, xy, whiten) -> float:
    """``seg.end_F`` with the frames' errors correlated in time.

    The segmentation's ``end_F`` (its breakpoint against "still sliding at
    the end", F(1, ``end_dof``)) assumes independent errors; errors shared
    by neighbouring frames (an inter-frame codec's slow drift, an AR(1)
    error) bend the track's last frames as a slide's end would, and the
    test then reads "ended" far more often than its level (fit.decide's
    END_FACTOR comment; docs/measurements.md, gross13 class A and endf13).
    Here both fits, at the segmentation's breakpoints (``(seg.t0, seg.t1)``
    and ``(seg.unended.t0, end)``) and its rolling acceleration, are made
    again by generalised least squares: each axis's design ``[1, tau,
    c2]`` (:func:`_path_basis`, as :func:`_solve_many`'s) and data whitened by the Cholesky factor of
    the errors' correlation; the F statistic is the whitened one, on the
    same degrees of freedom.

    Parameters
    ----------
    seg : Segments
        The segmentation of ``(t, xy)`` (its breakpoint in view: ``t1``
        finite and ``unended`` set, no rest in view); otherwise
        ``seg.end_F`` is returned.
    t : ndarray, shape (n,)
        Frame times (s) given to :func:`segment_track`.
    xy : ndarray, shape (n, 2)
        Ball centres (m) given to :func:`segment_track`.
    whiten : callable
        ``whiten(t_fit, M)``: ``L^-1 M`` for the rows of ``M`` (k, c) at the
        fitted frames' times ``t_fit`` (s), ``L L^T`` the errors' correlation
        between them (unit diagonal, the same for both axes;
        recover.mle.time_whitener).

    Returns
    -------
    float
        The F statistic (dimensionless), 0 when the whitened breakpoint
        fit is no better than the unended one.
    """
    if seg.unended is None or not np.isfinite(seg.t1) or seg.geometry_cov is None or seg.t2 is not None:
        # Nothing to test, or the rest in view (fit.decide.sliding_ended does
        # not ask then).
        return float(seg.end_F)
    t = np.asarray(t, dtype=float)
    xy = np.asarray(xy, dtype=float)
    good = np.all(np.isfinite(xy), axis=1) & np.isfinite(t)
    t, xy = t[good], xy[good]
    k = seg.geometry_cov["frames"]
    tf, xf = t[k], xy[k]
    def design(t0, t1, a_r):
        tau, _, c2, roll = (v[0] for v in _path_basis(tf, np.array([float(t0)]),
                                                      np.array([min(t1, tf[-1] + 1.0)])))
        X = np.stack([np.ones_like(tau), tau, c2], axis=1)
        y = xf - roll[:, None] * a_r[None, :]  # rolling's known deceleration (eq. 18)
        return np.concatenate([X, y], axis=1)

    def sse_of(w):
        Xw, yw = w[:, :3], w[:, 3:]
        beta = np.linalg.lstsq(Xw, yw, rcond=None)[0]
        r = yw - Xw @ beta
        return float(np.sum(r * r))

    # Both fits' columns whitened in one pass (column by column the same
    # numbers: the filter's gains are the times' alone).
    w = whiten(tf, np.concatenate([design(seg.t0, seg.t1, np.asarray(seg.a_roll, dtype=float)),
                                   design(seg.unended.t0, np.inf, np.zeros(2))], axis=1))
    sse, sse_un = sse_of(w[:, :5]), sse_of(w[:, 5:])
    dof = max(int(seg.end_dof), 1)
    return max(sse_un - sse, 0.0) / max(sse / dof, 1e-300)
