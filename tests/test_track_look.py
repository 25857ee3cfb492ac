"""The tracker's look decision (disc or shaded) on simulated ball patches.

Each decision pools ``LOOK_FRAMES`` frames, as the tracker does; 34
decisions (408 patches) per kind of ball.  A uniform ball must be fitted as
a disc whether its image is exact or smeared by a codec (misfit that the
chi-square test alone takes for shading: on a lossy codec the shaded
look must also move the centre); a shaded ball must be fitted as shaded.
"""

import cv2
import numpy as np
import pytest

from cuespin.render.draw import disc_coverage
from cuespin.track.model import fit_disc, streak_model
from cuespin.track.tracker import LOOK_FRAMES, look_vote, shaded_look

R, FELT, BALL, NOISE = 10.0, 80.0, 200.0, 3.0
HALF = int(np.ceil(R + 3))
N_DECISIONS = 34


def patch(rng, kind):
    """A ball's patch (grey levels), its top-left pixel and true centre."""
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


def decisions(kind, seed=0, lossless=False):
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
        out.append(shaded_look(votes, lossless))
    return np.array(out)


@pytest.mark.parametrize("kind", ["exact", "smeared"])
def test_uniform_ball_on_a_lossy_codec_is_fitted_as_a_disc(kind):
    # The pooled shift of 12 frames has 1/12 of one frame's variance: a
    # decision against it at 1 stated error is a > 3-sigma event, so any
    # false "shaded" beyond the binomial margin of ~0 (one in 34) is a bug.
    assert decisions(kind).sum() <= 1


@pytest.mark.parametrize("lossless", [False, True])
def test_shaded_ball_is_fitted_as_shaded(lossless):
    # Its lit side moves the disc fit's centre by several stated errors.
    assert decisions("shaded", lossless=lossless).mean() >= 1 - 1 / N_DECISIONS


def test_uniform_ball_on_lossless_video_is_fitted_as_a_disc():
    # Without a codec the chi-square test alone decides: at LOOK_P = 0.1%
    # per decision, none of 34 is expected.
    assert decisions("exact", lossless=True).sum() <= 1
