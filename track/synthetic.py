"""Colour videos for the tracker's tests and benchmarks (not the renderer).

A scene's exact ball coverage (the project's renderer's) drawn in any ball
and felt colours, with independent noise per channel, written by PyAV in any
codec and pixel format (with chosen presentation times, for
variable-frame-rate files).  The renderer's realistic looks replace this
where they exist; this stays the tracker's own minimal colour check.
"""

from __future__ import annotations

from fractions import Fraction

import av
import numpy as np

from cuespin.render import FrameRenderer


def colour_frames(scene, ball_bgr, felt_bgr, noise: float, seed: int = 0, ramp: float = 0.0,
                  others=(), noise_bank: int = 0):
    """Yield BGR uint8 frames of ``scene``'s shot.

    Parameters
    ----------
    ball_bgr, felt_bgr : sequence of 3 floats
        Colours (levels).
    noise : float
        Gaussian noise per channel and pixel (levels), independent channels.
    ramp : float
        Lighting ramp across the frame's width (relative brightness change).
    others : sequence of (u, v, bgr)
        Other balls at rest (centre px, colour), drawn with the same radius.
    noise_bank : int
        If > 0, the felt's noise is drawn from this many precomputed noise
        frames, rolled by a random offset per frame (fast, for long speed
        benchmarks; not independent between frames).
    """
    r = FrameRenderer(scene)
    h, w = scene.camera.height, scene.camera.width
    rng = np.random.default_rng(seed)
    light = 1.0 + ramp * (np.arange(w) / w - 0.5)
    felt = np.asarray(felt_bgr, float)[None, None, :] * light[None, :, None] * np.ones((h, 1, 1))
    from cuespin.render.draw import disc_coverage
    for u, v, col in others:
        u0, v0, n = int(u - r.radius_px - 2), int(v - r.radius_px - 2), int(2 * r.radius_px + 5)
        cov = disc_coverage(u, v, r.radius_px, u0, v0, n, n)[..., None]
        sl = (slice(v0, v0 + n), slice(u0, u0 + n))
        felt[sl] = felt[sl] * (1 - cov) + np.asarray(col, float) * cov
    ball = np.asarray(ball_bgr, float)
    bank = [np.clip(np.rint(felt + noise * rng.standard_normal(felt.shape)), 0, 255).astype(np.uint8)
            for _ in range(noise_bank)]
    for k in range(r.n_frames):
        if bank:
            img8 = np.roll(bank[k % len(bank)], int(rng.integers(0, w)), axis=1)
            cov, u0, v0 = r.ball_patch(k)
            if cov is not None:
                ch, cw = cov.shape
                sl = (slice(v0, v0 + ch), slice(u0, u0 + cw))
                c = cov[..., None]
                img8[sl] = np.clip(np.rint(img8[sl] * (1 - c) + ball * light[u0:u0 + cw, None] * c), 0, 255)
            yield img8
            continue
        img = felt + (noise * rng.standard_normal(felt.shape) if noise > 0 else 0.0)
        cov, u0, v0 = r.ball_patch(k)
        if cov is not None:
            ch, cw = cov.shape
            sl = (slice(v0, v0 + ch), slice(u0, u0 + cw))
            c = cov[..., None]
            img[sl] = img[sl] * (1 - c) + (ball * light[u0:u0 + cw, None]
                                           + (noise * rng.standard_normal((ch, cw, 3)) if noise > 0 else 0)) * c
        yield np.clip(np.rint(img), 0, 255).astype(np.uint8)


def write_av(frames, path, codec: str, pix_fmt: str, fps: float, times=None, options=None,
             time_base=Fraction(1, 90000), bit_rate: int | None = None) -> None:
    """Encode BGR frames with PyAV; ``times`` (s) set each frame's presentation time.

    ``bit_rate`` (bit/s) for rate-controlled codecs (MJPG, mp4v): FFmpeg's
    default (about 1 Mbit/s) flattens sensor noise into blocks.
    """
    frames = iter(frames)
    first = next(frames)
    h, w = first.shape[:2]
    with av.open(str(path), "w") as c:
        s = c.add_stream(codec, rate=Fraction(fps).limit_denominator(1000))
        s.width, s.height, s.pix_fmt = w, h, pix_fmt
        if options:
            s.options = options
        if bit_rate:
            s.bit_rate = int(bit_rate)
        if times is not None:  # the encoder's clock, so frames keep their own times
            s.codec_context.time_base = time_base
            s.time_base = time_base
        k = 0
        for img in _chain(first, frames):
            fmt = "gray" if img.ndim == 2 else "bgr24"
            fr = av.VideoFrame.from_ndarray(img, format=fmt)
            if times is not None:
                fr.pts = int(round(times[k] / time_base))
                fr.time_base = time_base
            for p in s.encode(fr):
                c.mux(p)
            k += 1
        for p in s.encode():
            c.mux(p)


def _chain(first, rest):
    yield first
    yield from rest
