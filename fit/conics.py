"""Geometric (orthogonal-distance) fits of the sliding path: parabola or line.

The parabola is Theorem 1's: ``y = a x^2`` (a > 0) rotated by ``theta`` and
moved to the vertex, so the constraint is built in.  Each point's residual
is its signed distance to the curve, from the foot point that solves
``2 a^2 x^3 + (1 - 2 a Y) x - X = 0`` in the parabola's frame.

Curved or straight: the F statistic of the sums of squared orthogonal
distances of the line (2 parameters) and the parabola (4 parameters),
``F = ((SSE_line - SSE_par) / 2) / (SSE_par / (n - 4))``, decided by
fit.decide.curved (threshold calibrated by simulation).  The F form takes
the noise from the residuals themselves, so it holds when the tracker's
stated noise is optimistic (lossy codecs).  Pure functions of arrays.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import f as f_dist

from cuespin.fit.decide import curved as decide_curved
from cuespin.fit.lm import lm_fit
from cuespin.physics.parabola import Parabola

# Residual evaluations the orthogonal-distance parabola fit may take
# (scipy's max_nfev; with the analytic Jacobian, parabola_jacobian, one per
# iteration).  With finite differences (5 evaluations an iteration) the cap
# was 60, about 12 iterations: on the 60 MJPG benchmark shots curved paths
# converged in 3-33 evaluations and straight ones in 8-44, 8 of 40 crept to
# the cap without meeting the 1e-12 tolerances, and at 200 evaluations that
# cost 1.9 s of a 2.5 s recovery (benchmarks/recover_speed.py) while the
# paper's figures on those shots did not change.  The same 12 iterations.
PARABOLA_MAX_NFEV = 12


@dataclass(frozen=True)
class LineFit:
    """A line through ``point`` along unit ``direction``; ``residuals`` are
    signed orthogonal distances (m)."""

    point: np.ndarray
    direction: np.ndarray
    residuals: np.ndarray

    @property
    def sse(self) -> float:
        return float(self.residuals @ self.residuals)


@dataclass(frozen=True)
class ParabolaFit:
    """A constrained parabola fit; falsy when it failed (``reason`` says why).

    ``cov`` is the covariance of ``(log a, theta, vertex_x, vertex_y)`` from
    the fit's Jacobian, at the noise its residuals show.
    """

    ok: bool
    reason: str
    parabola: Parabola | None = None
    residuals: np.ndarray | None = None
    cov: np.ndarray | None = None

    @property
    def sse(self) -> float:
        return float(self.residuals @ self.residuals) if self.residuals is not None else np.inf

    def __bool__(self):
        return self.ok


@dataclass(frozen=True)
class PathShape:
    """The decision between parabola and line for a sliding path.

    ``F`` is the F statistic and ``p_value`` its nominal F(2, n - 4) upper
    tail (for reports); ``curved`` is fit.decide.curved's verdict.
    """

    curved: bool
    F: float
    p_value: float
    line: LineFit
    parabola: ParabolaFit
    sigma: float


def fit_line(p) -> LineFit:
    """Total-least-squares line through points (m), shape (n, 2)."""
    p = np.asarray(p, dtype=float)
    c = p.mean(axis=0)
    _, _, vt = np.linalg.svd(p - c, full_matrices=False)
    d = vt[0]
    n = np.array([-d[1], d[0]])
    return LineFit(point=c, direction=d, residuals=(p - c) @ n)


def _foot_points(par: Parabola, p):
    """Each point's foot on the parabola: its local coordinates ``(X, Y)``
    and the foot's local abscissa ``x`` (Newton on the foot-point cubic
    ``2 a^2 x^3 + (1 - 2 a Y) x - X = 0`` from ``x = X``)."""
    q = par.to_local(p)
    X, Y = q[..., 0], q[..., 1]
    a = par.a
    x = X.copy()
    # The iteration's constants made once (the same numbers each time).
    a2, a6, k = 2 * a * a, 6 * a * a, 1 - 2 * a * Y
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        for _ in range(30):
            f = a2 * x**3 + k * x - X
            fp = a6 * x**2 + k
            step = f / np.where(np.abs(fp) > 1e-12, fp, 1e-12)
            x -= step
            if not np.all(np.abs(step) >= 1e-15):
                break
    return X, Y, x


def parabola_distances(par: Parabola, p, feet=None) -> np.ndarray:
    """Signed orthogonal distances (m) from points to a parabola (+ inside);
    ``feet``: :func:`_foot_points` of the same, when already found."""
    X, Y, x = _foot_points(par, p) if feet is None else feet
    a = par.a
    d = np.hypot(x - X, a * x * x - Y)
    return np.where(Y >= a * X * X, d, -d)


def parabola_jacobian(par: Parabola, p, feet=None) -> np.ndarray:
    """Derivatives of :func:`parabola_distances` with respect to ``(log a,
    theta, vertex_x, vertex_y)``, shape (n, 4).

    At the foot point the distance is ``n . (P - C)`` with ``n`` the unit
    normal ``(-2 a x, 1) / sqrt(1 + 4 a^2 x^2)`` (local frame, pointing to
    the inside); the foot's own shift and the normal's turning drop out (both
    are perpendicular to ``P - C``), so each derivative is the normal
    against the parameter's motion of the point relative to the curve:
    ``-a x^2 n_y`` for ``log a``, ``n . (Y, -X)`` for ``theta`` and minus
    the normal in table axes for the vertex.  ``feet``: as for
    :func:`parabola_distances`.
    """
    X, Y, x = _foot_points(par, p) if feet is None else feet
    a = par.a
    norm = np.sqrt(1.0 + 4.0 * a * a * x * x)
    nx, ny = -2.0 * a * x / norm, 1.0 / norm
    c, s = np.cos(par.theta), np.sin(par.theta)
    return np.stack([-a * x * x * ny, nx * Y - ny * X, -(c * nx - s * ny), -(s * nx + c * ny)], axis=-1)


def fit_parabola(p, start: Parabola, max_nfev: int = PARABOLA_MAX_NFEV) -> ParabolaFit:
    """Orthogonal-distance fit of Theorem 1's parabola to points (m).

    Parameters
    ----------
    p : ndarray, shape (n, 2)
        Points on the sliding path (m).
    start : Parabola
        Starting parabola (e.g. from the time-based segmentation).
    max_nfev : int
        Residual evaluations allowed (:data:`PARABOLA_MAX_NFEV` for the
        path's shape; recover.paper runs its answer's fit to convergence).

    Returns
    -------
    ParabolaFit
    """
    p = np.asarray(p, dtype=float)
    if len(p) < 5:
        return ParabolaFit(False, f"only {len(p)} points on the sliding path")
    if not (np.isfinite(start.a) and start.a > 0):
        return ParabolaFit(False, "no curvature to start from")

    def build(q):
        # log a is unbounded while the fit explores; keep exp finite.
        # (np.clip's bounds on the float: the same number, NaN kept, without its overhead)
        return Parabola(a=float(np.exp(min(max(float(q[0]), -60.0), 60.0))), theta=float(q[1]), vertex=np.array(q[2:4]))

    last = {}

    def feet(q):
        # MINPACK asks for the Jacobian at the point whose distances it has
        # just evaluated: the feet (a Newton solve a point) are found once.
        key = np.asarray(q, dtype=float).tobytes()
        if key not in last:
            par = build(q)
            last.clear()
            last[key] = par, _foot_points(par, p)
        return last[key]

    def resid(q):
        par, found = feet(q)
        return parabola_distances(par, p, found)

    def jac(q):
        par, found = feet(q)
        return parabola_jacobian(par, p, found)

    q0 = np.r_[np.log(start.a), start.theta, start.vertex]
    try:
        # A straight path sends a towards 0, where the fit wanders: cap the
        # effort (PARABOLA_MAX_NFEV).
        r = lm_fit(resid, q0, jac, None, ftol=1e-12, xtol=1e-12, max_nfev=max_nfev)  # least_squares' lm
    except (ValueError, FloatingPointError) as exc:
        return ParabolaFit(False, f"parabola fit failed: {exc}")
    if not np.all(np.isfinite(r.x)):
        return ParabolaFit(False, "parabola fit diverged")
    par, found = feet(r.x)
    res = parabola_distances(par, p, found)
    try:
        cov = np.linalg.inv(r.jac.T @ r.jac) * float(res @ res) / max(len(p) - 4, 1)
    except np.linalg.LinAlgError:
        cov = None
    return ParabolaFit(True, "", par, res, cov)


def classify_path(p, start: Parabola | None, curved: bool | None = None) -> PathShape:
    """Fit line and parabola to a sliding path and choose (fit.decide.curved).

    Parameters
    ----------
    p : ndarray, shape (n, 2)
        Sliding-path points (m).
    start : Parabola or None
        Starting parabola; None (no curvature seen at all) means straight.
    curved : bool, optional
        An earlier decision on the same path to keep (a refit through
        another camera, recover.calibration); decided here when None.
    """
    p = np.asarray(p, dtype=float)
    line = fit_line(p)
    par = fit_parabola(p, start) if start is not None else ParabolaFit(False, "no curvature")
    n = len(p)
    if not par or n <= 5 or not np.isfinite(par.sse):
        return PathShape(False, 0.0, 1.0, line, par, float(np.std(line.residuals)))
    F = max(line.sse - par.sse, 0.0) / 2.0 / max(par.sse / (n - 4), 1e-300)
    pval = float(f_dist.sf(F, 2, n - 4))
    sigma = float(np.sqrt(par.sse / (n - 4)))
    return PathShape(curved=decide_curved(F, n).yes if curved is None else bool(curved), F=float(F), p_value=pval, line=line,
                     parabola=par, sigma=sigma)
