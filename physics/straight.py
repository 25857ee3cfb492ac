"""Straight sliding (paper section 1.4, eq. 23-30) and its five cases (Figure 4).

When ``v0 . w0 = 0`` the slip is collinear with ``v0`` and the whole path is a
line along ``i_hat``.  The paper's frame: ``i_hat`` along ``v0`` (along
``w0 x z_hat`` when ``v0 = 0``), ``j_hat = z_hat x i_hat`` so that
``i_hat x j_hat = z_hat``; scalars ``v0 = v0 . i_hat >= 0`` and
``w0 = w0 . j_hat``.  Natural roll is ``R w0 = v0`` (case 4).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cuespin.physics.motion import BallParams, z_cross

# Relative tolerance for the paper's equality cases (2 and 4) and for
# deciding that v0 and w0 are orthogonal; far below what any video resolves.
CASE_RTOL = 1e-9


@dataclass(frozen=True)
class StraightMotion:
    """Closed-form straight motion (eq. 23-30), scalars along ``i_hat``.

    Attributes
    ----------
    case : int
        Figure 4 case, 1 to 5.
    i_hat, j_hat : ndarray, shape (2,)
        The paper's frame for the line.
    v0, w0, u0 : float
        ``v0 . i_hat`` (m/s), ``w0 . j_hat`` (rad/s), ``v0 - R w0`` (eq. 23).
    x1, x2 : float
        ``x1 - x0`` (eq. 24) and ``x2 - x0`` (eq. 24 + 27), metres along i_hat.
    v1 : float
        Velocity when sliding ends (eq. 25), m/s along i_hat.
    t1, t2 : float
        Sliding and total motion durations from the strike (eq. 26, 28), s.
    t3, x3 : float
        When and where (from x0, along i_hat) the velocity first becomes zero:
        eq. 29-30 if during sliding (cases 1-2), else ``t2`` and ``x2``.
    """

    case: int
    i_hat: np.ndarray
    j_hat: np.ndarray
    v0: float
    w0: float
    u0: float
    x1: float
    v1: float
    t1: float
    x2: float
    t2: float
    t3: float
    x3: float


def is_straight(v0, w0, rtol: float = CASE_RTOL) -> bool:
    """True when ``v0 . w0`` is zero to ``rtol`` of ``|v0||w0|`` (section 1.4)."""
    v0 = np.asarray(v0, dtype=float)
    w0 = np.asarray(w0, dtype=float)
    return abs(float(v0 @ w0)) <= rtol * float(np.hypot(*v0) * np.hypot(*w0)) + 1e-300


def straight_frame(v0, w0):
    """The paper's ``(i_hat, j_hat)`` for a straight shot (section 1.4).

    Returns ``i_hat`` along ``v0``, or along ``w0 x z_hat`` when ``v0 = 0``
    (spin only), and ``j_hat = z_hat x i_hat``.  Raises ValueError when both
    ``v0`` and ``w0`` are zero (no motion, no line).
    """
    v0 = np.asarray(v0, dtype=float)
    w0 = np.asarray(w0, dtype=float)
    if np.hypot(*v0) > 0:
        i_hat = v0 / np.hypot(*v0)
    elif np.hypot(*w0) > 0:
        i_hat = -z_cross(w0) / np.hypot(*w0)  # w0 x z_hat = -(z_hat x w0)
    else:
        raise ValueError("v0 and w0 are both zero: the ball does not move")
    return i_hat, z_cross(i_hat)


def straight_case(v0: float, w0: float, R: float) -> int:
    """Figure 4's case for scalar ``v0 >= 0`` and ``w0`` along ``j_hat``.

    (1) ``R w0 < -5/2 v0``: reverses while sliding; (2) ``= -5/2 v0``: stops
    as sliding ends; (3) between: slides then rolls forward; (4) ``R w0 = v0``:
    rolls from the strike; (5) ``R w0 > v0``: speeds up while sliding.
    """
    rw = R * w0
    tol = CASE_RTOL * max(abs(v0), abs(rw), 1e-300)
    if abs(rw + 2.5 * v0) <= tol:
        return 2
    if abs(rw - v0) <= tol:
        return 4
    if rw < -2.5 * v0:
        return 1
    if rw < v0:
        return 3
    return 5


def straight_motion(v0, w0, params: BallParams) -> StraightMotion:
    """Closed-form straight motion, eq. 23-30, for orthogonal ``v0`` and ``w0``.

    Parameters
    ----------
    v0 : array_like, shape (2,)
        Initial velocity (m/s).
    w0 : array_like, shape (2,)
        Initial planar angular velocity (rad/s), orthogonal to ``v0``.
    params : BallParams
        Ball and cloth constants; ``mu_r > 0``.

    Returns
    -------
    StraightMotion
    """
    R, mu_s, mu_r, g = params.R, params.mu_s, params.mu_r, params.g
    i_hat, j_hat = straight_frame(v0, w0)
    v = float(np.asarray(v0, dtype=float) @ i_hat)
    w = float(np.asarray(w0, dtype=float) @ j_hat)
    case = straight_case(v, w, R)
    u = v - R * w  # eq. 23
    if case == 4:
        u = 0.0
    x1 = 2.0 / (49.0 * mu_s * g) * abs(u) * (6 * v + R * w)  # eq. 24
    v1 = (5 * v + 2 * R * w) / 7.0  # eq. 25
    t1 = 2.0 / 7.0 * abs(u) / (mu_s * g)  # eq. 26
    c = 5 * v + 2 * R * w
    if case == 2:
        c = v1 = 0.0
    x2 = x1 + abs(c) * c / (70.0 * mu_r * g)  # eq. 27
    t2 = t1 + abs(c) / (5.0 * mu_r * g)  # eq. 28
    if case in (1, 2):
        t3 = v / (mu_s * g)  # eq. 29
        x3 = 0.5 * v**2 / (mu_s * g)  # eq. 30
    else:
        t3, x3 = t2, x2
    return StraightMotion(case=case, i_hat=i_hat, j_hat=j_hat, v0=v, w0=w, u0=u,
                          x1=x1, v1=v1, t1=t1, x2=x2, t2=t2, t3=t3, x3=x3)
