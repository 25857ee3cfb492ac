"""The renderer: exact disc coverage, centroid truth, noise, codecs, sidecar."""

import cv2
import numpy as np
import pytest

from cuespin.data_gen.sampler import make_scene, sample_scene, sample_shot
from cuespin.physics import positions
from cuespin.render import FrameRenderer, disc_coverage, read_truth_csv, render_video, truth_path
from cuespin.render.draw import noise_lut

# The requirement for the drawn disc; measured max over 2000 random
# placements, radii 8-20 px: 1.4e-3 px, RMS 4.5e-4 (pixel integration, as on a sensor).
CENTROID_TOL_PX = 0.01
# 8-bit rounding of a noise-free frame moves the centroid further; measured
# max over the frames below: 1.7e-3 px.
QUANTISED_CENTROID_TOL_PX = 0.01


def centroid(img):
    vv, uu = np.mgrid[0:img.shape[0], 0:img.shape[1]]
    return np.array([(img * uu).sum(), (img * vv).sum()]) / img.sum()


def test_disc_coverage_exact_area_and_centroid():
    rng = np.random.default_rng(0)
    worst = 0.0
    for _ in range(2000):
        r = rng.uniform(8, 20)
        c = rng.uniform(25, 26, 2)
        cov = disc_coverage(c[0], c[1], r, 0, 0, 52, 52)
        assert cov.sum() == pytest.approx(np.pi * r * r, rel=1e-12)
        assert cov.min() >= -1e-12 and cov.max() <= 1 + 1e-12
        worst = max(worst, np.abs(centroid(cov) - c).max())
    assert worst < CENTROID_TOL_PX


def test_partial_pixel_coverage_matches_supersampling():
    # Independent check of the analytic area: 400x400 supersampling per pixel.
    cov = disc_coverage(10.3, 9.7, 5.2, 0, 0, 20, 20)
    s = 400
    g = (np.arange(20 * s) + 0.5) / s - 0.5
    inside = ((g[None, :] - 10.3) ** 2 + (g[:, None] - 9.7) ** 2) <= 5.2**2
    ss = inside.reshape(20, s, 20, s).mean(axis=(1, 3))
    assert np.abs(cov - ss).max() < 5e-3  # supersampling's own error ~ 1/s per edge pixel


@pytest.mark.parametrize("exposure_frames", [0.0, 1.0])
def test_rendered_frame_centroid_equals_truth(exposure_frames):
    shot, params = sample_shot(11, "case3")
    fps = 240.0
    scene = make_scene(shot, params, fps=fps, exposure_s=exposure_frames / fps,
                       render={"noise_sigma": 0.0, "gradient": 0.0})
    r = FrameRenderer(scene)
    rng = np.random.default_rng(0)
    bg = r.background.astype(float)
    moving = np.flatnonzero((r.truth.t > shot.t0) & (r.truth.t < shot.t0 + 0.5))[::10]
    for k in moving:
        diff = r.render(k, rng).astype(float) - bg
        assert np.abs(centroid(diff) - r.truth.uv[k]).max() < QUANTISED_CENTROID_TOL_PX


def test_noise_level_and_independence():
    shot, params = sample_shot(2, "case3")
    sigma = 5.0
    scene = make_scene(shot, params, fps=120.0, render={"noise_sigma": sigma, "felt_grey": 100})
    r = FrameRenderer(scene, n_frames=3)
    frames = list(r.frames(seed=1))
    resid = [f[:200, :400].astype(float) - r.background[:200, :400] for f in frames]
    for e in resid:
        # Rounded Gaussian: variance sigma^2 + 1/12.
        assert e.std() == pytest.approx(np.sqrt(sigma**2 + 1 / 12), rel=0.02)
        assert abs(e.mean()) < 0.05
    rho = np.corrcoef(resid[0].ravel(), resid[1].ravel())[0, 1]
    assert abs(rho) < 0.01
    # The LUT draws the law of round(sigma z).
    lut = noise_lut(sigma)
    assert lut.mean() == pytest.approx(0.0, abs=1e-3)
    assert lut.std() == pytest.approx(np.sqrt(sigma**2 + 1 / 12), rel=1e-3)


def test_same_seed_same_frames():
    scene = sample_scene(5, "leaves_table", fps=60.0)
    a = list(FrameRenderer(scene).frames())
    b = list(FrameRenderer(scene).frames())
    assert all(np.array_equal(x, y) for x, y in zip(a, b))


def read_all(path):
    cap = cv2.VideoCapture(str(path))
    out = []
    while True:
        ok, im = cap.read()
        if not ok:
            break
        out.append(im)
    cap.release()
    return out


def test_lossless_video_bit_exact_and_sidecar(tmp_path):
    scene = sample_scene(8, "leaves_table", fps=60.0, noise=4.0, blur=True, codec="FFV1")
    video = tmp_path / "shot.avi"
    truth = render_video(scene, video)
    frames = list(FrameRenderer(scene).frames())
    back = read_all(video)
    assert len(back) == len(frames) == len(truth.t)
    for a, b in zip(frames, back):
        for ch in range(b.shape[2]):
            assert np.array_equal(a, b[:, :, ch])
    side = read_truth_csv(truth_path(video))
    assert list(side) == ["frame", "t", "u_px", "v_px", "x_m", "y_m"]
    np.testing.assert_array_equal(side["frame"], np.arange(len(frames)))
    np.testing.assert_allclose(side["t"], np.arange(len(frames)) / 60.0, rtol=0, atol=1e-15)
    xy = positions(scene.truth, scene.physics, side["t"])
    np.testing.assert_allclose(np.c_[side["x_m"], side["y_m"]], xy, atol=1e-15)
    np.testing.assert_allclose(np.c_[side["u_px"], side["v_px"]], truth.uv, atol=1e-12)


def test_lossy_video_reads_back_frame_for_frame(tmp_path):
    scene = sample_scene(9, "leaves_table", fps=60.0, noise=4.0, codec="MJPG")
    video = tmp_path / "shot.avi"
    render_video(scene, video)
    frames = list(FrameRenderer(scene).frames())
    back = read_all(video)
    assert len(back) == len(frames)
    # JPEG at OpenCV's default quality: mean error well under the noise sigma.
    err = np.mean([np.abs(a.astype(float) - b[:, :, 0]).mean() for a, b in zip(frames, back)])
    assert err < 4.0


def test_video_length_follows_motion():
    # A ball that stops in view: the video runs to the stop plus the tail.
    shot, params = sample_shot(4, "case2")
    scene = make_scene(shot, params, fps=60.0)
    r = FrameRenderer(scene)
    from cuespin.physics import phases
    ph = phases(shot, params)
    assert r.truth.t[-1] == pytest.approx(ph.t2 + 0.25, abs=1 / 60)
    # A ball that leaves: the last frame is the first with the centre off the table.
    scene = sample_scene(4, "leaves_table", fps=120.0)
    r = FrameRenderer(scene)
    inside = scene.table.contains(r.truth.xy)
    assert inside[:-1].all() and not inside[-1]
