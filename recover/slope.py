"""Whether a table that is not level explains a track the level model does
not: the rolling phase fitted once more with a constant in-plane
acceleration (a slope), for the refusal's reason (recover.estimate.unexplained).

On a level table a rolling ball moves along a line and decelerates by
``k = 5/7 mu_r g`` along its velocity (paper eq. 16).  On a table sloped by
``theta`` it also accelerates by ``a = 5/7 g sin(theta)`` downhill (the
rolling ball's inertia takes 2/7 of the slope's pull, as it takes 2/7 of
friction's), two more parameters.  Along the path that acceleration cannot
be told from a wrong ``mu_r``; across it, no friction gives it.  Pure
functions of arrays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from cuespin.recover.measurements import MAX_CODEC_NOISE_RATIO, build_measurements, codec_excess, codec_noise_ratio
from cuespin.recover.mle import ar1_from_lag1, ar1_sandwich, lag1_autocorrelation, shared_sandwich

# The across-path acceleration must be this many of its standard errors off
# zero for the slope to be named: a level table's rolling ball (a wrong
# mu_r, which the acceleration's part along the path takes up) measured
# |z| at most 2.6 on 48 generated level tracks with a wrong mu_r whose
# sloped fit explained them (docs/measurements.md "corners17"); 5 leaves a
# margin, under the 10-1476 of generated sloped tracks and the real
# clips' 45-53.  Its standard error allows for tracking errors correlated
# along the track (AR(1), rolling_slope): on 400 level tracks at each
# lag-1 correlation 0, 0.5 and 0.8 (recover.simulate's null rolling
# tracks) |z| passed 1.96 on 14, 18, 18 (nominal 20) and 5 on none, where
# the plain (J^T J)^-1 gave 16, 103, 196 and 0, 2, 35 (docs/measurements.md
# "stats12b"; 14, 16, 14 with the rho band below, rev13s).  On inter-frame
# video the codec's correlation in time instead: 24 of 400 level tracks
# over 1.96, none over 5 (rev13s).  So |z| is near N(0, 1) and 5's nominal
# false-positive rate (6e-7) is below what 400 tracks measure: 0 of 1600,
# under 0.19% (95%).
SLOPE_Z = 5.0
# Fewer rolling frames than this leave the six parameters unmeasured.
MIN_ROLLING_FRAMES = 12
# The AR(1) sandwich's variance of the across-path acceleration is taken
# at its largest over the correlations within RHO_BAND_SE of the residuals'
# lag-1 autocorrelation's sampling error (_rho_band), not at the point
# estimate alone: on short rolling phases that estimate is noisy and the
# variance is not monotone in rho (near 1 a shared error moves the start
# and velocity, not the acceleration), so an error of it either way can
# shrink the standard error.  On 400 short level phases per length (60 fps,
# AR(1) rho 0.8; review 13's short.py) |z| passed 1.96 on 16%, 11%, 10% at
# 12, 20, 40 frames and 5 on 3 (12 frames) at the point estimate; 4.8%,
# 5.2%, 6.8% and none with the band at 1 s.e. (held out, seed 5: 3.3%,
# 5.5%, 3.7%; independent errors 1.3-4.3%).  At 2 s.e. 2.5-6.0% (wider than
# needed); rho raised by 1-2 s.e. instead 11-28%; MIN_ROLLING_FRAMES raised
# to 40 leaves 10%.  The cost: a real clip's slope (0.0056 m/s^2) over 40
# frames passed SLOPE_Z on 52% of phases with independent errors, 65% at
# the point estimate (docs/measurements.md "rev13s").
RHO_BAND_SE = 1.0
# Correlations asked across the band (its ends included): not tuned.
RHO_BAND_POINTS = 9
# A rolling ball's acceleration per unit slope (sin theta): 5/7 g, as its
# rolling deceleration is 5/7 mu_r g (eq. 16).
ROLLING_SHARE = 5.0 / 7.0


@dataclass(frozen=True)
class SlopeFit:
    """The rolling phase's two fits.

    ``a`` the constant in-plane acceleration beyond the rolling friction
    (m/s^2, table axes), ``a_across`` its part across the path (m/s^2,
    signed along the path's left normal) and ``z_across`` that over its
    standard error; ``ratio_level`` and ``ratio_slope`` the codec-noise
    ratios (recover.measurements.codec_noise_ratio) the level and the sloped
    fit need on the same frames; ``frames`` how many; ``ar1`` the lag-1
    correlation of the tracking errors the standard error allows for
    (measured from the sloped fit's residuals).
    """

    a: np.ndarray
    a_across: float
    z_across: float
    ratio_level: float
    ratio_slope: float
    frames: int
    g: float = 9.81
    ar1: float = 0.0

    @property
    def explains(self) -> bool:
        """The slope explains the rolling phase: the sloped fit needs no
        more codec noise than the guard allows, and its acceleration across
        the path (which no friction gives) is over :data:`SLOPE_Z` standard
        errors.  The level fit's own ratio is not asked: a track refused on
        the whole may miss by less in its rolling phase alone (measured 9.9
        there, 12 on the whole, its slope 53 standard errors)."""
        return bool(self.ratio_slope <= MAX_CODEC_NOISE_RATIO and abs(self.z_across) > SLOPE_Z)

    @property
    def slope_mm_per_m(self) -> float:
        """The slope that gives ``a`` to a rolling ball, ``|a| / (5/7 g)`` (mm/m)."""
        return 1000.0 * float(np.hypot(*self.a)) / (ROLLING_SHARE * self.g)

    def reason(self) -> str:
        """The refusal's reason in the user's terms."""
        size = float(np.hypot(*self.a))
        u = self.a / size
        axis = ("+x" if u[0] > 0 else "-x") if abs(u[0]) > abs(u[1]) else ("+y" if u[1] > 0 else "-y")
        return (f"the table is not level: the rolling ball accelerates {size:.4f} m/s^2 towards {axis} "
                f"(({u[0]:+.2f}, {u[1]:+.2f}) in table axes), a slope of {self.slope_mm_per_m:.1f} mm/m "
                f"(a = 5/7 g slope); {abs(self.a_across):.4f} m/s^2 of it across the path "
                f"({abs(self.z_across):.0f} standard errors), which no friction gives (its part along the path "
                f"could be a wrong mu_r instead); the level model needed {self.ratio_level:.0f} times the "
                f"tracker's stated error as codec noise, with the slope {self.ratio_slope:.1f}; cuespin models "
                "a level table")


def _sideways(t, T):
    """Displacement across the path (m) per unit across acceleration of a
    ball rolling to rest at ``T`` under friction along its velocity, to
    first order in the slope: ``v_n' = a_n - k v_n / |v|`` with ``|v| = k (T
    - t)`` gives ``v_n = -a_n (T - t) ln(1 - t/T)`` and this integral
    (``t^2/2`` for small ``t``, ``T^2/4`` at rest)."""
    if not np.isfinite(T) or T <= 0:
        return 0.5 * t * t
    e = np.clip(t / T, 0.0, 1.0)
    w = 1.0 - e
    with np.errstate(divide="ignore", invalid="ignore"):
        wlog = np.where(w > 0, w * w * np.log1p(-e), 0.0)
    return T * T * (0.5 * e - 0.25 * e * e + 0.5 * wlog)


def rolling_path(p, t, k):
    """Centres (m), shape (n, 2), of a ball rolling from ``p[:2]`` at
    velocity ``p[2:4]`` (m/s) at ``t = 0`` under the rolling deceleration
    ``k`` (m/s^2, eq. 16) and, with ``len(p) == 6``, a constant acceleration
    ``p[4:6]`` (m/s^2), to first order across the path (:func:`_sideways`);
    at rest from the stop on."""
    v = np.asarray(p[2:4], dtype=float)
    speed = float(np.hypot(*v))
    u = v / speed if speed > 0 else np.array([1.0, 0.0])
    n = np.array([-u[1], u[0]])
    a = np.asarray(p[4:6], dtype=float) if len(p) > 4 else np.zeros(2)
    dec = k - float(a @ u)
    T = speed / dec if dec > 0 else float("inf")
    tc = np.minimum(t, T)
    s = speed * tc - 0.5 * dec * tc * tc
    return p[:2] + s[:, None] * u + (float(a @ n) * _sideways(t, T))[:, None] * n


def _rho_band(meas, J, rho1: float, rho: float) -> np.ndarray:
    """The AR(1) correlations the slope's variance is asked at: the errors'
    ``rho`` (from the residuals' lag-1 autocorrelation ``rho1``,
    recover.mle.ar1_from_lag1) and :data:`RHO_BAND_POINTS` across those
    that ``rho1`` plus or minus :data:`RHO_BAND_SE` of its sampling error
    ``sqrt((1 - rho1^2) / N)`` (N pairs of consecutive frames, both axes)
    give."""
    pairs = max(2 * (int(np.sum(meas.single)) - 1), 1)
    half = RHO_BAND_SE * math.sqrt(max(1.0 - max(rho1, 0.0) ** 2, 0.0) / pairs)
    lo, hi = (ar1_from_lag1(meas, J, r) for r in (rho1 - half, rho1 + half))
    return np.r_[rho, np.linspace(lo, hi, RHO_BAND_POINTS)]


def rolling_slope(t, xy, cov, k: float, sigma: float, px_to_m=None, g: float = 9.81,
                  acf=None) -> SlopeFit | None:
    """Fit the rolling frames ``t, xy`` (from the end of sliding to the
    rest) level and sloped, each once, weighted by the stated covariances.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Times (s) of the rolling frames.
    xy : ndarray, shape (n, 2)
        Centres (m).
    cov : ndarray, shape (n, 2, 2)
        Stated covariances (m^2).
    k : float
        Rolling deceleration ``5/7 mu_r g`` (m/s^2) of the friction given.
    sigma : float
        The track's stated per-axis error at the median frame (m), as the
        guard's ratio uses.
    px_to_m : ndarray, shape (n, 2, 2), optional
        Metres per pixel (the codec's error lives in the image).
    g : float
        Gravity (m/s^2).
    acf : tuple, optional
        An inter-frame codec's correlation of the whole error in time
        (recover.mle.INTER_CODEC_ACF, tau in s): the errors' covariance is
        that model's (recover.mle.shared_sandwich).  None: AR(1), its
        lag-1 correlation read from the residuals.

    Returns
    -------
    SlopeFit or None
        None with fewer than :data:`MIN_ROLLING_FRAMES` frames or a fit
        that did not run.
    """
    t = np.asarray(t, dtype=float)
    if len(t) < MIN_ROLLING_FRAMES:
        return None
    tt = t - t[0]
    meas = build_measurements(tt, xy, cov, px_to_m=px_to_m)
    A = np.column_stack([np.ones_like(tt), tt, 0.5 * tt * tt])
    c = np.linalg.lstsq(A, xy, rcond=None)[0]  # each coordinate quadratic: the start
    v = c[1]
    u = v / max(float(np.hypot(*v)), 1e-12)
    fits = []
    try:
        for start in (np.r_[c[0], v], np.r_[c[0], v, c[2] + k * u]):
            fit = least_squares(lambda p: meas.whiten(rolling_path(p, tt, k)).ravel(), start, method="lm")
            res = fit.fun.reshape(-1, 2)
            cv = codec_excess(meas, res, len(start))
            fits.append((fit, codec_noise_ratio(meas, cv, sigma)))
    except (ValueError, np.linalg.LinAlgError, FloatingPointError):
        return None
    (_, ratio_level), (sloped, ratio_slope) = fits
    p = sloped.x
    J = sloped.jac
    dof = max(2 * meas.n - len(p), 1)
    scale = max(1.0, float(np.sum(sloped.fun ** 2)) / dof)  # the codec's share, as a scale on the stated errors
    # Tracking errors correlated along the track (a lossy codec, AR(1) of
    # lag-1 rho) move the fitted acceleration more than independent ones:
    # at rho 0.8 the plain (J^T J)^-1 put the level table's |z| over
    # SLOPE_Z on 35 of 400 tracks.  Its covariance is the AR(1) sandwich
    # at the errors' correlation read from the residuals (as the MLE's
    # AR(1) model reads it, recover.mle.ar1_from_lag1).  An inter-frame
    # codec's error is shared on two time scales (0.02 s and 2.8 s), and
    # its slow part looks like the motion, so the residuals cannot show it
    # and no one rho states it: there its measured correlation in time (the
    # MLE's, recover.mle.codec_sandwich).  On 200 level tracks with that
    # error the AR(1) sandwich put |z| over 1.96 on 50 and over SLOPE_Z on
    # 4 (480 fps; docs/measurements.md "rev13s").
    speed = float(np.hypot(*p[2:4]))
    u = p[2:4] / speed if speed > 0 else np.array([1.0, 0.0])
    n = np.array([-u[1], u[0]])
    a_across = float(p[4:6] @ n)
    rho = 0.0
    try:
        if acf is not None:
            var = float(n @ shared_sandwich(meas, J, acf)[4:6, 4:6] @ n)
        else:
            rho1 = lag1_autocorrelation(meas, sloped.fun.reshape(-1, 2))[0]
            rho = ar1_from_lag1(meas, J, rho1)
            var = max(float(n @ ar1_sandwich(meas, J, r)[4:6, 4:6] @ n) for r in _rho_band(meas, J, rho1, rho))
    except np.linalg.LinAlgError:
        return None
    se = math.sqrt(max(var * scale, 0.0))
    return SlopeFit(a=np.asarray(p[4:6], dtype=float), a_across=a_across,
                    z_across=a_across / se if se > 0 else float("inf"), ratio_level=float(ratio_level),
                    ratio_slope=float(ratio_slope), frames=len(t), g=g, ar1=rho)
