"""The renderer: exact disc coverage, centroid truth, noise, codecs, sidecar."""

import cv2
import numpy as np
import pytest

from cuespin.data_gen.sampler import make_scene, sample_scene, sample_shot
from cuespin.physics import positions
from cuespin.render import FrameRenderer, disc_coverage, read_truth_csv, render_video, truth_path
from cuespin.render import noise as nz
from cuespin.render.draw import ALIAS_MAX_SIGMA, BYTE_NOISE_SIGMA, AliasNoise, ByteNoise, noise_lut
from cuespin.render.noise import noise_bytes, noise_values

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
    assert list(side) == ["frame", "t", "u_px", "v_px", "x_m", "y_m", "uc_px", "vc_px"]
    np.testing.assert_array_equal(side["frame"], np.arange(len(frames)))
    np.testing.assert_allclose(side["t"], np.arange(len(frames)) / 60.0, rtol=0, atol=1e-15)
    xy = positions(scene.truth, scene.physics, side["t"])
    np.testing.assert_allclose(np.c_[side["x_m"], side["y_m"]], xy, atol=1e-15)
    np.testing.assert_allclose(np.c_[side["u_px"], side["v_px"]], truth.uv, atol=1e-12)
    # Top-down: the projected centre is the silhouette's centroid.
    np.testing.assert_allclose(np.c_[side["uc_px"], side["vc_px"]], truth.uv, atol=1e-12)


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


# --- the realistic look ----------------------------------------------------

def realistic(seed=3, preset="case3", **over):
    """A sampled realistic scene with some render keys overridden."""
    from cuespin.physics.scene import Scene

    sc = sample_scene(seed, preset, fps=over.pop("fps", 120.0), look="realistic",
                      blur=over.pop("blur", True), noise=over.pop("noise", None))
    render = dict(sc.render)
    render.update(over)
    return Scene(physics=sc.physics, camera=sc.camera, table=sc.table, render=render, truth=sc.truth)


def test_realistic_frames_are_colour_with_rails_in_view():
    scene = realistic(noise=3.0)
    r = FrameRenderer(scene, n_frames=3)
    f = next(r.frames())
    assert f.shape == (scene.camera.height, scene.camera.width, 3) and f.dtype == np.uint8
    # The cloth has the felt's colour, the frame's corner is outside the table.
    felt = np.asarray(scene.render["felt_colour"])
    mid = r.background[scene.camera.height // 2 - 5:scene.camera.height // 2 + 5,
                       scene.camera.width // 2 - 5:scene.camera.width // 2 + 5].reshape(-1, 3)
    ramp = 1 + scene.render["ramp"]
    assert np.all(np.abs(mid.mean(0) - felt) <= felt * (ramp - 1) / 2 + 6 * scene.render["texture"] * felt + 2)
    assert np.abs(r.background[2, 2].astype(float) - felt).max() > 20


@pytest.mark.parametrize("exposure_blur", [False, True])
def test_realistic_silhouette_centroid_equals_truth(exposure_blur):
    # Flat shading (ambient 1, no highlight, no markings, no texture or ramp):
    # the image is the exact coverage times the ball's colour, then the lens
    # PSF, which keeps centroids: the centroid per channel is the truth.
    scene = realistic(blur=exposure_blur, ambient=1.0, specular=0.0, markings="none",
                      texture=0.0, ramp=0.0, noise_sigma=0.0, cue=False, balls=[])
    r = FrameRenderer(scene)
    bg = r.background.astype(float)
    rng = np.random.default_rng(0)
    moving = np.flatnonzero(r.truth.t > scene.truth.t0)[::9][:12]
    for k in moving:
        # The drawing itself (before 8 bits): pixel integration's own error,
        # measured max 1.3e-3 px.
        d, u0, v0 = r._ball_delta(k)
        for c in range(3):
            assert np.abs(centroid(d[..., c]) + [u0, v0] - r.truth.uv[k]).max() < CENTROID_TOL_PX
        # The 8-bit frame: a 7.5-px ball on 100 levels of contrast per
        # channel; measured max 0.0155 px on one channel, all channels
        # together within the plain look's tolerance.
        q = r.render(k, rng).astype(float) - bg
        assert np.abs(centroid(q.sum(-1)) - r.truth.uv[k]).max() < QUANTISED_CENTROID_TOL_PX


def test_realistic_noise_is_independent_per_channel():
    scene = realistic(noise=4.0, cue=False)
    r = FrameRenderer(scene, n_frames=2)
    f = next(r.frames(seed=3)).astype(float) - r.background
    e = f[200:300, 300:500].reshape(-1, 3)
    assert e.std(0) == pytest.approx(np.full(3, np.sqrt(16 + 1 / 12)), rel=0.05)
    rho = np.corrcoef(e.T)
    assert np.abs(rho[np.triu_indices(3, 1)]).max() < 0.03


@pytest.mark.parametrize("sigma", [0.5, 2.0, 5.0, 8.0, ALIAS_MAX_SIGMA])
def test_alias_noise_draws_the_tables_exact_law(sigma):
    # Every (first byte, second byte) pair once: the drawn values' counts
    # are the 16-bit table's counts exactly.
    an = AliasNoise(sigma)
    hi, lo = np.meshgrid(np.arange(256), np.arange(256), indexing="ij")
    n = noise_values(an.tables, hi.ravel(), lo.ravel())
    assert np.array_equal(np.sort(n), np.sort(noise_lut(sigma)))
    # A frame is clip(img + n) of its stream's bytes, saturating like the sensor's 8 bits.
    for level in (2, 128, 250):
        img = np.full((256, 256), level, np.uint8)
        b, c = noise_bytes(77, img.size, True)
        want = np.clip(level + noise_values(an.tables, b, c).reshape(img.shape), 0, 255)
        assert np.array_equal(an.add_to(img, Word(77)), want)


class Word:
    """A generator stand-in whose one raw word (a frame's seed) is ``w``."""

    def __init__(self, w):
        class bit_generator:
            @staticmethod
            def random_raw():
                return np.uint64(w)
        self.bit_generator = bit_generator


@pytest.mark.parametrize("sigma", [BYTE_NOISE_SIGMA[0], 1.0, 1.5, 2.0, 3.0, 5.0, 8.0, 15.0, BYTE_NOISE_SIGMA[1]])
def test_byte_noise_law_has_the_exact_laws_mean_and_variance(sigma):
    # The realistic look's noise: 256 equally likely integers whose variance
    # is the exact law's (round(sigma z)) within 1.5% (measured on a 0.05
    # grid: at most 1.34% below sigma 3, 0.44% from 3 to 40), symmetric,
    # kurtosis near a Gaussian's.
    bn = ByteNoise(sigma)
    exact = noise_lut(sigma).astype(float)
    v = bn.table.astype(float)
    assert len(v) == 256 and v.mean() == 0.0 and np.array_equal(np.sort(v), np.sort(-v))
    assert abs(v.var() / exact.var() - 1) < (0.015 if sigma < 3 else 0.005)
    assert 2.7 < ((v - v.mean()) ** 4).mean() / v.var() ** 2 < 3.1
    assert np.abs(v).max() <= 127
    # The kernel's tables draw the table: byte b -> table[b].
    assert np.array_equal(noise_values(bn.tables, np.arange(256), None), bn.table)
    for level in (2, 128, 250):
        img = np.full((48, 64, 3), level, np.uint8)
        b, _ = noise_bytes(5, img.size, False)
        want = np.clip(level + bn.table[b].reshape(img.shape), 0, 255)
        assert np.array_equal(bn.add_to(img, Word(5)), want)


@pytest.mark.parametrize("two", [False, True])
def test_compiled_noise_is_the_reference_bit_for_bit(two):
    # The compiled kernel (AVX-512 VBMI) and the OpenCV fallback against the
    # numpy definition: every grey level, saturation at both ends, a size
    # that is no multiple of 64 (the padded last chunk), several seeds.
    tables = AliasNoise(6.0).tables if two else ByteNoise(6.0).tables
    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, (123, 77, 3)).astype(np.uint8)
    img.reshape(-1)[:512] = np.repeat(np.arange(256), 2)
    for seed in (0, 1, 2**63 + 12345, 2**64 - 1):
        ref = nz.add_noise(img, tables, seed, two, compiled=False)
        assert np.array_equal(nz.add_noise_opencv(img, tables, seed, two), ref)
        out = np.empty_like(img)
        assert nz.add_noise(img, tables, seed, two, out=out) is out and np.array_equal(out, ref)
    if not two:
        # The portable kernel (any vector ISA) of a one-byte law, where it compiles.
        for sigma in (0.5, 2.0, 6.0):
            t = ByteNoise(sigma).tables
            fn = nz.count_kernel(t)
            if fn is not None:
                for seed in (3, 2**64 - 1):
                    assert np.array_equal(nz.run_kernel(fn, img, t, seed, False),
                                          nz.add_noise_reference(img, t, seed, False))
    if nz.kernel(two) is None:
        pytest.skip("no AVX-512 VBMI noise kernel on this CPU (other kernels draw the same frames)")


def test_noise_stream_bytes_are_uniform_and_independent():
    # The SplitMix64 bytes a frame reads: uniform, and the pairs of
    # neighbouring bytes (within a word, across words, 8 words apart: the
    # same byte of the next word) independent: chi-square on 16 x 16 cells
    # of the high nibbles, 255 degrees of freedom, 2.76 M pairs (one frame);
    # 400 is its 1e-8 quantile, an honest test that a broken stream fails by far.
    b, _ = noise_bytes(2026, 1280 * 720 * 3, False)
    b = b.astype(np.int64)
    counts = np.bincount(b, minlength=256)
    e = b.size / 256
    assert ((counts - e) ** 2 / e).sum() < 400
    for lag in (1, 8, 64, 3840):
        pair = (b[:-lag] >> 4) * 16 + (b[lag:] >> 4)
        c = np.bincount(pair, minlength=256)
        e = pair.size / 256
        assert ((c - e) ** 2 / e).sum() < 400, lag


def test_byte_noise_frames_are_fresh_and_seeded():
    bn = ByteNoise(4.0)
    img = np.full((360, 640, 3), 100, np.uint8)
    rng = np.random.default_rng(5)
    a, b = (bn.add_to(img, rng).astype(float) - 100 for _ in range(2))
    # Standard error of a correlation over 691 200 values: 0.0012.
    assert abs(np.corrcoef(a.ravel(), b.ravel())[0, 1]) < 0.01              # frames independent
    c = a.reshape(-1, 3)
    assert np.abs(np.corrcoef(c.T)[np.triu_indices(3, 1)]).max() < 0.01     # channels too
    assert abs(np.corrcoef(a[:, :-1].ravel(), a[:, 1:].ravel())[0, 1]) < 0.01  # neighbours too
    assert abs(np.corrcoef(a[:-1].ravel(), a[1:].ravel())[0, 1]) < 0.01      # rows too
    assert a.std() == pytest.approx(np.sqrt(bn.table.var()), rel=0.01)
    assert abs(a.mean()) < 0.03                                              # se 0.005
    again = bn.add_to(img, np.random.default_rng(5)).astype(float) - 100
    assert np.array_equal(again, a)


def test_orientation_of_a_rolling_ball_turns_by_distance_over_R():
    from cuespin.physics import phases
    from cuespin.render.draw import ball_motion
    from cuespin.render.look import Orientation

    shot, params = sample_shot(0, "case4")          # rolls from the strike
    scene = make_scene(shot, params)
    motion = ball_motion(scene)
    ph = phases(shot, params)
    t = np.linspace(shot.t0, min(ph.t2, shot.t0 + 1.0), 7)
    rot = Orientation(lambda tt: motion(tt).w, 0.0, float(t[-1]))(t)
    dist = np.hypot(*(motion(t).x - shot.x0).T)
    ang = np.arccos(np.clip((np.trace(rot, axis1=1, axis2=2) - 1) / 2, -1, 1))
    # Angle mod 2 pi against distance / R; axis z x v_hat (eq. 12).
    expect = np.mod(dist / params.R + np.pi, 2 * np.pi) - np.pi
    # The integration step straddling the strike's jump in w: up to one step.
    from cuespin.render.look import ORIENT_STEP_RAD
    np.testing.assert_allclose(ang, np.abs(expect), atol=ORIENT_STEP_RAD)
    axis = np.array([-shot.v0[1], shot.v0[0], 0.0]) / np.hypot(*shot.v0)
    k = np.argmax(np.abs(np.sin(ang)))
    A = rot[k]
    w = np.array([A[2, 1] - A[1, 2], A[0, 2] - A[2, 0], A[1, 0] - A[0, 1]]) / (2 * np.sin(ang[k]))
    np.testing.assert_allclose(w * np.sign(np.sin(expect[k])), axis, atol=1e-6)


def test_prefix_product_on_rows_is_the_pairwise_scan_bit_for_bit():
    # The scan on component rows (4, n) does quat_mul's and the norm's
    # arithmetic in their order: the orientation (so every marked frame) is unchanged.
    from cuespin.render.look import prefix_product, quat_from_rotvec, quat_mul

    def on_pairs(dq):                                # the scan as it was, on (n, 4)
        q, d = dq.copy(), 1
        while d < len(q):
            q[d:] = quat_mul(q[d:], q[:-d])
            q /= np.linalg.norm(q, axis=-1, keepdims=True)
            d *= 2
        return q

    rng = np.random.default_rng(5)
    for n in (1, 2, 3, 17, 1000):
        rv = np.c_[rng.normal(0, 0.002, (n, 2)), np.zeros(n)]
        rv[::4] = 0.0
        dq = quat_from_rotvec(rv)
        assert np.array_equal(prefix_product(dq), on_pairs(dq))
    seq = dq[0]
    for k in range(1, 50):
        seq = quat_mul(dq[k], seq)
    np.testing.assert_allclose(prefix_product(dq)[49], seq, atol=1e-12)


def test_table_labels_are_the_layers_masks():
    # Points on every part, near sights and pockets, and on the parts'
    # boundaries exactly: the one-pass labels are table_layers' masks.
    from cuespin.physics.scene import Table
    from cuespin.render import look as lk

    tb = Table()
    L, W, C, R = tb.length, tb.width, lk.CUSHION_WIDTH_M, lk.RAIL_WIDTH_M
    rng = np.random.default_rng(2)
    n = 60000
    s, p = lk.sights(L, W), np.array(lk.pockets(L, W))
    k, j, a = rng.integers(len(s), size=n), rng.integers(len(p), size=n), rng.uniform(0, 2 * np.pi, n)
    rr = p[j, 2] * rng.uniform(0.97, 1.03, n)
    x = np.r_[rng.uniform(-0.3, L + 0.3, n), s[k, 0] + rng.uniform(-0.012, 0.012, n),
              p[j, 0] + rr * np.cos(a), rng.choice([0.0, L, -C, L + C, -C - R, L + C + R, 0.5 * L], n)]
    y = np.r_[rng.uniform(-0.3, W + 0.3, n), s[k, 1] + rng.uniform(-0.012, 0.012, n),
              p[j, 1] + rr * np.sin(a), rng.choice([0.0, W, -C, W + C, -C - R, W + C + R, 0.3], n)]
    layers = lk.table_layers(np.stack([x, y], -1), L, W)
    want = np.zeros(len(x), np.uint8)
    for i, name in enumerate(lk.TABLE_PARTS[1:], start=1):
        want[layers[name]] = i
    got = lk.table_labels(x, y, L, W)
    assert np.array_equal(got, want)
    assert set(np.unique(got)) == set(range(len(lk.TABLE_PARTS)))


@pytest.mark.parametrize("turn, tilt", [(0.0, 0.0), (0.35, 0.0), (-0.2, 2e-4)])
def test_static_labels_computed_only_off_the_cloth_are_the_full_maps(turn, tilt):
    # Through a homography the table's parts are computed only on tiles
    # that are not wholly cloth or wholly beyond the rails: the same labels,
    # and the same table points, as on every pixel.
    from cuespin.physics.scene import Camera, Scene
    from cuespin.render import look as lk

    sc = realistic(noise=0.0, duration=0.05)
    H0 = np.asarray(sc.camera.homography, float)
    c, s = np.cos(turn), np.sin(turn)
    w, h = sc.camera.width, sc.camera.height
    # Turned about the frame's centre, with a little perspective.
    M = np.array([[c, -s, 0.5 * w * (1 - c) + 0.5 * h * s], [s, c, 0.5 * h * (1 - c) - 0.5 * w * s],
                  [tilt, 0.0, 1.0 - tilt * 0.5 * w]])
    cam = Camera(fps=sc.camera.fps, width=w, height=h, homography=tuple(map(tuple, M @ H0)))
    r = FrameRenderer(Scene(physics=sc.physics, camera=cam, table=sc.table, render=sc.render,
                            truth=sc.truth))
    label, at = r._homography_labels(h, w)
    xy = r._cloth_grid(h, w)
    assert np.array_equal(label, lk.table_labels(xy[..., 0], xy[..., 1], sc.table.length, sc.table.width))
    assert (label == 0).mean() > 0.3 and (label == 2).any() and (label == 4).any()
    rows, cols = np.nonzero(label >= 0)
    x, y = at(rows, cols)
    assert np.array_equal(x, xy[..., 0].ravel()) and np.array_equal(y, xy[..., 1].ravel())


def test_mark_mask_skips_only_points_no_mark_covers():
    # The arc cosine is taken only near each mark: the mask is the full
    # formula's bit for bit, on random normals and on normals straddling the
    # far end of each mark's antialiased edge (a + 0.5 / radius) by 1e-9 to 1e-5 rad.
    from cuespin.render import look as lk

    rng = np.random.default_rng(4)
    for kind, radius_px in (("dots", 12.0), ("logo", 7.5), ("dots", 40.0)):
        n = [rng.normal(size=(20000, 3))]
        for c, a in lk.marks(kind):
            e = np.cross(c, [0.3, 0.5, 0.8])
            e /= np.linalg.norm(e)
            ang = a + 0.5 / radius_px + rng.choice([-1, 1], 2000) * 10.0 ** rng.uniform(-9, -5, 2000)
            n.append(np.cos(ang)[:, None] * c + np.sin(ang)[:, None] * e)
        n = np.concatenate(n)
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
        n = n.reshape(-1, 40, 3)
        want = np.zeros(n.shape[:-1])
        for c, a in lk.marks(kind):
            ang = np.arccos(np.clip(n @ c, -1.0, 1.0))
            want = np.maximum(want, np.clip((a - ang) * radius_px + 0.5, 0.0, 1.0))
        got = lk.mark_mask(n, kind, radius_px)
        assert np.array_equal(got, want)
        assert 0 < (got > 0).mean() < 0.5


def test_lookup_colours_is_the_palettes_rows():
    from cuespin.render.draw import lookup_colours

    rng = np.random.default_rng(6)
    palette = rng.uniform(0, 255, (6, 3)).astype(np.float32)
    for shape in ((37, 53), (500, 16)):
        labels = rng.integers(0, 6, shape).astype(np.uint8)
        got = lookup_colours(palette, labels)
        assert got.dtype == np.float32 and np.array_equal(got, palette[labels])


def test_tiles_composited_as_one_stack_are_the_tile_by_tile_sums():
    # Tiles inside the frame go through one stacked pair of OpenCV calls,
    # the frame's partial edge tiles one by one: every pixel is numpy's
    # rint((f + frac) + acc) in float32, clipped, as tile by tile.
    from cuespin.render.draw import TILE_PX as T

    scene = realistic(noise=3.0, cue=False, balls=[])
    r = FrameRenderer(scene, n_frames=2)
    h, w = r.cam.height, r.cam.width
    rng = np.random.default_rng(5)
    rows, cols = -(-h // T), -(-w // T)
    keys = set(zip(rng.integers(0, rows, 40).tolist(), rng.integers(0, cols, 40).tolist()))
    keys |= {(rows - 1, cols - 1), (rows - 1, 0), (0, cols - 1)}
    tiles = {k: rng.normal(0, 40, (T, T, 3)).astype(np.float32) for k in keys}
    r._cue_tiles = lambda k: tiles
    r._ball_delta = lambda k: (None, 0, 0)
    got = r._render_realistic(0, np.random.default_rng(9))
    want = r._noise.add_to(r.background, np.random.default_rng(9))
    for (ty, tx), acc in tiles.items():
        sl = (slice(ty * T, ty * T + T), slice(tx * T, tx * T + T))
        f = want[sl]
        clean = (f.astype(np.float32) + r._frac[sl]) + acc[:f.shape[0], :f.shape[1]]
        want[sl] = np.clip(np.rint(clean), 0, 255).astype(np.uint8)
    assert h % T or w % T, "the scene's frame has no partial edge tiles: the test does not test them"
    assert np.array_equal(got, want)


def test_frames_reusing_the_last_stack_are_drawn_afresh():
    # While ball and cue are still, a frame reuses the last frame's tiles
    # and their stack: each frame is what a fresh renderer draws for it.
    scene = realistic(noise=3.0, cue=False, balls=[], markings="dots")
    r = FrameRenderer(scene, n_frames=4)
    assert scene.truth.t0 > 4 / scene.camera.fps, "the ball moves in these frames: nothing is reused"
    got, stacks = [], []
    for k in range(4):
        got.append(r.render(k, np.random.default_rng(k)))
        stacks.append(r._stack)
    assert all(s is stacks[0] for s in stacks) and stacks[0][6] is not None
    for k in (0, 3):
        assert np.array_equal(FrameRenderer(scene, n_frames=4).render(k, np.random.default_rng(k)), got[k])


def test_markings_move_with_spin():
    # A rolling ball's top moves at 2 v: the marks seen from above run ahead
    # of the centre in the direction of motion, and a still ball's do not move.
    scene = realistic(seed=0, preset="case4", blur=False, ambient=1.0, specular=0.0,
                      markings="dots", mark_colour=[0, 0, 0], ball_colour=[230, 230, 230],
                      noise_sigma=0.0, cue=False, balls=[])
    r = FrameRenderer(scene)
    R = scene.physics.R
    centre = np.array([[200.3, 150.6]])

    def marks_at(t):
        rots = r._orient(np.array([t]))
        cov, colour, iu, iv = r._ball_windows(centre, r.cam.to_table(centre), r._albedo, rots)
        return ((cov[0] > 0.99) * (1 - colour[0].mean(-1) / 230)).astype(np.float64)

    def shift(a, b):
        # Dominant translation of the marks (phase correlation): the
        # centroid of dark pixels would mislead, as a mark growing towards
        # the middle outweighs one shrinking to the rim.
        (du, dv), _ = cv2.phaseCorrelate(a, b)
        return np.array([du, dv])

    t0 = scene.truth.t0
    assert np.array_equal(marks_at(0.2 * t0), marks_at(0.9 * t0))
    for t in t0 + np.linspace(0.02, 0.5, 5):
        st = r.motion(np.array([t]))
        dt = 0.1 * R / np.hypot(*st.v[0])                       # a tenth of a radian
        d = shift(marks_at(t), marks_at(t + dt))
        move_img = scene.camera.jacobian(st.x[0]) @ st.v[0]
        assert np.linalg.norm(d) > 0.2
        assert np.dot(d, move_img) > 0.8 * np.linalg.norm(d) * np.linalg.norm(move_img)


@pytest.mark.parametrize("codec", ["FFV1", "MJPG"])
def test_realistic_render_round_trips_through_a_real_file(tmp_path, codec):
    # A few frames around the strike, cue in view (FFV1 encodes colour
    # noise slowly: 0.18 s a frame here).
    scene = realistic(seed=5, preset="leaves_table", fps=60.0, noise=3.0, codec=codec,
                      duration=0.1, cue=True)
    video = tmp_path / "shot.avi"
    truth = render_video(scene, video)
    frames = list(FrameRenderer(scene).frames())
    back = read_all(video)
    assert len(back) == len(frames) == len(truth.t)
    if codec == "FFV1":
        assert all(np.array_equal(a, b) for a, b in zip(frames, back))
    else:
        # Colour JPEG at OpenCV's default quality (chroma subsampled): mean
        # error per channel measured 2.2-2.4 at noise 3.
        err = np.mean([np.abs(a.astype(float) - b).mean() for a, b in zip(frames, back)])
        assert err < 4.0
    side = read_truth_csv(truth_path(video))
    np.testing.assert_allclose(np.c_[side["uc_px"], side["vc_px"]], truth.uvc, atol=1e-12)


# --- real cameras: tilted, with lens distortion ------------------------------

def through_camera(scene, **cam_kw):
    """``scene`` seen through the steepest camera data_gen samples: 15 deg tilt,
    1.5 m up, k1 = -0.25 (a phone's wide lens), with the scene's fps and exposure."""
    from cuespin.physics.scene import Scene, pinhole_camera

    kw = dict(height_m=1.5, tilt_deg=15.0, size=(800, 450), k1=-0.25, roll_deg=1.0)
    kw.update(cam_kw)
    cam = pinhole_camera(scene.table, fps=scene.camera.fps, exposure_s=scene.camera.exposure_s, **kw)
    return Scene(physics=scene.physics, camera=cam, table=scene.table, render=scene.render,
                 truth=scene.truth)


@pytest.mark.parametrize("exposure_blur", [False, True])
def test_sphere_under_perspective_drawn_to_its_truth(exposure_blur):
    scene = through_camera(realistic(blur=exposure_blur, ambient=1.0, specular=0.0,
                                     markings="none", texture=0.0, ramp=0.0, noise_sigma=0.0,
                                     cue=False, balls=[]))
    r = FrameRenderer(scene)
    assert not r.similar
    cam = scene.camera
    moving = np.flatnonzero(r.truth.t > scene.truth.t0)[::15][:8]
    for k in moving:
        # Drawn silhouette (exact polygon coverage, lens PSF): its centroid is
        # the truth; measured max 6.6e-4 px before 8 bits (pixel integration,
        # as for the disc), 0.004 px after (1280x720, 25 frames).
        d, u0, v0 = r._ball_delta(k)
        for c in range(3):
            assert np.abs(centroid(d[..., c]) + [u0, v0] - r.truth.uv[k]).max() < CENTROID_TOL_PX
        xy = r._xy_nodes[k]
        np.testing.assert_allclose(r.truth.uvc[k], cam.to_pixels(xy).mean(0), atol=1e-9)
        if not exposure_blur:
            # The truth is the camera's own silhouette centroid (720 vertices):
            # OUTLINE_VERTICES=128 is within 1e-4 px of it (measured 1.2e-5).
            off = cam.silhouette_centroid_offset(xy[0])
            np.testing.assert_allclose(r.truth.uv[k] - r.truth.uvc[k], off, atol=1e-4)
    # Under this camera the silhouette's centroid is measurably off the
    # projected centre (what the tracker must estimate).
    assert np.abs(r.truth.uv - r.truth.uvc).max() > 0.01


def test_plain_look_through_a_tilted_camera():
    shot, params = sample_shot(11, "case3")
    scene = through_camera(make_scene(shot, params, fps=120.0, render={"noise_sigma": 0.0}))
    r = FrameRenderer(scene)
    rng = np.random.default_rng(0)
    bg = r.background.astype(float)
    for k in np.flatnonzero(r.truth.t > shot.t0)[::20][:5]:
        f = r.render(k, rng)
        assert f.ndim == 2
        cov, u0, v0 = r.ball_patch(k)
        assert np.abs(centroid(cov) + [u0, v0] - r.truth.uv[k]).max() < CENTROID_TOL_PX
        assert np.abs(centroid(f.astype(float) - bg) - r.truth.uv[k]).max() < QUANTISED_CENTROID_TOL_PX


def test_tilted_realistic_render_has_rails_through_the_lens(tmp_path):
    scene = through_camera(realistic(seed=2, preset="case4", fps=60.0, noise=2.0, codec="FFV1",
                                     duration=0.1, cue=True))
    video = tmp_path / "tilted.avi"
    truth = render_video(scene, video)
    back = read_all(video)
    assert len(back) == len(truth.t) and back[0].shape == (450, 800, 3)
    r = FrameRenderer(scene, n_frames=1)
    # The playing surface's corners, through the lens, are on cloth; just
    # outside the rail the image is not the cloth.
    felt = np.asarray(scene.render["felt_colour"], float)
    L, W = scene.table.length, scene.table.width
    inner = scene.camera.project(np.array([[0.3, 0.3, 0.0], [L - 0.3, W - 0.3, 0.0]]))
    for u, v in np.rint(inner).astype(int):
        assert np.abs(r.background[v, u] - felt).max() < 0.4 * felt.max()
    rail = scene.camera.project(np.array([[L / 2 + 0.2, -0.1, 0.0]]))[0]
    u, v = np.rint(rail).astype(int)
    assert np.abs(r.background[v, u] - felt).max() > 20


def test_bad_look_settings_refused_in_one_line():
    from cuespin.render.draw import render_settings

    for bad, key in (({"look": "fancy"}, "render.look"),
                     ({"look": "realistic", "ball_colour": [1, 2]}, "render.ball_colour"),
                     ({"look": "realistic", "markings": "stripes"}, "render.markings"),
                     ({"look": "realistic", "psf_sigma": -1}, "render.psf_sigma"),
                     ({"look": "realistic", "balls": [{"x": 1}]}, "render.balls")):
        scene = realistic()
        from cuespin.physics.scene import Scene
        s = Scene(physics=scene.physics, camera=scene.camera, table=scene.table, render=bad,
                  truth=scene.truth)
        with pytest.raises(ValueError, match=key.replace(".", r"\.")) as e:
            render_settings(s)
        assert "\n" not in str(e.value)


def test_struck_ball_moves_after_the_contact():
    # A ball_contact shot (render.contacts): the struck ball rests until the
    # contact, then is drawn along its own path; it is not in the static scene.
    from cuespin.physics.contact import scene_trajectory

    scene = sample_scene(2, "ball_contact", fps=60.0, look="realistic", noise=0.0, blur=False)
    r = FrameRenderer(scene)
    assert list(r._struck) == [0]
    tc = scene_trajectory(scene).first_contact.t
    xy, uv, albedo = r._struck[0]
    before = r.truth.t < tc
    rest = np.array([scene.render["balls"][0]["x"], scene.render["balls"][0]["y"]])
    np.testing.assert_allclose(xy[before, 0], np.broadcast_to(rest, xy[before, 0].shape), atol=1e-12)
    assert np.hypot(*(xy[-1, 0] - rest)) > 2 * scene.physics.R
    # Drawn where its path says: the frame differs from the background there.
    k = len(r.truth.t) - 1
    f = r.render(k, np.random.default_rng(0)).astype(float)
    u, v = np.rint(uv[k, 0]).astype(int)
    if 0 <= u < scene.camera.width and 0 <= v < scene.camera.height:
        assert np.abs(f[v, u] - r.background[v, u]).max() > 20
    u, v = np.rint(scene.camera.to_pixels(rest)).astype(int)
    felt = np.asarray(scene.render["felt_colour"], float)
    assert np.abs(r.background[v, u] - felt).max() < 0.5 * felt.max()


def test_plain_look_keeps_its_own_defaults():
    # Keys both looks know (texture: grey levels in the plain look, a
    # relative amount in the realistic one) default per look.
    from cuespin.render.draw import RENDER_DEFAULTS, render_settings
    from cuespin.render.look import LOOK_DEFAULTS

    shot, params = sample_shot(1, "case3")
    plain = render_settings(make_scene(shot, params))
    assert plain["texture"] == RENDER_DEFAULTS["texture"] == 0.0
    assert render_settings(realistic())["texture"] == realistic().render["texture"]
    assert LOOK_DEFAULTS["texture"] != 0.0


@pytest.mark.slow
def test_tracker_states_honest_errors_on_byte_noise(tmp_path):
    """A uniform realistic ball (benchmarks/track.py's realistic shot 5, seed
    0: FFV1, noise 2.6) drawn with the exact law (AliasNoise) and with
    ByteNoise: the tracker's err/se over the moving frames alike and honest
    (measured: 1.18 with the exact law; on 10 shots of every look the two
    laws' err/se and RMSE agreed shot by shot, README)."""
    import pandas as pd

    from cuespin.data_gen.sampler import sample_scenes
    from cuespin.render import draw, render_video
    from cuespin.track.tracker import TrackerConfig
    from cuespin.track.video import track_video

    z = {}
    for law in ("alias", "byte"):
        scene = sample_scenes(6, 0, look="realistic", codec="FFV1")[5]
        scene.render.update(ambient=1.0, specular=0.0, markings="none", psf_sigma=0.0, cue=False, balls=[],
                            max_duration=0.6)
        path = tmp_path / f"{law}.avi"
        old = draw.NOISE_LAW
        try:
            draw.NOISE_LAW = law
            render_video(scene, path)
        finally:
            draw.NOISE_LAW = old
        tr = track_video(path, scene, TrackerConfig(threaded=False))
        truth = pd.read_csv(path.with_suffix(".truth.csv"))
        n = min(tr.n_frames, len(truth))
        tuv = np.c_[truth.uc_px, truth.vc_px][:n]
        moving = tr.ok[:n] & (tr.t[:n] > scene.truth.t0 + 0.02)
        z[law] = np.sqrt(np.mean(((tr.uv[:n] - tuv)[moving] / tr.stderr_px[:n][moving]) ** 2))
    assert 0.8 <= z["byte"] <= 1.35 and abs(z["byte"] / z["alias"] - 1) < 0.2, z


def test_noise_edge_cases_review():
    """A constant negative law is not countable (its thresholds lie past the
    last byte), a negative seed draws what its 64-bit mask draws, and the
    environment override picks an implementation without changing a pixel."""
    import os

    from cuespin.render.noise import NOISE_ENV, add_noise, add_noise_reference, count_thresholds

    assert count_thresholds(np.full(256, -1)) is None
    img = np.full((7, 13, 3), 100, np.uint8)
    tab = np.zeros((3, 256), np.uint8)
    tab[0] = (np.arange(256) % 5 - 2).astype(np.int8).view(np.uint8)
    ref = add_noise_reference(img, tab, -5, False)
    assert np.array_equal(ref, add_noise_reference(img, tab, 2**64 - 5, False))
    assert np.array_equal(ref, add_noise(img, tab, -5, False))
    old = os.environ.get(NOISE_ENV)
    try:
        for choice in ("opencv", "reference", "auto"):
            os.environ[NOISE_ENV] = choice
            assert np.array_equal(ref, add_noise(img, tab, -5, False)), choice
    finally:
        if old is None:
            os.environ.pop(NOISE_ENV, None)
        else:
            os.environ[NOISE_ENV] = old
