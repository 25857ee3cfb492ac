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
from scipy.optimize import minimize, minimize_scalar
from scipy.stats import f as f_dist

# Consecutive end frames within this many sigma of the final position are at rest.
REST_SIGMAS = 5.0
MIN_REST_FRAMES = 5
# Frames of motion needed before any fit is attempted.
MIN_MOVING_FRAMES = 6
# A sliding phase must beat rolling-from-the-strike by an F-test at this level.
SLIDING_TEST_LEVEL = 0.01


@dataclass(frozen=True)
class Segments:
    """Phases found in a track; falsy when it could not be segmented.

    Times in s, positions in m, velocities in m/s, accelerations in m/s^2.
    ``sliding_p`` is the F-test's p-value for "no sliding phase" (rolling
    from the strike); ``t1 == t0`` when it is not below the test level.
    ``t2``/``x2`` are None when no rest is in view; ``t1`` is ``inf`` (and
    ``x1``, ``v1`` extrapolated to the last frame) when the ball was still
    sliding when the track ended.  ``slide`` and ``roll``
    index the frames of each phase; ``sigma`` is the position noise (m) the
    fit's residuals show.
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
    sliding_p: float = float("nan")

    def __bool__(self):
        return self.ok


def _design(t, t0, t1):
    """Design matrix (per axis) for x0, v0, a_s, and the rolling time term."""
    tau = np.maximum(t - t0, 0.0)
    tau1 = max(t1 - t0, 0.0)
    ts = np.minimum(tau, tau1)
    tr = np.maximum(tau - tau1, 0.0)
    # x = x0 + v0 tau + a_s (ts^2/2 + tau1 tr) + a_r tr^2/2
    return np.stack([np.ones_like(t), tau, 0.5 * ts**2 + tau1 * tr], axis=1), 0.5 * tr**2


def _solve(t, xy, t0, t1, decel):
    """Least squares for fixed breakpoints; ``decel`` is the rolling deceleration.

    Normal equations (3 x 3 per call): this is the inner loop of the search.
    A sliding phase shorter than the design can resolve (case 4: rolling from
    the strike) drops the sliding term.
    """
    A, roll_term = _design(t, t0, t1)
    if t1 - t0 < 1e-9:
        A = A[:, :2]
    AtA = A.T @ A
    a_r = np.zeros(2)
    for _ in range(2):  # the direction of v1 from the previous solve
        y = xy - roll_term[:, None] * a_r
        try:
            coef = np.linalg.solve(AtA, A.T @ y)
        except np.linalg.LinAlgError:
            coef = np.linalg.lstsq(A, y, rcond=None)[0]
        if len(coef) == 2:
            coef = np.vstack([coef, np.zeros(2)])
        v1 = coef[1] + coef[2] * max(t1 - t0, 0.0)
        speed = np.hypot(*v1)
        a_r = -decel * v1 / speed if speed > 0 else np.zeros(2)
    res = xy - A @ coef[:A.shape[1]] - roll_term[:, None] * a_r
    return float(np.sum(res * res)), np.vstack([coef, a_r]), res


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
    while k > 0 and near[k - 1]:
        k -= 1
    return k if n - k >= MIN_REST_FRAMES else None


def noise_from_track(xy):
    """Position noise (m) from second differences of consecutive positions.

    Motion contributes ``a dt^2``, tiny at video rates, so the robust spread
    of second differences is ``sqrt(6)`` times the per-axis noise.
    """
    d2 = xy[2:] - 2 * xy[1:-1] + xy[:-2]
    if len(d2) < 3:
        return float("nan")
    mad = np.median(np.abs(d2 - np.median(d2, axis=0)), axis=0) * 1.4826
    return float(np.sqrt(np.mean(mad**2)) / np.sqrt(6.0))


def segment_track(t, xy, decel: float, sigma: float | None = None,
                  exposure_s: float = 0.0) -> Segments:
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
    # Motion starts where the ball leaves its first position by more than noise.
    start = np.median(xy[:3], axis=0)
    away = np.hypot(*(xy - start).T) > REST_SIGMAS * sigma
    if away.sum() < MIN_MOVING_FRAMES:
        return Segments(False, "the ball does not move in the track")
    k_move = int(np.argmax(away))
    rest_k = find_rest_end(t, xy, sigma)
    k_end = rest_k if rest_k is not None else len(t)
    if k_end - k_move < MIN_MOVING_FRAMES:
        return Segments(False, f"only {k_end - k_move} frames of motion")
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

    def cost(p):
        t0, t1 = p
        if t1 < t0:
            return np.inf
        return _solve(tf, xf, t0, min(t1, beyond), decel)[0]

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
    costs = [cost((t0_guess, c)) for c in cands]
    t1_guess = float(cands[int(np.argmin(costs))])
    # A hundredth of a frame is plenty: the maximum-likelihood fit refines
    # both times with the full model.
    best = minimize(cost, [t0_guess, max(t1_guess, t0_guess)], method="Nelder-Mead",
                    options={"xatol": 1e-2 * dt, "fatol": 1e-2 * sigma**2, "maxiter": 200,
                             "initial_simplex": [[t0_guess, t1_guess],
                                                 [t0_guess + 0.5 * dt, t1_guess],
                                                 [t0_guess, t1_guess + 2 * dt]]})
    t0, t1 = (float(v) for v in best.x)
    # Nelder-Mead stalls on the kinks of this profile; polish each time in
    # turn by a bounded 1-D search.
    for _ in range(2):
        t0 = float(minimize_scalar(lambda a: cost((a, t1)), bounds=(t0 - dt, min(t0 + dt, t1)),
                                   method="bounded", options={"xatol": 1e-3 * dt}).x)
        r1 = minimize_scalar(lambda b: cost((t0, b)), bounds=(t0, min(t1 + dt, beyond)),
                             method="bounded", options={"xatol": 1e-3 * dt})
        if t1 > t0 + dt:
            r1b = minimize_scalar(lambda b: cost((t0, b)), bounds=(max(t1 - dt, t0), t1),
                                  method="bounded", options={"xatol": 1e-3 * dt})
            r1 = min(r1, r1b, key=lambda r: r.fun)
        t1 = float(r1.x)
    best = type(best)(x=np.array([t0, t1]), fun=cost((t0, t1)))
    # A breakpoint within two frames of the track's end is not observed.
    if t1 > tf[-1] - 2 * dt:
        t1 = beyond
    # Is a sliding phase seen at all?  F-test of "rolling from the strike"
    # (case 4) against the fit with sliding, which adds a_s and t1 (3
    # parameters), at the 1% level, with the noise from the residuals.
    # Without it, a huge a_s over a sliver of time fits noise and trades off
    # against v0.
    r = minimize_scalar(lambda a: cost((a, a)), bounds=(t0 - 3 * dt, t0 + 3 * dt),
                        method="bounded", options={"xatol": 1e-2 * dt})
    dof_full = max(2 * len(tf) - 9, 1)
    F = max(r.fun - best.fun, 0.0) / 3.0 / max(best.fun / dof_full, 1e-300)
    lr = float(f_dist.sf(F, 3, dof_full))  # p-value of "no sliding"
    rolling_from_strike = lr >= SLIDING_TEST_LEVEL
    if rolling_from_strike:
        t0 = t1 = float(r.x)
    # Is the end of sliding seen?  F-test of "still sliding when the track
    # ends" against the breakpoint found (one more parameter), at the 1%
    # level: a kink fitted into noise near the end must not pass for one.
    if t1 < beyond and not rolling_from_strike:
        dof_bp = max(2 * len(tf) - 8, 1)
        F_end = max(cost((t0, beyond)) - cost((t0, t1)), 0.0) / max(cost((t0, t1)) / dof_bp, 1e-300)
        if f_dist.sf(F_end, 1, dof_bp) >= SLIDING_TEST_LEVEL:
            t1 = beyond
    sse, coef, res = _solve(tf, xf, t0, t1, decel)
    x0, v0, a_s, a_r = coef
    tau1 = min(t1, beyond) - t0
    v1 = v0 + a_s * tau1
    x1 = x0 + v0 * tau1 + 0.5 * a_s * tau1**2
    dof = max(2 * len(tf) - 8, 1)
    if t1 >= beyond:
        t1 = float("inf")  # sliding had not ended when the track did
    slide = np.flatnonzero((t >= t0) & (t < t1))
    roll = np.flatnonzero((t >= t1) & (t < (t[k_end] if rest_k is not None else np.inf)))
    t2 = x2 = None
    if rest_k is not None and not np.isfinite(t1):
        # Sliding ran into the rest (case 2, eq. 29): both end when the
        # sliding velocity v0 + a_s tau is smallest.
        tau_stop = -float(v0 @ a_s) / max(float(a_s @ a_s), 1e-300)
        t1 = float(min(max(t0 + tau_stop, t0), t[rest_k]))
        tau1 = t1 - t0
        v1 = np.zeros(2)
        x1 = x0 + v0 * tau1 + 0.5 * a_s * tau1**2
    if rest_k is not None:
        x2 = np.mean(xy[rest_k:], axis=0)
        # The rolling deceleration is along -v1: v = 0 when |v1| = |a_r| (t - t1).
        ar = np.hypot(*a_r)
        t2 = t1 + (np.hypot(*v1) / ar if ar > 0 else 0.0)
        t2 = float(min(max(t2, t1), t[rest_k]))
    return Segments(True, "", t0=t0, x0=x0, t1=t1, x1=x1, v0=v0, v1=v1, a_slide=a_s, a_roll=a_r,
                    t2=t2, x2=x2, slide=slide, roll=roll,
                    sigma=float(np.sqrt(sse / dof)), t_last=float(t[k_end - 1]), residuals=res,
                    sliding_p=lr)
