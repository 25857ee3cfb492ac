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
