"""The paper's forward model (Jia, Mason, Erdmann, section 1).

A ball rests at ``x0`` until the strike at ``t0``; it then slides with
constant slip direction (eq. 3-13) until ``t1``, rolls along a line
(eq. 14-19) until ``t2`` and rests at ``x2``.  Everything here is a pure
function of numpy arrays and small frozen dataclasses; times are absolute
(seconds on the video's clock), so the strike time ``t0`` is part of the shot.

The table frame is right-handed with z up; planar cross products are the
scalar z component, ``a x b = a[0] b[1] - a[1] b[0]``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

# |u0| below this (m/s) counts as "no slip": paper case 4, t1 = t0.  Far below
# anything a video resolves (a slip of 1e-9 m/s slides for 1e-10 s).
SLIP_ZERO = 1e-9
# |v1| below this (m/s) counts as "stopped when sliding ends": paper case 2.
SPEED_ZERO = 1e-9


@dataclass(frozen=True)
class BallParams:
    """Ball and cloth constants, SI units.

    Attributes
    ----------
    R : float
        Ball radius (m).
    mu_s : float
        Sliding friction coefficient (dimensionless).
    mu_r : float
        Rolling friction coefficient in the paper's energy convention: the
        rolling ball decelerates at ``(5/7) mu_r g`` (eq. 16).
    g : float
        Gravitational acceleration (m/s^2).
    """

    R: float = 0.028575
    mu_s: float = 0.2
    mu_r: float = 0.01
    g: float = 9.81


def rolling_deceleration(mu_r: float, g: float) -> float:
    """Eq. 16: a rolling ball's deceleration ``(5/7) mu_r g`` (m/s^2) along
    its velocity, with ``mu_r`` in the paper's energy convention
    (:class:`BallParams`) and ``g`` in m/s^2."""
    return 5.0 / 7.0 * mu_r * g


@dataclass(frozen=True)
class Shot:
    """Initial conditions of one shot.

    Attributes
    ----------
    x0 : tuple of float
        Rest position before the strike, table frame (m).
    v0 : tuple of float
        Velocity just after the strike (m/s).
    w0 : tuple of float
        Planar angular velocity just after the strike (rad/s).
    t0 : float
        Strike time (s).
    """

    x0: tuple[float, float]
    v0: tuple[float, float]
    w0: tuple[float, float]
    t0: float = 0.0

    def __post_init__(self):
        for name in ("x0", "v0", "w0"):
            object.__setattr__(self, name, tuple(map(float, getattr(self, name))))
        object.__setattr__(self, "t0", float(self.t0))


@dataclass(frozen=True)
class Phases:
    """Phase boundaries of a shot (paper section 1), absolute times.

    Attributes
    ----------
    u0 : ndarray, shape (2,)
        Initial contact (slip) velocity, eq. 2 (m/s).
    u_hat : ndarray, shape (2,)
        Constant slip direction while sliding; zeros when there is no slip.
    t1, x1, v1 :
        End of sliding (s), its position (m) and velocity (m/s), eq. 10-13.
    t2, x2 :
        End of rolling (s) and rest position (m), eq. 17-19.  ``t2`` is
        ``inf`` and ``x2`` NaN when ``mu_r == 0`` and the ball never stops.
    """

    u0: np.ndarray
    u_hat: np.ndarray
    t0: float
    x0: np.ndarray
    v0: np.ndarray
    w0: np.ndarray
    t1: float
    x1: np.ndarray
    v1: np.ndarray
    t2: float
    x2: np.ndarray
    params: BallParams = field(repr=False)

    @property
    def sliding_duration(self) -> float:
        """Length of the sliding phase ``t1 - t0`` (s)."""
        return self.t1 - self.t0

    @property
    def rolling_duration(self) -> float:
        """Length of the rolling phase ``t2 - t1`` (s); ``inf`` if never stops."""
        return self.t2 - self.t1


@dataclass(frozen=True)
class State:
    """Ball state at an array of times; each array has a leading time axis.

    Attributes
    ----------
    x : ndarray, shape (n, 2)
        Centre position (m).
    v : ndarray, shape (n, 2)
        Velocity (m/s).
    w : ndarray, shape (n, 2)
        Planar angular velocity (rad/s).
    phase : ndarray of int, shape (n,)
        0 at rest before the strike, 1 sliding, 2 rolling, 3 at rest after.
    """

    x: np.ndarray
    v: np.ndarray
    w: np.ndarray
    phase: np.ndarray


BEFORE, SLIDING, ROLLING, REST = 0, 1, 2, 3


def cross(a, b):
    """Scalar z component of the planar cross product ``a x b`` (vectorised)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def z_cross(a):
    """``z_hat x a`` for planar vectors: rotate by +90 degrees (vectorised)."""
    a = np.asarray(a, dtype=float)
    out = np.empty(a.shape[:-1] + (2,))  # not np.stack: called in the fits' every residual
    out[..., 0] = -a[..., 1]
    out[..., 1] = a[..., 0]
    return out


def contact_velocity(v, w, R):
    """Contact (slip) velocity ``u = v + R z_hat x w`` (eq. 1).

    Parameters
    ----------
    v : array_like, shape (..., 2)
        Velocity (m/s).
    w : array_like, shape (..., 2)
        Planar angular velocity (rad/s).
    R : float
        Ball radius (m).

    Returns
    -------
    ndarray, shape (..., 2)
        Slip velocity of the contact point (m/s).
    """
    return np.asarray(v, dtype=float) + R * z_cross(w)


def phases(shot: Shot, params: BallParams) -> Phases:
    """Phase boundaries of a shot: eq. 2, 10-13 (sliding), 17-19 (rolling).

    Parameters
    ----------
    shot : Shot
        Initial conditions.
    params : BallParams
        Ball and cloth constants.

    Returns
    -------
    Phases
        Slip direction and the times, positions and velocities where sliding
        and rolling end.  Pure rolling from the strike (paper case 4) has
        ``t1 == t0``; a ball that stops as sliding ends (case 2) has
        ``t2 == t1``.
    """
    # Component by component in floats (the fits call this for every
    # residual): the same operations, in the same order, as on 2-vectors.
    R, mu_s, mu_r, g = params.R, params.mu_s, params.mu_r, params.g
    (x0x, x0y), (v0x, v0y), (w0x, w0y) = shot.x0, shot.v0, shot.w0
    u0x, u0y = v0x + R * -w0y, v0y + R * w0x  # eq. 2, u0 = v0 + R z_hat x w0
    speed_u0 = float(np.hypot(u0x, u0y))
    if speed_u0 > SLIP_ZERO:
        ux, uy = u0x / speed_u0, u0y / speed_u0
        tau1 = 2.0 / 7.0 * speed_u0 / (mu_s * g)  # eq. 10
    else:
        ux = uy = tau1 = 0.0
    c = mu_s * g * tau1
    v1x, v1y = v0x - c * ux, v0y - c * uy  # eq. 7 at t1, = eq. 11
    c = 0.5 * mu_s * g * tau1**2
    x1x, x1y = x0x + v0x * tau1 - c * ux, x0y + v0y * tau1 - c * uy  # eq. 9 at t1, = eq. 13
    speed_v1 = float(np.hypot(v1x, v1y))
    if speed_v1 <= SPEED_ZERO:
        v1x = v1y = tau2 = 0.0
        x2 = np.array([x1x, x1y])
    elif mu_r > 0:
        tau2 = 7.0 / 5.0 * speed_v1 / (mu_r * g)  # eq. 17
        c = 7.0 / 10.0 * speed_v1 / (mu_r * g)
        x2 = np.array([x1x + c * v1x, x1y + c * v1y])  # eq. 19
    else:
        tau2, x2 = np.inf, np.full(2, np.nan)
    t1 = shot.t0 + tau1
    return Phases(u0=np.array([u0x, u0y]), u_hat=np.array([ux, uy]), t0=shot.t0, x0=np.array(shot.x0),
                  v0=np.array(shot.v0), w0=np.array(shot.w0), t1=t1, x1=np.array([x1x, x1y]),
                  v1=np.array([v1x, v1y]), t2=t1 + tau2, x2=x2, params=params)


def evaluate(shot: Shot, params: BallParams, t, ph: Phases | None = None) -> State:
    """Position, velocity and angular velocity at any array of times.

    Parameters
    ----------
    shot : Shot
        Initial conditions.
    params : BallParams
        Ball and cloth constants.
    t : array_like, shape (n,)
        Absolute times (s); any order, any values.
    ph : Phases, optional
        Precomputed ``phases(shot, params)``, to save recomputing it.

    Returns
    -------
    State
        ``x`` (m), ``v`` (m/s), ``w`` (rad/s) and ``phase`` at each time: at
        rest at ``x0`` before ``t0``; eq. 7-9 while sliding; eq. 18 and
        ``w = z_hat x v / R`` while rolling; at rest at ``x2`` after ``t2``.
    """
    if ph is None:
        ph = phases(shot, params)
    R, mu_s, mu_r, g = params.R, params.mu_s, params.mu_r, params.g
    t = np.atleast_1d(np.asarray(t, dtype=float))
    n = t.shape[0]
    v = np.zeros((n, 2))
    w = np.zeros((n, 2))
    phase = np.full(n, BEFORE, dtype=np.int8)

    before, sliding, rolling, rest = _phase_masks(ph, t)
    phase[sliding], phase[rolling], phase[rest] = SLIDING, ROLLING, REST
    x = _positions(ph, params, t, before, sliding, rolling, rest)
    s = (t[sliding] - ph.t0)[:, None]
    v[sliding] = ph.v0 - mu_s * g * s * ph.u_hat  # eq. 7
    w[sliding] = ph.w0 + 2.5 / R * mu_s * g * s * z_cross(ph.u_hat)  # eq. 8
    if rolling.any():
        v1_hat = ph.v1 / np.hypot(*ph.v1)
        r = (t[rolling] - ph.t1)[:, None]
        v[rolling] = ph.v1 - rolling_deceleration(mu_r, g) * r * v1_hat  # eq. 16
        w[rolling] = z_cross(v[rolling]) / R  # eq. 12, no slip while rolling
    return State(x=x, v=v, w=w, phase=phase)


def _phase_masks(ph: Phases, t):
    return t < ph.t0, (t >= ph.t0) & (t < ph.t1), (t >= ph.t1) & (t < ph.t2), t >= ph.t2


def _phase_index(ph: Phases, t, ordered: bool | None = None):
    """:func:`_phase_masks` as four slices when ``t`` is in time order (the
    fits' frame times and their exposure nodes): the same frames, found by
    bisection instead of four passes and scattered copies; the masks when
    ``t`` is not sorted or a phase boundary is NaN.  ``ordered``: whether
    ``t`` is sorted, when the caller knows (checked here otherwise)."""
    t0, t1, t2 = ph.t0, ph.t1, ph.t2
    if t0 != t0 or t1 != t1 or t2 != t2 or not (ordered if ordered is not None else np.all(t[1:] >= t[:-1])):
        return _phase_masks(ph, t)
    i0, i1, i2 = t.searchsorted((t0, t1, t2), side="left").tolist()  # first frame at or after each boundary
    return slice(0, i0), slice(i0, i1), slice(i1, i2), slice(i2, len(t))


def _any(index) -> bool:
    """Whether a phase's mask or slice selects any frame."""
    return index.stop > index.start if isinstance(index, slice) else bool(index.any())


def _positions(ph: Phases, params: BallParams, t, before, sliding, rolling, rest) -> np.ndarray:
    """Centre (m) at times ``t`` given the phase of each: eq. 9 and 18."""
    g, mu_s, mu_r = params.g, params.mu_s, params.mu_r
    # An axis at a time: (k,) arrays, not (k, 1) ones broadcast against
    # 2-vectors (numpy's inner loops are then two elements long), the same
    # operations in the same order.
    x = np.empty((t.shape[0], 2))
    x[before] = ph.x0
    s = t[sliding] - ph.t0
    c = 0.5 * mu_s * g * s**2
    for d in (0, 1):
        x[sliding, d] = ph.x0[d] + ph.v0[d] * s - c * ph.u_hat[d]  # eq. 9
    if _any(rolling):
        v1_hat = ph.v1 / np.hypot(*ph.v1)
        r = t[rolling] - ph.t1
        c = 0.5 * rolling_deceleration(mu_r, g) * r**2
        for d in (0, 1):
            x[rolling, d] = ph.x1[d] + ph.v1[d] * r - c * v1_hat[d]  # eq. 18
    x[rest] = ph.x2
    return x


def positions(shot: Shot, params: BallParams, t, ph: Phases | None = None,
              ordered: bool | None = None) -> np.ndarray:
    """Ball centre (m) at an array of times, shape (n, 2); see :func:`evaluate`
    (the same equations, without velocities: the fits' inner loop).
    ``ordered``: whether ``t`` is sorted, when the caller knows."""
    if ph is None:
        ph = phases(shot, params)
    t = np.atleast_1d(np.asarray(t, dtype=float))
    return _positions(ph, params, t, *_phase_index(ph, t, ordered))


def _powers(s) -> np.ndarray:
    """Rows ``(1, s, s^2)``, shape (k, 3) (np.stack's numbers, without its overhead)."""
    out = np.empty((s.shape[0], 3))
    out[:, 0] = 1.0
    out[:, 1] = s
    np.multiply(s, s, out=out[:, 2])
    return out


def positions_jacobian(shot: Shot, params: BallParams, t, rolling: bool = False,
                       ph: Phases | None = None, ordered: bool | None = None) -> np.ndarray:
    """Derivatives of :func:`positions` with respect to the shot, shape (n, 2, p).

    The parameters are ``(x0x, x0y, t0, v0x, v0y, w0x, w0y)`` (p = 7), or
    with ``rolling`` ``(x0x, x0y, t0, v0x, v0y)`` (p = 5) for the shot
    rolling from the strike, ``w0 = z_hat x v0 / R`` (paper case 4).  Each
    phase's position is a polynomial in time whose coefficients depend on the
    shot through eq. 2 and 10-19, so the derivatives are exact (the fits'
    Jacobians: a finite difference cost six residual evaluations more per
    iteration).  At a phase boundary the derivative is the later phase's.

    Parameters
    ----------
    shot : Shot
        Initial conditions (with ``rolling``, ``w0`` must be ``z_hat x v0 / R``).
    params : BallParams
        Ball and cloth constants.
    t : array_like, shape (n,)
        Absolute times (s).
    rolling : bool
        Differentiate the rolling-from-the-strike model (w0 tied to v0).
    ph : Phases, optional
        Precomputed ``phases(shot, params)``.
    ordered : bool, optional
        Whether ``t`` is sorted, when the caller knows.

    Returns
    -------
    ndarray, shape (n, 2, p)
        ``d x(t) / d p`` (m per unit of each parameter: m, s, m/s, rad/s).
    """
    if ph is None:
        ph = phases(shot, params)
    t = np.atleast_1d(np.asarray(t, dtype=float))
    R, mu_g, mu_r, g = params.R, params.mu_s * params.g, params.mu_r, params.g
    n_par = 5 if rolling else 7
    eye = np.eye(2)
    zc = np.array([[0.0, -1.0], [1.0, 0.0]])  # z_hat x: a matrix
    d_x0 = np.zeros((2, n_par))
    d_x0[:, 0:2] = eye
    d_t0 = np.zeros(n_par)
    d_t0[2] = 1.0
    d_v0 = np.zeros((2, n_par))
    d_v0[:, 3:5] = eye
    if rolling:
        d_w0 = zc @ d_v0 / R  # w0 = z x v0 / R
    else:
        d_w0 = np.zeros((2, n_par))
        d_w0[:, 5:7] = eye
    d_u0 = d_v0 + R * zc @ d_w0  # eq. 2: zero when rolling
    speed_u0 = float(np.hypot(*ph.u0))
    tau1 = ph.t1 - ph.t0
    if speed_u0 > SLIP_ZERO:
        d_uhat = (eye - np.outer(ph.u_hat, ph.u_hat)) / speed_u0 @ d_u0
        d_tau1 = 2.0 / (7.0 * mu_g) * ph.u_hat @ d_u0  # eq. 10
    else:
        d_uhat, d_tau1 = np.zeros((2, n_par)), np.zeros(n_par)
    v1 = ph.v0 - mu_g * tau1 * ph.u_hat  # eq. 11, before any zeroing of a stop
    d_v1 = d_v0 - mu_g * np.outer(ph.u_hat, d_tau1) - mu_g * tau1 * d_uhat
    d_x1 = d_x0 + tau1 * d_v0 + np.outer(v1, d_tau1) - 0.5 * mu_g * tau1**2 * d_uhat  # eq. 13
    speed_v1 = float(np.hypot(*v1))
    # Each phase's position is a quadratic in its own time; so are its
    # derivatives: rows (1, s, s^2) times three (2, p) coefficients.
    out = np.empty((t.shape[0], 2 * n_par))
    before, sliding, rolls, rest = _phase_index(ph, t, ordered)
    out[before] = d_x0.ravel()
    # eq. 9: x0 + v0 s - 1/2 mu_s g s^2 u_hat, s = t - t0 (d s / d t0 = -1,
    # times the velocity v0 - mu_s g s u_hat, eq. 7)
    C = np.stack([d_x0 - np.outer(ph.v0, d_t0), d_v0 + mu_g * np.outer(ph.u_hat, d_t0), -0.5 * mu_g * d_uhat])
    s = t[sliding] - ph.t0
    out[sliding] = _powers(s) @ C.reshape(3, -1)
    if _any(rolls):
        a_r = rolling_deceleration(mu_r, g)  # eq. 16
        v1_hat = v1 / speed_v1
        d_v1hat = (eye - np.outer(v1_hat, v1_hat)) / speed_v1 @ d_v1
        d_r = d_t0 + d_tau1  # r = t - t0 - tau1
        # eq. 18: x1 + v1 r - 1/2 a_r r^2 v1_hat (velocity v1 - a_r r v1_hat)
        C = np.stack([d_x1 - np.outer(v1, d_r), d_v1 + a_r * np.outer(v1_hat, d_r), -0.5 * a_r * d_v1hat])
        r = t[rolls] - ph.t1
        out[rolls] = _powers(r) @ C.reshape(3, -1)
    if _any(rest):
        if speed_v1 <= SPEED_ZERO:  # stopped as sliding ended (case 2): x2 = x1
            out[rest] = d_x1.ravel()
        else:  # eq. 19: x2 = x1 + 7/10 |v1| v1 / (mu_r g)
            c = 0.7 / (mu_r * g)
            out[rest] = (d_x1 + c * (speed_v1 * eye + np.outer(v1, v1 / speed_v1)) @ d_v1).ravel()
    return out.reshape(-1, 2, n_par)


def kinetic_energy(v, w, R):
    """Kinetic energy per unit mass, ``|v|^2/2 + (1/5) R^2 |w|^2`` (J/kg).

    Parameters
    ----------
    v, w : array_like, shape (..., 2)
        Velocity (m/s) and planar angular velocity (rad/s).
    R : float
        Ball radius (m).
    """
    v = np.asarray(v, dtype=float)
    w = np.asarray(w, dtype=float)
    return 0.5 * np.sum(v * v, axis=-1) + 0.2 * R**2 * np.sum(w * w, axis=-1)
