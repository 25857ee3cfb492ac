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

from dataclasses import dataclass, field, replace

import numpy as np

from cuespin.fit.conics import fit_parabola
from cuespin.fit.decide import rolling_speed_differs, stop_apart
from cuespin.physics.motion import BallParams, rolling_deceleration, z_cross
from cuespin.physics.parabola import Parabola
from cuespin.recover.mle import MIN_SLIDING_FRAMES, unseen_slip_cov

# The rolling-speed test (rolling_speed_asked) is asked under an inter-frame
# codec's errors when their short correlation time spans at most this many
# frames: measured to hold at 5 (240 fps, 0 of 55), not at 10 (480 fps, 7
# of 62); 8 lies between, not measured there (docs/measurements.md, v1chk).
ROLL_SPEED_MAX_CORR_FRAMES = 8.0
# ... and under AR(1) errors (a lossy intra-frame codec's, recover.mle's
# fitted ``ar1``) whose correlation time, -1 / ln(ar1), spans at most this
# many frames (ar1 <= exp(-1) = 0.37): simulated AR(1) nulls through
# recover.estimate (rolls_to_rest_tracks' shots, rho 0.3-0.9), fitted ar1
# <= 0.37: 0 of 464 beyond the threshold (max |z| 3.24; seeds 13, 14, 15).
# Two frames (ar1 <= 0.61) was tried first: 1 of 452 on seeds 13-14, then 2
# of 509 on seed 15 (60 fps, fitted ar1 0.46-0.53, z 3.6-4.0), beyond the
# level's margin (docs/measurements.md, seg16).
ROLL_SPEED_MAX_AR1_FRAMES = 1.0
# A candidate satisfies eq. 37 when its predicted x1 is within this many
# position-noise sigmas of the measured one (the measured x1 is itself an
# estimate; callers add a frame's travel); every candidate within it is kept.
CONSISTENCY_SIGMAS = 6.0

# The line method's premise, x1 on the line from x0 to x2, is refused past
# this many of the offset's standard errors (recover.paper.line_offset, a
# normal variate on a straight path).  Measured |offset| / error: straight
# answers at most 1.5 (cases 1, 2, 3 on MJPG; 0.09, 0.97, 1.48 on fresh
# MJPG seed 5), bending short slides 4.7 (seed 21 realistic shot 13, its
# answer 33 stated errors off: the slide 4 frames, its curvature not
# testable), 9.7, 14, 35, 92, 277, 570, 600.  4: a straight path's false refusal 6e-5 when its
# errors are as stated.  (Was CONSISTENCY_SIGMAS, 6, eq. 37's tolerance.)
LINE_OFFSET_SIGMAS = 4.0
# Roots that reproduce the geometry equally well are told apart by their
# sliding time t1 - t0 = 2 |u0| / (7 mu_s g) (eq. 10) against the one the
# segmentation measured (eq. 26): a root is kept only within this many
# frames of it.  The segmentation places t1 to within 1.5e-3 s at 240 fps
# (tests/test_fit.py), under a frame; the spurious roots seen on exact
# tracks slide 0.06-0.13 s longer or shorter (issue 11), 4-8 frames at 60 fps.
TIE_T1_FRAMES = 2.0
# Theorem 1 fixes the vertex's offset across the slip: |p . n_hat| =
# alpha |beta| / (mu_s g).  A fitted parabola whose vertex is off by more
# than this fraction of it (plus the position tolerance) does not fit
# Theorem 1 and is not an answer.  The fitted vertex is extrapolated beyond
# the sliding arc, so it is loose: 0.5 rejects only gross misfits.
THEOREM1_RTOL = 0.5
# The end of sliding, x1 and t1 (eq. 26), is where the segmentation's
# breakpoint falls; a sliding arc seen in fewer frames than this leaves it
# to where the strike and the end of sliding fall between frames, which
# x1's stated errors do not carry (the maximum-likelihood fit's rule,
# recover.mle.MIN_SLIDING_FRAMES, counted on the segmentation's frames).
# Seed 21's realistic MJPG shot 13 (60 fps, sliding 4 frames, 2 of them
# in the arc): the line's answer 29 stated errors off (v0 40%), x1 3.4 mm
# off against 0.19 mm stated.  Measured (docs/measurements.md, rec8): of 188
# cached rendered shots 2 changed status, neither a correct ok (so its
# false-refusal rate is 0 of 0 measured, not measured small); of 31
# short_slide.py shots (rest in view) with 1-2 frame arcs, the paper's one ok
# was 196% off (review 10c).  The same number as the MLE's rule, counted on
# the segmentation's frames (the MLE counts t0 < t < t1).
PAPER_MIN_SLIDING_FRAMES = MIN_SLIDING_FRAMES
# An answer's own sliding time (eq. 10) must agree with the one the
# segmentation measured (eq. 26).  One tolerance (sliding_time_tolerance)
# is the time the end of sliding can be told apart from rolling: past t1
# the two paths part by (mu_s g / 2) dt^2, under SLIDING_END_SIGMAS
# position sigmas for dt = sqrt(2 SLIDING_END_SIGMAS sigma / (mu_s g)),
# plus TIE_T1_FRAMES frames for the breakpoint's placement.  An ok answer
# more than SLIDING_TIME_TOLERANCES of them off is refused.  Measured
# (docs/measurements.md, arc9; the generator's simulated tracks, no video):
# the correct answers (ok, within 3 stated errors) of 2 x 120 case-2 and
# 2 x 150 sliding tracks (recover.simulate, seeds 3, 4, 11, 12) lie at most
# 1.46 tolerances off (parabolas; lines 1.06, case 2 at 480 fps); the wrong
# ok answers of short_slide.py's shots with the rest in view, arcs run over
# the whole track (369-2073 frames) or of 3 frames, 46-264% off, lie
# 12.6-145 tolerances off.  3: twice the largest correct one.
SLIDING_END_SIGMAS = CONSISTENCY_SIGMAS
SLIDING_TIME_TOLERANCES = 3.0
# Evaluations the answer's parabola fit may take (fit.conics.fit_parabola,
# one an iteration with its analytic Jacobian), so that it converges and
# its covariance (the converged fit's) holds: from the decision's fit,
# stopped at fit.conics.PARABOLA_MAX_NFEV, the 22 parabola answers of seed
# 5's fresh MJPG shots took 1-59 more (median 8), one was still stepping at 200.
PAPER_PARABOLA_MAX_NFEV = 200
# The answer's root must exist with the inputs moved this many standard
# errors either way along each axis of their covariance (its independent
# components; recover.paper.with_stderr): an answer whose root vanishes
# nearer is not a smooth function of its inputs over their errors, and the
# delta method's errors do not hold for it.  pap37's one-sided differences
# took sliding_tracks(56, 11)[55]'s parabola answer, whose root vanished
# both ways at 0.01 of an input's error (the review of pap37, onesided.py).
# 0.5: half an error each way, where a linearisation must hold if the stated
# errors are to mean what they say.  Along the axes, not each input alone:
# the parabola's inputs are strongly correlated, and one moved by half its
# marginal error with the others held is far outside their joint errors; so
# asked, 16 of sliding_tracks(200, 11)'s 76 paper answers were refused (ok
# 60, coverage 93.8%), along the axes 6 (ok 70, 92.9%; docs/measurements.md,
# fixpap).
ROOT_SPAN_SIGMAS = 0.5


@dataclass(frozen=True)
class PaperResult:
    """Answer of the paper's method; ``status`` as CONVENTIONS.md says.

    ``solutions`` lists every consistent ``(v0, w0)`` pair when there is more
    than one (status ``ambiguous``).  ``trajectory`` is ``parabola`` or ``line``.
    ``stderr`` holds standard errors of ``v0`` and ``w0`` when ``ok``.
    ``stop_apart`` is fit.decide.stop_apart's answer when case 2 was asked
    (None: not asked), for a refit to keep.  ``rolling_speed`` is
    fit.decide.rolling_speed_differs's Decision when the line's case 3 was
    asked it (:func:`rolling_speed_z`; None: not asked).  ``cov`` the covariance of
    ``(v0, w0)`` (4 x 4; m/s and rad/s) whose diagonal ``stderr`` holds,
    for statistics of the answer (:func:`sliding_time_stderr`).
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
    stderr: dict = field(default_factory=dict)
    stop_apart: bool | None = None
    cov: np.ndarray | None = None
    rolling_speed: object | None = None

    def __bool__(self):
        return self.status == "ok"


def w0_from(v0, u0_vec, R):
    """Eq. 31: ``w0 = z_hat x (v0 - u0) / R``."""
    return z_cross(np.asarray(v0, float) - np.asarray(u0_vec, float)) / R


def recover_parabola(par: Parabola, x0, x1, params: BallParams, tol: float,
                     tau1: float | None = None, tau1_tol: float = 0.0) -> PaperResult:
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
    tau1, tau1_tol : float, optional
        Measured sliding time ``t1 - t0`` (s, eq. 26) and how far a root's
        may be from it (s): breaks ties between roots that satisfy eq. 37.
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
    pn = alpha * abs(beta) / mu_g  # Theorem 1: the vertex's offset across the slip
    if abs(abs(float(p @ n_hat)) - pn) > tol + THEOREM1_RTOL * pn:
        return PaperResult("failed", f"the fitted vertex is {abs(float(p @ n_hat)) * 1e3:.1f} mm across "
                           f"the slip where Theorem 1 puts it at {pn * 1e3:.1f} mm: the parabola does "
                           "not fit Theorem 1", "parabola", x0=x0, x1=x1)
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
    distinct = break_tie(distinct, params, tau1, tau1_tol)
    if len(distinct) > 1:
        return PaperResult("ambiguous", f"{len(distinct)} solutions satisfy eq. 37 within the noise "
                           "and the measured sliding time",
                           "parabola", x0=x0, x1=x1, solutions=distinct)
    s = distinct[0]
    return PaperResult("ok", "", "parabola", v0=s["v0"], w0=s["w0"], x0=x0, x1=x1, u0=s["u0"])


def sliding_time(v0, w0, params: BallParams) -> float:
    """Eq. 10: ``t1 - t0 = 2 |u0| / (7 mu_s g)``, ``u0 = v0 + R z_hat x w0``."""
    u0 = np.asarray(v0, float) + params.R * z_cross(np.asarray(w0, float))
    return 2.0 * float(np.hypot(*u0)) / (7.0 * params.mu_s * params.g)


def sliding_time_stderr(v0, w0, cov, params: BallParams) -> float:
    """Standard error (s) of eq. 10's sliding time ``2 |u0| / (7 mu_s g)``,
    ``u0 = v0 + R z_hat x w0``, by the delta method from the covariance
    ``cov`` (4 x 4) of ``(v0, w0)`` (m/s, rad/s); NaN without one or when
    the slip is zero (no gradient there)."""
    if cov is None:
        return float("nan")
    u0 = np.asarray(v0, float) + params.R * z_cross(np.asarray(w0, float))
    norm = float(np.hypot(*u0))
    if norm <= 0:
        return float("nan")
    u_hat = u0 / norm
    # d|u0| / dv0 = u_hat; d|u0| / dw0 = R (z_hat x)^T u_hat = R (u_y, -u_x)
    g = 2.0 / (7.0 * params.mu_s * params.g) * np.r_[u_hat, params.R * np.array([u_hat[1], -u_hat[0]])]
    return float(np.sqrt(max(float(g @ np.asarray(cov, float)[:4, :4] @ g), 0.0)))


def break_tie(sols: list, params: BallParams, tau1: float | None, tau1_tol: float) -> list:
    """The solutions whose sliding time is within ``tau1_tol`` of the
    measured ``tau1`` (all of them when none is, or no time is given)."""
    if tau1 is None or not np.isfinite(tau1) or len(sols) < 2:
        return sols
    near = [s for s in sols if abs(sliding_time(s["v0"], s["w0"], params) - tau1) <= tau1_tol]
    return near or sols


def recover_line(x0, x1, x2, params: BallParams, tol: float, heading=None,
                 tau1: float | None = None, tau1_tol: float = 0.0) -> PaperResult:
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
    points (status ``ambiguous``).  ``tau1`` (s), the sliding time the
    segmentation measured (eq. 26), breaks the remaining ties: roots whose
    own sliding time (eq. 10) is further than ``tau1_tol`` from it go.
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
    sols = break_tie(sols, params, tau1, tau1_tol)
    if len(sols) > 1:
        return PaperResult("ambiguous", f"{len(sols)} solutions reproduce x1 and x2 (eq. 43 "
                           "hypotheses) and the measured sliding time",
                           "line", x0=x0, x1=x1, x2=x2, solutions=sols)
    return PaperResult("ok", "", "line", v0=sols[0]["v0"], w0=sols[0]["w0"], x0=x0, x1=x1, x2=x2)


def segment_weights(seg, n: int) -> dict | None:
    """The segmentation's estimates as weights on the track's ``n`` frames
    (fit.segment: ``geometry_cov``): ``x0``, ``x1``, the sliding velocity
    at the breakpoint ``v1`` (m/s per m) and, with a rest in view, ``x2``
    (its frames' mean), each an array (n,) with ``estimate = w @ xy``; None
    when the segmentation kept no weights."""
    g = seg.geometry_cov or {}
    if g.get("w") is None or not len(g["frames"]) or int(np.max(g["frames"])) >= n:
        return None
    out = {}
    cols = [("x0", g["w"][:, 0]), ("x1", g["w1"])] + ([("v1", g["wv1"])] if g.get("wv1") is not None else [])
    for name, col in cols:
        out[name] = np.zeros(n)
        np.add.at(out[name], g["frames"], col)
    if g.get("rest") is not None and len(g["rest"]):
        out["x2"] = np.zeros(n)
        out["x2"][g["rest"]] = 1.0 / len(g["rest"])
    return out


def inputs_covariance(seg, meas, names, noise=(0.0, 1.0)) -> np.ndarray | None:
    """Covariance (m^2) of the segmentation's estimates
    ``names`` (of :func:`segment_weights`), shape (2k, 2k), under the
    errors the track's measurements ``meas`` state (each frame's covariance
    with the codec's share, a rest's frames sharing theirs as the
    maximum-likelihood fit has them: recover.measurements.linear_covariance),
    plus the breakpoints' own shares (:func:`breakpoint_shares`); None
    without the weights.  ``noise``: the maximum-likelihood fit's ``(ar1, scale[, acf])``
    (recover.estimate.mle_noise; linear_covariance's arguments)."""
    from cuespin.recover.measurements import linear_covariance
    w = segment_weights(seg, len(meas.t)) if meas is not None else None
    if w is None or any(k not in w for k in names):
        return None
    return linear_covariance(meas, np.stack([w[k] for k in names]), *noise) + breakpoint_shares(seg, names)


def breakpoint_shares(seg, names) -> np.ndarray:
    """What the breakpoints' own errors add to the covariance of the
    segmentation's estimates ``names`` (fit.segment: t0 moves ``x0`` along
    ``v0``, t1 moves ``x1`` along ``v1``), shape (2k, 2k), ordered as
    ``names``; beside their weights' share (linear in the frames)."""
    g = seg.geometry_cov or {}
    zero = np.zeros((2, 2))
    out = np.zeros((2 * len(names), 2 * len(names)))
    at = {k: 2 * i for i, k in enumerate(names)}
    if "x0" in at:
        out[at["x0"]:at["x0"] + 2, at["x0"]:at["x0"] + 2] = g.get("x0_t0", zero)
    if "x1" in at:
        out[at["x1"]:at["x1"] + 2, at["x1"]:at["x1"] + 2] = g.get("x1_t1", zero)
    if "x0" in at and "x1" in at:
        out[at["x0"]:at["x0"] + 2, at["x1"]:at["x1"] + 2] = g.get("x0x1_t", zero)
        out[at["x1"]:at["x1"] + 2, at["x0"]:at["x0"] + 2] = g.get("x0x1_t", zero).T
    return out


def parabola_weights(par: Parabola, p) -> np.ndarray:
    """The converged orthogonal fit's ``(log a, theta, vertex)`` as per-axis
    weights on its points ``p`` (m), shape (4, n, 2): the fit is locally
    linear in them, ``dq = -(J^T J)^-1 J^T N dp`` with ``J`` the distances'
    Jacobian (fit.conics.parabola_jacobian) and ``N`` each point's unit
    normal (minus its vertex columns)."""
    from cuespin.fit.conics import parabola_jacobian
    J = parabola_jacobian(par, p)
    M = np.linalg.solve(J.T @ J, J.T)  # (4, n)
    return M[:, :, None] * J[None, :, 2:4]


def parabola_inputs_covariance(seg, xy, par: Parabola, meas, noise=(0.0, 1.0)) -> np.ndarray | None:
    """Covariance of the parabola method's inputs ``(log a, theta, vertex,
    x0, x1)``, shape (8, 8), all under the track's measurements' errors in
    one call (recover.measurements.linear_covariance: AR(1), the fit's
    scale, the terms between the parabola and the end points), plus the
    breakpoints' own shares (:func:`breakpoint_shares`); None without the segmentation's
    weights.  (The parabola fit's own covariance takes its frames as
    independent: on AR(1) tracks of lag-1 0.8 the paper's answers covered
    59.2% in 95% intervals, RMS z 3.33.)"""
    from cuespin.recover.measurements import linear_covariance
    n = len(meas.t) if meas is not None else 0
    w = segment_weights(seg, n) if meas is not None else None
    if w is None or len(xy) != n:
        return None
    G = np.zeros((8, n, 2))
    try:
        G[:4, seg.slide] = parabola_weights(par, np.asarray(xy)[seg.slide])
    except np.linalg.LinAlgError:
        return None
    for k, name in ((4, "x0"), (6, "x1")):
        G[k, :, 0] = G[k + 1, :, 1] = w[name]
    C = linear_covariance(meas, G, *noise)
    C[4:, 4:] += breakpoint_shares(seg, ("x0", "x1"))
    return C


def geometry_covariance(seg, sigma: float, lossless: bool, meas=None, noise=(0.0, 1.0)) -> np.ndarray:
    """Covariance (m^2) of ``(x0, x1, x2)``, shape (6, 6).

    With the track's measurements ``meas`` (recover.measurements, the ones
    the maximum-likelihood fit weights by): :func:`inputs_covariance`, the
    segmentation's estimates being linear in the frames.  (Before, a lossy
    codec's rests were floored at one frame's error: on seed 5's fresh MJPG
    shots ``x0`` was then stated 2.7 times its error against the truth in
    RMS, ``x2`` 1.7 times.)  Without ``meas``, the segmentation's own
    covariances (every frame independent at its residuals' noise); with a
    lossy codec the rests then no better than one frame (``sigma``, per
    axis).  No rest in view: ``x2`` one frame's, apart."""
    g = seg.geometry_cov or {}
    one = sigma**2 * np.eye(2)
    has_rest = g.get("rest") is not None and len(g["rest"]) > 0
    C = inputs_covariance(seg, meas, ("x0", "x1", "x2") if has_rest else ("x0", "x1"), noise)
    if C is not None:
        out = np.zeros((6, 6))
        out[:len(C), :len(C)] = C
        if not has_rest:
            out[4:6, 4:6] = one
        return out
    C = np.zeros((6, 6))
    C[0:2, 0:2] = g.get("x0", one)
    C[2:4, 2:4] = g.get("x1", one)
    C[0:2, 2:4] = C[2:4, 0:2] = g.get("x0x1", np.zeros((2, 2)))
    C[4:6, 4:6] = g["x2"] if g.get("x2") is not None else one
    if not lossless:
        for k in (0, 4):
            C[k:k + 2, k:k + 2] = np.maximum(C[k:k + 2, k:k + 2], one)
    return C


def with_stderr(res: PaperResult, solve, x, C, params: BallParams) -> PaperResult:
    """``res`` with standard errors of ``v0`` and ``w0`` by the delta method:
    the inputs' covariance ``C`` through the numerical Jacobian of
    ``solve`` (inputs to a PaperResult) at ``x``, following the answer's
    own root (the solution nearest it).  (Tried and left out: drawing the
    inputs from N(x, C), 200 draws, the larger error of the two.  On 49
    MJPG benchmark shots it moved the answered shots' errors in stated
    ones by under 3%, while over 10% of the draws on 5 of 24 parabola shots
    had no answer (the parabola's and the end points' errors are drawn
    independently, so a draw can break Theorem 1 or eq. 37), and it took
    2-8 times the recovery's time.)  An input whose move by
    ``ROOT_SPAN_SIGMAS`` of its error, or by the difference's step, either
    way leaves no root (the answer on the edge of the method's domain, or
    on a sliver of its inputs' errors), or no ``C``, makes the answer
    ``degenerate`` (:func:`unpropagated`): an ``ok`` always states its
    errors, and they are the delta method's."""
    from dataclasses import replace
    if res.status != "ok":
        return res
    if C is None:
        return unpropagated(res, "the inputs' covariance is not available")
    base = np.r_[res.v0, params.R * np.asarray(res.w0)]

    def pick(r):
        sols = [{"v0": r.v0, "w0": r.w0}] if r.status == "ok" else r.solutions
        vs = [np.r_[s["v0"], params.R * np.asarray(s["w0"])] for s in sols]
        return min(vs, key=lambda v: float(np.hypot(*(v - base)[:2]) + np.hypot(*(v - base)[2:]))) \
            if vs else None

    lam, E = np.linalg.eigh(0.5 * (C + C.T))
    for k in np.flatnonzero(lam > 0):
        dx = ROOT_SPAN_SIGMAS * np.sqrt(lam[k]) * E[:, k]
        if pick(solve(x + dx)) is None or pick(solve(x - dx)) is None:
            return unpropagated(res, f"the inputs moved by {ROOT_SPAN_SIGMAS:g} of their error along one of its "
                                f"{len(x)} independent components (the covariance's axes) leave no root one way: "
                                "the answer exists only on a sliver of the inputs' errors "
                                "(recover.paper.ROOT_SPAN_SIGMAS), and its error is not the delta method's")
    sd = np.sqrt(np.clip(np.diag(C), 0, None))
    J = np.zeros((4, len(x)))
    for i, s in enumerate(sd):
        if s <= 0:
            continue
        dx = np.zeros(len(x))
        h = 1e-3 * s
        dx[i] = h
        a, b = pick(solve(x + dx)), pick(solve(x - dx))
        if a is None or b is None:
            # The answer on the edge of the method's domain: its map from
            # the inputs is not smooth there.  (pap37 took the one-sided
            # difference from the side with a root: on 60 case-4 shots to
            # rest, where x1 = x0 put every answer on that edge, its errors
            # covered 75.0% of 192 components, RMS z 3.36; case 4 is now
            # propagated from (x0, x2), :func:`_paper`.)
            return unpropagated(res, f"input {i + 1} of {len(x)} moved by {h / s:g} of its standard error "
                                f"{'up' if a is None else 'down'} leaves no root: the answer is on the edge of "
                                "the method's domain, not a smooth function of its inputs there, and its error is "
                                "not the delta method's")
        J[:, i] = (a - b) / (2 * h)
    D = np.diag([1.0, 1.0, 1.0 / params.R, 1.0 / params.R])  # (v0, R w0) to (v0, w0)
    cov = D @ J @ C @ J.T @ D
    se = np.sqrt(np.clip(np.diag(cov), 0, None))
    if not np.all(np.isfinite(se)):
        return unpropagated(res, "the propagated covariance is not finite")
    return replace(res, stderr={"v0": se[0:2], "w0": se[2:4]}, cov=cov)


def with_unseen_slip(res: PaperResult, dv: float, params: BallParams) -> PaperResult:
    """``res`` (an answer from the rolling segments, x1 at x0) with the
    errors of a slip the track cannot exclude added, as the
    maximum-likelihood fit's rolling answer states them
    (recover.mle.result): a slide of ``tau1`` leaves the rolling path from
    ``v0 - mu_s g tau1 u_hat``, so the rolling answer's ``v0`` is off by
    ``dv = mu_s g tau1 u_hat`` and its ``w0`` by ``-5/2 z x dv / R`` (eqs. 7,
    8), ``|dv|`` up to the fit's ``dv`` (m/s, recover.mle.unseen_slip) in a
    direction the track does not show; its error spans that disc at 95%
    (per axis ``dv / 1.96``).  Case 4's line answer otherwise states only
    x0's and x2's errors: on short_slip_tracks(160, 22) (slides 1-8 frames,
    60-480 fps) its 37 ``ok`` answers lay 560-85,000 stated errors off in v0
    (docs/measurements.md, papshort)."""
    if res.status != "ok" or not dv > 0 or res.cov is None:
        return res
    cov = res.cov + unseen_slip_cov(dv, params.R)
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    return replace(res, cov=cov, stderr={**res.stderr, "v0": se[:2], "w0": se[2:]})


def unpropagated(res: PaperResult, why: str) -> PaperResult:
    """``res`` refused: an ``ok`` must state its errors (CONVENTIONS.md;
    ``stderr`` holds them when ``ok``), and where they cannot be propagated
    (no covariance of the inputs; an input moved either way leaving no
    root) the answer is ``degenerate`` with ``why``, its v0 and w0 null
    (not determined to any stated precision; the geometry x0, x1, x2 kept).
    Before, :func:`with_stderr` returned such answers ``ok`` without
    errors whenever one side had no root: realistic H.264 37/1 and 38/22
    (held37), 29% and 12% off in v0 (counted as misses, the paper's
    coverage there 80.0%, not 88.9%); pap37 gave them one-sided
    differences, whose errors depend on the step at a square-root edge;
    they are refused here (fixpap)."""
    from dataclasses import replace
    return replace(res, status="degenerate", reason=f"its errors cannot be propagated: {why}", v0=None, w0=None,
                   u0=None, stderr={}, cov=None)


def path_shape(seg, xy, params: BallParams, curved: bool | None = None):
    """The sliding path's shape (fit.conics.classify_path, started from the
    segmentation's parabola; ``curved`` an earlier decision to keep), or
    None when fewer than 5 frames slide."""
    from cuespin.fit.conics import classify_path
    from cuespin.physics.parabola import sliding_parabola
    from cuespin.recover.mle import initial_guess

    if not (seg and seg.t1 > seg.t0 and seg.slide is not None and len(seg.slide) >= 5):
        return None
    x0, t0, v0, w0 = initial_guess(seg, params)
    try:
        start = sliding_parabola(x0, v0, w0, params)
    except ValueError:
        start = None
    return classify_path(np.asarray(xy)[seg.slide], start, curved)


def paper_from_segments(seg, t, xy, params: BallParams, sigma: float, frame_dt: float,
                        strike_seen: bool = True, lossless: bool = True, curved: bool | None = None,
                        near=None, apart: bool | None = None, meas=None, noise=(0.0, 1.0)) -> PaperResult:
    """The paper's method on a segmented track (the segmentation the
    decisions chose): parabola or line by fit.decide.curved, the sliding
    time breaking ties, with the status and reason CONVENTIONS.md asks for.

    Parameters
    ----------
    seg : Segments
        The chosen segmentation (rolling from the strike, or sliding).
    t, xy : ndarray
        The track's frame times (s) and centres (m) that ``seg`` indexes.
    sigma : float
        Per-axis position noise (m).
    frame_dt : float
        Frame interval (s).
    strike_seen : bool
        The strike is in view (fit.decide.strike_in_view): without it,
        ``x0`` is an extrapolation and the method has no answer.
    lossless : bool
        Passed on to the standard errors without ``meas`` (a lossy codec's
        rest frames share one error).
    curved : bool, optional
        The path's shape decided before (a refit of the same track through
        another camera keeps it); decided here when None.
    near : tuple, optional
        ``(v0, w0)`` of an earlier answer on the same track: of several
        roots the nearest is the answer (the same root, moved by the camera).
    apart : bool, optional
        fit.decide.stop_apart's answer decided before (an earlier answer's
        :attr:`PaperResult.stop_apart`, kept by a refit); asked here when None.
    meas : Measurements, optional
        The track's measurements (recover.measurements.build_measurements on
        the same ``t``, as the maximum-likelihood fit uses them): the errors
        of ``x0``, ``x1`` and ``x2`` follow from its per-frame covariances
        and rests (:func:`geometry_covariance`); without it, from ``sigma``.
    noise : tuple
        ``(ar1, scale[, acf])`` (recover.estimate.mle_noise): the
        maximum-likelihood fit's error model over ``meas``, its errors'
        lag-1 correlation between frames, ``max(1, chi2/dof)`` and an
        inter-frame codec's correlation in time; the paper's inputs are
        measured by the same frames, so their errors follow the same model
        (recover.measurements.linear_covariance).
    """
    res = _paper(seg, t, xy, params, sigma, frame_dt, strike_seen, lossless, curved, near, apart, meas, noise)
    return sliding_time_check(res, seg, params, sigma, frame_dt)


def sliding_time_tolerance(params: BallParams, sigma: float, frame_dt: float) -> float:
    """How far (s) an answer's sliding time may lie from the measured one:
    TIE_T1_FRAMES frames plus the time after t1 in which sliding and
    rolling part by less than SLIDING_END_SIGMAS position sigmas (m)."""
    return TIE_T1_FRAMES * frame_dt + float(np.sqrt(2.0 * SLIDING_END_SIGMAS * sigma / (params.mu_s * params.g)))


def sliding_time_check(res: PaperResult, seg, params: BallParams, sigma: float, frame_dt: float) -> PaperResult:
    """``res``, or ``failed`` when its sliding time (eq. 10) disagrees with
    the segmentation's measured ``t1 - t0`` (eq. 26) by more than
    SLIDING_TIME_TOLERANCES of :func:`sliding_time_tolerance`: the answer does not describe the track
    it was measured on (the segmentation ran the arc too long, or the root
    slides seconds where the track slid frames)."""
    if res.status != "ok" or not seg or not np.isfinite(seg.t1):
        return res
    measured = float(seg.t1 - seg.t0)
    answer = sliding_time(res.v0, res.w0, params)
    tol = sliding_time_tolerance(params, sigma, frame_dt)
    if abs(answer - measured) <= SLIDING_TIME_TOLERANCES * tol:
        return res
    return replace(res, status="failed", reason=(
        f"the answer slides {answer:.3f} s (eq. 10), the track {measured:.3f} s (eq. 26): "
        f"{abs(answer - measured) / tol:.0f} times the {tol * 1e3:.0f} ms to which the end of sliding "
        f"can be placed (more than {SLIDING_TIME_TOLERANCES:g}), so the answer does not describe this track"),
                   v0=None, w0=None, u0=None, solutions=[], stderr={}, cov=None)


def nearest_root(res: PaperResult, near, params: BallParams) -> PaperResult:
    """``res`` with, when ambiguous, the root nearest ``near = (v0, w0)``
    as its answer (status ``ok``)."""
    if near is None or res.status != "ambiguous" or not res.solutions:
        return res
    from dataclasses import replace
    ref = np.r_[near[0], params.R * np.asarray(near[1])]
    s = min(res.solutions, key=lambda s: float(np.linalg.norm(np.r_[s["v0"], params.R * s["w0"]] - ref)))
    return replace(res, status="ok", reason="", v0=s["v0"], w0=s["w0"], u0=s.get("u0"), solutions=[])


def _paper(seg, t, xy, params, sigma, frame_dt, strike_seen, lossless, curved, near=None,
           apart=None, meas=None, noise=(0.0, 1.0)) -> PaperResult:
    """paper_from_segments; the root nearest ``near`` is chosen inside each
    solve, so a root chosen that way gets its standard errors too."""
    if not seg:
        return PaperResult("failed", f"the track could not be segmented: {seg.reason}")
    if not strike_seen:
        return PaperResult("degenerate", "the strike is not in view (the first frames already show "
                           "the ball moving): x0 is not measured, and the paper's method needs it")
    if not np.isfinite(seg.t1):
        return PaperResult("degenerate", "sliding had not ended when the track did: x1, and so "
                           "the paper's method, is not determined", x0=seg.x0)
    if seg.t1 > seg.t0 and seg.t1_bound:
        return PaperResult("degenerate", "where sliding ends is not identified: the breakpoint's sliding "
                           "deceleration sits on its bound (fit.segment.SLIDE_DECEL_RATIO times the rolling "
                           "one: a slide too short to show its deceleration, or mu_s g under that many times "
                           "(5/7) mu_r g), so t1 and x1 are where the bound put them", x0=seg.x0)
    n_slide = 0 if seg.slide is None else len(seg.slide)
    if seg.t1 > seg.t0 and n_slide < PAPER_MIN_SLIDING_FRAMES:
        return PaperResult("degenerate", f"sliding seen in {n_slide} frame(s): x1 and t1, where sliding "
                           "ends, rest on where it falls between frames, and the paper's method needs them "
                           f"(at least {PAPER_MIN_SLIDING_FRAMES} frames)", x0=seg.x0, x1=seg.x1)
    # x1 is itself estimated (to about a frame's travel), so eq. 37 and the line's
    # forward check are held to that, not to the pixel noise alone.
    tol = CONSISTENCY_SIGMAS * sigma + np.hypot(*seg.v1) * frame_dt
    tau1, tau1_tol = seg.t1 - seg.t0, TIE_T1_FRAMES * frame_dt
    geo = geometry_covariance(seg, sigma, lossless, meas, noise)
    shape = path_shape(seg, xy, params, curved)
    if shape is not None:
        if shape.curved:
            # The answer's parabola is the orthogonal-distance fit run to
            # convergence: the decision's fit (fit.conics.classify_path) stops
            # at PARABOLA_MAX_NFEV evaluations from the segmentation's
            # parabola, which is fitted in time, and stayed near it, where
            # the covariance is the converged fit's.  (Measured on the 22
            # parabola answers of seed 5's fresh MJPG shots, x0's error from
            # the measurements: capped, RMS error / stated 0.69, coverage
            # 100%; converged, 1.10 and 90.9%.  The capped answers lay 2-3
            # times nearer the truth in median: they borrowed the time fit's
            # precision without stating it.)
            par = shape.parabola
            done = fit_parabola(np.asarray(xy)[seg.slide], par.parabola, max_nfev=PAPER_PARABOLA_MAX_NFEV)
            if done:
                par = done

            def solve_par(x):
                q = Parabola(a=float(np.exp(x[0])), theta=float(x[1]), vertex=x[2:4])
                return nearest_root(recover_parabola(q, x[4:6], x[6:8], params, tol, tau1, tau1_tol),
                                    near, params)

            x = np.r_[np.log(par.parabola.a), par.parabola.theta, par.parabola.vertex, seg.x0, seg.x1]
            C = parabola_inputs_covariance(seg, xy, par.parabola, meas, noise)
            if C is None and par.cov is not None:
                C = np.zeros((8, 8))
                C[:4, :4] = par.cov
                C[4:, 4:] = geo[:4, :4]
            return with_stderr(solve_par(x), solve_par, x, C, params)
        why_line = (f"the sliding path is straight within the noise (F = {shape.F:.3g} for "
                    "curvature, under the calibrated threshold)")
    else:
        why_line = "no sliding seen (rolling from the strike)" if seg.t1 <= seg.t0 else \
            "sliding too short to fit a parabola (fewer than 5 frames)"
    if seg.x2 is None:
        return PaperResult("degenerate", f"{why_line}, and no rest point is in view: the paper's "
                           "line method needs x2", "line", x0=seg.x0, x1=seg.x1)
    heading = seg.v0 / np.hypot(*seg.v0) if np.hypot(*seg.v0) > 0 else None

    def solve_line(x):
        return nearest_root(recover_line(x[0:2], x[2:4], x[4:6], params, tol, heading, tau1, tau1_tol),
                            near, params)

    case2 = ran_into_rest(seg)
    if not case2 and seg.t1 > seg.t0:
        # A stopping point x1 within its errors of the rest x2 (the same
        # decision, fit.decide.stop_apart) is case 2 as far as the track can
        # tell: the line's eq. 39 at x2 - x1 about zero turns x1's error
        # into w0's through a square root.  (Seed 21's realistic shot 27:
        # the breakpoint 7 of its errors early, x1 1.8 mm short of the rest,
        # the line's w0 6.8 stated errors off; case 2's answer within 0.02
        # rad/s.)
        case2 = not (stop_apart(case2_distance(seg, geo)).yes if apart is None else bool(apart))
    if not case2:
        # The line method's premise: x0, x1, x2 on one line.  A sliding arc
        # too short to test for a parabola (5 frames or fewer) can still
        # bend the path: x1 was 13.8 and 570 of its errors off the line on
        # two MJPG shots (the line's answers 540 and 1300 stated errors off),
        # at most 1.5 on the straight ones (cases 1, 2, 3).
        off, sd = line_offset(seg.x0, seg.x1, seg.x2, geo)
        if abs(off) > LINE_OFFSET_SIGMAS * sd:
            return PaperResult("failed", f"x1 lies {abs(off) * 1e3:.2f} mm ({abs(off) / sd:.0f} of its errors) off "
                               "the line from x0 to x2: the path is not straight, and the line method needs "
                               f"it ({why_line})", "line", x0=seg.x0, x1=seg.x1, x2=seg.x2)
    if case2:
        # Case 2: sliding ends at the rest (eq. 29), so x1 is x2, the rest's
        # mean; the breakpoint's own x1, extrapolated to where the sliding
        # velocity vanishes, sat 2-4 of its errors off the rest on MJPG, and
        # with x2 - x1 about zero eq. 39's square root turned that into w0
        # errors of 4-6 stated ones (every miss of the paper's errors).
        # Taken only when the two agree within their errors (a decision,
        # fit.decide.stop_apart): a stopping point apart from the rest means
        # the ball moved on after sliding, and case 2 does not hold.
        d2 = case2_distance(seg, geo)
        apart = stop_apart(d2).yes if apart is None else bool(apart)
        if apart:
            return PaperResult("failed", f"sliding's stopping point x1 lies {d2 ** 0.5:.1f} of its "
                               "errors from the rest x2: sliding did not run into the rest, and the "
                               "segmentation found no breakpoint before it", "line", x0=seg.x0, x1=seg.x1, x2=seg.x2,
                               stop_apart=True)
        def solve_case2(x):
            return nearest_root(recover_line(x[0:2], x[2:4], x[2:4], params, tol, heading, tau1, tau1_tol),
                                near, params)

        idx = np.r_[0:2, 4:6]
        x = np.r_[seg.x0, seg.x2]
        return replace(with_stderr(solve_case2(x), solve_case2, x, geo[np.ix_(idx, idx)], params), stop_apart=False)
    # Case 3: sliding ends at x1 and the ball rolls to x2 (eq. 16-19), so
    # the segmentation's sliding speed there must be the one that rolls
    # |x2 - x1| (eq. 19; eq. 25 and 27 on the line): asked of the rest's
    # frames against the rolling path from x1 at v1 (eq. 18), in their
    # errors (rolling_speed_z, fit.decide.rolling_speed_differs).
    # Realistic H.264 36/38: the rest found 66 ms before the stop, the
    # breakpoint 100 ms early and x1 10 mm short, |v1| 0.198 m/s where
    # 9.6 mm of rolling allows 0.037 (docs/measurements.md, p38, v1chk).
    # (Rolling from the strike, x1 = x0, is not asked: not calibrated; nor
    # where the errors' correlation in time is not the one measured:
    # rolling_speed_asked.)
    rolls = rolling_speed_differs(rolling_speed_z(seg, params, sigma, t, xy, meas, noise)) \
        if seg.t1 > seg.t0 and rolling_speed_asked(noise, frame_dt) else None
    if rolls is not None and rolls.yes:
        return PaperResult("failed", f"the slide's speed where it ends, |v1| {np.hypot(*seg.v1):.3f} m/s, rolls "
                           f"past the rest (eq. 18-19: {rolling_speed(seg.x1, seg.x2, params):.3f} m/s rolls the "
                           f"{np.hypot(*(seg.x2 - seg.x1)) * 1e3:.1f} mm from x1 to it; the rest's frames "
                           f"{rolls.statistic:+.1f} of their errors from the rolling path): x1 is not where "
                           f"sliding ended ({why_line})", "line", x0=seg.x0, x1=seg.x1, x2=seg.x2,
                           rolling_speed=rolls)
    if seg.t1 <= seg.t0:
        # Case 4, rolling from the strike: the segmentation ties x1 to x0
        # (tau1 = 0), so the answer is the line's from (x0, x2) with x1 at
        # x0, a smooth map there (eq. 43's two hypotheses meet at s1 = 0,
        # and moving x0 moves x1 with it), and the covariance propagated is
        # that of the inputs it uses, x0 and x2.  (pap37 moved x1 apart from
        # x0: a shorter slide has no root, and the one-sided differences'
        # errors covered 75.0% of 192 components on 60 case-4 shots to rest,
        # RMS z 3.36, the review of pap37's case4_rest.py.)
        def solve_case4(x):
            return nearest_root(recover_line(x[0:2], x[0:2], x[2:4], params, tol, heading, tau1, tau1_tol),
                                near, params)

        idx = np.r_[0:2, 4:6]
        x = np.r_[seg.x0, seg.x2]
        return with_stderr(solve_case4(x), solve_case4, x, geo[np.ix_(idx, idx)], params)
    x = np.r_[seg.x0, seg.x1, seg.x2]
    return replace(with_stderr(solve_line(x), solve_line, x, geo, params), rolling_speed=rolls)


def rolling_speed_asked(noise, frame_dt: float) -> bool:
    """Is :func:`rolling_speed_z`'s error stated under these errors?
    ``noise`` is the maximum-likelihood fit's ``(ar1, scale[, acf])``
    (recover.estimate.mle_noise).  Asked where the errors' correlation in
    time is short (an inter-frame codec's short time at most
    :data:`ROLL_SPEED_MAX_CORR_FRAMES` frames, AR(1)'s at most
    :data:`ROLL_SPEED_MAX_AR1_FRAMES`): the breakpoints' share, from the
    profile's curvature, takes the frames as independent.  Measured
    (docs/measurements.md, v1chk, seg16): independent errors
    (rolls_to_rest_tracks held out, 1 of 925 beyond the threshold; through
    recover.estimate 0 of 408); an inter-frame codec's correlation
    (recover.mle.INTER_CODEC_ACF, its short time ``acf[2]`` / ``frame_dt``
    frames, through recover.estimate) at 60-240 fps 0 of 139 (max |z|
    1.77), at 480 fps (10 frames) 7 of 62 at |z| up to 59; AR(1) errors
    (a lossy intra-frame codec's, ``-1 / ln(ar1)`` frames) with the fitted
    ar1 <= 0.37, 0 of 464; with 0.37-0.61, 3 of 497; at rho 0.7-0.9 15
    of 391 at |z| up to 81.  (Before seg16 never asked under AR(1): realistic MJPG
    49/16's line answer, its rest found 46 ms early and its breakpoint 70
    ms early on a slide into the rest, stood `ok` 9.1 stated errors off;
    asked, z 9.5, and the slide into the rest answers within 1.9.)"""
    ar1 = float(noise[0]) if len(noise) > 0 else 0.0
    acf = noise[2] if len(noise) > 2 else None
    if ar1 > 0 and not (ar1 < 1 and -1.0 / np.log(ar1) <= ROLL_SPEED_MAX_AR1_FRAMES):
        return False
    return acf is None or float(acf[2]) / frame_dt <= ROLL_SPEED_MAX_CORR_FRAMES


def rolling_speed(x1, x2, params: BallParams) -> float:
    """Eq. 19 (eq. 16-17 integrated): the speed (m/s) at ``x1`` that rolls
    to rest at ``x2``, ``sqrt(2 (5/7) mu_r g |x2 - x1|)``."""
    d = float(np.hypot(*(np.asarray(x2, float) - np.asarray(x1, float))))
    return float(np.sqrt(2.0 * rolling_deceleration(params.mu_r, params.g) * d))


def rolling_speed_z(seg, params: BallParams, sigma: float, t, xy, meas=None, noise=(0.0, 1.0)) -> float:
    """Does the ball roll from the breakpoint to the rest as case 3 says?
    The rest's frames' mean position along the rolling direction against
    where the rolling path from the segmentation's ``x1`` and ``v1`` puts
    the ball at those frames' times (eq. 18, stopped at eq. 17's ``t2``:
    past it, at eq. 19's ``x2``), in the standard error of their difference
    (dimensionless; positive: the rest short of the path's; NaN where not
    defined: no rest, ``v1`` zero, no weights).

    Eq. 19 alone, ``|v1|`` against ``sqrt(2 (5/7) mu_r g |x2 - x1|)``, read
    the rest's first frames, where the ball still creeps within its noise
    (or a track ending before the stop), as the rest: its null's z had mean
    1.04 (48 simulated case 1/3/5 tracks), and right line answers of
    sliding_tracks cut 0.07-0.2 s before the stop read 4-7.5
    (docs/measurements.md, v1chk).  Eq. 18 at the rest's own frames holds
    for those frames too.  Where the breakpoint is early on a slide into the
    rest (realistic H.264 36/38: |v1| 0.198 m/s where the 9.6 mm to the rest
    allow 0.037) the path runs on far past the rest.

    ``x1``, ``v1`` and the rest's mean are linear in the track's frames
    ``t``, ``xy`` (s, m; :func:`segment_weights`): their covariance is
    recover.measurements.linear_covariance's under ``meas`` and ``noise``
    (the maximum-likelihood fit's error model, as
    :func:`geometry_covariance`), or the frames independent at ``sigma``
    (m, per axis) without ``meas``; plus the breakpoints' own share (the
    path refitted as they move, t1 with it: fit.segment's ``x1v1_t``).
    Propagated to first order: along ``v1_hat`` the path has gone ``s(tau)
    = |v1| tau - (5/7) mu_r g tau^2 / 2``, ``tau`` the time since ``t1``
    capped at the stop, and ``ds / d|v1| = tau``."""
    g = seg.geometry_cov or {}
    if seg.x2 is None or seg.v1 is None or seg.x1 is None or g.get("rest") is None or not len(g["rest"]) \
            or not np.isfinite(seg.t1):
        return float("nan")
    t, xy = np.asarray(t, float), np.asarray(xy, float)
    decel = rolling_deceleration(params.mu_r, params.g)
    v1 = np.asarray(seg.v1, float)
    speed = float(np.hypot(*v1))
    w = segment_weights(seg, len(t))
    if speed <= 0 or decel <= 0 or w is None or any(k not in w for k in ("x1", "v1")):
        return float("nan")
    rest = np.asarray(g["rest"])
    e = v1 / speed
    x1 = np.asarray(seg.x1, float)
    xbar = np.mean(xy[rest], axis=0)
    tau = np.clip(t[rest] - seg.t1, 0.0, speed / decel)
    s = speed * tau - 0.5 * decel * tau**2
    resid = float(e @ (xbar - x1)) - float(np.mean(s))
    w2 = np.zeros(len(t))
    w2[rest] = 1.0 / len(rest)
    W = np.stack([w["x1"], w2, w["v1"]])
    if meas is not None:
        from cuespin.recover.measurements import linear_covariance
        C = linear_covariance(meas, W, *noise)
    else:
        C = sigma**2 * np.kron(W @ W.T, np.eye(2))
    C = np.pad(C, ((0, 1), (0, 1)))  # (x1, xbar, v1, t1)
    if g.get("x1v1_t") is not None:
        idx = np.r_[0:2, 4:7]
        C[np.ix_(idx, idx)] += g["x1v1_t"]
    # d resid: -e.dx1 + e.dxbar - mean(tau) e.dv1 + (xbar - x1)_perp.dv1 / |v1| + mean(ds/dt1) dt1
    perp = (np.eye(2) - np.outer(e, e)) @ (xbar - x1) / speed
    moving = (t[rest] - seg.t1 > 0) & (t[rest] - seg.t1 < speed / decel)
    ds_dt1 = float(np.mean(np.where(moving, -(speed - decel * tau), 0.0)))
    grad = np.r_[-e, e, -float(np.mean(tau)) * e + perp, -ds_dt1]
    var = float(grad @ C @ grad)
    if not var > 0:
        return float("nan")
    return float(-resid / np.sqrt(var))


def line_offset(x0, x1, x2, C) -> tuple[float, float]:
    """Signed distance (m) of ``x1`` from the line through ``x0`` and ``x2``,
    and its standard error from the points' covariance ``C`` (6 x 6, m^2,
    :func:`geometry_covariance`, cross terms included: to first order the
    offset moves with x1 across the line, and against x0 and x2 scaled by
    how far along x1 lies, ``g = [-(1 - a) n, n, -a n]``)."""
    x0, x1, x2 = (np.asarray(v, float) for v in (x0, x1, x2))
    span = x2 - x0
    length = float(np.hypot(*span))
    n_hat = z_cross(span / length)
    along = float((x1 - x0) @ span) / length**2
    g = np.r_[-(1 - along) * n_hat, n_hat, -along * n_hat]
    var = float(g @ np.asarray(C, float)[:6, :6] @ g)
    return float((x1 - x0) @ n_hat), float(np.sqrt(max(var, 1e-30)))


def case2_distance(seg, geo) -> float:
    """``|x1 - x2|^2`` in the covariance of their difference (``geo``, the
    points' covariance, :func:`geometry_covariance`): chi^2(2) when the
    sliding phase's stopping point ``x1`` is the rest ``x2`` (case 2)."""
    d = np.asarray(seg.x1, float) - np.asarray(seg.x2, float)
    # x1's fit can reach into the rest's frames (the stop creeps): their shared error cancels.
    C = geo[2:4, 2:4] + geo[4:6, 4:6] - geo[2:4, 4:6] - geo[4:6, 2:4]
    try:
        return float(d @ np.linalg.solve(C, d))
    except np.linalg.LinAlgError:
        return float("inf")


def ran_into_rest(seg) -> bool:
    """The segmentation found sliding running into the rest (case 2: the
    ball stops as sliding ends; fit.segment then sets ``v1`` to zero and
    ``t1 = t2``)."""
    return bool(seg.x2 is not None and seg.t2 is not None and np.isfinite(seg.t1)
                and seg.v1 is not None and not np.any(seg.v1) and seg.t1 >= seg.t2)
