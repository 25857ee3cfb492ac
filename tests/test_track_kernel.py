"""The compiled fit (track/kernel.py) against its numpy reference (track/reference.py).

The kernel keeps the reference's arithmetic pixel by pixel; only sums over
pixels and blur nodes are taken in another order.  Measured: the model and
its rows agree to 1e-13 of their size (bit for bit on a sharp disc), fitted
centres to 2e-11 px and stated errors to 5e-12 of themselves, on single
fits and on whole tracks (plain, blurred MJPG, realistic, tilted camera).
The tolerances below are a hundred times those.
"""

import numpy as np
import pytest

from cuespin.track import model, reference, tracker
from cuespin.track.outline import Ellipse
from cuespin.track.tracker import TrackerConfig
from cuespin.track.video import track_video

H = W = 37
U0, V0, R_PX = 500, 283, 14.3
ELLIPSE = Ellipse(((1 / 13.0**2, 0.0008), (0.0008, 1 / 15.0**2)))
MODEL_RTOL = 1e-11   # of the largest value of the model or row
# The compiled and numpy forms sum in different orders (fastmath's
# reassociation): measured, centres within 2e-11 px and stated errors 5e-12
# relative on five tracks, but 6e-10 px and 3.4e-9 on sample_scenes(1, 6,
# realistic, FFV1)'s track after its noise became the byte law (a frame
# whose fit is less well conditioned); held to 30-100 times the largest.
CENTRE_TOL_PX = 2e-8
STDERR_RTOL = 1e-7


SPHERE = model.SphereLook(0.6, 1.0, 40.0)  # the lit sphere's look, the renderer's defaults (light from +u, +v)
SPHERE_PSF = model.SphereLook(0.6, 1.0, 40.0, 0.8)  # the same through a lens's blur (PSF sigma 0.8 px)


@pytest.mark.parametrize("blur", [0.0, 7.0])
@pytest.mark.parametrize("shade", [False, True, "sphere", "sphere_psf"])
@pytest.mark.parametrize("ellipse", [False, True])
def test_model_rows_are_the_references(blur, shade, ellipse):
    rng = np.random.default_rng(3)
    felt = 90.0 + rng.normal(0, 2, (H, W))
    b = blur * np.array([0.8, 0.6])
    taus = model.blur_nodes(np.hypot(*b))
    look = (12.0, -7.0, -20.0) if shade is True else None
    if shade in ("sphere", "sphere_psf"):
        look = np.r_[60.0, 120.0, -5.0, (SPHERE if shade == "sphere" else SPHERE_PSF).geometry()]
    for blur_rows in (False, True):
        args = ([518.27, 301.64], b, 210.0, felt, R_PX, U0, V0, taus, look, blur_rows, ELLIPSE if ellipse else None)
        m, JT = model._model_rows(*args)
        m_ref, JT_ref = reference.model_rows(*args)
        assert m.shape == m_ref.shape and JT.shape == JT_ref.shape
        assert np.abs(m - m_ref).max() <= MODEL_RTOL * np.abs(m_ref).max()
        for row, row_ref in zip(JT, JT_ref):
            assert np.abs(row - row_ref).max() <= MODEL_RTOL * max(np.abs(row_ref).max(), 1.0)


@pytest.mark.parametrize("blur", [0.0, 7.0])
@pytest.mark.parametrize("ellipse", [False, True])
def test_fits_are_the_references(blur, ellipse):
    """Every kind of fit the tracker makes (disc or look, blur fixed or
    fitted, pixels left out or not) on a noisy ball: the same outcome,
    iterations, centre, level, look and stated covariance."""
    rng = np.random.default_rng(5)
    felt = 90.0 + rng.normal(0, 2, (H, W))
    c = np.array([518.31, 301.72])
    b = blur * np.array([0.8, 0.6])
    outline = ELLIPSE if ellipse else None
    img = felt + model.streak_model(c, b, 200.0, felt, R_PX, U0, V0, model.blur_nodes(np.hypot(*b)),
                                    (10.0, -6.0, -15.0), outline=outline)[0]
    img = img + rng.normal(0, 3.0, img.shape)
    n_ok = 0
    for shade in (False, True, SPHERE, SPHERE_PSF):
        for fit_blur in (False, True):
            for valid in (None, rng.random((H, W)) > 0.1):
                kw = dict(b0=1.1 * b, fit_blur=fit_blur, shade=shade, valid=valid, outline=outline)
                f = model.fit_disc(img, felt, U0, V0, c + [0.4, -0.3], R_PX, 170.0, **kw)
                g = reference.fit_disc(img, felt, U0, V0, c + [0.4, -0.3], R_PX, 170.0, **kw)
                assert (f.ok, f.reason, f.n_iter) == (g.ok, g.reason, g.n_iter)
                assert np.abs(f.c - g.c).max() <= CENTRE_TOL_PX
                if f.ok:
                    n_ok += 1
                    assert abs(f.G - g.G) <= 1e-9 * abs(g.G)
                    assert np.all(np.abs(f.stderr - g.stderr) <= STDERR_RTOL * g.stderr)
                    assert np.abs(f.cov - g.cov).max() <= STDERR_RTOL * np.abs(g.cov).max()
                    assert (f.shade is None) == (g.shade is None)
                    if shade:
                        assert np.allclose(f.shade, g.shade, rtol=1e-9, atol=1e-9)
    # A sharp ball's blur is not fitted (a fit of it fails in both forms).
    assert n_ok == (16 if blur else 8)


def test_failed_fits_fail_alike():
    felt = np.full((H, W), 90.0)
    # No ball in the window: the centre's columns are zero, the equations singular.
    args = (felt + np.random.default_rng(1).normal(0, 1, (H, W)), felt, U0, V0, [U0 - 40.0, V0 - 40.0], R_PX, 200.0)
    f, g = model.fit_disc(*args), reference.fit_disc(*args)
    assert not f and (f.reason, f.n_iter) == (g.reason, g.n_iter) == ("singular normal equations", 1)


def _track(path, scene, ref, monkeypatch):
    with monkeypatch.context() as mp:
        if ref:
            mp.setattr(model, "_model_rows", reference.model_rows)
            mp.setattr(tracker, "fit_disc", reference.fit_disc)
        return track_video(path, scene, TrackerConfig(threaded=False))


def assert_same_track(a, b):
    assert np.array_equal(a.status, b.status)
    ok = a.ok
    assert ok.sum() > 20
    assert np.abs(a.uv[ok] - b.uv[ok]).max() <= CENTRE_TOL_PX
    assert np.all(np.abs(a.stderr_px[ok] - b.stderr_px[ok]) <= STDERR_RTOL * b.stderr_px[ok])
    assert a.look_factor == pytest.approx(b.look_factor, rel=1e-9)


def test_plain_track_is_the_references(tmp_path, monkeypatch):
    from cuespin.render import render_video
    from tests.test_track import short_scene

    scene = short_scene(duration=0.3, codec="MJPG")
    video = tmp_path / "plain.avi"
    render_video(scene, video)
    assert_same_track(_track(video, scene, False, monkeypatch), _track(video, scene, True, monkeypatch))


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["blurred", "realistic", "tilted"])
def test_tracks_are_the_references(tmp_path, monkeypatch, kind):
    from cuespin.data_gen.sampler import sample_scenes
    from cuespin.render import render_video
    from tests.test_track import short_scene
    from tests.test_track_outline import tilted_scene

    if kind == "blurred":
        scene = short_scene(blur=True, codec="MJPG")
    elif kind == "realistic":
        scene = sample_scenes(1, 6, look="realistic", codec="FFV1")[0]
        scene.render["max_duration"] = 1.0
    else:
        scene = tilted_scene()
    video = tmp_path / f"{kind}.avi"
    render_video(scene, video)
    assert_same_track(_track(video, scene, False, monkeypatch), _track(video, scene, True, monkeypatch))


def test_kernel_compiles_where_no_cache_can_be_written(tmp_path):
    # A read-only install (no folder numba may cache in): numba refuses
    # cache=True there, and the kernel must compile without it, not raise.
    import subprocess
    import sys
    script = tmp_path / "ro.py"
    script.write_text(
        "import numba.core.caching as c\n"
        "for name in ('InTreeCacheLocator', 'InTreeCacheLocatorFsAgnostic', 'UserWideCacheLocator',\n"
        "             'UserProvidedCacheLocator', 'IPythonCacheLocator', 'ZipCacheLocator'):\n"
        "    if hasattr(c, name):\n"
        "        getattr(c, name).from_function = classmethod(lambda cls, *a, **k: None)\n"
        "from numba import njit\n"
        "try:\n"
        "    njit(cache=True)(lambda x: x)\n"
        "    raise SystemExit('numba still found a cache folder: the test does not test')\n"
        "except RuntimeError:\n"
        "    pass\n"
        "from cuespin.track import kernel\n"
        "print(kernel._disc_arc(0.1, 1.0, 1.0))\n")
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert abs(float(out.stdout) - 0.8852312458335592) < 1e-12
