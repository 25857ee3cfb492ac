"""Theorem 1: the sliding path of a curved shot is a parabola.

The path is ``y = a x^2`` rotated about the origin by ``theta = phi + pi/2``
(``u_hat = (cos phi, sin phi)``), then translated to the vertex ``x*``.  Its
axis points along ``-u_hat``: the ball bends away from the slip.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cuespin.physics.motion import BallParams, contact_velocity, cross


@dataclass(frozen=True)
class Parabola:
    """A parabola ``y = a x^2`` rotated by ``theta`` and moved to ``vertex``.

    Attributes
    ----------
    a : float
        Curvature parameter (1/m); the curvature at the vertex is ``2a``.
    theta : float
        Rotation (rad); the axis of symmetry points along
        ``(-sin theta, cos theta)``.
    vertex : ndarray, shape (2,)
        Vertex position ``x*`` (m).
    t_star : float
        Time of the vertex after the strike, eq. 22 (s); may lie outside the
        sliding interval.
    """

    a: float
    theta: float
    vertex: np.ndarray
    t_star: float = float("nan")

    def to_local(self, p):
        """Table points (m), shape (n, 2), into the parabola's frame, where
        the curve is ``y = a x^2``."""
        p = np.asarray(p, dtype=float) - self.vertex
        c, s = np.cos(self.theta), np.sin(self.theta)
        return np.stack([c * p[..., 0] + s * p[..., 1], -s * p[..., 0] + c * p[..., 1]], axis=-1)

    def to_table(self, q):
        """Local points, shape (n, 2), back to table metres."""
        q = np.asarray(q, dtype=float)
        c, s = np.cos(self.theta), np.sin(self.theta)
        return np.stack([c * q[..., 0] - s * q[..., 1], s * q[..., 0] + c * q[..., 1]], axis=-1) + self.vertex

    def implicit_residual(self, p):
        """``y_local - a x_local^2`` (m) at table points: zero on the curve."""
        q = self.to_local(p)
        return q[..., 1] - self.a * q[..., 0] ** 2


def sliding_parabola(x0, v0, w0, params: BallParams) -> Parabola:
    """Theorem 1's parabola for a curved shot (``v0 x u_hat != 0``).

    Parameters
    ----------
    x0 : array_like, shape (2,)
        Strike position (m).
    v0 : array_like, shape (2,)
        Initial velocity (m/s).
    w0 : array_like, shape (2,)
        Initial planar angular velocity (rad/s).
    params : BallParams
        Ball and cloth constants.

    Returns
    -------
    Parabola
        ``a = mu_s g / (2 (v0 x u_hat)^2)``, ``theta = phi + pi/2`` and the
        vertex ``x* = x0 + (v0.u_hat)/(mu_s g) (v0 - (v0.u_hat) u_hat / 2)``.
        Raises ValueError for a straight shot (``a`` would be infinite).
    """
    x0 = np.asarray(x0, dtype=float)
    v0 = np.asarray(v0, dtype=float)
    mu_g = params.mu_s * params.g
    u0 = contact_velocity(v0, w0, params.R)
    u_hat = u0 / np.hypot(*u0)
    vxu = float(cross(v0, u_hat))
    if vxu == 0.0:
        raise ValueError("v0 is parallel to the slip: the sliding path is a line")
    phi = float(np.arctan2(u_hat[1], u_hat[0]))
    vu = float(v0 @ u_hat)
    vertex = x0 + vu / mu_g * (v0 - 0.5 * vu * u_hat)
    return Parabola(a=mu_g / (2.0 * vxu**2), theta=phi + np.pi / 2, vertex=vertex,
                    t_star=vu / mu_g)  # eq. 22
