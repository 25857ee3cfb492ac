"""Maximum-likelihood fit of the forward model to the time-stamped track.

Unknowns ``x0, t0, v0, w0`` (and ``mu_s, mu_r`` with ``fit_friction``).  Each
observed centroid is the exposure-average of the ball's centre, with
Gaussian noise of the tracker's measured standard error; the fit minimises
the weighted squared residuals (scipy's least_squares), and standard errors
come from the Jacobian at the optimum, scaled up by the reduced chi-square
when the residuals are larger than the stated noise.

Model no more than the data supports: a full fit with free slip is compared
with rolling from the strike (``w0 = z_hat x v0 / R``, paper case 4) by a
likelihood-ratio test; rolling is kept unless the full model improves the
chi-square by more than chi^2(2) at the 1% level (9.21), the chi-square
difference divided by the full fit's reduced chi-square when that exceeds 1.  When the track
ends before sliding does, the slip's magnitude (so ``w0``) is not determined
and the answer is ``degenerate`` with ``w0`` withheld.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from cuespin.physics.motion import BallParams, Shot, phases, positions, z_cross

# chi^2(2) at the 1% level: free slip must beat rolling-from-the-strike by this.
SLIP_LR_THRESHOLD = 9.21
# A fit whose residuals are this many times the stated variance does not
# describe the track (it stopped far from the shot, or the track is not one
# shot); it is reported as failed, never as an answer.  Good fits measured
# over the 200-shot benchmark stay far below it (README).
MAX_CHI2_PER_DOF = 100.0
# v0 is "not determined" when its standard error is this fraction of |v0| or
# more: the 95% interval then reaches from zero to twice the speed.  Tracks
# that show the strike measure |v0| to 1e-5-1e-3 (README); one that starts
# mid-shot extrapolates back to an unseen strike and trades t0 against v0
# (measured: 25 m/s of error on a 0.07 m/s shot).
MAX_REL_STDERR_V0 = 0.5
# Convergence tolerances of the Levenberg-Marquardt fit (see _fit).
LM_TOL = 1e-7
# Gauss-Legendre nodes for averaging the model over the exposure: exact for
# the (quadratic) motion within a phase.
_GL_T, _GL_W = np.polynomial.legendre.leggauss(3)


@dataclass(frozen=True)
class MLEResult:
    """Answer of the maximum-likelihood fit; ``status`` as CONVENTIONS.md says.

    Vectors are ndarrays or None when not determined; ``stderr`` holds the
    same keys as the estimates.  ``model`` is ``full`` (free slip) or
    ``rolling`` (rolling from the strike, chosen by the likelihood ratio
    ``slip_lr``).  ``residuals`` are the normalised residuals per frame
    (shape (n, 2)), ``cov`` the covariance of the fitted parameters in the
    order ``names``.
    """

    status: str
    reason: str
    v0: np.ndarray | None = None
    w0: np.ndarray | None = None
    x0: np.ndarray | None = None
    t0: float | None = None
    t1: float | None = None
    t2: float | None = None
    x2: np.ndarray | None = None
    mu_s: float | None = None
    mu_r: float | None = None
    stderr: dict = field(default_factory=dict)
    model: str = ""
    slip_lr: float = float("nan")
    chi2: float = float("nan")
    dof: int = 0
    residuals: np.ndarray | None = None
    cov: np.ndarray | None = None
    names: tuple = ()

    def __bool__(self):
        return self.status == "ok"


def _unpack(p, rolling, fit_friction, params: BallParams):
    x0, t0, v0 = p[0:2], p[2], p[3:5]
    i = 5
    if rolling:
        w0 = z_cross(v0) / params.R  # no slip: u0 = 0
    else:
        w0 = p[5:7]
        i = 7
    if fit_friction and rolling:  # no sliding: mu_s leaves no trace in the track
        params = BallParams(R=params.R, mu_s=params.mu_s, mu_r=float(p[i]), g=params.g)
    elif fit_friction:
        params = BallParams(R=params.R, mu_s=float(p[i]), mu_r=float(p[i + 1]), g=params.g)
    return Shot(x0=x0, v0=v0, w0=w0, t0=float(t0)), params


def model_track(shot: Shot, params: BallParams, t, exposure_s: float = 0.0):
    """Observed centre (m) at frame times: the position averaged over the exposure."""
    t = np.asarray(t, dtype=float)
    if exposure_s <= 0:
        return positions(shot, params, t)
    nodes = t[:, None] + 0.5 * exposure_s * _GL_T[None, :]
    x = positions(shot, params, nodes.ravel()).reshape(len(t), len(_GL_T), 2)
    return np.einsum("k,nkd->nd", 0.5 * _GL_W, x)


def _fit(t, xy, sig, p0, rolling, fit_friction, params, exposure_s):
    def resid(p):
        shot, pr = _unpack(p, rolling, fit_friction, params)
        return ((model_track(shot, pr, t, exposure_s) - xy) / sig).ravel()

    lo = np.full(len(p0), -np.inf)
    hi = np.full(len(p0), np.inf)
    # Scale steps to each parameter: metres, seconds, m/s, rad/s.
    x_scale = np.r_[1e-3, 1e-3, 1e-3, 1e-2, 1e-2]
    if not rolling:
        x_scale = np.r_[x_scale, 1.0, 1.0]
    if fit_friction and rolling:
        lo[-1:], hi[-1:] = [0.0], [0.5]
        x_scale = np.r_[x_scale, 1e-3]
    elif fit_friction:
        lo[-2:], hi[-2:] = [1e-3, 0.0], [2.0, 0.5]
        x_scale = np.r_[x_scale, 1e-2, 1e-3]
    if fit_friction:  # bounded: trust-region reflective
        p0 = np.clip(p0, lo + 1e-9, hi - 1e-9)
        return least_squares(resid, p0, bounds=(lo, hi), x_scale=x_scale, method="trf",
                             diff_step=1e-7, xtol=1e-10, ftol=1e-10, gtol=1e-10, max_nfev=60)
    # max_nfev counts residual evaluations, Jacobians included: ~12 iterations,
    # plenty from the segmentation's start; beyond that the fit is lost anyway.
    # Tolerances 1e-7: answers within 5e-6 standard errors of those at 1e-10
    # (10 benchmark shots, both codecs), in 25% less time.
    return least_squares(resid, p0, x_scale=x_scale, method="lm", diff_step=1e-7,
                         xtol=LM_TOL, ftol=LM_TOL, gtol=LM_TOL, max_nfev=100)


def initial_guess(seg, params: BallParams):
    """Start values ``(x0, t0, v0, w0)`` from the piecewise-quadratic segmentation.

    The slip direction is the sliding deceleration's (eq. 3); its magnitude
    follows from the sliding time, eq. 10 (``|u0| = 7/2 mu_s g (t1 - t0)``);
    ``w0 = z_hat x (v0 - u0) / R`` (eq. 31).
    """
    mu_g = params.mu_s * params.g
    a = np.asarray(seg.a_slide, dtype=float)
    u_hat = -a / np.hypot(*a) if np.hypot(*a) > 0 else np.zeros(2)
    t1 = seg.t1 if np.isfinite(seg.t1) else seg.t_last + 0.25 * (seg.t_last - seg.t0)
    u0 = 3.5 * mu_g * max(t1 - seg.t0, 0.0) * u_hat
    w0 = z_cross(np.asarray(seg.v0) - u0) / params.R
    return np.asarray(seg.x0, float), float(seg.t0), np.asarray(seg.v0, float), w0


def fit_mle(t, xy, sigma, params: BallParams, start, exposure_s: float = 0.0,
            fit_friction: bool = False, sliding_ended: bool = True,
            sliding_obvious: bool = False) -> MLEResult:
    """Maximum-likelihood estimate of the shot from a track.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Frame times (s) of frames where the ball was found.
    xy : ndarray, shape (n, 2)
        Observed centres (m).
    sigma : float or ndarray, shape (n,)
        Per-axis standard error of each centre (m).
    params : BallParams
        Known constants (start values of mu_s and mu_r with ``fit_friction``).
    start : tuple
        ``(x0, t0, v0, w0)`` start values, e.g. from :func:`initial_guess`.
    exposure_s : float
        Exposure (s): the model is averaged over it.
    fit_friction : bool
        Estimate ``mu_s`` and ``mu_r`` too.
    sliding_ended : bool
        Whether the track shows sliding end (the segmentation's verdict).
        Sliding that outlasts the track leaves the slip's magnitude, so
        ``w0``, undetermined: the fit then has a flat valley along it and
        may stop anywhere in it, even with ``t1`` just inside the track.
    sliding_obvious : bool
        The segmentation already rejected rolling from the strike
        overwhelmingly; the rolling fit (only there to be rejected by the
        likelihood ratio) is skipped.

    Returns
    -------
    MLEResult
        Never raises for bad data.
    """
    t = np.asarray(t, dtype=float)
    xy = np.asarray(xy, dtype=float)
    sig = np.broadcast_to(np.asarray(sigma, dtype=float), t.shape)[:, None]
    good = np.all(np.isfinite(xy), axis=1) & np.isfinite(sig[:, 0]) & (sig[:, 0] > 0)
    t, xy, sig = t[good], xy[good], sig[good]
    if len(t) < 8:
        return MLEResult("failed", f"only {len(t)} usable frames in the track")
    x0, t0, v0, w0 = (np.asarray(s, dtype=float) for s in start)
    extra = [params.mu_s, params.mu_r] if fit_friction else []
    extra_roll = [params.mu_r] if fit_friction else []
    try:
        full = _fit(t, xy, sig, np.r_[x0, t0, v0, w0, extra], False, fit_friction, params, exposure_s)
        roll = None if sliding_obvious else \
            _fit(t, xy, sig, np.r_[x0, t0, v0, extra_roll], True, fit_friction, params, exposure_s)
        if roll is not None and full.cost > roll.cost:
            # Rolling is nested in the full model, so the full fit stopped in a
            # local minimum: restart it from the rolling answer, nudged along
            # the segmentation's slip, and keep the better.
            shot_r, pr_r = _unpack(roll.x, True, fit_friction, params)
            nudge = 0.05 * np.hypot(*shot_r.v0) / params.R
            w_start = np.asarray(shot_r.w0) + nudge * (np.asarray(w0) - np.asarray(shot_r.w0)) / \
                max(np.hypot(*(np.asarray(w0) - np.asarray(shot_r.w0))), 1e-12)
            fr = [pr_r.mu_s, pr_r.mu_r] if fit_friction else []
            again = _fit(t, xy, sig, np.r_[roll.x[:5], w_start, fr], False, fit_friction, params,
                         exposure_s)
            if again.cost < full.cost:
                full = again
    except (ValueError, np.linalg.LinAlgError, FloatingPointError) as exc:
        return MLEResult("failed", f"the fit did not run: {exc}")
    chi_full = 2 * full.cost
    chi_roll = 2 * roll.cost if roll is not None else np.inf
    # Quasi-likelihood: when the residuals are larger than the stated noise
    # (lossy codecs), the ratio is measured in the residuals' own scale.
    dof_full = max(2 * len(t) - len(full.x), 1)
    lr = (chi_roll - chi_full) / max(1.0, chi_full / dof_full)
    rolling = lr < SLIP_LR_THRESHOLD
    res = roll if rolling else full
    if not res.success and res.status <= 0:
        return MLEResult("failed", f"the fit did not converge: {res.message}")
    shot, pr = _unpack(res.x, rolling, fit_friction, params)
    ph = phases(shot, pr)
    n_par = len(res.x)
    dof = max(2 * len(t) - n_par, 1)
    chi2 = 2 * res.cost
    if chi2 / dof > MAX_CHI2_PER_DOF:
        return MLEResult("failed", f"the fitted shot does not describe the track (residuals "
                         f"{np.sqrt(chi2 / dof):.0f} times the stated noise): the fit stopped far "
                         "from the shot, or the track is not one shot", chi2=float(chi2), dof=int(dof))
    J = res.jac
    try:
        cov = np.linalg.inv(J.T @ J) * max(1.0, chi2 / dof)
    except np.linalg.LinAlgError:
        return MLEResult("degenerate", "the track does not determine the shot (singular information matrix)")
    se = np.sqrt(np.clip(np.diag(cov), 0, None))
    stderr = {"x0": se[0:2], "t0": float(se[2]), "v0": se[3:5]}
    if rolling:
        # w0 = z x v0 / R: its errors are v0's, rotated and scaled.
        cv = cov[3:5, 3:5]
        Rz = np.array([[0.0, -1.0], [1.0, 0.0]]) / pr.R
        stderr["w0"] = np.sqrt(np.diag(Rz @ cv @ Rz.T))
    else:
        stderr["w0"] = se[5:7]
    if fit_friction:
        stderr["mu_r"] = float(se[-1])
        if not rolling:
            stderr["mu_s"] = float(se[-2])
    resid = res.fun.reshape(-1, 2)
    names = ("x0x", "x0y", "t0", "v0x", "v0y") + (() if rolling else ("w0x", "w0y")) + \
        ((("mu_r",) if rolling else ("mu_s", "mu_r")) if fit_friction else ())
    out = dict(v0=shot_vec(shot.v0), w0=shot_vec(shot.w0), x0=shot_vec(shot.x0), t0=shot.t0,
               t1=ph.t1, t2=ph.t2 if np.isfinite(ph.t2) else None,
               x2=ph.x2 if np.isfinite(ph.t2) else None,
               mu_s=pr.mu_s if fit_friction and not rolling else None,
               mu_r=pr.mu_r if fit_friction else None,
               stderr=stderr, model="rolling" if rolling else "full", slip_lr=float(lr),
               chi2=float(chi2), dof=int(dof), residuals=resid, cov=cov, names=names)
    speed = float(np.hypot(*shot.v0))
    se_speed = float(np.hypot(*stderr["v0"]))
    if not se_speed < MAX_REL_STDERR_V0 * speed:
        return MLEResult("degenerate",
                         f"the track does not determine v0 (standard error {se_speed:.3g} m/s for "
                         f"|v0| = {speed:.3g} m/s): the strike at t0 is not in view, or the ball "
                         f"was tracked in too few frames", stderr=stderr, model=out["model"],
                         slip_lr=float(lr), chi2=float(chi2), dof=int(dof), residuals=resid,
                         cov=cov, names=names)
    t_end = float(t[-1])
    frame = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    if not rolling and (ph.t1 > t_end - 2 * frame or not sliding_ended):
        lower = 3.5 * pr.mu_s * pr.g * (t_end - shot.t0)
        out.update(w0=None)
        out["stderr"] = {k: v for k, v in stderr.items() if k != "w0"}
        return MLEResult("degenerate",
                         f"the track ends (t = {t_end:.3f} s) before sliding does: the slip, so w0, "
                         f"is not determined (|u0| > {lower:.2f} m/s); v0 is",
                         **out)
    return MLEResult("ok", "", **out)


def shot_vec(v):
    """A shot's tuple as an ndarray."""
    return np.asarray(v, dtype=float)


def crb_covariance(shot: Shot, params: BallParams, t, sigma, exposure_s: float = 0.0,
                   rolling: bool = False) -> np.ndarray:
    """Cramer-Rao covariance of ``(x0, t0, v0[, w0])`` at the true shot.

    The inverse Fisher information ``(J^T J)^-1`` of the same model and noise
    the fit uses, with ``J`` by central differences at the truth.
    """
    t = np.asarray(t, dtype=float)
    sig = np.broadcast_to(np.asarray(sigma, dtype=float), t.shape)[:, None]
    p = np.r_[shot.x0, shot.t0, shot.v0] if rolling else np.r_[shot.x0, shot.t0, shot.v0, shot.w0]
    steps = np.r_[1e-7, 1e-7, 1e-8, 1e-7, 1e-7, 1e-5, 1e-5][:len(p)]
    cols = []
    for i, h in enumerate(steps):
        dp = np.zeros_like(p)
        dp[i] = h
        a = model_track(_unpack(p + dp, rolling, False, params)[0], params, t, exposure_s)
        b = model_track(_unpack(p - dp, rolling, False, params)[0], params, t, exposure_s)
        cols.append(((a - b) / (2 * h) / sig).ravel())
    J = np.stack(cols, axis=1)
    return np.linalg.inv(J.T @ J)
