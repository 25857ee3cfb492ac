"""A shot continued past cushions and other balls: plausible, not modelled exactly.

The paper's model (``cuespin.physics.motion``) ends at the first contact
(CONVENTIONS.md, "What a shot is").  To render what a camera would see after
it, the motion is continued piecewise: between contacts the ball follows the
paper's sliding/rolling equations from its state just after the last
contact, so the path is exact between contacts and plausible across them.

Contacts, for a ball of radius R on a table of ``length x width``:

- **Cushion**: the centre reaches a cushion line's offset, ``x = R``,
  ``x = length - R``, ``y = R`` or ``y = width - R`` (the ball touches the
  playing surface's edge), moving towards it.  The normal velocity is
  reversed and scaled by the restitution ``e`` (0.9 by default: measured
  cushion restitutions of pool tables lie around 0.8-0.95), the tangential
  velocity is kept (a frictionless cushion).  The planar spin ``w`` is kept:
  the cushion's nose touches the ball near the height of its centre, where
  the spin's slip is vertical, so its friction (not modelled) would mostly
  act on the vertical motion this model leaves out.  A ball rolling into a
  cushion therefore leaves it sliding, with its top spin still driving it
  towards the cushion, and friction on the cloth brings it back to rolling
  (the familiar slowing and curving after a bank).
- **Ball**: the centre comes within 2R of another ball, which rests there.
  Equal masses, frictionless balls: the velocity's component along the line
  of centres is shared, ``(1 - e_b)/2`` kept and ``(1 + e_b)/2`` passed on
  (``e_b = 0.95``); the tangential part and the spin are kept.  The struck
  ball starts sliding without spin; its own path (cushions included, other
  balls ignored) is in :attr:`Trajectory.struck`.  It is no longer an
  obstacle for the shot's ball afterwards.

Kinetic energy (``kinetic_energy``) never rises across a contact: a cushion
only shrinks ``|v|`` and keeps ``w``; at a ball the two balls share
``(1 + e_b^2)/2 <= 1`` of the normal part's energy.

Contact times are exact for this model: each phase's path is a quadratic in
time (eq. 9, eq. 18), so a cushion line is reached at a root of a quadratic
and another ball at a root of a quartic.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cuespin.physics.motion import (
    BallParams, Shot, State, evaluate, phases, positions, rolling_deceleration,
)

CUSHION_RESTITUTION = 0.9
BALL_RESTITUTION = 0.95
# More contacts than this in one shot stops the simulation (a ball trapped
# in a corner bounces ever faster as its speed decays; a video never sees it).
MAX_CONTACTS = 100
# Root finding: imaginary parts below this (relative) count as real roots.
_IMAG_TOL = 1e-7


@dataclass(frozen=True)
class ContactEvent:
    """One contact of the shot's ball.

    Attributes
    ----------
    t : float
        Time of the contact (s, absolute).
    kind : str
        ``"cushion"`` or ``"ball"``.
    point : tuple of float
        The ball's centre at the contact (m).
    normal : tuple of float
        Unit normal from the cushion (or the struck ball) towards the ball's
        centre.
    other : int
        Index of the struck ball in ``balls``; -1 for a cushion.
    """

    t: float
    kind: str
    point: tuple[float, float]
    normal: tuple[float, float]
    other: int = -1


@dataclass(frozen=True)
class Trajectory:
    """A shot continued across contacts: one paper shot per stretch between them.

    Attributes
    ----------
    params : BallParams
    segments : tuple of Shot
        ``segments[0]`` is the shot itself; ``segments[i]`` starts at
        ``contacts[i - 1].t`` from the state just after that contact.
    contacts : tuple of ContactEvent
        In time order.
    struck : tuple of (int, Trajectory)
        Each ball the shot's ball struck, with its own path.
    """

    params: BallParams
    segments: tuple[Shot, ...]
    contacts: tuple[ContactEvent, ...] = ()
    struck: tuple = ()

    @property
    def starts(self) -> np.ndarray:
        """Start time (s) of each segment after the first."""
        return np.array([s.t0 for s in self.segments[1:]])

    @property
    def first_contact(self) -> ContactEvent | None:
        """The first contact, where the paper's model ends; None if none."""
        return self.contacts[0] if self.contacts else None

    def _segment_of(self, t: np.ndarray) -> np.ndarray:
        return np.searchsorted(self.starts, t, side="right")

    def positions(self, t) -> np.ndarray:
        """Ball centre (m) at an array of times (s), shape (n, 2)."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        seg = self._segment_of(t)
        x = np.empty((t.shape[0], 2))
        for i in np.unique(seg):
            m = seg == i
            x[m] = positions(self.segments[i], self.params, t[m])
        return x

    def state(self, t) -> State:
        """Position, velocity, angular velocity and phase at an array of times.

        ``phase`` is that of the segment in force (0 only before the strike).
        """
        t = np.atleast_1d(np.asarray(t, dtype=float))
        seg = self._segment_of(t)
        n = t.shape[0]
        x, v, w = np.empty((n, 2)), np.empty((n, 2)), np.empty((n, 2))
        phase = np.empty(n, dtype=np.int8)
        for i in np.unique(seg):
            m = seg == i
            s = evaluate(self.segments[i], self.params, t[m])
            x[m], v[m], w[m], phase[m] = s.x, s.v, s.w, s.phase
        return State(x=x, v=v, w=w, phase=phase)

    def velocities(self, t) -> np.ndarray:
        """Velocity (m/s) at an array of times, shape (n, 2)."""
        return self.state(t).v

    def angular_velocity(self, t) -> np.ndarray:
        """Planar angular velocity (rad/s) at an array of times, shape (n, 2)."""
        return self.state(t).w

    @property
    def t_rest(self) -> float:
        """When the ball finally comes to rest (s); ``inf`` if it never does."""
        return float(phases(self.segments[-1], self.params).t2)


def _pieces(shot: Shot, params: BallParams):
    """The moving phases of a shot as ``(ta, tb, c0, c1, c2)``: on ``[ta, tb]``
    the centre is ``c0 + c1 s + c2 s^2`` with ``s = t - ta`` (eq. 9, eq. 18)."""
    ph = phases(shot, params)
    g = params.g
    out = []
    if ph.t1 > ph.t0:
        out.append((ph.t0, ph.t1, ph.x0, ph.v0, -0.5 * params.mu_s * g * ph.u_hat))  # eq. 9
    speed1 = float(np.hypot(*ph.v1))
    if ph.t2 > ph.t1 and speed1 > 0:
        v1_hat = ph.v1 / speed1
        out.append((ph.t1, ph.t2, ph.x1, ph.v1, -0.5 * rolling_deceleration(params.mu_r, g) * v1_hat))  # eq. 18
    return out


def _first_root(poly: np.ndarray, s_max: float) -> float | None:
    """Smallest root in (0, s_max] of a polynomial (highest power first) at
    which it is falling (the gap closing), or None."""
    poly = np.trim_zeros(np.asarray(poly, dtype=float), "f")
    if poly.size < 2:
        return None
    roots = np.roots(poly)
    scale = max(1.0, np.abs(roots).max(initial=0.0))
    real = roots[np.abs(roots.imag) <= _IMAG_TOL * scale].real
    dpoly = np.polyder(poly)
    best = None
    for s in np.sort(real):
        if s <= 0 or s > s_max:
            continue
        if np.polyval(dpoly, s) < 0:  # approaching; a graze or a departure is no contact
            best = float(s)
            break
    return best


def _next_contact(shot: Shot, params: BallParams, table, balls: np.ndarray, active: np.ndarray,
                  t_end: float):
    """The first contact of a paper shot after ``shot.t0``: ``(t, kind, normal, other)`` or None."""
    R = params.R
    # Cushion lines as (axis, offset, normal sign): n . x >= offset inside.
    lines = ((0, R, 1.0), (0, table.length - R, -1.0), (1, R, 1.0), (1, table.width - R, -1.0))
    best = None
    for ta, tb, c0, c1, c2 in _pieces(shot, params):
        s_max = min(tb, t_end) - ta
        if s_max <= 0:
            break
        for axis, off, sign in lines:
            # gap(s) = sign (x_axis(s) - off), positive inside the table.
            poly = sign * np.array([c2[axis], c1[axis], c0[axis] - off])
            s = _first_root(poly, s_max)
            if s is not None and (best is None or ta + s < best[0]):
                n = np.zeros(2)
                n[axis] = sign
                best = (ta + s, "cushion", n, -1)
        for j in np.flatnonzero(active):
            d = [np.array([c2[a], c1[a], c0[a] - balls[j, a]]) for a in (0, 1)]
            poly = np.polyadd(np.polymul(d[0], d[0]), np.polymul(d[1], d[1]))
            poly = np.polysub(poly, [4.0 * R * R])  # |x - b|^2 - (2R)^2
            s = _first_root(poly, s_max)
            if s is not None and (best is None or ta + s < best[0]):
                x = c0 + c1 * s + c2 * s * s
                n = (x - balls[j]) / np.hypot(*(x - balls[j]))
                best = (ta + s, "ball", n, int(j))
        if best is not None:
            return best  # pieces are in time order: a later piece cannot come first
    return None


def simulate(shot: Shot, params: BallParams, table, balls=(), restitution: float = CUSHION_RESTITUTION,
             ball_restitution: float = BALL_RESTITUTION, t_end: float = np.inf,
             max_contacts: int = MAX_CONTACTS) -> Trajectory:
    """Continue a shot past cushion and ball contacts.

    Parameters
    ----------
    shot : Shot
        Initial conditions (the paper's).
    params : BallParams
        Ball and cloth constants.
    table : Table
        Playing surface (m); its edges are the cushions.
    balls : array_like, shape (k, 2)
        Centres (m) of other balls resting on the table.
    restitution : float
        Cushion restitution for the normal velocity, in (0, 1].
    ball_restitution : float
        Ball-ball restitution, in (0, 1].
    t_end : float
        No contacts are looked for after this time (s).
    max_contacts : int
        Stop continuing after this many contacts.

    Returns
    -------
    Trajectory
    """
    if not (0 < restitution <= 1) or not (0 < ball_restitution <= 1):
        raise ValueError(f"restitution must lie in (0, 1], got {restitution} and {ball_restitution}")
    R = params.R
    balls = np.asarray(balls, dtype=float).reshape(-1, 2)
    # A ball already touching the shot's ball at the start is not an obstacle.
    active = np.hypot(*(balls - np.array(shot.x0)).T) >= 2 * R if len(balls) else np.zeros(0, bool)
    segments, contacts, struck = [shot], [], []
    while len(contacts) < max_contacts:
        hit = _next_contact(segments[-1], params, table, balls, active, t_end)
        if hit is None:
            break
        tc, kind, n, other = hit
        st = evaluate(segments[-1], params, [tc])
        x, v, w = st.x[0], st.v[0], st.w[0]
        vn = float(v @ n)
        if kind == "cushion":
            v_new = v - (1.0 + restitution) * vn * n  # normal reversed, scaled by e
        else:
            v_new = v - 0.5 * (1.0 + ball_restitution) * vn * n
            passed = 0.5 * (1.0 + ball_restitution) * vn * n  # vn < 0: along -n, at the struck ball
            other_shot = Shot(x0=balls[other], v0=passed, w0=(0.0, 0.0), t0=tc)
            struck.append((other, simulate(other_shot, params, table, (), restitution,
                                           ball_restitution, t_end, max_contacts)))
            active = active.copy()
            active[other] = False
        contacts.append(ContactEvent(t=float(tc), kind=kind, point=(float(x[0]), float(x[1])),
                                     normal=(float(n[0]), float(n[1])), other=other))
        segments.append(Shot(x0=x, v0=v_new, w0=w, t0=tc))
    return Trajectory(params=params, segments=tuple(segments), contacts=tuple(contacts),
                      struck=tuple(struck))


def scene_balls(render: dict) -> np.ndarray:
    """Centres (m) of the other balls in a scene's ``render.balls`` list of
    ``{"x": .., "y": .., ...}`` objects, shape (k, 2)."""
    balls = render.get("balls") or []
    return np.array([[float(b["x"]), float(b["y"])] for b in balls], dtype=float).reshape(-1, 2)


def scene_trajectory(scene) -> Trajectory:
    """The path a scene's truth follows on its table.

    With ``render.contacts`` true, the shot continues past cushions and the
    balls of ``render.balls`` (restitutions ``render.cushion_restitution``,
    ``render.ball_restitution``); otherwise it is the paper's shot alone
    (the ball runs on through where the cushions would be, as before).
    """
    r = scene.render
    if not r.get("contacts", False):
        return Trajectory(params=scene.physics, segments=(scene.truth,))
    return simulate(scene.truth, scene.physics, scene.table, scene_balls(r),
                    float(r.get("cushion_restitution", CUSHION_RESTITUTION)),
                    float(r.get("ball_restitution", BALL_RESTITUTION)))
