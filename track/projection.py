"""From the fitted image of the ball to the projection of its centre.

The tracker fits a centrally symmetric model to the ball's image (the disc,
or under perspective the ellipse of the ball's local outline,
:mod:`cuespin.track.outline`), so what it locates is the centre of the
silhouette.  Under perspective the sphere's silhouette is
an ellipse (through a lens, nearly one) whose centre is not the image of the
ball's centre: the silhouette's centroid lies 0.03-0.3 px from it on a
1280 x 720 view from 1.5-3 m tilted up to 15 degrees (up to 0.7 px with a
wide lens; docs/calibration.md section 7).  The camera knows that offset at
every table position (:meth:`~cuespin.physics.camera.Camera.silhouette_centroid_offset`),
so it is taken off here; for a top-down similarity it is zero.
"""

from __future__ import annotations

import numpy as np

from cuespin.track.outline import is_similarity

# Vertices of the silhouette polygon: its centroid converges as 1/n^2
# (720 vertices: 1e-4 px on a 20-px ball), so 256 keep it within 1e-3 px.
OUTLINE_VERTICES = 256
# The offset varies by under 1e-3 px per px of position on the views above,
# so one fixed-point step from the fitted centre is within 1e-6 px; two are
# taken for margin.
FIXED_POINT_STEPS = 2


def projected_centres(camera, uv_fit, R: float) -> np.ndarray:
    """Pixels of the ball's projected centre from the fitted silhouette centres.

    Parameters
    ----------
    camera : Camera
        The scene's camera.
    uv_fit : ndarray, shape (n, 2)
        Centres of the ball's image as the tracker fitted them (px), finite.
    R : float
        Ball radius (m).

    Returns
    -------
    ndarray, shape (n, 2)
        ``uv_fit`` less the silhouette's centroid offset at each position (px).
    """
    uv_fit = np.asarray(uv_fit, dtype=float)
    if len(uv_fit) == 0:
        return uv_fit.copy()
    uv = uv_fit.copy()
    if is_similarity(camera):  # the same disc everywhere: no offset (the polygons' sums give ~1e-10 px)
        return uv
    for _ in range(FIXED_POINT_STEPS):
        off = camera.silhouette_centroid_offset(camera.to_table(uv), R, OUTLINE_VERTICES)
        uv = uv_fit - off
    return uv
