"""Seeded shots that end at a contact: aimed at a cushion or at another ball.

Used by the sampler's ``cushion`` and ``ball_contact`` presets.  Each shot is
drawn until its first contact (``cuespin.physics.contact.simulate``) is of
the wanted kind and leaves enough motion before it to analyse.
"""

from __future__ import annotations

import numpy as np

from cuespin.physics.contact import simulate
from cuespin.physics.motion import BallParams, Shot, positions
from cuespin.physics.scene import Table

CONTACT_PRESETS = ("cushion", "ball_contact")
# The contact comes at least this long after the strike (s): a few frames
# of free motion at 60 fps is too little to fit.
MIN_FREE_S = 0.25
# ... and at most this long after it, so videos stay short.
MAX_FREE_S = 2.5
# Thinnest cut: the struck ball's centre this many R off the path (a hit
# needs under 2R; thinner cuts barely change the shot's ball's motion).
MAX_CUT_R = 1.5


def sample_contact_shot(rng: np.random.Generator, preset: str, params: BallParams,
                        table: Table = Table()) -> tuple[Shot, np.ndarray]:
    """A shot whose first contact is a cushion (``cushion``) or a ball (``ball_contact``).

    Parameters
    ----------
    rng : numpy.random.Generator
        Local source of randomness.
    preset : str
        ``cushion`` or ``ball_contact``.
    params : BallParams
        Ball and cloth constants.
    table : Table
        Playing surface.

    Returns
    -------
    (Shot, ndarray)
        The shot (``t0`` 0.1-0.5 s) and the centres (m) of the other balls,
        shape (k, 2): none for ``cushion``, the struck ball for ``ball_contact``.
    """
    R = params.R
    lo, hi = np.array([0.2, 0.2]), np.array([table.length - 0.2, table.width - 0.2])
    for _ in range(1000):
        x0 = rng.uniform(lo, hi)
        t0 = float(rng.uniform(0.1, 0.5))
        speed = float(rng.uniform(0.8, 3.0))
        ang = float(rng.uniform(0, 2 * np.pi))
        v0 = speed * np.array([np.cos(ang), np.sin(ang)])
        k = float(rng.uniform(0.0, 2.0))
        spin_ang = float(rng.uniform(0, 2 * np.pi))
        w0 = k * speed / R * np.array([np.cos(spin_ang), np.sin(spin_ang)])
        shot = Shot(x0=x0, v0=v0, w0=w0, t0=t0)
        balls = np.zeros((0, 2))
        if preset == "ball_contact":
            t_hit = t0 + float(rng.uniform(MIN_FREE_S, MAX_FREE_S))
            x_hit, x_next = positions(shot, params, [t_hit, t_hit + 1e-3])
            d = x_next - x_hit
            if np.hypot(*d) < 1e-6:
                continue
            perp = np.array([-d[1], d[0]]) / np.hypot(*d)
            centre = x_hit + float(rng.uniform(-MAX_CUT_R, MAX_CUT_R)) * R * perp
            if not table.contains(centre[None, :], margin=2 * R)[0]:
                continue
            balls = centre[None, :]
        first = simulate(shot, params, table, balls, t_end=t0 + MAX_FREE_S).first_contact
        want = "ball" if preset == "ball_contact" else "cushion"
        if first is not None and first.kind == want and first.t - t0 >= MIN_FREE_S:
            return shot, balls
    raise RuntimeError(f"no {preset} shot found in 1000 draws")  # not seen: most draws qualify


def sample_contact(rng: np.random.Generator, preset: str, params: BallParams | None = None,
                   table: Table = Table()) -> tuple[Shot, BallParams, np.ndarray]:
    """Friction as the sampler draws it (mu_s 0.1-0.3, mu_r 0.005-0.02) when
    ``params`` is None, then :func:`sample_contact_shot`: ``(shot, params, balls)``."""
    if params is None:
        params = BallParams(mu_s=float(rng.uniform(0.1, 0.3)), mu_r=float(rng.uniform(0.005, 0.02)))
    shot, balls = sample_contact_shot(rng, preset, params, table)
    return shot, params, balls


def contact_render(balls: np.ndarray) -> dict:
    """The ``render`` keys of a contact scene: contacts on, the other balls listed."""
    return {"contacts": True, "balls": [{"x": float(b[0]), "y": float(b[1])} for b in balls]}
