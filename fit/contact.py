"""Where the analysed motion ends: the first contact in a track.

CONVENTIONS.md ("What a shot is"): the paper's motion ends at the first
contact with a cushion or another ball; fit and recover use only the frames
before it.  Two tests, the earlier answer wins:

1. **Geometry.** The ball's centre comes within R of a cushion line
   (``x = 0``, ``x = length``, ``y = 0``, ``y = width`` of ``table``), in a
   frame, or on the path a local quadratic fit of the frames before
   extrapolates to the next frame (a fast ball can touch the cushion and be
   back out by the next frame).  Kind ``cushion``.
2. **A change of motion the model cannot explain.**  The paper's path is
   piecewise quadratic in time with position and velocity continuous (the
   strike aside): only the acceleration jumps, where sliding ends and where
   the ball stops.  At each boundary between two frames, quadratics fitted
   to the ``W`` frames on either side (free accelerations, so a kink is
   allowed) are compared at the boundary: a Wald test of "same position and
   same velocity", chi-square with 4 degrees of freedom under the model,
   against the track's noise (its stated errors, scaled up by what the
   local fits' residuals show).  The first run of boundaries above
   :data:`CHANGE_THRESHOLD` is a contact, placed at the run's largest
   statistic, unless, with the frames off the one path through its windows
   left out (:func:`outlier_frames`), the motion on both sides reads the
   same (:func:`trimmed_statistic`): a few frames off the path (a tracker's
   outliers) with the same motion either side are not a contact.  Kind ``ball`` when the ball's centre is then within a
   diameter (plus a tolerance) of a ball known to rest there, ``cushion``
   when near a cushion, else ``unknown``.

Pure functions of arrays.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2 as chi2_dist

from cuespin.fit.segment import noise_from_track

# Time each side of a boundary in the change test (s): long enough to
# measure a velocity, short next to most sliding phases (0.15-0.3 s).  In
# frames, clipped to MIN_WINDOW..MAX_WINDOW (at 60 fps 8 frames, 0.13 s).
WINDOW_S = 0.1
MIN_WINDOW, MAX_WINDOW = 8, 64
# The change statistic (about chi-square, 4 d.o.f., under the model) above
# which a boundary is a contact.  Calibrated by simulation
# (``python benchmarks/contact.py calibrate --n 600 --seed 7``): over 600
# contact-free simulated tracks (presets random, case1-5, masse,
# leaves_table; 60-480 fps; noise 0.005-0.5 px at 500 px/m) the largest
# statistic was MEASURED_NULL_MAX (99th percentile 19.6); the threshold
# keeps 1.6 times that.  With it, 199 of 200 simulated contacts were found
# within one frame (``detect --n 200 --seed 3``; the miss, a 0.15 m/s change
# at 0.35 px noise, was within the noise).
MEASURED_NULL_MAX = 25.5
CHANGE_THRESHOLD = 40.0
# The ball's centre this many standard errors beyond R of a cushion line
# has touched it; when classifying a change, this near (or 1 cm) is at it.
CUSHION_SIGMAS = 3.0
# A change within this distance (m) beyond 2R of a known ball's centre is
# that ball's contact.
BALL_TOLERANCE_M = 0.01
# The ball has moved (the strike is behind) once this many frames in a row
# are this many standard errors from where it started.
MOVE_SIGMAS = 5.0
MOVE_CONFIRM_FRAMES = 3
# The ball is still from the track's start to a change when no window's fitted
# velocity is off zero at this family-wise level: each window's v.v / var is
# chi-square with 2 degrees of freedom (the two axes' velocities, independent
# and of equal variance under the window's fit; survival exp(-x / 2)), and m
# windows are held to Bonferroni's STILL_LEVEL / m, x <= -2 ln(STILL_LEVEL / m)
# (13.8 for one window; the windows overlap, so the family's rate is under
# STILL_LEVEL).  At 0.1% per window without the correction, a still rest
# drifting 15 errors (tests/test_contact.py) broke it in 1 of 9 tracks (240
# fps, 73 windows, largest 16.6).
STILL_LEVEL = 1e-3
# Placing a jump, the motion before it may kink (sliding ending), but only
# before the first flagged boundary, whose frames are clear of the jump:
# a kink allowed up to the candidate imitated the jump and placed it 1-9
# frames late in 10 of 100 simulated ball contacts; no kink at all (plain
# quadratics) placed it early by up to 8 frames when sliding ended within a
# window of the contact.  KINK_END_GAP frames before the candidate are kept
# clear as well.
KINK_END_GAP = 0
CHANGE_POINT_KINK = True
# A run of frames off the ball's path is not a contact when the motion on
# either side of it is one motion (:func:`outlier_frames`,
# :func:`trimmed_statistic`): a frame is off when its deleted residual from
# one quadratic through the 2 W frames of a flagged boundary, in its stated
# errors (times the test's scale), exceeds chi-square(2)'s point at
# OUTLIER_LEVEL over those frames (Bonferroni: -2 ln(OUTLIER_LEVEL / 2W),
# 14.7 at W = 8; the deleted residual of a frame with the stated error is
# exactly chi-square(2) on a path that is one quadratic).  At most
# MAX_OUTLIER_SHARE of the 2 W frames are taken off: a run off the path is a
# minority of the frames around it, more is a change of motion.  1/4 from
# measured distributions (docs/measurements.md, gapcov): on 300 contact-free
# generated tracks (benchmarks/contact.py's, noise 0.005-0.5 px) with a run
# of 1/16-3/8 of the 2 W frames, 4-6 stated errors off one way, among W
# frames, the runs the rule clears needed 1/8 (9 of 12), 3/16 (2) and 1/4
# (1), none more, and 48/13 needs 1/4; on its null, 400 paired contact
# scenes (real contacts must stand), 1/4 loses 1 of 305 (H.264-like errors;
# McNemar margin 2), 3/16 none, 5/16 the same 1.  So 1/4 clears every run
# the rule can, within the null's margin.  Its ceiling: (MIN_WINDOW - 3) /
# (2 MIN_WINDOW) = 5/16, each side keeping the 3 frames its quadratic needs
# when every frame taken off falls on it (above it a side's fit in
# trimmed_statistic was singular on a paired scene).  Realistic
# H.264 48/13 (docs/measurements.md, held39 and rimdot): frames 57, 59, 63,
# 64, 2.3-2.8 px off where a dark dot reaches the ball's rim, flagged
# boundary 63 at 41.5 over the threshold's 40, a false "unknown" contact at
# 1.067 s and from it a false end of sliding answered `ok` 15 stated errors
# off; without those four frames the boundary reads 2.2.
OUTLIER_LEVEL = 0.01
MAX_OUTLIER_SHARE = 0.25
# A flagged run is cleared only when, those frames left out, the motions on
# both sides are one at OUTLIER_LEVEL: the trimmed statistic at or under
# chi-square(4)'s point (13.3), not merely under CHANGE_THRESHOLD.  Left out
# next to a real change, frames cost its statistic its nearest evidence: at
# the threshold itself the rule lost 13 (independent errors) and 17
# (H.264-like) of 400 simulated contacts on a table without cushions,
# gaining none (docs/measurements.md, rimdot).
SAME_MOTION_CHI2 = float(chi2_dist.isf(OUTLIER_LEVEL, 4))


@dataclass(frozen=True)
class Contact:
    """The first contact in a track.

    Attributes
    ----------
    t : float
        Estimated time of the contact (s).
    index : int
        First frame (index into the track) at or after the contact: fit the
        frames before it.
    kind : str
        ``cushion``, ``ball`` or ``unknown``.
    statistic : float
        The change test's statistic at the contact (NaN for a contact found
        by geometry alone).
    """

    t: float
    index: int
    kind: str
    statistic: float = float("nan")


def edge_gap(xy, table, R: float) -> np.ndarray:
    """Distance (m) from the ball's centre to its nearest cushion line, less R.

    Zero or negative: touching a cushion.  Shape (n,).
    """
    xy = np.asarray(xy, dtype=float)
    d = np.stack([xy[:, 0], table.length - xy[:, 0], xy[:, 1], table.width - xy[:, 1]], axis=1)
    return d.min(axis=1) - R


def window_frames(t) -> int:
    """Frames each side of a boundary: :data:`WINDOW_S` at the track's frame rate."""
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    return int(np.clip(round(WINDOW_S / dt), MIN_WINDOW, MAX_WINDOW))


def _frame_sigma(stderr_m, n: int, xy=None) -> np.ndarray:
    """Per-frame error (m): the stated one, its median where missing, or the
    track's own scatter (``fit.segment.noise_from_track``) when none is stated."""
    se = np.asarray(stderr_m, dtype=float)
    if se.ndim == 0:
        se = np.full(n, float(se))
    elif se.ndim == 2:
        se = np.sqrt(np.mean(se**2, axis=1))
    good = np.isfinite(se) & (se > 0)
    if good.any():
        fill = float(np.median(se[good]))
    else:
        fill = noise_from_track(np.asarray(xy, dtype=float)) if xy is not None else float("nan")
        if not np.isfinite(fill) or fill <= 0:
            fill = 1e-4  # 0.05 px at 500 px/m: a tracker's typical error
    return np.where(good, se, fill)


def _window_fits(t, xy, sig, starts, W, tau):
    """Weighted quadratic fits over ``W`` frames from each start, centred at ``tau``.

    Returns the estimates ``(n, 2 axes, 3)`` of ``(x, v, a/2)`` at ``tau``,
    their (unscaled) covariance ``(n, 3, 3)`` and each fit's chi-square.
    """
    idx = starts[:, None] + np.arange(W)[None, :]
    s = t[idx] - tau[:, None]
    X = np.stack([np.ones_like(s), s, s * s], axis=-1)          # (n, W, 3)
    w = 1.0 / sig[idx] ** 2                                      # (n, W)
    Xw = X * w[:, :, None]
    cov = np.linalg.inv(np.swapaxes(Xw, 1, 2) @ X)
    coef = np.swapaxes(cov @ (np.swapaxes(Xw, 1, 2) @ xy[idx]), 1, 2)   # (n, 2, 3)
    resid = xy[idx] - X @ np.swapaxes(coef, 1, 2)
    chi2 = np.sum(resid**2 * w[:, :, None], axis=(1, 2))
    return coef, cov, chi2


def change_statistic(t, xy, stderr_m, W: int | None = None, details: bool = False, time_corr=None):
    """The change test at every boundary with ``W`` frames on each side.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Frame times (s).
    xy : ndarray, shape (n, 2)
        Ball centre (m); every frame valid.
    stderr_m : ndarray, shape (n,) or (n, 2)
        Per-frame standard error (m).
    W : int, optional
        Frames on each side; :func:`window_frames` when absent.
    time_corr : callable, optional
        ``time_corr(t)``: the per-axis correlation (k, k) of the errors of
        frames at times ``t`` (s), as ``recover.mle.time_correlation`` gives
        for an inter-frame codec; None: independent errors.  With it, each
        boundary's statistic is divided by :func:`correlation_inflation`.

    Returns
    -------
    b : ndarray of int, shape (m,)
        Boundaries: the first frame after each.
    stat : ndarray, shape (m,)
        Wald statistic of equal position and velocity at the boundary, in
        units of the noise scaled by ``scale``.
    scale : float or ndarray, shape (m,)
        Factor (>= 1) by which the local fits' residuals exceed the stated
        errors (median over windows); with ``time_corr``, per boundary,
        times the square root of :func:`correlation_inflation`.
    coef : tuple of ndarray
        Left and right fits ``(m, 2, 3)`` at each boundary's midpoint time.
    jump_chi2 : ndarray, shape (m,)
        With ``details``: the two fits' chi-square (unscaled), the fit with
        a jump at the boundary.
    """
    t = np.asarray(t, dtype=float)
    xy = np.asarray(xy, dtype=float)
    n = len(t)
    sig = _frame_sigma(stderr_m, n)
    W = window_frames(t) if W is None else W
    if n < 2 * W:
        z = np.zeros(0)
        out = np.zeros(0, int), z, 1.0, (np.zeros((0, 2, 3)), np.zeros((0, 2, 3)))
        return (*out, z) if details else out
    b = np.arange(W, n - W + 1)
    tau = 0.5 * (t[b - 1] + t[b])
    cl, covl, chil = _window_fits(t, xy, sig, b - W, W, tau)
    cr, covr, chir = _window_fits(t, xy, sig, b, W, tau)
    dof = 2 * (W - 3)
    # Residual scatter beyond the stated errors (codec, tracker): robust
    # median over all windows; chi-square(dof)'s median is about dof (1 - 2/(9 dof))^3.
    med_null = dof * (1 - 2 / (9 * dof)) ** 3
    scale2 = max(1.0, float(np.median(np.concatenate([chil, chir]))) / med_null)
    d = cl[:, :, :2] - cr[:, :, :2]                              # (m, 2, 2): x, v
    C = covl[:, :2, :2] + covr[:, :2, :2]
    Ci = np.linalg.inv(C)
    scale2 = scale2 if time_corr is None else scale2 * correlation_inflation(t, sig, b, W, C, time_corr)
    stat = np.einsum("nai,nij,naj->n", d, Ci, d) / scale2
    if time_corr is not None and len(stat):
        # A shot's own drift beyond the pooled correlation (recover.mle's
        # INTER_CODEC_ACF note; the recovery's shared_scale): most boundaries
        # see no change, so the statistic's lower quartile should be
        # chi-square(4)'s (shot_drift2).
        drift2 = shot_drift2(stat)
        stat, scale2 = stat / drift2, scale2 * drift2
    out = b, stat, (float(np.sqrt(scale2)) if np.ndim(scale2) == 0 else np.sqrt(scale2)), (cl, cr)
    return (*out, chil + chir) if details else out


# The shot's own drift (change_statistic on an inter-frame codec) is read
# from the statistic's lower quartile over chi-square(4)'s (scipy.stats.chi2
# .ppf(0.25, 4)), not its median: a track ending soon after its contact had
# the changes' windows (strike, slide's end, stop, contact) in half its
# boundaries, and the median divided its contact away (review of contact36:
# 80 simulated contacts cut 0.25 s after, geometry off, 27 missed against 20
# read independently; shot 29 at 60 fps 4767 -> 82.6, a factor ~58).  At
# most DRIFT2_MAX: realistic H.264 seed 36's 480-fps tracks read 6-8 by the
# median (contact36).
CHI2_4_Q25 = 1.9226
DRIFT2_MAX = 10.0


def shot_drift2(stat) -> float:
    """The change statistic's own scale beyond the pooled correlation: its
    lower quartile over chi-square(4)'s, in [1, DRIFT2_MAX]."""
    return float(np.clip(np.percentile(stat, 25) / CHI2_4_Q25, 1.0, DRIFT2_MAX))


def _window_map(t, sig, starts, W, tau) -> np.ndarray:
    """The linear map (n, 2, W) from a window's ``W`` centres (one axis) to
    its weighted quadratic's position and velocity at ``tau``
    (:func:`_window_fits`' first two coefficients)."""
    idx = starts[:, None] + np.arange(W)[None, :]
    s = t[idx] - tau[:, None]
    X = np.stack([np.ones_like(s), s, s * s], axis=-1)
    Xw = X * (1.0 / sig[idx] ** 2)[:, :, None]
    return (np.linalg.inv(np.swapaxes(Xw, 1, 2) @ X) @ np.swapaxes(Xw, 1, 2))[:, :2, :]


def correlation_inflation(t, sig, b, W: int, C, time_corr) -> np.ndarray:
    """How much errors correlated in time widen the change test's position
    and velocity difference at each boundary, shape (m,): the mean
    eigenvalue of ``C^-1 V``, ``V`` the difference's covariance under the
    correlation ``time_corr(t)`` (the errors of the ``2 W`` frames around
    the boundary, left and right windows alike) and ``C`` (m, 2, 2) its
    covariance with independent errors.  An inter-frame codec's error
    shared over tens of milliseconds (recover.mle.INTER_CODEC_ACF: 21 ms)
    moves a window's fitted velocity as one: read against independent
    errors it looks like a change of motion (contact36: 4 of 80 simulated
    contact-free tracks, all at 480 fps, over the threshold).

    A scalar, not the full ``V``: the exact Wald form ``d' V^-1 d`` is
    chi-square(4) per boundary (measured, chi2c) but found fewer contacts
    at the same threshold (400 simulated contacts: 8 found only by this
    form, none only by the exact one; no false contact from either on 480
    null tracks): a contact is a velocity jump, the direction in which
    ``V`` is widest at 240-480 fps (docs/measurements.md chi2c)."""
    tau = 0.5 * (t[b - 1] + t[b])
    A = np.concatenate([_window_map(t, sig, b - W, W, tau), -_window_map(t, sig, b, W, tau)], axis=2)
    rows = (b - W)[:, None] + np.arange(2 * W)[None, :]
    As = A * sig[rows][:, None, :]                  # the map from whitened errors
    # One correlation per pattern of frame times (one for evenly spaced frames).
    rel = np.round((t[rows] - t[rows[:, :1]]) * 1e9).astype(np.int64)
    _, first, which = np.unique(rel, axis=0, return_index=True, return_inverse=True)
    V = np.empty((len(b), 2, 2))
    for j, i in enumerate(first):
        m = np.flatnonzero(which.ravel() == j)
        V[m] = As[m] @ time_corr(t[rows[i]]) @ np.swapaxes(As[m], 1, 2)
    return np.maximum(0.5 * np.trace(np.linalg.solve(C, V), axis1=1, axis2=2), 1.0)


def _kink_chi2(t, xy, sig, lo: int, hi: int, tau: float, end_gap: int = 0,
               kappa_max: float = np.inf, stop_below: float = -np.inf) -> float:
    """Smallest chi-square of the model's own motion over frames ``lo..hi-1``:
    one quadratic with position and velocity continuous and the acceleration
    free to change once, at any time ``kappa`` in the window (the end of
    sliding, or the ball stopping).  ``kappa`` is found on a grid refined
    four times (to 1/8192 of a frame), so its error costs nothing at any
    noise a tracker reaches.  With ``end_gap``, the kink is kept that many
    frames before the last (a kink at the very end would imitate a jump),
    and with ``kappa_max`` (s, absolute) no later than that.  Refinement
    stops once the chi-square is at or below ``stop_below`` (a smaller one
    would change no decision)."""
    s = t[lo:hi] - tau
    w = 1.0 / sig[lo:hi] ** 2
    y = xy[lo:hi]
    dt = float(np.median(np.diff(t[lo:hi])))

    # One kink column z = (s - kappa)_+^2 added to the quadratic: by the
    # partitioned least-squares identity the chi-square drops by
    # (z~' W r0)^2 / (z~' W z~) per axis, z~ being z with the quadratic's
    # part taken out (vectorised over kappa).
    X0 = np.stack([np.ones_like(s), s, s * s], axis=1)
    WX0 = X0 * w[:, None]
    A0inv = np.linalg.inv(X0.T @ WX0)
    r0 = y - X0 @ (A0inv @ (WX0.T @ y))
    chi2_0 = float(np.sum(r0 * r0 * w[:, None]))
    wr0 = r0 * w[:, None]

    def chi2(kappas):
        Z = np.maximum(s[None, :] - kappas[:, None], 0.0) ** 2
        Zt = Z - ((Z @ WX0) @ A0inv) @ X0.T
        den = np.sum(Zt * Zt * w[None, :], axis=1)
        num = Zt @ wr0
        drop = np.where(den > 1e-300, np.sum(num * num, axis=1) / np.maximum(den, 1e-300), 0.0)
        return chi2_0 - drop

    k_max = min(s[max(len(s) - 1 - end_gap, 0)], kappa_max - tau)
    k_max = max(k_max, s[0])
    grid = np.arange(s[0], k_max + 1e-12, dt / 2)
    step = dt / 2
    best_c = np.inf
    for _ in range(4):
        c = chi2(np.minimum(grid, k_max))
        i = int(np.argmin(c))
        best, best_c = grid[i], min(best_c, float(c[i]))
        if best_c <= stop_below:
            break
        step /= 8
        grid = best + step * np.arange(-8, 9)
    return best_c


def kink_statistic(t, xy, sig, W, b, stat, jump_chi2, scale, screen, first_over=None):
    """The change statistic against the model's own kink, where the fast one exceeds ``screen``.

    A boundary the fast test (:func:`change_statistic`) flags is tested
    again against an acceleration change anywhere in its window, velocity
    continuous (:func:`_kink_chi2`), which the fast test's windows cannot
    absorb when the kink falls inside one of them: the chi-square that
    model leaves, less the jump model's, in units of the scaled noise.  It
    never exceeds the fast statistic (the fast null is this one with the
    kink at the boundary), so boundaries below ``screen`` keep theirs.
    With ``first_over``, stops after the first boundary whose statistic
    exceeds it (the rest keep their fast value).
    """
    stat = np.array(stat, dtype=float)
    for i in np.flatnonzero(stat > screen):
        k = int(b[i])
        tau = 0.5 * (t[k - 1] + t[k])
        # Refined only while the answer could still exceed ``screen``.
        sc2 = float(scale[i] if np.ndim(scale) else scale) ** 2
        stop = float(jump_chi2[i]) + screen * sc2
        stat[i] = (_kink_chi2(t, xy, sig, k - W, k + W, tau, stop_below=stop)
                   - float(jump_chi2[i])) / sc2
        if first_over is not None and stat[i] > first_over:
            break
    return stat


def outlier_frames(t, xy, sig, idx, scale2: float = 1.0, level: float | None = None,
                   max_share: float | None = None) -> np.ndarray:
    """Frames of ``idx`` off the one quadratic path through them.

    Repeatedly the frame whose deleted residual (its residual from the
    weighted quadratic through all of ``idx`` over ``1 - h``, h its
    leverage: the error of predicting it from the others), in its stated
    error ``sig`` times ``sqrt(scale2)``, is largest is taken off while that
    chi-square (2 axes) exceeds ``-2 ln(level / len(idx))`` (chi-square(2)'s
    point at ``level`` over the frames, Bonferroni), at most ``max_share``
    of the frames (rounded down); ``level`` and ``max_share`` default to
    :data:`OUTLIER_LEVEL` and :data:`MAX_OUTLIER_SHARE`.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Frame times (s).
    xy : ndarray, shape (n, 2)
        Ball centres (m).
    sig : ndarray, shape (n,)
        Per-frame standard error (m).
    idx : array_like of int
        The frames to test.
    scale2 : float
        Factor (>= 1) on the stated variances (:func:`change_statistic`'s
        scale, squared).

    Returns
    -------
    ndarray of int
        The frames taken off, in the order they were.
    """
    level = OUTLIER_LEVEL if level is None else level
    max_share = MAX_OUTLIER_SHARE if max_share is None else max_share
    idx = list(np.asarray(idx, dtype=int))
    limit = -2.0 * np.log(level / max(len(idx), 1))
    gone = []
    while len(gone) < int(max_share * (len(idx) + len(gone))) and len(idx) > 4:
        k = np.asarray(idx)
        s = t[k] - t[k].mean()
        X = np.stack([np.ones_like(s), s, s * s], axis=1)
        w = 1.0 / sig[k] ** 2
        A = np.linalg.inv(X.T @ (X * w[:, None]))
        r = xy[k] - X @ (A @ ((X * w[:, None]).T @ xy[k]))
        h = np.einsum("ni,ij,nj->n", X, A, X) * w
        d = np.sum(r * r, axis=1) * w / np.maximum(1.0 - h, 1e-12) / scale2
        j = int(np.argmax(d))
        if d[j] <= limit:
            break
        gone.append(idx.pop(j))
    return np.asarray(gone, dtype=int)


def trimmed_statistic(t, xy, sig, b: int, W: int, scale2: float = 1.0) -> float:
    """The change statistic at boundary ``b`` (first frame after it) with
    the frames off the one path through its ``2 W`` frames left out
    (:func:`outlier_frames`): the Wald statistic of equal position and
    velocity of the quadratics fitted to the rest of the ``W`` frames on
    each side, in the stated errors times ``sqrt(scale2)``.  Without such
    frames it is :func:`change_statistic`'s at ``b``.  The fits are
    :func:`_window_fits`' with the left-out frames weighted 0 (their error
    infinite)."""
    gone = outlier_frames(t, xy, sig, np.arange(b - W, b + W), scale2)
    sig = np.array(sig, dtype=float)
    sig[gone] = np.inf
    tau = np.full(2, 0.5 * (t[b - 1] + t[b]))
    (cl, cr), (covl, covr), _ = _window_fits(t, xy, sig, np.array([b - W, b]), W, tau)
    d = cl[:, :2] - cr[:, :2]
    return float(np.einsum("ai,ij,aj->", d, np.linalg.inv(covl[:2, :2] + covr[:2, :2]), d)) / scale2


def _change_point(t, xy, sig, lo: int, hi: int, candidates, kink: bool = False,
                  kappa_max: float = np.inf) -> int:
    """Maximum-likelihood place of one jump in frames ``lo..hi-1``: the
    boundary (first frame after) among ``candidates`` whose fits before and
    after (quadratics; before, with ``kink``, the model's own motion with a
    kink allowed, :func:`_kink_chi2`) leave the least chi-square over the
    same frames."""
    best, best_c = None, np.inf
    for k in candidates:
        if k - lo < 5 or hi - k < 3:
            continue
        if kink:
            c = _kink_chi2(t, xy, sig, lo, k, t[k - 1], end_gap=KINK_END_GAP, kappa_max=kappa_max)
        else:
            c = float(_window_fits(t, xy, sig, np.array([lo]), k - lo, np.array([t[lo]]))[2][0])
        c += float(_window_fits(t, xy, sig, np.array([k]), hi - k, np.array([t[k]]))[2][0])
        if c < best_c:
            best, best_c = int(k), c
    return best if best is not None else int(candidates[0])


def _moved_index(xy, sig) -> int:
    """First frame of the first ``MOVE_CONFIRM_FRAMES`` in a row away from the
    start by ``MOVE_SIGMAS`` errors: the strike is behind it.  The start is
    the median of the first ``2 MOVE_CONFIRM_FRAMES - 1`` frames: one frame
    off (the first of seed 34's H.264 shot 27, 0.35 px, 7 stated errors)
    made every later frame "moved", and the strike itself a contact."""
    start = np.median(xy[:2 * MOVE_CONFIRM_FRAMES - 1], axis=0)
    far = np.hypot(*(xy - start).T) > MOVE_SIGMAS * sig * np.sqrt(2)
    run = np.convolve(far.astype(int), np.ones(MOVE_CONFIRM_FRAMES, int), "valid")
    hits = np.flatnonzero(run == MOVE_CONFIRM_FRAMES)
    return int(hits[0]) if hits.size else len(xy)


def strike_at(coef_before, cov_before, scale=1.0) -> bool:
    """A change of motion is the strike: the ball still in every window
    before it, from the track's start (``coef_before``, ``(m, 2 axes, 3)``
    of :func:`_window_fits`, one per boundary whose left window ends by the
    change; ``cov_before`` their unscaled covariances ``(m, 3, 3)``, times
    ``scale`` (scalar or ``(m,)``) squared as :func:`change_statistic`
    scales the noise).  Still: each window's fitted velocity within its
    errors of zero, the ``m`` windows together at ``STILL_LEVEL``
    (Bonferroni: ``v.v / var <= -2 ln(STILL_LEVEL / m)`` in each).  A
    contact changes a moving ball's motion; a still ball's only change is
    the strike.  (pap37's first rule asked only the window just before the
    change, at ``2 MOVE_SIGMAS^2`` = 50, a position rule's constant: it
    meant "slow", not "still", and took real contacts and a re-strike after
    a rest for the strike: strike_power.py's 400 scenes on a 100-m table
    lost 9 contacts of each error kind; a second strike after a rest was
    found in 0 of 8 scenes.)"""
    v = np.asarray(coef_before, float).reshape(-1, 2, 3)[:, :, 1]
    if not len(v):
        return False
    var = np.asarray(cov_before, float).reshape(-1, 3, 3)[:, 1, 1] * np.broadcast_to(
        np.asarray(scale, float), (len(v),)) ** 2
    still = -2.0 * np.log(STILL_LEVEL / len(v))
    return bool(np.all(var > 0) and np.all(np.sum(v * v, axis=1) / var <= still))


def _crossing_time(c, t_lo, t_hi, tau, target) -> float | None:
    """First time in [t_lo, t_hi] the quadratic ``c0 + c1 s + c2 s^2`` (``s = t - tau``)
    reaches ``target``."""
    poly = np.trim_zeros(np.array([c[2], c[1], c[0] - target]), "f")
    if poly.size < 2:
        return None
    roots = np.roots(poly)
    real = np.sort(roots[np.abs(roots.imag) < 1e-9].real) + tau
    hit = real[(real >= t_lo - 1e-12) & (real <= t_hi + 1e-12)]
    return float(hit[0]) if hit.size else None


def _cushion_by_geometry(t, xy, sig, table, R, start: int, W: int):
    """First frame whose centre, or the path extrapolated to it from the
    frames before, is within R of a cushion line: ``(t_contact, index)`` or None."""
    lines = ((0, R), (0, table.length - R), (1, R), (1, table.width - R))

    def crossing(c, t_lo, t_hi):
        times = [_crossing_time(c[axis], t_lo, t_hi, t_lo, off) for axis, off in lines]
        times = [tc for tc in times if tc is not None]
        return min(times) if times else None

    return _by_geometry(t, xy, sig, lambda p: edge_gap(p, table, R), crossing, start, W)


# Points per frame interval at which the extrapolated path is tested against
# a listed ball's circle: 1/256 of a frame, far below the one-frame target.
BALL_CROSSING_STEPS = 256


def ball_gap(xy, balls, R: float) -> np.ndarray:
    """Distance (m) of each centre beyond touching the nearest listed ball
    (centres 2R apart); ``inf`` without balls."""
    balls = np.asarray(balls, dtype=float).reshape(-1, 2)
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    if not len(balls):
        return np.full(len(xy), np.inf)
    return np.hypot(xy[:, None, 0] - balls[None, :, 0], xy[:, None, 1] - balls[None, :, 1]).min(axis=1) - 2 * R


def _ball_by_geometry(t, xy, sig, balls, R, start: int, W: int):
    """First frame whose path extrapolated to it from the frames before (or
    whose centre) reaches a ball the scene lists at rest (centres 2R apart):
    ``(t_contact, index)`` or None.  The ball is never seen inside that
    circle (it bounces off), so it is the path that tells: a contact too
    gentle for the change test against a realistic look's tracking noise
    (0.1 m/s; statistic 36 against the threshold's 40, the ball_contact
    preset's seed 4 at 120 fps) is found where the path meets the ball."""
    if not len(np.asarray(balls, dtype=float).reshape(-1, 2)):
        return None
    steps = np.linspace(0.0, 1.0, BALL_CROSSING_STEPS + 1)

    def crossing(c, t_lo, t_hi):
        s = (t_hi - t_lo) * steps
        pts = c[:, 0][None, :] + c[:, 1][None, :] * s[:, None] + c[:, 2][None, :] * (s * s)[:, None]
        hit = np.flatnonzero(ball_gap(pts, balls, R) <= 0)
        return float(t_lo + s[hit[0]]) if hit.size else None

    return _by_geometry(t, xy, sig, lambda p: ball_gap(p, balls, R), crossing, start, W)


def _by_geometry(t, xy, sig, gap_of, crossing, start: int, W: int):
    """First frame whose centre is ``CUSHION_SIGMAS`` errors beyond an
    obstacle (``gap_of(xy)``, m, below zero inside it), or whose path
    extrapolated from the frames before crosses it (``crossing(coef, t_lo,
    t_hi)``: the first time the quadratic about ``t_lo`` reaches it, or
    None): ``(t_contact, index)`` or None."""
    n = len(t)
    gap = gap_of(xy)
    # A centre seen beyond the line by CUSHION_SIGMAS errors: the contact is
    # certain by then (one that comes to rest against the cushion sits on
    # the line; the crossing test below places the rest).
    touching = gap[start:] <= -CUSHION_SIGMAS * sig[start:]
    first = start + int(np.argmax(touching)) if touching.any() else n
    # Between frames: a quadratic through the W frames before k, carried on
    # to t_k; if it crossed the obstacle, the contact came before frame k
    # (a fast ball can touch and be back out between two frames).
    stop = min(first + 1, n)
    for size in range(MOVE_CONFIRM_FRAMES, W + 1):
        # Windows of ``size`` frames after the strike: shorter ones just after it.
        ks = np.arange(start + size, stop) if size == W else np.arange(start + size, min(start + size + 1, stop))
        if not ks.size:
            continue
        coef, _, _ = _window_fits(t, xy, sig, ks - size, size, t[ks - 1])  # (m, 2, 3) about t_{k-1}
        h = (t[ks] - t[ks - 1])[:, None]
        pred = coef[:, :, 0] + coef[:, :, 1] * h + coef[:, :, 2] * h * h
        crossed = np.flatnonzero(gap_of(pred) <= 0)
        if crossed.size:
            i = int(crossed[0])
            k = int(ks[i])
            tc = crossing(coef[i], t[k - 1], t[k])
            return (tc if tc is not None else float(t[k])), k
    if first < n:
        # Touching in a frame with no crossing on the way there: the ball
        # crept into the cushion; the contact is placed at that frame.
        return float(t[first]), first
    return None


def find_contact(t, xy, ok, stderr_m, table, R: float, balls=(), W: int | None = None,
                 threshold: float = CHANGE_THRESHOLD, time_corr=None) -> Contact | None:
    """The first contact in a track, or None.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Frame times (s).
    xy : ndarray, shape (n, 2)
        Ball centre (m) in the table frame; NaN where not found.
    ok : ndarray of bool, shape (n,)
        Frames where the ball was found.
    stderr_m : ndarray, shape (n,) or (n, 2), or float
        Standard error of each centre (m).
    table : Table
        Playing surface: its edges are the cushions.
    R : float
        Ball radius (m).
    balls : array_like, shape (k, 2)
        Centres (m) of other balls known to rest on the table.
    W : int, optional
        Frames each side of a boundary in the change test; :func:`window_frames`
        when absent.
    threshold : float
        Change statistic above which a boundary is a contact.
    time_corr : callable, optional
        ``time_corr(t)``: the per-axis correlation (k, k) of the errors of
        frames at times ``t`` (s), for errors correlated in time (an
        inter-frame codec: ``recover.mle.time_correlation``); None:
        independent.  See :func:`change_statistic`.

    Returns
    -------
    Contact or None
        ``index`` is into the full track (``ok`` frames and the others).
    """
    t = np.asarray(t, dtype=float)
    xy = np.asarray(xy, dtype=float)
    ok = np.asarray(ok, dtype=bool) & np.all(np.isfinite(xy), axis=1)
    rows = np.flatnonzero(ok)
    if rows.size < MOVE_CONFIRM_FRAMES + 1:
        return None
    tt, pp = t[rows], xy[rows]
    sig = _frame_sigma(stderr_m if np.ndim(stderr_m) == 0 else np.asarray(stderr_m)[rows], len(rows), pp)
    moved = _moved_index(pp, sig)
    W = window_frames(tt) if W is None else W
    if moved >= len(rows):
        return None
    found = []
    geo = _cushion_by_geometry(tt, pp, sig, table, R, moved, W)
    if geo is not None:
        found.append(Contact(t=geo[0], index=int(rows[geo[1]]), kind="cushion"))
    hit = _ball_by_geometry(tt, pp, sig, balls, R, moved, W)
    if hit is not None:
        found.append(Contact(t=hit[0], index=int(rows[hit[1]]), kind="ball"))
        if geo is None or hit[1] < geo[1]:
            geo = hit
    b_all, stat_all, scale_all, (cl_all, cr_all), jump_all = change_statistic(
        tt, pp, sig, W, details=True, time_corr=time_corr)
    # Boundaries with the left window wholly after the strike, and not past
    # a cushion contact already found.
    last = geo[1] if geo is not None else len(tt)
    anchored = False
    while True:
        keep = (b_all - W >= moved) & (b_all <= last)
        b, stat, cl, cr, jump_chi2 = b_all[keep], stat_all[keep], cl_all[keep], cr_all[keep], jump_all[keep]
        scale = scale_all[keep] if np.ndim(scale_all) else scale_all
        stat = kink_statistic(tt, pp, sig, W, b, stat, jump_chi2, scale, threshold, first_over=threshold)
        # Kept for later passes: a boundary refined to at most the threshold
        # is not refined again (its statistic does not depend on the pass).
        stat_all[keep] = stat
        over = np.flatnonzero(stat > threshold)
        if not over.size:
            break
        # A run of flagged boundaries (the first and those within W after it)
        # is no change when, with the frames off the path left out, each
        # reads one motion on both sides (SAME_MOTION_CHI2): those frames are
        # outliers, and the search goes on past the run.
        run = over[b[over] <= b[over[0]] + W]
        if not any(trimmed_statistic(tt, pp, sig, int(b[r]), W,
                                     float(scale[r] if np.ndim(scale) else scale) ** 2) > SAME_MOTION_CHI2
                   for r in run):
            stat_all[np.isin(b_all, b[run])] = 0.0
            continue
        # The first boundary over the threshold has the jump somewhere in its
        # right window: place it by maximum likelihood there, with a few
        # frames beyond (no more: a second contact may follow soon after).
        i = int(over[0])
        k0 = int(b[i])
        hi = min(k0 + W + 4, len(tt))
        cands = np.arange(k0, hi - 3)
        # Before the jump the model's own kink is allowed, but only before
        # k0: its frames are free of the jump (earlier boundaries were).
        k = (_change_point(tt, pp, sig, k0 - W, hi, cands, kink=CHANGE_POINT_KINK,
                           kappa_max=float(tt[k0 - 1])) if cands.size else k0)
        j = int(np.clip(np.searchsorted(b, k), 0, len(b) - 1))
        before = b_all <= k
        # The left windows' covariances (change_statistic's, which it does
        # not return) only when the strike question is asked, once a track.
        if not anchored and strike_at(cl_all[before],
                                      _window_fits(tt, pp, sig, b_all[before] - W, W,
                                                   0.5 * (tt[b_all[before] - 1] + tt[b_all[before]]))[1],
                                      scale_all[before] if np.ndim(scale_all) else scale_all):
            # The ball was still in every window before this change: it is
            # the strike (a change of motion by definition), which
            # _moved_index placed too early (a resting ball's track wandering
            # by MOVE_SIGMAS errors: realistic H.264 38/21, "moved" at 0.10
            # s, the strike at 0.40 s cut as an unknown contact, and every
            # frame of motion with it).  The search starts again after the
            # strike's window, once: the track's first motion is the strike,
            # every later change a contact (a re-strike after a rest too).
            moved, anchored = k, True
            continue
        if b[j] == k:
            tc = _jump_time(cl[j], cr[j], tt[k - 1], tt[k])
            centre = cl[j][:, 0] + cl[j][:, 1] * (tc - 0.5 * (tt[k - 1] + tt[k]))
        else:  # too near the end for windows on both sides
            tc, centre = 0.5 * (tt[k - 1] + tt[k]), pp[k - 1]
        kind = _kind_at(centre, table, R, balls, float(np.median(sig)))
        found.append(Contact(t=tc, index=int(rows[k]), kind=kind, statistic=float(stat[i])))
        break
    if not found:
        return None
    return min(found, key=lambda c: (c.index, c.t))


def _jump_time(cl, cr, t_lo, t_hi) -> float:
    """Where the left and right fits (about the midpoint) meet: the time in
    [t_lo, t_hi] minimising their squared distance (position is continuous
    at a contact, velocity is not)."""
    tau = 0.5 * (t_lo + t_hi)
    d = cl - cr                                     # (2, 3): x, v, a/2 differences
    s = np.linspace(t_lo - tau, t_hi - tau, 201)
    gap = d[:, 0][None, :] + d[:, 1][None, :] * s[:, None] + d[:, 2][None, :] * (s * s)[:, None]
    return float(tau + s[np.argmin(np.sum(gap * gap, axis=1))])


def _kind_at(centre, table, R, balls, sigma) -> str:
    balls = np.asarray(balls, dtype=float).reshape(-1, 2)
    if len(balls):
        dist = np.hypot(*(balls - centre).T)
        if dist.min() <= 2 * R + BALL_TOLERANCE_M:
            return "ball"
    if edge_gap(centre[None, :], table, R)[0] <= max(CUSHION_SIGMAS * sigma, BALL_TOLERANCE_M):
        return "cushion"
    return "unknown"


# Frames before a detected contact left out as well: the detector places a
# contact within one frame (benchmarks/contact.py), and one frame of margin
# keeps a late placement's first frame after the contact out of the fit.
CUT_MARGIN_FRAMES = 1


def analysed_frames(t, contact: Contact | None, exposure_s: float = 0.0,
                    margin: int = CUT_MARGIN_FRAMES) -> int:
    """How many leading frames of a track the fit may use: all of them without
    a contact, else those before ``contact.index - margin`` whose exposure
    (centred on the frame's time) ends before the contact.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Frame times (s).
    contact : Contact or None
    exposure_s : float
        Exposure (s).
    margin : int
        Frames left out before the contact's index.
    """
    t = np.asarray(t, dtype=float)
    if contact is None:
        return len(t)
    n = max(contact.index - margin, 0)
    before = np.flatnonzero(t[:n] + 0.5 * exposure_s < contact.t)
    return int(before[-1]) + 1 if before.size else 0
