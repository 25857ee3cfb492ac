"""The paper's closed-form recovery (Jia, Mason, Erdmann, section 2).

Section 2.1, a parabolic sliding path (eq. 31-38), and section 2.2, a
straight one (eq. 39-44).  Inputs are geometry only: the parabola (or the
line's direction), ``x0``, the end of sliding ``x1`` and, for a line, the
rest point ``x2``; timestamps are not used.

Figure 5 (the direction of v0 in section 2.1) is missing from the paper's
text.  Derived here instead: write ``v0 = alpha u_hat + beta n_hat`` with
``n_hat = z_hat x u_hat``.  Eq. 33 gives ``alpha^2 = 2 mu_s g p.u_hat`` and eq.
34 ``beta^2 = mu_s g / (2a)`` (``v0 x u_hat = -beta``).  Theorem 1's vertex
gives ``p.n_hat = alpha beta / (mu_s g)``, which fixes the sign of
``alpha beta``; what is left is ``v0`` against ``-v0``.  For each of the two
candidates, eq. 38 gives ``u0`` (both roots tried) and eq. 37, the full
vector equation for ``x1 - x0``, is checked; the consistent candidate is the
answer (the paper's "(x1 - x0) . xi_hat > 0" test, stated without xi_hat).
The "cross products" after eq. 37 are dot products (CONVENTIONS.md).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cuespin.physics.motion import BallParams, z_cross
from cuespin.physics.parabola import Parabola

# A candidate satisfies eq. 37 when its predicted x1 is within this many
# position-noise sigmas of the measured one (the measured x1 is itself an
# estimate; callers add a frame's travel); every candidate within it is kept.
CONSISTENCY_SIGMAS = 6.0


@dataclass(frozen=True)
class PaperResult:
    """Answer of the paper's method; ``status`` as CONVENTIONS.md says.

    ``solutions`` lists every consistent ``(v0, w0)`` pair when there is more
    than one (status ``ambiguous``).  ``trajectory`` is ``parabola`` or ``line``.
    """

    status: str
    reason: str
    trajectory: str = ""
    v0: np.ndarray | None = None
    w0: np.ndarray | None = None
    x0: np.ndarray | None = None
    x1: np.ndarray | None = None
    x2: np.ndarray | None = None
    u0: float | None = None
    solutions: list = field(default_factory=list)

    def __bool__(self):
        return self.status == "ok"


def w0_from(v0, u0_vec, R):
    """Eq. 31: ``w0 = z_hat x (v0 - u0) / R``."""
    return z_cross(np.asarray(v0, float) - np.asarray(u0_vec, float)) / R


def recover_parabola(par: Parabola, x0, x1, params: BallParams, tol: float) -> PaperResult:
    """Section 2.1: v0 and w0 from the sliding parabola, ``x0`` and ``x1``.

    Parameters
    ----------
    par : Parabola
        ``a`` (1/m), rotation ``theta`` (rad) and vertex ``x*`` (m).
    x0, x1 : array_like, shape (2,)
        Strike position and end of sliding (m).
    params : BallParams
        ``mu_s``, ``g`` and ``R``.
    tol : float
        Distance (m) within which eq. 37 counts as satisfied.
    """
    x0 = np.asarray(x0, float)
    x1 = np.asarray(x1, float)
    mu_g = params.mu_s * params.g
    u_hat = np.array([np.sin(par.theta), -np.cos(par.theta)])  # eq. 32
    n_hat = z_cross(u_hat)
    p = np.asarray(par.vertex, float) - x0
    pu = float(p @ u_hat)
    if pu <= 0 or par.a <= 0:
        return PaperResult("failed", "the fitted vertex lies behind the strike along the slip "
                           "(p . u_hat <= 0): the parabola does not fit Theorem 1", "parabola")
    alpha = np.sqrt(2 * mu_g * pu)  # |v0 . u_hat|, eq. 33
    beta = np.sqrt(mu_g / (2 * par.a)) * np.sign(float(p @ n_hat) or 1.0)  # eq. 34 and the vertex
    d = x1 - x0
    cands = []
    for sgn in (1.0, -1.0):
        v0 = sgn * (alpha * u_hat + beta * n_hat)  # |v0| is eq. 35
        vu = float(v0 @ u_hat)
        disc = vu**2 - 2 * mu_g * float(d @ u_hat)
        if disc < 0:
            disc = 0.0  # noise can push the double-root case below zero
        for root in (1.0, -1.0):
            u0 = 3.5 * (vu + root * np.sqrt(disc))  # eq. 38
            if u0 <= 0:
                continue
            pred = 2.0 / 49.0 * u0 / mu_g * (7 * v0 - u0 * u_hat)  # eq. 37
            cands.append((float(np.hypot(*(pred - d))), v0, u0))
    if not cands:
        return PaperResult("failed", "no positive slip satisfies eq. 38", "parabola", x0=x0, x1=x1)
    cands.sort(key=lambda c: c[0])
    good = [c for c in cands if c[0] <= tol]
    sols = [{"v0": c[1], "w0": w0_from(c[1], c[2] * u_hat, params.R), "u0": c[2]} for c in good]
    if not good:
        return PaperResult("failed", f"no solution satisfies eq. 37 (best misses x1 by "
                           f"{cands[0][0] * 1e3:.2f} mm)", "parabola", x0=x0, x1=x1)
    distinct = [s for i, s in enumerate(sols)
                if all(np.hypot(*(s["v0"] - o["v0"])) > 1e-6 * (1 + np.hypot(*o["v0"]))
                       or abs(s["u0"] - o["u0"]) > 1e-6 * (1 + o["u0"]) for o in sols[:i])]
    if len(distinct) > 1:
        return PaperResult("ambiguous", f"{len(distinct)} solutions satisfy eq. 37 within the noise",
                           "parabola", x0=x0, x1=x1, solutions=distinct)
    s = distinct[0]
    return PaperResult("ok", "", "parabola", v0=s["v0"], w0=s["w0"], x0=x0, x1=x1, u0=s["u0"])


def recover_line(x0, x1, x2, params: BallParams, tol: float, heading=None) -> PaperResult:
    """Section 2.2: v0 and w0 of a straight shot from ``x0``, ``x1``, ``x2``.

    Both hypotheses of eq. 43 are tried, along both orientations of the line
    (``i_hat`` along ``x2 - x0`` as the paper says, and against it, which is
    where v0 points when the ball reverses while sliding and comes to rest
    behind its start, case 1); each solution is kept when it meets its own
    hypothesis and, forward through eq. 24 and 27, reproduces the measured
    ``x1`` and ``x2`` within ``tol``.  ``heading``, the direction the ball
    was seen to leave ``x0`` in (the video shows the order of the path, if
    not its timing), rejects solutions whose ``v0`` points the other way;
    without it, reversed-orientation solutions can reproduce the same three
    points (status ``ambiguous``).
    """
    x0, x1, x2 = (np.asarray(v, float) for v in (x0, x1, x2))
    R, mu_s, mu_r, g = params.R, params.mu_s, params.mu_r, params.g
    if mu_r <= 0:
        return PaperResult("degenerate", "mu_r = 0: the ball never stops, the line method needs x2",
                           "line", x0=x0, x1=x1, x2=x2)
    span = x2 - x0
    if np.hypot(*span) < tol:
        return PaperResult("degenerate", "the rest point is at the strike point: no line to follow",
                           "line", x0=x0, x1=x1, x2=x2)
    sols = []
    for orient in (1.0, -1.0):
        i_hat = orient * span / np.hypot(*span)
        j_hat = z_cross(i_hat)
        s1, s2 = float((x1 - x0) @ i_hat), float((x2 - x0) @ i_hat)
        C = np.sign(s2 - s1) * np.sqrt(70 * mu_r * g * abs(s2 - s1))  # eq. 39-40
        D = 24.5 * mu_s * g * s1  # eq. 41
        for hyp, arg in (("le", C * C + 4 * D), ("gt", C * C - 4 * D)):
            if arg < 0:
                continue
            v0 = np.sqrt(arg) / 7.0  # eq. 43
            w0 = (C - 5 * v0) / (2 * R)  # eq. 44
            if (hyp == "le") != (R * w0 <= v0 + 1e-12 * max(v0, 1e-12)):
                continue
            # Forward through eq. 24 and 27: does it reproduce x1 and x2?
            p1 = 2.0 / (49 * mu_s * g) * abs(v0 - R * w0) * (6 * v0 + R * w0)
            c = 5 * v0 + 2 * R * w0
            p2 = p1 + abs(c) * c / (70 * mu_r * g)
            if abs(p1 - s1) > tol or abs(p2 - s2) > tol:
                continue
            if heading is not None and v0 > 0 and float(i_hat @ heading) < 0:
                continue
            sol = {"v0": v0 * i_hat, "w0": w0 * j_hat}
            if not any(np.hypot(*(sol["v0"] - o["v0"])) < 1e-9 and np.hypot(*(sol["w0"] - o["w0"])) < 1e-6
                       for o in sols):
                sols.append(sol)
    if not sols:
        return PaperResult("failed", "no hypothesis of eq. 43 is consistent with x1 and x2", "line",
                           x0=x0, x1=x1, x2=x2)
    if len(sols) > 1:
        return PaperResult("ambiguous", f"{len(sols)} solutions reproduce x1 and x2 (eq. 43 hypotheses)",
                           "line", x0=x0, x1=x1, x2=x2, solutions=sols)
    return PaperResult("ok", "", "line", v0=sols[0]["v0"], w0=sols[0]["w0"], x0=x0, x1=x1, x2=x2)
