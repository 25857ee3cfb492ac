"""The colour Cramer-Rao bound of a realistic look (track.bound), on the
renderer's own frames: it draws the ball through the renderer's private
drawing code, so a change there must keep it working."""

import numpy as np
import pytest

from cuespin.data_gen.sampler import sample_scenes
from cuespin.render.draw import FrameRenderer
from cuespin.track.bound import centroid_crb_realistic


@pytest.mark.parametrize("markings", ["none", "dots"])
def test_realistic_bound_of_a_moving_frame(markings):
    scene = sample_scenes(3, 0, look="realistic", codec="FFV1")[2]
    scene.render.update(markings=markings, max_duration=0.5)
    r = FrameRenderer(scene)
    k = int(np.flatnonzero(r.truth.t > scene.truth.t0 + 0.05)[0])
    b = centroid_crb_realistic(r, k, False)
    # A 1e-3-1e-1 px bound: the centroid of a ~10-px ball at noise 1-8 per
    # channel (benchmarks/track.py realistic: 0.003-0.017 px per look).
    assert b.shape == (2,) and np.all(np.isfinite(b)) and np.all((b > 1e-4) & (b < 0.1)), b


@pytest.mark.parametrize("markings", ["none", "dots"])
def test_markings_of_unknown_pattern_carry_no_information(markings):
    # A tracker that does not know the dots' pattern cannot use their edges:
    # the default bound leaves the pixels they change out (each a free
    # level), so it is at least the bound of one that knows the pattern and
    # only not its orientation, and the same on an unmarked ball.
    from cuespin.track.bound import realistic_image_jacobian

    scene = sample_scenes(3, 0, look="realistic", codec="FFV1")[2]
    scene.render.update(markings=markings, max_duration=0.5, specular=0.0)
    r = FrameRenderer(scene)
    k = int(np.flatnonzero(r.truth.t > scene.truth.t0 + 0.05)[0])
    unknown, known = centroid_crb_realistic(r, k, False), centroid_crb_realistic(r, k, False, pattern_known=True)
    J, names = realistic_image_jacobian(r, k, False)
    dropped = int(np.sum(~J.any(axis=(1, 2))))
    if markings == "none":
        np.testing.assert_allclose(unknown, known, rtol=1e-9)
    else:
        assert "turn_x" not in names and "turn_x" in realistic_image_jacobian(r, k, False, True)[1]
        assert dropped > 0 and np.all(unknown >= known * (1 - 1e-6)), (unknown, known)
