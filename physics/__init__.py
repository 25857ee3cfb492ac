"""The paper's forward model: the one source of truth for the ball's motion."""

from cuespin.physics.motion import (BallParams, Phases, Shot, State, contact_velocity, cross,
                            evaluate, kinetic_energy, phases, positions, rolling_deceleration, z_cross)
from cuespin.physics.parabola import Parabola, sliding_parabola
from cuespin.physics.straight import StraightMotion, is_straight, straight_case, straight_motion

__all__ = [
    "BallParams", "Phases", "Shot", "State", "contact_velocity", "cross", "evaluate",
    "kinetic_energy", "phases", "positions", "rolling_deceleration", "z_cross", "Parabola", "sliding_parabola",
    "StraightMotion", "is_straight", "straight_case", "straight_motion",
]
