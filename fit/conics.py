"""Geometric (orthogonal-distance) fits of the sliding path: parabola or line.

The parabola is Theorem 1's: ``y = a x^2`` (a > 0) rotated by ``theta`` and
moved to the vertex, so the constraint is built in.  Each point's residual
is its signed distance to the curve, from the foot point that solves
``2 a^2 x^3 + (1 - 2 a Y) x - X = 0`` in the parabola's frame.

Curved or straight: with the position noise ``sigma`` known, the drop in
the sum of squared orthogonal distances from the line (2 parameters) to the
parabola (4 parameters) is chi^2 with 2 degrees of freedom when the path is
straight; the parabola is kept only above the 1% point (9.21).  Pure
functions of arrays.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from physics.parabola import Parabola

CURVE_LR_THRESHOLD = 9.21  # chi^2(2), 1%


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
    """A constrained parabola fit; falsy when it failed (``reason`` says why)."""

    ok: bool
    reason: str
    parabola: Parabola | None = None
    residuals: np.ndarray | None = None

    @property
    def sse(self) -> float:
        return float(self.residuals @ self.residuals) if self.residuals is not None else np.inf

    def __bool__(self):
        return self.ok


@dataclass(frozen=True)
class PathShape:
    """The decision between parabola and line for a sliding path.

    ``lr`` is ``(SSE_line - SSE_parabola) / sigma^2``; ``curved`` when it
    exceeds :data:`CURVE_LR_THRESHOLD`.
    """

    curved: bool
    lr: float
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


def parabola_distances(par: Parabola, p) -> np.ndarray:
    """Signed orthogonal distances (m) from points to a parabola (+ inside)."""
    q = par.to_local(p)
    X, Y = q[..., 0], q[..., 1]
    a = par.a
    x = X.copy()
    for _ in range(30):  # Newton on the foot-point cubic; monotone for a > 0 near X
        f = 2 * a * a * x**3 + (1 - 2 * a * Y) * x - X
        fp = 6 * a * a * x**2 + (1 - 2 * a * Y)
        step = f / np.where(np.abs(fp) > 1e-12, fp, 1e-12)
        x -= step
        if np.max(np.abs(step)) < 1e-15:
            break
    d = np.hypot(x - X, a * x * x - Y)
    return np.where(Y >= a * X * X, d, -d)


def fit_parabola(p, start: Parabola) -> ParabolaFit:
    """Orthogonal-distance fit of Theorem 1's parabola to points (m).

    Parameters
    ----------
    p : ndarray, shape (n, 2)
        Points on the sliding path (m).
    start : Parabola
        Starting parabola (e.g. from the time-based segmentation).

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
        return Parabola(a=float(np.exp(q[0])), theta=float(q[1]), vertex=np.array(q[2:4]))

    def resid(q):
        return parabola_distances(build(q), p)

    q0 = np.r_[np.log(start.a), start.theta, start.vertex]
    try:
        r = least_squares(resid, q0, method="lm", xtol=1e-14, ftol=1e-14, max_nfev=2000)
    except (ValueError, FloatingPointError) as exc:
        return ParabolaFit(False, f"parabola fit failed: {exc}")
    if not np.all(np.isfinite(r.x)):
        return ParabolaFit(False, "parabola fit diverged")
    par = build(r.x)
    return ParabolaFit(True, "", par, parabola_distances(par, p))


def classify_path(p, sigma: float, start: Parabola | None) -> PathShape:
    """Fit line and parabola to a sliding path and choose by the likelihood ratio.

    Parameters
    ----------
    p : ndarray, shape (n, 2)
        Sliding-path points (m).
    sigma : float
        Per-axis position noise (m).
    start : Parabola or None
        Starting parabola; None (no curvature seen at all) means straight.
    """
    line = fit_line(p)
    par = fit_parabola(p, start) if start is not None else ParabolaFit(False, "no curvature")
    lr = (line.sse - par.sse) / sigma**2 if par else 0.0
    return PathShape(curved=bool(par) and lr > CURVE_LR_THRESHOLD, lr=float(lr), line=line,
                     parabola=par, sigma=float(sigma))
