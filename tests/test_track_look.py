"""The tracker's look decision (disc or shaded) on simulated ball patches.

Each decision pools ``LOOK_FRAMES`` frames, as the tracker does; 34
decisions (408 patches) per kind of ball.  A uniform ball whose image is the
model's must be fitted as a disc (false "shaded" at most the nominal
``LOOK_P`` plus its binomial margin: none of 34); a shaded ball as shaded.
A uniform ball smeared as a codec smears it is fitted as shaded, on purpose
(see ``LOOK_P``): the test pins that down, so a change to it is deliberate.
"""

import cv2
import numpy as np

from cuespin.render.draw import disc_coverage
from cuespin.track.model import fit_disc, streak_model
from cuespin.track.tracker import LOOK_FRAMES, look_vote, shaded_look

R, FELT, BALL, NOISE = 10.0, 80.0, 200.0, 3.0
HALF = int(np.ceil(R + 3))
N_DECISIONS = 34


def patch(rng, kind):
    """A ball's patch (grey levels), its felt, top-left pixel and true centre."""
    c = np.array([50.0, 40.0]) + rng.uniform(-0.5, 0.5, 2)
    u0, v0 = int(round(c[0])) - HALF, int(round(c[1])) - HALF
    n = 2 * HALF + 1
    felt = np.full((n, n), FELT)
    if kind == "shaded":  # lit from the upper left, darker rim: the model's own look
        img, _ = streak_model(c, np.zeros(2), BALL, felt, R, u0, v0, np.zeros(1), (-40.0, -40.0, -30.0))
        img = img + felt
    else:
        img = felt + (BALL - FELT) * disc_coverage(c[0], c[1], R, u0, v0, n, n)
    if kind == "smeared":  # a codec's smear of the edge (chroma at half resolution)
        img = cv2.GaussianBlur(img, (0, 0), 0.7)
    img = np.clip(np.rint(img + NOISE * rng.standard_normal(img.shape)), 0, 255)
    return img, felt, u0, v0, c


def decisions(kind, seed=0):
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(N_DECISIONS):
        votes = []
        while len(votes) < LOOK_FRAMES:
            img, felt, u0, v0, c = patch(rng, kind)
            start = c + rng.normal(0.0, 0.05, 2)  # the moments' start is this close
            s = fit_disc(img, felt, u0, v0, start, R, BALL, shade=True)
            d = fit_disc(img, felt, u0, v0, s.c, R, BALL)
            if s and d:
                votes.append(look_vote(d, s, img.size))
        out.append(shaded_look(votes))
    return np.array(out)


def test_uniform_ball_is_fitted_as_a_disc():
    # Nominal false rate LOOK_P = 0.1% a decision: 0.03 expected in 34.
    assert decisions("exact").sum() <= 1


def test_shaded_ball_is_fitted_as_shaded():
    assert decisions("shaded").mean() >= 1 - 1 / N_DECISIONS


def test_codec_smeared_uniform_ball_is_fitted_as_shaded():
    # Measured: 34 of 34 (the smear's misfit passes the chi-square test).
    assert decisions("smeared").mean() >= 1 - 1 / N_DECISIONS
