"""A 4:2:0 video's half-resolution colour in the centre's fit (MJPG)."""
import numpy as np
import pytest

from cuespin.data_gen.sampler import sample_scenes
from cuespin.render.draw import FrameRenderer
from cuespin.render.video import encode_frames
from cuespin.track.colour import chroma_shared, learn_projection
from cuespin.track.misfit import JPEG_CHROMA_VAR, codec_variance
from cuespin.track.model import block_sides, fit_disc, streak_model
from cuespin.track.reader import FrameSource, probe
from cuespin.track.synthetic import write_av
from cuespin.track.tracker import FIT_BLUR_PX


def two_px_term(e, x):
    """Amplitude (px) of the sinusoid of period 2 px in the coordinate ``x`` in the errors ``e``."""
    A = np.c_[np.cos(np.pi * x), np.sin(np.pi * x), np.ones_like(x)]
    coef = np.linalg.lstsq(A, e, rcond=None)[0]
    return float(np.hypot(coef[0], coef[1]))


def mjpg_fits(tmp_path, n=48):
    """benchmarks/track.py realistic seed 0 shot 7 (a yellow ball with a
    highlight on grey felt, 240 fps, 2.3 px a frame): ``n`` frames spread
    over its path through OpenCV's MJPG writer (4:2:0), the felt under each
    window from the frame where the ball is farthest, each ball fitted from
    its true centre on pixels and on the chroma's 2 x 2 blocks.  The
    projection, the video's description, the fits' (ok, error u, v, stated
    error u, v), shape (n, 2, 5), and the true centres (px)."""
    scene = sample_scenes(8, 0, look="realistic", codec="FFV1")[7]
    scene.render.update(cue=False, balls=[], max_duration=0.8, specular=0.5)
    fr = FrameRenderer(scene)
    rng = np.random.default_rng(0)
    ks = np.linspace(20, fr.n_frames - 20, n).round().astype(int)
    raw = [fr.render(int(k), rng) for k in ks]
    path = tmp_path / "shot.avi"
    encode_frames(raw, path, "MJPG", scene.camera.fps, raw[0].shape[1::-1])
    coded = np.stack(list(FrameSource(path, probe(path))))
    uv = np.array([fr._uv_nodes[k].mean(axis=0) for k in ks])
    blur = np.array([fr._uv_nodes[k][-1] - fr._uv_nodes[k][0] for k in ks])
    r = scene.physics.R * scene.camera.px_per_m(uv[n // 2])
    proj = learn_projection(coded, r)
    P = proj.many(coded)
    half = int(np.ceil(r + 0.5 * np.hypot(*blur[0]) + 3))
    out = []
    for j in range(n):
        far = int(np.argmax(np.hypot(*(uv - uv[j]).T)))
        u0, v0 = int(round(uv[j, 0])) - half, int(round(uv[j, 1])) - half
        win = np.s_[v0:v0 + 2 * half + 1, u0:u0 + 2 * half + 1]
        fb = np.hypot(*blur[j]) > FIT_BLUR_PX
        G0 = float(np.median(P[j][win]))
        row = []
        for block in (1, 2):
            f = fit_disc(P[j][win], P[far][win], u0, v0, uv[j], r, G0, b0=blur[j], fit_blur=fb, shade=True,
                         block=block)
            row.append((f.ok, *(f.c - uv[j]), *f.stderr))
        out.append(row)
    return proj, probe(path), np.array(out), uv


@pytest.fixture(scope="module")
def shot7(tmp_path_factory):
    return mjpg_fits(tmp_path_factory.mktemp("chroma"))


# The 2 px term's amplitude, estimated from n errors of residual RMS s,
# is Rayleigh with scale s * sqrt(2 / n) when there is no such term: above
# this many scales with probability 0.001.
RAYLEIGH_999 = np.sqrt(-2 * np.log(0.001))


def test_fit_on_mjpg_models_the_chroma_blocks(shot7):
    # Measured (48 frames): on pixels the error's 2 px term is 0.236 /
    # 0.064 px (u / v; 4.3 / 2.8 Rayleigh scales: present; the realistic
    # benchmark's shot 7 MJPG tracked: 0.247 / 0.065); on the blocks 0.103
    # / 0.049 (2.7 / 2.4 scales: a remainder at p 0.02-0.05, under half the
    # pixels' in u).  On 24 frames (review7) the blocks' 0.068 had looked
    # like none.
    proj, info, out, uv = shot7
    n = len(uv)
    assert info.chroma_block == (2, 2) and proj.luma_blind  # yellow with a highlight: the white-free channel
    assert out[:, :, 0].all()
    amp = np.array([[two_px_term(out[:, b, 1 + a], uv[:, a]) for a in (0, 1)] for b in (0, 1)])
    rms = np.sqrt(np.mean(out[:, :, 1:3] ** 2, axis=0))
    scale = np.sqrt(np.maximum(rms**2 - amp**2 / 2, 0) * 2 / n)
    assert amp[0, 0] > RAYLEIGH_999 * scale[0, 0]  # the pixels' model misses the blocks ...
    assert amp[1, 0] < 0.5 * amp[0, 0]  # ... the blocks' takes most of it out
    assert np.all(rms[1] < rms[0])


def test_blocks_stated_error_on_mjpg(shot7):
    # The blocks' fits' error / stated error (RMS over both axes of the 48
    # frames, 96 values: its standard error ~0.072 of its value): measured
    # 1.33 with the jackknife's sandwich, 2.04 with the fit's own CR1
    # (the same fits with fit_disc(jackknife=False)); on 24 frames 1.09 and
    # 1.65.  The stated error is still ~25% short on this shot (the
    # realistic benchmark's shot 7 MJPG tracked: 1.21; README's Known
    # limits).  Asserted: below CR1's value less 3 of its standard errors
    # (2.04 - 3 x 0.147), and not overstated beyond 3 standard errors of 1.
    out = shot7[2]
    z = out[:, 1, 1:3] / out[:, 1, 3:5]
    assert 1 - 3 * 0.072 < np.sqrt(np.mean(z**2)) < 2.04 - 3 * 0.147


# An RMS of 120 values' standard error: 1 / sqrt(240), 0.065 (0.07 of 1.14).
RMS_120_SE = 1 / np.sqrt(2 * 120)


@pytest.mark.parametrize("block,band", [
    (2, (0.93, 1.35)),
    ((2, 1), (1 - 3 * RMS_120_SE, 1 + 3 * RMS_120_SE)),
    ((4, 1), (1 - 3 * RMS_120_SE, 1 + 3 * RMS_120_SE)),
])
def test_blocks_stated_error_independent_noise(block, band):
    # A disc (r 9 px) seen through 4:2:0 blocks with independent noise per
    # block (4 levels), fitted with the shaded look, whose sandwich clusters
    # 3 x 3 blocks: nothing correlated, yet CR1 stated 1.48 times too little
    # (60 fits; 1.43 over 150), the jackknife 1.14 (1.11 over 150): the
    # clusters' leverage, not a correlation.  Band: 1.14 +- 3 standard
    # errors of an RMS of 120 values (0.07).  On 4:2:2's and 4:1:1's oblong
    # blocks (the disc an ellipse on their grid, model._coarse) the
    # jackknife's err/se over these 60 fits 1.02 (2 x 1) and 0.94 (4 x 1;
    # over 150: 1.02, 0.97); band 1 +- 3 standard errors.
    bx, by = block_sides(block)
    rng = np.random.default_rng(1)
    r, n = 9.0, 36
    z = []
    for _ in range(60):
        c = 18.0 + rng.uniform(-1, 1, 2)
        felt = np.full((n, n), 100.0)
        img = felt + streak_model(c, np.zeros(2), 160.0, felt, r, 0, 0, np.zeros(1))[0].reshape(n, n)
        means = img.reshape(n // by, by, n // bx, bx).mean(axis=(1, 3))
        means += 4.0 * rng.standard_normal(means.shape)
        f = fit_disc(np.repeat(np.repeat(means, by, 0), bx, 1), felt, 0, 0, c + 0.3, r, 150.0, shade=True,
                     block=block)
        assert f.ok
        z.append((f.c - c) / f.stderr)
    assert band[0] < np.sqrt(np.mean(np.square(z))) < band[1]


def test_codec_variance_only_on_an_intra_frame_lossy_codecs_blocks():
    assert codec_variance(lossless=False, inter_frame=False, block=2) == JPEG_CHROMA_VAR > 1
    assert codec_variance(lossless=True, inter_frame=False, block=2) == 1.0  # FFV1 yuv420p: no quantisation
    assert codec_variance(lossless=False, inter_frame=True, block=2) == 1.0  # H.264: recover.mle.INTER_CODEC_ACF
    assert codec_variance(lossless=False, inter_frame=False, block=1) == 1.0  # grey, or a projection seeing luma
    assert codec_variance(lossless=False, inter_frame=False, block=(2, 1)) == JPEG_CHROMA_VAR  # MJPG 4:2:2
    assert codec_variance(lossless=False, inter_frame=False, block=(1, 1)) == 1.0


def test_blocks_stated_error_on_mjpg_with_the_codec_term(shot7):
    # The same 48 frames' blocks' fits with the covariance the tracker
    # states on MJPG (track.misfit.codec_variance from the probed stream):
    # err/se 1.334 without it (test_blocks_stated_error_on_mjpg; u 1.65,
    # v 0.91), 1.108 with it (codecerr12).  Band: 1 +- 3 standard errors of
    # an RMS of 96 values (0.072): 1.334 is above it.
    proj, info, out, uv = shot7
    V = codec_variance(info.lossless, info.inter_frame, 2)
    z = out[:, 1, 1:3] / (out[:, 1, 3:5] * np.sqrt(V))
    assert V == JPEG_CHROMA_VAR
    assert 1 - 3 * 0.072 < np.sqrt(np.mean(z**2)) < 1 + 3 * 0.072


def test_tracker_states_the_codec_term_on_mjpg_blocks(tmp_path, monkeypatch):
    # The tracker, not the test, applies the term (review 9a): a colour shot
    # through OpenCV's MJPG writer (4:2:0, intra-frame, lossy), its
    # projection luma-blind so its fits run on the chroma's blocks, tracked
    # as is and with the term set to 1.  The same centres (the term comes
    # after every rule that reads the covariance), and each frame's stated
    # covariance, the look's factor taken off, JPEG_CHROMA_VAR times the
    # fits' own (to float rounding).
    from cuespin.render.video import encode_frames
    from cuespin.track import misfit
    from cuespin.track.synthetic import colour_frames
    from cuespin.track.video import track_video
    from cuespin.data_gen.sampler import make_scene, sample_shot
    from cuespin.physics import Shot

    shot, params = sample_shot(2, "case3")  # test_track_formats' small scene: 60 frames, a 5.7 px ball
    scene = make_scene(Shot(shot.x0, shot.v0, shot.w0, t0=0.1), params, fps=120.0, px_per_m=200.0,
                       render={"duration": 0.5, "noise_sigma": 0.0})
    video = tmp_path / "v.avi"
    # a yellow ball on grey felt (BGR): 17 grey levels apart, 130 in blue
    frames = list(colour_frames(scene, (40, 200, 220), (170, 170, 170), noise=2.0, seed=1))
    encode_frames(frames, video, "MJPG", scene.camera.fps, frames[0].shape[1::-1])
    info = probe(video)
    assert info.chroma_block == (2, 2) and not info.lossless and not info.inter_frame
    res = track_video(video, scene)
    monkeypatch.setattr(misfit, "JPEG_CHROMA_VAR", 1.0)
    own = track_video(video, scene)
    assert res.projection.luma_blind and res.ok.sum() > 20, res.status_counts()
    np.testing.assert_array_equal(res.ok, own.ok)
    np.testing.assert_array_equal(res.uv[res.ok], own.uv[own.ok])
    stated = res.cov_px[res.ok] / res.look_factor
    np.testing.assert_allclose(stated, JPEG_CHROMA_VAR * own.cov_px[own.ok] / own.look_factor, rtol=1e-12)


@pytest.mark.parametrize("pix_fmt,block", [("yuv420p", (2, 2)), ("yuv422p", (2, 1)), ("yuv411p", (4, 1))])
def test_chroma_shared_states_a_luma_blind_sums_variance(tmp_path, pix_fmt, block):
    # Noise frames (8 levels a channel, independent per pixel) through FFV1
    # in the pixel format: the variance of a luma-blind channel's sums over
    # block-aligned 4 x 4 patches of a frame difference is what
    # colour.chroma_shared states from the per-pixel covariance (each chroma
    # sample counted over its block); counting the pixels as independent
    # states 1 / 4 (4:2:0, 4:1:1) or 1 / 2 (4:2:2) of it.  Measured (seeds 3
    # and 4, blue - green and green - red): measured / stated 0.99-1.03
    # (4:2:0), 0.98-1.03 (4:2:2), 0.92-0.99 (4:1:1); band 0.85-1.15, ~4
    # standard errors of the ratio's spread there.  (On 8 x 8 patches 4:1:1
    # reads 1.27-1.51: its decoder interpolates the chroma, which correlates
    # neighbouring blocks; docs/measurements.md, yuv422.)
    rng = np.random.default_rng(3)
    h = w = 256
    frames = [np.clip(128 + 8 * rng.standard_normal((h, w, 3)), 0, 255).astype(np.uint8) for _ in range(2)]
    video = tmp_path / "n.avi"
    write_av(iter(frames), video, "ffv1", pix_fmt, 30.0)
    info = probe(video)
    assert info.chroma_block == block
    a, b = (f.astype(float) for f in FrameSource(video, info))
    d = (a - b) / np.sqrt(2)  # one frame's noise
    S = np.cov(d.reshape(-1, 3).T)
    wb = np.array([1.0, -1.0, 0.0])  # blue minus green: blind to luma
    k = 4
    sums = (d @ wb).reshape(h // k, k, w // k, k).sum(axis=(1, 3)).ravel()
    stated = k * k * wb @ chroma_shared(S, block) @ wb
    pixels = k * k * wb @ S @ wb
    assert 0.85 < sums.var() / stated < 1.15, sums.var() / stated
    assert sums.var() > 1.5 * pixels
