"""The tracker reports the image of the ball's centre, not its silhouette's centroid (issue 12)."""

import numpy as np

from cuespin.physics.camera import default_camera, pinhole_camera
from cuespin.physics.scene import Table
from cuespin.track.projection import projected_centres

R = 0.028575


def test_silhouette_centres_map_back_to_the_projected_centre():
    cam = pinhole_camera(Table(), height_m=1.5, tilt_deg=15.0, size=(1280, 720), k1=-0.2, fps=120.0, R=R)
    xy = np.random.default_rng(0).uniform([0.1, 0.1], [2.4, 1.2], size=(50, 2))
    centre = cam.to_pixels(xy)
    silhouette = centre + cam.silhouette_centroid_offset(xy, R, 720)
    # The offset this corrects is worth correcting: tenths of a pixel on this view.
    assert np.abs(silhouette - centre).max() > 0.05
    assert np.abs(projected_centres(cam, silhouette, R) - centre).max() < 2e-3  # 256-vertex polygon's own error


def test_top_down_similarity_has_no_offset():
    cam = default_camera()
    uv = cam.to_pixels(np.array([[0.5, 0.3], [2.0, 1.0]]))
    assert np.allclose(projected_centres(cam, uv, R), uv, atol=1e-9)
