"""The ball's local outline under perspective: exact ellipse coverage, and the tracker
fitting it to find the projected centre (issue 12, item 3)."""

import numpy as np
import pytest

from cuespin.physics.camera import default_camera, pinhole_camera
from cuespin.physics.scene import Scene, Table
from cuespin.render.draw import OUTLINE_VERTICES, polygon_coverage_batch
from cuespin.track.model import disc_with_gradient, fit_disc
from cuespin.track.outline import (Ellipse, ellipse_with_gradient, is_similarity, local_outline,
                                   moment_ellipse)
from cuespin.track.projection import projected_centres

R = 0.028575


def random_ellipse(rng):
    a, b, th = rng.uniform(6, 16), rng.uniform(6, 16), rng.uniform(0, np.pi)
    Rm = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    return a, b, Rm, Ellipse(tuple(map(tuple, Rm @ np.diag([a**-2, b**-2]) @ Rm.T)))


def test_ellipse_coverage_is_exact_and_its_derivatives_are_the_edge_chords():
    rng = np.random.default_rng(0)
    for _ in range(6):
        a, b, Rm, ell = random_ellipse(rng)
        c = np.array([40.0, 35.0]) + rng.uniform(-1, 1, 2)
        t = np.linspace(0, 2 * np.pi, 20000, endpoint=False)
        poly = c + (Rm @ np.vstack([a * np.cos(t), b * np.sin(t)])).T
        ref = polygon_coverage_batch(poly[None], np.array([20]), np.array([15]), 41, 41)[0]
        cov, du, dv = ellipse_with_gradient(c[0], c[1], ell, 20, 15, 41, 41)
        # The 20000-gon's own area deficit is 1.6e-8 of the ellipse's: max 1.5e-7 per pixel (measured).
        assert np.abs(cov - ref).max() < 5e-7
        assert abs(cov.sum() - np.pi * a * b) < 1e-9
        e = 1e-5
        fd_u = (ellipse_with_gradient(c[0] + e, c[1], ell, 20, 15, 41, 41)[0]
                - ellipse_with_gradient(c[0] - e, c[1], ell, 20, 15, 41, 41)[0]) / (2 * e)
        fd_v = (ellipse_with_gradient(c[0], c[1] + e, ell, 20, 15, 41, 41)[0]
                - ellipse_with_gradient(c[0], c[1] - e, ell, 20, 15, 41, 41)[0]) / (2 * e)
        assert np.abs(fd_u - du).max() < 1e-6 and np.abs(fd_v - dv).max() < 1e-6
        centre, fitted = moment_ellipse(poly)
        np.testing.assert_allclose(centre, c, atol=1e-9)
        np.testing.assert_allclose(fitted.Qm, ell.Qm, rtol=1e-6)


def test_circle_as_ellipse_is_the_disc():
    ell = Ellipse(((1 / 13.0**2, 0.0), (0.0, 1 / 13.0**2)))
    for x, y in zip(ellipse_with_gradient([20.3, 19.8], 21.1, ell, 3, 4, 35, 35),
                    disc_with_gradient([20.3, 19.8], 21.1, 13.0, 3, 4, 35, 35)):
        np.testing.assert_allclose(x, y, atol=1e-12)


def test_similarity_cameras_keep_the_disc():
    cam = default_camera()
    assert is_similarity(cam)
    assert local_outline(cam, [300.0, 200.0], R, R * 500.0) is None
    assert not is_similarity(pinhole_camera(height_m=2.0, tilt_deg=0.0, R=R))


@pytest.mark.parametrize("height,tilt,k1", [(1.5, 15.0, -0.25), (1.5, 15.0, 0.25), (3.0, 0.0, -0.25)])
def test_noise_free_silhouette_fitted_to_its_projected_centre(height, tilt, k1):
    """The renderer's exact silhouette (128-gon through the lens) at 30 places over the
    table: the outline fit, less the camera's offset, lands on the projected centre.
    Measured max 0.0015 px (1.5 m, 15 deg, k1 -0.25); the disc at the centre's
    scale was 0.10-0.83 px off."""
    cam = pinhole_camera(Table(), height_m=height, tilt_deg=tilt, size=(1280, 720), k1=k1,
                         k2=-0.1 * k1, R=R, roll_deg=1.0)
    r0 = R * cam.px_per_m(cam.to_table([[640.0, 360.0]])[0])
    rng = np.random.default_rng(1)
    worst = 0.0
    for p in np.c_[rng.uniform(0.05, 2.49, 30), rng.uniform(0.05, 1.22, 30)]:
        uvc = cam.to_pixels(p)
        u0, v0 = int(uvc[0]) - 22, int(uvc[1]) - 22
        poly = cam.ball_outline(p, R, OUTLINE_VERTICES)
        felt = np.full((45, 45), 90.0)
        frame = felt + 120.0 * polygon_coverage_batch(poly[None], np.array([u0]), np.array([v0]), 45, 45)[0]
        ell = local_outline(cam, uvc + 0.7, R, r0)  # shape from a prediction a pixel off
        f = fit_disc(frame, felt, u0, v0, uvc + [0.3, -0.2], r0, 200.0, outline=ell)
        assert f, f.reason
        worst = max(worst, np.abs(projected_centres(cam, f.c[None], R)[0] - uvc).max())
    assert worst < 0.003


def tilted_scene(seed=3, noise=2.0, seconds=0.6):
    from cuespin.data_gen.sampler import sample_scene

    sc = sample_scene(seed, preset="random", fps=120.0, noise=noise, look="plain", codec="FFV1")
    cam = pinhole_camera(sc.table, height_m=1.5, tilt_deg=15.0, size=(800, 450), k1=-0.25, k2=0.05,
                         fps=120.0, exposure_s=sc.camera.exposure_s, roll_deg=1.0, R=sc.physics.R)
    return Scene(physics=sc.physics, camera=cam, table=sc.table,
                 render={**sc.render, "max_duration": seconds, "gradient": 0.0}, truth=sc.truth)


def test_tilted_distorted_video_tracked_to_the_projected_centre(tmp_path):
    """A rendered shot seen from 1.5 m, 15 degrees, k1 -0.25 (noise 2, FFV1): the
    tracked centre on the truth's projected centre to within its stated errors,
    and those honest.  Measured over seeds 1-6: RMS 0.0027-0.0036 px (stated
    0.0029-0.0038), err/se 0.74-1.04, largest |err|/se 3.3; seed 3 with the disc
    at the image centre's scale: 0.022 px, err/se 0.24 (a shaded fit's errors)."""
    from cuespin.render import render_video
    from cuespin.track.video import track_video

    scene = tilted_scene()
    video = tmp_path / "tilted.avi"
    truth = render_video(scene, video)
    res = track_video(video, scene)
    moving = res.ok & (truth.t > scene.truth.t0 + 0.02)
    assert moving.sum() >= 30, res.status_counts()
    err = res.uv[moving] - truth.uvc[moving]
    z = err / res.stderr_px[moving]
    assert np.sqrt(np.mean(err**2)) < 0.006  # twice the largest measured
    # RMS of 70 standard normals lies in 0.84-1.16 with 95%; seed 6's 0.74 (26 frames) sets the floor.
    assert 0.7 < np.sqrt(np.mean(z**2)) < 1.3
    assert np.abs(z).max() < 5.0
    # In table metres through the camera: the same errors, stated through cov_to_table.
    cam = scene.camera
    err_m = res.xy[moving] - cam.to_table(truth.uvc[moving])
    cov_m = cam.cov_to_table(res.xy[moving], res.cov_px[moving])
    z_m = err_m / np.sqrt(np.diagonal(cov_m, axis1=1, axis2=2))
    assert 0.7 < np.sqrt(np.mean(z_m**2)) < 1.3


@pytest.mark.slow
@pytest.mark.parametrize("height,tilt,k1", [(3.0, 0.0, -0.25), (2.25, 8.0, -0.12), (1.5, 15.0, 0.25)])
def test_tracked_centre_in_table_metres_at_its_bound(tmp_path, height, tilt, k1):
    """benchmarks/perspective.py's measure on one shot per camera: the tracked
    centre's table-metre error against the silhouette's Cramer-Rao bound, and
    against the tracker's stated errors (through cov_to_table)."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from perspective import bounds, scene_for

    from cuespin.render import FrameRenderer, render_video
    from cuespin.track.video import track_video

    scene = scene_for(0, height, tilt, k1, 2.0)
    video = tmp_path / "p.avi"
    truth = render_video(scene, video)
    res = track_video(video, scene)
    # Found in every frame in view, the resting ball too: the search is sized
    # by the ball where it is (track/radius.py; at 1.5 m, 15 degrees, k1 +0.25
    # the resting ball was two blobs in 43 of 145 frames before).
    size = np.array([scene.camera.width, scene.camera.height])
    in_view = np.all((truth.uvc > 20) & (truth.uvc < size - 20), axis=1)  # 20 px: the largest ball, 18
    assert res.ok[in_view].all(), res.status_counts()
    moving = np.flatnonzero(res.ok & (truth.t > scene.truth.t0 + 0.02))
    assert len(moving) >= 30, res.status_counts()
    cam = scene.camera
    true_xy = cam.to_table(truth.uvc[moving])
    err = res.xy[moving] - true_xy
    cov_m = cam.cov_to_table(res.xy[moving], res.cov_px[moving])
    z = err / np.sqrt(np.diagonal(cov_m, axis1=1, axis2=2))
    bound = np.sqrt(np.mean(np.diagonal(bounds(scene, FrameRenderer(scene), moving, true_xy), axis1=1, axis2=2)))
    assert np.sqrt(np.mean(err**2)) < 1.3 * bound
    assert 0.8 < np.sqrt(np.mean(z**2)) < 1.25
