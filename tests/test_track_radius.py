"""The ball's radius over the image (track/radius.py): the search, the background
learner and the moments start sized by the ball where it is (issue 12, item 3).

The camera of these tests is the steepest the issue allows with a pincushion
lens (1.5 m, 15 degrees, k1 +0.25, 1280 x 720): the ball is 8.8 px at the far
side of the table and 18 px at the near corners, where the image centre's
radius is 8.7.
"""

import sys
from pathlib import Path

import numpy as np
import pytest

from cuespin.physics.camera import default_camera
from cuespin.track.background import Background, ball_wide
from cuespin.track.outline import local_outline
from cuespin.track.radius import RadiusMap
from cuespin.track.tracker import OK, TWO_BLOBS, BallTracker
from cuespin.track.video import search_mask

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from perspective import scene_for  # noqa: E402


def steep_scene(seed=0, **kw):
    return scene_for(seed, 1.5, 15.0, 0.25, 2.0, **kw)


def centre_radius(cam, R):
    return R * cam.px_per_m(cam.to_table([[cam.width / 2, cam.height / 2]])[0])


def test_radius_map_is_the_outlines_size():
    """The map's bilinear radius within 0.5% of the camera's outline's
    equal-area radius anywhere on the playing surface (measured: 0.2%), its
    scales spanning it; a similarity camera keeps one radius and one band."""
    scene = steep_scene()
    cam, R = scene.camera, scene.physics.R
    mask = search_mask(cam, scene.table, R, (cam.height, cam.width))
    radii = RadiusMap((cam.height, cam.width), centre_radius(cam, R), cam, R, region=mask)
    assert radii.r_max / radii.r_min > 2.0
    vs, us = np.nonzero(mask)
    pick = np.random.default_rng(0).choice(len(us), 200, replace=False)
    for u, v in zip(us[pick], vs[pick]):
        exact = local_outline(cam, (u, v), R).radius
        assert abs(radii.at((u, v)) / exact - 1) < 5e-3
        assert abs(radii.image()[v, u] / exact - 1) < 5e-3
    assert radii.scales[0] <= radii.r_min * 1.05 and radii.scales[-1] >= radii.r_max / 1.05
    # The bands partition the surface.
    total = np.zeros(mask.shape, int)
    for _, _, (v0, v1, u0, u1), on in radii.bands(mask):
        total[v0:v1, u0:u1] += on
    assert np.array_equal(total, mask.astype(int))

    flat = RadiusMap((640, 1280), 14.2875, default_camera(), R)
    assert flat.constant and flat.scales == (14.2875,) and flat.at((3.0, 600.0)) == 14.2875
    assert [b[1:] for b in flat.bands()] == [(14.2875, (0, 640, 0, 1280), None)]


def one_frame(scene, k, seed=1):
    """Frame ``k`` of the plain look (noise 2) built from the renderer's exact
    coverage, and the background it was drawn on."""
    from cuespin.render import FrameRenderer

    fr = FrameRenderer(scene)
    s = fr.settings
    cov, u0, v0 = fr.ball_patch(k)
    img = fr.background.astype(float)
    h, w = cov.shape
    img[v0:v0 + h, u0:u0 + w] += (s["ball_grey"] - img[v0:v0 + h, u0:u0 + w]) * cov
    frame = np.clip(np.rint(img + np.random.default_rng(seed).normal(0, s["noise_sigma"], img.shape)), 0, 255)
    contrast = s["ball_grey"] - s["felt_grey"]
    bg = Background(image=fr.background.astype(np.float32), sigma=s["noise_sigma"], polarity=int(np.sign(contrast)),
                    contrast=abs(contrast), n_samples=9, path_pixels=0, weak_samples=np.zeros(9, bool))
    return frame.astype(np.uint8), bg, fr.truth.uvc[k]


@pytest.mark.parametrize("k", [0, 60])
def test_search_peaks_on_a_ball_larger_than_the_centres(k):
    """The resting ball near the camera (14.2 px, 1.6x the centre's 8.7;
    frame 60: 11.7 px) is found within 1 px of its centre by the full
    search (measured 0.24, 0.48 px); with the centre's radius alone the
    filter peaked on the ball's rim, 11 px off and as two blobs at rest
    (measured: frame 0 two blobs, frame 60 5.7 px off)."""
    scene = steep_scene()
    cam, R = scene.camera, scene.physics.R
    frame, bg, truth = one_frame(scene, k)
    mask = search_mask(cam, scene.table, R, (cam.height, cam.width))
    r0 = centre_radius(cam, R)
    radii = RadiusMap((cam.height, cam.width), r0, cam, R, region=mask)
    loc, status = BallTracker(bg, r0, 0.0, search_mask=mask, camera=cam, R=R, radii=radii)._full_search(frame)
    assert status == OK and np.hypot(*(loc - truth)) < 1.0
    old, old_status = BallTracker(bg, r0, 0.0, search_mask=mask, camera=cam, R=R)._full_search(frame)
    assert old_status == TWO_BLOBS or np.hypot(*(old - truth)) > 3.0


def test_ball_wide_takes_the_local_radius():
    """Near the camera a cue's strip (a quarter of the near ball's width, but
    wider than 0.6 of the centre's radius) is not ball-wide; the near ball is."""
    scene = steep_scene()
    cam, R = scene.camera, scene.physics.R
    shape = (cam.height, cam.width)
    r0 = centre_radius(cam, R)
    radii = RadiusMap(shape, r0, cam, R)
    near = np.array(np.unravel_index(np.argmax(radii.image()), shape))[::-1]  # (u, v)
    near = near + np.sign(np.array([cam.width, cam.height]) / 2 - near) * 60  # inside the frame
    r_near = radii.at(near)
    assert r_near > 1.7 * r0
    vv, uu = np.mgrid[:shape[0], :shape[1]]
    strip = (np.abs(vv - near[1]) <= 0.5 * 1.1 * r_near / 2) & (np.abs(uu - near[0]) < 6 * r_near)
    disc = np.hypot(uu - near[0], vv - near[1]) <= 0.95 * r_near
    assert ball_wide(strip, r0).any()          # the centre's radius takes the strip for a ball
    assert not ball_wide(strip, radii).any()
    assert ball_wide(disc, radii).sum() > 0.9 * disc.sum()


@pytest.mark.slow
def test_steep_view_resting_ball_tracked_in_every_frame(tmp_path):
    """A rendered shot (FFV1 file, 0.5 s at 120 fps) struck near the camera,
    where the ball is 1.6x the image centre's size: found in every frame it
    is in view, never reported as two blobs, its table-metre error within
    1.3x the silhouette's Cramer-Rao bound and within its stated errors.
    Before the radius map the resting ball was two blobs in 43 of the first
    60 frames.  Measured: error / bound 1.10 (rest 1.13, moving 1.10), err/se
    0.73: conservative, since the look learnt on this resting ball is the
    shaded one (pooled chi-square 75.8 against 68.0 on 36 dof: the ellipse
    misfits the silhouette through k1 +0.25 near the corner a little, and
    the shaded fit's clustered sandwich states 1.5x the bound)."""
    from perspective import bounds

    from cuespin.render import FrameRenderer, render_video
    from cuespin.track.video import track_video

    scene = steep_scene(seconds=0.5)
    video = tmp_path / "steep.avi"
    truth = render_video(scene, video)
    res = track_video(video, scene)
    cam = scene.camera
    size = np.array([cam.width, cam.height])
    assert np.all((truth.uvc > 20) & (truth.uvc < size - 20))  # in view throughout (the ball: up to 18 px)
    assert (res.status == TWO_BLOBS).sum() == 0, res.status_counts()
    assert res.ok.all(), res.status_counts()
    frames = np.arange(len(res.t))
    true_xy = cam.to_table(truth.uvc)
    err = res.xy - true_xy
    cov_m = cam.cov_to_table(res.xy, res.cov_px)
    z = err / np.sqrt(np.diagonal(cov_m, axis1=1, axis2=2))
    bound = np.sqrt(np.mean(np.diagonal(bounds(scene, FrameRenderer(scene), frames, true_xy), axis1=1, axis2=2)))
    print(f"error/bound {np.sqrt(np.mean(err**2)) / bound:.3f}, err/se {np.sqrt(np.mean(z**2)):.3f}")
    assert np.sqrt(np.mean(err**2)) < 1.3 * bound
    assert 0.65 < np.sqrt(np.mean(z**2)) < 1.25
