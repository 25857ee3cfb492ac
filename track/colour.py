"""One channel that best separates this video's ball from its felt (pure functions).

For a ball of colour ``b`` over felt ``f`` with sensor noise covariance
``S`` per pixel (3x3, BGR), the image near the ball is
``f + (b - f) coverage + noise``, and the information about the centre is
``(b - f)^T S^-1 (b - f)`` times the coverage's geometric terms.  The
projection ``p = w . bgr`` with ``w = S^-1 (b - f)`` (Fisher's discriminant)
keeps all of it: fitting the projected channel is the colour fit's
maximum-likelihood estimate.  ``b - f`` and ``S`` are learnt from the video
(the samples the background is learnt from); nothing is read from the
scene's ``render`` block.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from cuespin.track.background import ball_wide, box_size, spread_threshold
from cuespin.track.model import block_area
from cuespin.track.radius import as_radius_map

# 8-bit rounding adds variance 1/12 per channel, whatever the sensor does.
ROUNDING_VAR = 1.0 / 12.0
# Smallest noise variance along any colour direction, as a fraction of the
# channels' mean: bounds the projection's gain on noise the frame
# differences cannot see (a lossy codec's own error).
CONDITION_FLOOR = 0.05
# A sample differs from its pixel's median by more than this many whitened
# noise sigmas: the ball (or something else moving) covers it.
BALL_SIGMAS = 6.0
# A box position votes on the ball's colour when its departure is at least
# this fraction of the largest in its sample (the ball's whole box).
PEAK_FRACTION = 0.5
# A sample whose largest departure is narrower than a ball votes on the
# ball's colour with its positions as wide as a ball, where there are
# enough of them (:func:`wide_votes`).  Width: the smaller eigenvalue of
# the central second moments of the departure's size along the position's
# colour, over a window of the ball's radius each side, in squared radii
# (a uniform disc 0.25, a band of width w w^2 / 12).
# Measured (/tmp/cue5/why.py) on sample_scenes(1, 6, realistic, FFV1)[0]
# cut to 0.8 s (a blue ball with dots on blue felt, a tan cue in view in 7
# of 9 samples) and its MJPG transcode: the cue's departing stretch (the
# part of the shaft away from where it lies in most samples, ~2 radii long
# and 0.7 wide) 0.04-0.14 where it departs most (67-70 levels in box means,
# the ball's 23-30: the channel was the cue's, R - B, and 31 of 97 frames
# were found), the ball 0.19-0.25 where it departs most; seed 7 shot 1
# (480 fps, MJPG), the ball leaving its rest slowly (two crescents of
# opposite sign: hence the departure's size, not its signed mass) 0.20-0.24.
WIDE_MIN = 0.15
# A narrow sample's ball-wide positions vote where they number at least
# this share of the ball's area (pi r^2 positions): fewer are a fragment
# (seed 7 shot 4, 480 fps: 8-14 positions by the cue, and the channel from
# them lost half the frames on MJPG), and the sample votes as before (the
# cue-tip shot, sample_scene(3): 58-59 of the 67 needed in two samples).
# Measured on the clip: 36-211 in its narrow samples (48 needed).
WIDE_COUNT = 0.25
# The width's window half-width in ball radii: the ball's disc in it.
WIDE_RADII = 1.0
# Every this many pixels of the window (each way) enter its moments: a
# disc's or a band's width is kept, at a quarter of the cost.
WIDE_STEP = 2
# The chi distribution's (3 degrees of freedom) 99th percentile: a whitened
# box mean's noise norm, were the codec's error independent between pixels.
CHI3_P99 = 3.368
# Pixels the noise covariance is estimated from: its variances' relative
# error is sqrt(2 / n), 0.4%, and the medians over a whole 1280 x 720 frame
# cost ~1.5 s, more than tracking a short shot.
NOISE_PIXELS = 100_000
# The projected felt is placed near this level, so the projected image
# reads like grey levels (every threshold downstream is in such units).
FELT_LEVEL = 100.0
# A specular highlight adds the light's colour, white, to every channel
# alike.  Where the ball's colour departs from the felt's in hue enough that
# a channel blind to white keeps at least this share of the separation (the
# squared contrast over the noise, Fisher's), that channel is used: the
# highlight is then invisible in it.  Measured on sample_scenes(6, 7,
# realistic, FFV1)[0] (orange on red felt, specular 0.61, noise 7.8): the
# channel along the ball's colour (mostly G and R) showed the highlight and
# not the ball's shadowed side (its R darker than the felt's, its G
# brighter), and 24 of 51 found centres were 0.25-0.36 radii off towards
# the lit side; blind to white (keeping ~0.45 of the separation) none were,
# the largest error 0.09 radii.
WHITE_FREE_MIN = 0.4
# A lossy codec's white-free channel is its chroma, and the codec loses a
# ball's faint chroma first (MJPG: subsampled 2 x 2, quantised in 16 x 16
# blocks).  A shaded ball's colour is its albedo times its shading, so in a
# channel where the felt's level lies between black and the ball's (the
# felt a dimmer copy of the ball there: red on red) its darker side fades
# into the felt and what the codec keeps is its lit side: realistic seed 8
# shot 19 (red on red, lens blur, 120 fps, MJPG; the felt at 0.63 of the lit
# ball's level) was fitted 0.17-0.26 radii towards the light in every
# frame, 48 of 97 beyond a quarter radius, in the white-free, Fisher's and
# the lit sphere's fits alike.  Where the ball matches the felt at a shading
# (shade_match) above FELT_SHADE_MIN, the channel blind to the felt's colour
# (felt_blind) is learnt instead: there the felt lies at 0 and the ball at
# its shading times its lit level: shot 19 0 false, 0.27 px RMSE (FFV1's
# gradients' channel: 0.044).  The value lies in the gap of the white-free
# channel's shade_match over the 27 realistic shots judged (seed 8's 20 and
# seed 0's 3-6, 9, 13, 17, MJPG): red on red 0.63 and 0.72, then 0.26
# (orange on red) and below.  The rule reads colours, not shading: an
# unshaded red ball on red felt (seed 0 shot 5, the uniform look) passes it
# and pays 0.15 -> 0.30 px RMSE, its stated errors following
# (docs/measurements.md, fp13).
FELT_SHADE_MIN = 0.5
# The ball's gradients are taken within this many radii of the positions
# that voted on its colour (those lie within ~0.5 radii of its centre, where
# a box the ball fills departs most): the rim and the PSF's spread in.
GRAD_RADII = 1.0
# A ball's pixel this many whitened noise sigmas off the plane of its
# colour and the felt's shows a highlight (the residual is one normal
# variable: noise alone passes it once in 5e8 pixels).
HIGHLIGHT_SIGMAS = 6.0
# This many such pixels over the samples: a highlight is seen.  Measured
# (FFV1, /tmp/shade9/learn.py): 0 on realistic seed 0 shots 1 and 5 (no
# highlight), 9 on sample_scenes(6, 7, realistic)[0] (specular 0.61, the
# highlight in 2 of 9 samples), 794 on (6, 6)[0] (specular 0.43).
# On grey felt a highlight (white) lies in the plane and is seen as white
# added to the ball (off_colour_plane): realistic seed 0 shot 7 (yellow on
# grey, specular 0.47, FFV1) 15-17 pixels a sample (the plane alone: 1 over
# the 9 samples; the gradients' channel there: RMSE 0.0075 -> 0.0208 px),
# shot 2 42-90; shots 1, 5, 9, 10 still 0 (shade10).
HIGHLIGHT_PIXELS = 1
# BT.601's luma row (B, G, R): a YUV video's decoder adds its luma to B, G
# and R alike, so BGR = 1 Y + chroma with Y = LUMA . BGR.
LUMA = np.array([0.114, 0.587, 0.299])
# Weights summing to at most this fraction of their absolute sum are blind
# to luma (the white-free weights sum to zero; float32 rounds them by ~1e-7).
LUMA_BLIND_TOL = 1e-5


@dataclass(frozen=True)
class Projection:
    """Maps a frame to one float32 channel in which the ball stands out most.

    Attributes
    ----------
    w : ndarray, shape (3,), or None
        Weights on B, G, R; None for grey video (the channel itself).
    offset : float
        Added after weighting.
    noise_cov : ndarray, shape (3, 3), or None
        Per-pixel noise covariance the weights were learnt with (BGR levels^2).
    """

    w: np.ndarray | None = None
    offset: float = 0.0
    noise_cov: np.ndarray | None = None

    @property
    def luma_blind(self) -> bool:
        """The weights sum to zero: luma, which a YUV video's decoder adds
        to B, G and R alike, leaves the projected level unchanged, so the
        channel is the video's chroma alone (half resolution in a 4:2:0
        video: :func:`cuespin.track.model.fit_disc`'s ``block``)."""
        if self.w is None:
            return False
        w = self.w.astype(np.float64)
        return abs(float(w.sum())) <= LUMA_BLIND_TOL * float(np.abs(w).sum())

    def __call__(self, frame: np.ndarray, v0: int = 0, v1: int | None = None, u0: int = 0,
                 u1: int | None = None) -> np.ndarray:
        """The projected window ``frame[v0:v1, u0:u1]`` as float32 (h, w)."""
        roi = frame[v0:v1, u0:u1]
        if self.w is None:
            return roi.astype(np.float32)
        if (isinstance(roi, np.ndarray) and roi.dtype == np.uint8 and roi.ndim == 3 and roi.shape[1] >= 2
                and self.w.dtype == np.float32):
            # Compiled, the same bits as BLAS's (one pass, no float32 copy:
            # ~4 numpy calls a window, 3-6 windows a frame).
            from cuespin.track.window import project_bgr
            return project_bgr(roi, self.w, np.float32(self.offset))
        return (roi.astype(np.float32) @ self.w + np.float32(self.offset)).astype(np.float32, copy=False)

    def many(self, frames: np.ndarray) -> np.ndarray:
        """Project a stack of frames, shape (n, h, w[, 3]), to (n, h, w) float32."""
        out = np.empty(frames.shape[:3], np.float32)  # filled in place: no second copy of the stack
        for i, f in enumerate(frames):
            out[i] = self(f)
        return out


GREY = Projection()


def median_counts(x: np.ndarray) -> np.ndarray:
    """Each column's median of ``x`` (n, c), non-negative whole numbers of
    any integer dtype: ``np.median(x, axis=0)`` (float64) bit for bit, from
    the values' counts.  numpy selects down a column's strided values: 24 ms
    for a 1280 x 640 frame's BGR against 4 ms here (measured, tspeed8)."""
    n = len(x)
    out = np.empty(x.shape[1])
    # 8-bit values counted by OpenCV's histogram (float32 counts, exact below
    # 2^24): a 1280 x 640 frame's BGR in 1.2 ms against bincount's 5.3 (its
    # strided column copied to intp; measured, trk1k).
    hist = x.dtype == np.uint8 and 0 < n < 2**24
    img = np.ascontiguousarray(x).reshape(1, n, -1) if hist else None
    for c in range(x.shape[1]):
        counts = cv2.calcHist([img], [c], None, [256], [0, 256]).ravel().astype(np.int64) if hist \
            else np.bincount(x[:, c])
        cum = np.cumsum(counts)
        # the order statistics (n - 1) // 2 and n // 2 (the same one for odd n)
        lo, hi = np.searchsorted(cum, [(n - 1) // 2, n // 2], side="right")
        out[c] = (lo + hi) / 2
    return out


def noise_covariance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per-pixel noise covariance (3x3) from two colour frames of the same scene.

    Robust to what moved between them: pixels whose difference is beyond 5
    MADs in any channel are left out (99.99994% of the noise stays in).
    Each channel's rounding (1/12) and ``CONDITION_FLOOR`` of the mean
    variance are added, so a noise-free or codec-flattened video still gets
    a well-conditioned covariance.  At most about ``NOISE_PIXELS`` pixels,
    on a regular grid, are used.
    """
    step = max(int(np.sqrt(a.shape[0] * a.shape[1] / NOISE_PIXELS)), 1)
    a, b = a[::step, ::step], b[::step, ::step]
    d = (a.astype(np.float32) - b.astype(np.float32)).reshape(-1, 3)
    # np.median(d, axis=0) and the MAD's median, bit for bit, from counts:
    # the differences are whole levels, their deviations halves.
    med = (median_counts(d.astype(np.int32) + 255) - 255).astype(np.float32)
    dev = np.abs(d - med)
    mad = 1.4826 * (median_counts((2 * dev).astype(np.int32)) / 2).astype(np.float32)
    lim = np.maximum(5 * mad, 1.5)
    keep = dev[:, 0] <= lim[0]  # channel by channel: np.all along an axis of 3 is ten times dearer
    for c in range(1, d.shape[1]):
        keep &= dev[:, c] <= lim[c]
    d = d[keep].astype(np.float64)
    cov = (d.T @ d) / max(len(d), 1) / 2.0
    # A lossy codec can flatten the felt's noise and share it between the
    # channels (MJPG at a low bit rate: differences 0 in flat felt, the rest
    # one chroma-free pattern), so the estimate may be near singular and a
    # projection along its null direction would amplify the codec's error
    # unseen.  Each channel's own rounding, and a floor of CONDITION_FLOOR
    # of the mean variance, keep every direction's noise honest.
    floor = ROUNDING_VAR + CONDITION_FLOOR * np.trace(cov) / 3.0
    return cov + floor * np.eye(3)


def chroma_shared(S: np.ndarray, chroma_block) -> np.ndarray:
    """The noise covariance (3 x 3, BGR levels^2) the centre's information
    sees when a lossy codec stores chroma once per block of ``chroma_block``
    pixels (an int: a square's side, 4:2:0's 2; a pair: across, down,
    4:2:2's (2, 1), 4:1:1's (4, 1)): the chroma part of ``S``'s noise
    amplitude counted ``b`` times, ``b^2`` the block's pixels, ``Q S Q'``
    with ``Q = 1 LUMA' + b (I - 1 LUMA')``.  A chroma sample's error is one
    error shared by its b^2 pixels (and the codec's coarser chroma
    quantisation blurs the ball's rim over them), so per-pixel noise, the
    frame differences', makes chroma look b^2 times as informative as it
    is.  ``S`` for a block of one pixel.

    Measured (docs/measurements.md, chroma36): realistic seed 36 shot 5
    (orange on red felt, 120 fps, H.264; the per-pixel noise 0.09-0.10
    levels^2 a channel, the rounding's) was fitted in the blue-difference
    chroma alone, w (-0.85, 0.55, 0.30), its track 1.22 px off the truth
    after the strike (FFV1 0.02 px)."""
    b = float(np.sqrt(block_area(chroma_block)))
    if b <= 1:
        return S
    one = np.ones(3)
    Q = np.outer(one, LUMA) + b * (np.eye(3) - np.outer(one, LUMA))
    return Q @ S @ Q.T


def median_u8(X: np.ndarray) -> np.ndarray:
    """``np.median(X.astype(np.float32), axis=0)`` bit for bit, for a uint8
    stack ``X`` (n, ...): by an odd-even transposition sort of the n frames
    (elementwise min/max in 8 bits).  numpy's median along the first axis
    selects within each pixel's n values one pixel at a time: 27 ms for
    9 x 120 x 400 x 3 against 0.7 ms here (measured, tspeed8)."""
    s = [x.copy() for x in X]
    n = len(s)
    for r in range(n):
        for i in range(r % 2, n - 1, 2):
            lo = np.minimum(s[i], s[i + 1])
            np.maximum(s[i], s[i + 1], out=s[i + 1])
            s[i] = lo
    m = n // 2
    if n % 2:
        return s[m].astype(np.float32)
    # whole levels: their mean (a half level at most) is exact in float32, as numpy's
    return (s[m - 1].astype(np.float32) + s[m].astype(np.float32)) * np.float32(0.5)


def departure_box_means(samples: np.ndarray, on: np.ndarray, ys: np.ndarray, xs: np.ndarray,
                        k: int) -> np.ndarray:
    """Each sample's departure from the samples' per-pixel median, zero off
    ``on`` (uint8, h x w: the pixels ``ys``, ``xs`` dilated by the k x k
    box), averaged over the box at those pixels: shape (n, len(ys), 3), float32.

    Computed one connected part of ``on`` at a time, over its bounding box:
    the box around a pixel of a part lies in that part, and the departures
    are whole levels (halves for an even count), so the box filter's sums
    are exact and equal those over any larger region, bit for bit.  Over
    the bounding box of all of ``on``, a lossy codec's scattered flicker
    (H.264: motion at both ends of the frame) made that the whole frame:
    ~0.5 s of medians for 2% of its pixels.
    """
    out = np.empty((len(samples), len(ys), 3), np.float32)
    n_parts, labels, stats, _ = cv2.connectedComponentsWithStats(on, connectivity=8)
    part = labels[ys, xs]
    for j in range(1, n_parts):
        sel = np.flatnonzero(part == j)
        if not len(sel):
            continue
        u0, v0, w, h = stats[j, :4]
        X8 = samples[:, v0:v0 + h, u0:u0 + w]
        D = (X8.astype(np.float32) - median_u8(X8)) * on[v0:v0 + h, u0:u0 + w, None]
        out[:, sel] = np.stack([cv2.blur(d, (k, k)) for d in D])[:, ys[sel] - v0, xs[sel] - u0]
    return out


def departure_width(samples: np.ndarray, s: int, ys: np.ndarray, xs: np.ndarray, zhat: np.ndarray,
                    h: int, Li: np.ndarray) -> np.ndarray:
    """How wide a sample's departure from the samples' per-pixel median is
    around the positions ``ys``, ``xs`` (float, shape (m,), in units of
    ``h``^2: a uniform disc of radius ``h`` 0.25, a band of width ``w``
    about (w / h)^2 / 12; 0 where nothing departs).

    ``samples``: the samples (n, h, w, 3), uint8; ``s``: the one judged.
    The departure from the samples' median (:func:`median_u8`, over the
    windows' pixels only) is
    whitened (``Li``: the noise's inverse Cholesky factor), projected on the
    position's unit colour ``zhat`` (m, 3) and taken in size over the
    (2h + 1)^2 window around it (every ``WIDE_STEP`` pixels); the width is
    the smaller eigenvalue of its central second moments (about its own
    centroid, so that a band off the window's centre is still a band).  In
    size, not signed: a ball that moved less than its diameter between the
    median's frames and this one departs as two crescents of opposite sign.
    """
    H, W = samples.shape[1:3]
    d = np.arange(-h, h + 1, WIDE_STEP)
    Y = np.clip(ys[:, None, None] + d[None, :, None], 0, H - 1)
    X = np.clip(xs[:, None, None] + d[None, None, :], 0, W - 1)
    win = samples[:, Y, X]                                   # (n, m, K, K, 3)
    D = win[s].astype(np.float32) - median_u8(win)
    p = np.abs(np.einsum("mklc,mc->mkl", D, (zhat @ Li).astype(np.float32)).reshape(len(ys), -1))
    cy, cx = np.meshgrid(d, d, indexing="ij")
    cx, cy = cx.ravel().astype(np.float32), cy.ravel().astype(np.float32)
    basis = np.stack([np.ones_like(cx), cx, cy, cx * cx, cy * cy, cx * cy], axis=1)
    m0, sx, sy, sxx, syy, sxy = (p @ basis).astype(np.float64).T   # the window's moments
    ok = m0 > 0
    m0 = np.where(ok, m0, 1.0)
    mx, my = sx / m0, sy / m0
    sxx, syy, sxy = sxx / m0 - mx * mx, syy / m0 - my * my, sxy / m0 - mx * my
    half = 0.5 * (sxx + syy)
    lmin = half - np.sqrt(np.maximum(half * half - (sxx * syy - sxy * sxy), 0.0))
    return np.where(ok, lmin / float(h * h), 0.0)


def box_noise_scale(a: np.ndarray, b: np.ndarray, k: int, L: np.ndarray) -> float:
    """How many times the whitened k x k box means' noise exceeds what the
    per-pixel noise (``L``, its Cholesky factor) gives (float, >= 1): the
    99th percentile of the norm of two frames' box means' difference
    (whitened, over sqrt 2; on a 4-pixel grid) over the chi-3's.

    ~1 on lossless video (measured 1.08, sample_scenes(1, 6, realistic,
    FFV1)[0]); a lossy codec's error is correlated over its blocks and a
    box mean does not average it away (MJPG: 4.2-5.0, its departures of
    resting frames reaching 20-22 box sigmas, realistic seed 0 shot 3).
    """
    d = cv2.blur(a.astype(np.float32) - b.astype(np.float32), (k, k))[::4, ::4].reshape(-1, 3)
    z = np.linalg.solve(L, d.T.astype(np.float64)) * (k / np.sqrt(2.0))
    return max(float(np.percentile(np.sqrt(np.einsum("ij,ij->j", z, z)), 99)) / CHI3_P99, 1.0)


def wide_votes(samples: np.ndarray, Z: np.ndarray, norm2: np.ndarray, big: np.ndarray, ys: np.ndarray,
               xs: np.ndarray, radius_px: float, L: np.ndarray, k: int) -> np.ndarray:
    """The box positions that vote on the ball's colour (bool, (n, m)):
    ``big`` (each sample's candidates within ``PEAK_FRACTION`` of its
    largest; squared whitened box means ``norm2``), except in a sample
    whose largest departs narrower than a ball (:func:`departure_width`
    under ``WIDE_MIN``) and beyond the codec's noise (over ``BALL_SIGMAS``
    of the k x k box means' noise, :func:`box_noise_scale`; within it there
    is nothing to tell apart) and that holds at least ``WIDE_COUNT`` pi r^2
    candidates as wide as a ball within ``PEAK_FRACTION`` of the largest of
    those: there those vote (something else departs most, and the ball
    departs too).  Judged from each sample's largest down, a few hundred at
    a time, until the first as wide as a ball and those near it.
    """
    n = len(samples)
    h = max(int(round(WIDE_RADII * radius_px)), 1)
    Li = np.linalg.inv(L)
    out = big.copy()
    cand = norm2 > BALL_SIGMAS**2
    floor2 = None
    for s in range(n):
        o = np.flatnonzero(cand[s])
        if not len(o):
            continue
        o = o[np.argsort(-norm2[s, o], kind="stable")]
        if departure_width(samples, s, ys[o[:1]], xs[o[:1]], Z[s, o[:1]] / np.sqrt(norm2[s, o[0]]), h, Li)[0] \
                >= WIDE_MIN:
            continue
        if floor2 is None:
            floor2 = (BALL_SIGMAS * box_noise_scale(samples[0], samples[n // 2], k, L)) ** 2
        if norm2[s, o[0]] <= floor2:
            continue
        wide = np.zeros(len(ys), bool)
        peak2 = None
        for i in range(1, len(o), 256):
            j = o[i:i + 256]
            if peak2 is not None:
                j = j[norm2[s, j] > PEAK_FRACTION**2 * peak2]
            if not len(j):
                break
            w = departure_width(samples, s, ys[j], xs[j], Z[s, j] / np.sqrt(norm2[s, j])[:, None], h, Li) >= WIDE_MIN
            if peak2 is None and w.any():
                peak2 = norm2[s, j[np.argmax(w)]]
                w &= norm2[s, j] > PEAK_FRACTION**2 * peak2
            wide[j] = w
        if wide.sum() >= WIDE_COUNT * np.pi * radius_px**2:
            out[s] = wide
    return out


def ball_direction(samples: np.ndarray, ys: np.ndarray, xs: np.ndarray, radius_px,
                   L: np.ndarray, votes: list | None = None) -> np.ndarray | None:
    """The whitened colour direction (unit, shape (3,)) in which the samples
    depart from each pixel's median where a ball fits in what moved
    (pixels ``ys``, ``xs``), or None when too few depart.

    Each sample's departure is averaged over a box the ball fills
    (:func:`cuespin.track.background.box_size`) before it is judged: a ball
    whose colour is close to the felt's departs by less than the noise at
    each pixel (blue on blue, noise 6.4: 4.9 sigmas) and only its highlight,
    its markings and the cue passed the per-pixel test, and set the
    channel (measured on sample_scenes(6, 6, realistic, MJPG)[0]: the ball
    lost in 20 frames, 92 frames more than R/4 off).  Averaged, the ball
    stands out by ~k noise sigmas while a cue, a highlight or a dot fills a
    small part of the box.  The direction is the principal axis of the
    departures' unit vectors, so that it is the one most box positions
    share (the ball's), not the one the largest departures share.
    ``votes``, when given, receives the voting positions (bool, (n, m)).
    """
    n, H, W, _ = samples.shape
    # One box for the whole image, the smallest ball's, so that the ball
    # fills it wherever it is (a radius map under perspective).
    r_min = as_radius_map(radius_px, (H, W)).r_min
    k = box_size(r_min)
    on = np.zeros((H, W), np.uint8)
    on[ys, xs] = 1
    on = cv2.dilate(on, np.ones((k, k), np.uint8))
    Db = departure_box_means(samples, on, ys, xs, k).astype(np.float64)
    Z = np.linalg.solve(L, Db.reshape(-1, 3).T).T.reshape(Db.shape) * k  # whitened: a box mean's noise is S / k^2
    norm2 = np.einsum("sij,sij->si", Z, Z)
    # Only departures near the sample's largest: a ball fills the box, while
    # a lossy codec's error (MJPG's blocks, correlated over the box, so not
    # averaged away) departs by a fraction of it but over the whole moving
    # region (blue on blue, MJPG: 2600-3800 such box positions per sample
    # against the ball's 430, and the direction was the codec's).
    peak2 = norm2.max(axis=1, keepdims=True)
    big = (norm2 > BALL_SIGMAS**2) & (norm2 > PEAK_FRACTION**2 * peak2)
    # Where the largest departure is narrower than a ball and the ball
    # departs too, the ball's positions vote: a cue's departing stretch, a
    # band, departs more than a ball close to the felt's colour (WIDE_MIN),
    # and PEAK_FRACTION then leaves the ball out of its sample.
    big = wide_votes(samples, Z, norm2, big, ys, xs, r_min, L, k)
    if votes is not None:
        votes.append(big)
    if big.sum() < 10:
        return None
    # One vote per sample (its unit vectors' mean outer product): the ball
    # departs from the median in every sample, the cue in the few it
    # crosses, but a long cue covers more box positions than the ball
    # (sample_scenes(6, 6, realistic, FFV1)[0], blue on blue: 1400-1600 of
    # the cue's against ~420 of the ball's in three of nine samples, and the
    # direction lay between theirs).
    M = np.zeros((3, 3))
    for z, b in zip(Z, big):
        if b.any():
            U = z[b] / np.sqrt(np.einsum("ij,ij->i", z[b], z[b]))[:, None]
            M += U.T @ U / len(U)
    return np.linalg.eigh(M)[1][:, -1]


def moved_boxes(samples: np.ndarray, radius_px, sd: np.ndarray) -> np.ndarray:
    """Where something as wide as a ball moved (bool, h x w): pixels whose
    mean over a box the ball fills spans, over the samples, more than the
    box mean's noise allows in some channel (:func:`spread_threshold`:
    7.5 of its sigmas, ``sd / k``, plus a level for rounding and a lossy
    codec's, or the spans' own 90th percentile's multiple where larger).

    Box means, not pixels: a ball close to the felt's colour departs from it
    by less than the per-pixel threshold in every channel (blue on blue,
    noise 6.4: 13-30 levels against 52; sample_scenes(6, 6, realistic,
    FFV1)[0]), nothing "moved", the luma weights were taken, in which that
    ball's contrast is 2.5 levels, and every found centre was 2-10 radii
    off.  The box mean's noise is ``k`` times smaller; a ball fills the box.
    """
    k = box_size(as_radius_map(radius_px, samples.shape[1:3]).r_min)
    lo = hi = None
    for s in samples:  # running extremes: no stack of blurred float frames
        # The box sums in integers (exact, 4x cheaper than cv2.blur of float32
        # frames); cv2.blur's means are these times 1 / k^2 rounded to float32,
        # and rounding keeps order, so the extremes' means are bit for bit its.
        b = cv2.boxFilter(s, cv2.CV_32S, (k, k), normalize=False)
        if lo is None:
            lo, hi = b, b.copy()
        else:
            np.minimum(lo, b, out=lo)
            np.maximum(hi, b, out=hi)
    def span(hi, lo):  # cv2.blur's float32 means' span
        return (hi * (1.0 / (k * k))).astype(np.float32) - (lo * (1.0 / (k * k))).astype(np.float32)

    noise_thr = 7.5 * np.maximum(sd, 0.5) / k + 1.0
    sub = span(hi[::4, ::4], lo[::4, ::4])
    thr = np.array([spread_threshold(sub[..., i], noise_thr[i], step=1) for i in range(3)])
    # The float32 span is the integer span / k^2 within 5e-5 levels (three
    # float32 roundings of values < 256), so it is needed only where that
    # comes within 1e-3 of a threshold: a few moving pixels, not the whole
    # frame's float64 products (~25 ms a 1280 x 640 learning).
    np.subtract(hi, lo, out=hi)
    # Channel by channel: numpy's any() along an axis of 3 costs ~12 ms a frame, these ~1.
    lim = np.floor((thr - 1e-3) * (k * k)).astype(np.int32)
    near = hi[..., 0] > lim[0]
    for c in range(1, hi.shape[-1]):
        near |= hi[..., c] > lim[c]
    out = np.zeros(near.shape, bool)
    d, low = hi[near], lo[near]
    out[near] = np.any(span(d + low, low) > thr, axis=-1)
    return out


def white_free(d: np.ndarray, S: np.ndarray) -> np.ndarray | None:
    """Fisher's weights for a ball departing from the felt along ``d`` (BGR)
    under noise ``S``, constrained to see no white (``w . (1, 1, 1) = 0``):
    ``w = S^-1 (d - l 1)`` with ``l = 1' S^-1 d / 1' S^-1 1``.  None when
    that keeps less than ``WHITE_FREE_MIN`` of the unconstrained separation
    ``d' S^-1 d`` (it keeps ``1 - (1' S^-1 d)^2 / (1' S^-1 1 d' S^-1 d)``:
    the squared sine of the angle between ``d`` and white in the noise's
    metric), as for a ball that differs from the felt mainly in brightness."""
    w, full, a, b = _blind_to(d, S, np.ones(3))
    if full <= 0 or 1.0 - a * a / (b * full) < WHITE_FREE_MIN:
        return None
    return w


def _blind_to(d: np.ndarray, S: np.ndarray, f: np.ndarray):
    """Fisher's weights for ``d`` under ``S`` with ``w . f = 0``:
    ``(w, d' S^-1 d, f' S^-1 d, f' S^-1 f)``, ``w = S^-1 (d - l f)``,
    ``l = f' S^-1 d / f' S^-1 f``; ``w`` None when ``f' S^-1 f <= 0``."""
    Sd, Sf = np.linalg.solve(S, d), np.linalg.solve(S, f)
    full, a, b = float(d @ Sd), float(f @ Sd), float(f @ Sf)
    return (Sd - (a / b) * Sf if b > 0 else None), full, a, b


def felt_blind(d: np.ndarray, S: np.ndarray, felt: np.ndarray) -> np.ndarray | None:
    """Fisher's weights for a ball departing from the felt along ``d`` (BGR)
    under noise ``S``, constrained to see none of the felt's colour ``felt``
    (BGR levels; ``w . felt = 0``: :func:`white_free`'s form with the felt's
    colour for white), ``w = S^-1 (d - l f)``, ``l = f' S^-1 d / f' S^-1 f``.
    A ball's colour is its albedo times its shading, so in this channel the
    felt lies at 0 and the ball at its shading times its lit level: no part
    of it, however dark, matches the felt.  None when nothing is left (``d``
    along the felt's colour)."""
    w, full, _, _ = _blind_to(d, S, np.asarray(felt, float))
    return w if w is not None and float(w @ d) > 1e-9 * full else None


def shade_match(proj: Projection, polarity: int, contrast: float) -> float:
    """The shading (a share of the ball's lit level) at which the ball
    matches the felt in the channel ``proj`` (the felt at ``FELT_LEVEL``,
    the ball's lit middle ``polarity`` x ``contrast`` from it: the
    background's, :class:`~cuespin.track.background.Background`): the felt's
    level over the lit ball's, both from black (the channel at a black
    pixel, ``proj.offset``).  Between 0 and 1 the ball's darker side (its
    colour times a shading under 1) passes through the felt's level; NaN
    without a ball (``polarity`` 0) or at black's level."""
    felt = FELT_LEVEL - float(proj.offset)
    ball = felt + polarity * float(contrast)
    return felt / ball if polarity and ball != 0 else float("nan")


def ball_gradients(samples: np.ndarray, ys: np.ndarray, xs: np.ndarray, votes: np.ndarray,
                   radius_px, L: np.ndarray | None = None, highlight: list | None = None) -> np.ndarray | None:
    """The colour image's gradients' second moments at the ball (3 x 3,
    BGR levels^2 / px^2), or None where no sample votes.

    The centre's Fisher information in a channel ``p = w . bgr`` is
    ``w' A w / w' S w`` times the pixel count, with ``A`` the mean outer
    product of the image's derivatives along the centre (the image's
    spatial gradients, both axes) over the ball's pixels: at its rim the
    ball's colour minus the felt's, inside the shading's change of the
    ball's own colour.  Taken on each sample's departure from the samples'
    per-pixel median (the felt's texture gone) over the voting positions
    (``votes``, :func:`ball_direction`) grown by ``GRAD_RADII`` of the
    ball's radius, one vote per sample.  The noise adds ``c S`` to ``A``
    (the gradients' noise has the pixels' colour covariance), which moves
    no generalized eigenvector of ``(A, S)``.  With ``highlight`` (a list)
    and ``L`` (the noise's Cholesky factor), each voting sample's count of
    :func:`off_colour_plane` pixels is appended to it.
    """
    n, H, W, _ = samples.shape
    r = as_radius_map(radius_px, (H, W)).r_min
    g = max(int(round(GRAD_RADII * r)), 1)
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * g + 1, 2 * g + 1))
    A = np.zeros((3, 3))
    used = 0
    for s in range(n):
        if not votes[s].any():
            continue
        v, u = ys[votes[s]], xs[votes[s]]
        v0, v1 = max(int(v.min()) - g - 1, 0), min(int(v.max()) + g + 2, H)
        u0, u1 = max(int(u.min()) - g - 1, 0), min(int(u.max()) + g + 2, W)
        on = np.zeros((v1 - v0, u1 - u0), np.uint8)
        on[v - v0, u - u0] = 1
        on = cv2.dilate(on, disc).astype(bool)
        on[[0, -1], :] = False
        on[:, [0, -1]] = False
        X = samples[:, v0:v1, u0:u1]
        D = X[s].astype(np.float64) - median_u8(X)
        gu = np.zeros_like(D)
        gv = np.zeros_like(D)
        gu[:, 1:-1] = (D[:, 2:] - D[:, :-2]) / 2
        gv[1:-1] = (D[2:] - D[:-2]) / 2
        gu, gv = gu[on], gv[on]
        A += (gu.T @ gu + gv.T @ gv) / len(gu)
        used += 1
        if highlight is not None:
            highlight.append(off_colour_plane(X[s].astype(np.float64)[on], median_u8(X)[on].astype(np.float64),
                                              X[s].astype(np.float64)[v - v0, u - u0], L))
    return A / used if used else None


def off_colour_plane(c: np.ndarray, f: np.ndarray, inner: np.ndarray, L: np.ndarray) -> int:
    """How many of the ball's pixels ``c`` (m, 3, BGR) show a highlight,
    over ``HIGHLIGHT_SIGMAS`` whitened noise sigmas (``L``): off the plane of
    its own colour ``b`` and the felt's ``f``, or, in it, white added to the
    ball.  A lit ball's pixels are its colour scaled by its shading, mixed at
    the rim with the felt: ``a b + m f`` with ``a + m`` at most about 1, and
    ``m`` about 0 where ``a`` exceeds 1 (the lit side); a highlight adds
    white, which leaves the plane unless the felt is grey, where it is ``f``
    added to the ball: ``a`` and ``m`` both above 0 and ``a + m`` above 1.
    ``b``: the median of ``inner``, the ball's pixels at the voting
    positions; ``f``: the median of ``f``."""
    b, fe = np.median(inner, axis=0), np.median(f, axis=0)
    Li = np.linalg.inv(L)
    M = Li @ np.c_[b, fe]
    Q = np.linalg.qr(M)[0]
    z = c @ Li.T
    r = z - (z @ Q) @ Q.T
    off = np.sqrt(np.einsum("ij,ij->i", r, r)) > HIGHLIGHT_SIGMAS
    # a and m of each pixel, each over its sigma (whitened noise: identity).
    P = np.linalg.pinv(M)
    a, m, k = z @ P[0], z @ P[1], P[0] + P[1]
    white = ((a > HIGHLIGHT_SIGMAS * np.linalg.norm(P[0])) & (m > HIGHLIGHT_SIGMAS * np.linalg.norm(P[1]))
             & ((a + m - 1) > HIGHLIGHT_SIGMAS * np.linalg.norm(k)))
    return int((off | white).sum())


def best_channel(A: np.ndarray, S: np.ndarray) -> np.ndarray:
    """The weights ``w`` (BGR) maximising ``w' A w / w' S w``: the channel
    that keeps most of the centre's information (:func:`ball_gradients`)
    under the noise ``S``, the top generalized eigenvector of ``(A, S)``."""
    L = np.linalg.cholesky(S)
    Li = np.linalg.inv(L)
    v = np.linalg.eigh(Li @ A @ Li.T)[1][:, -1]
    return np.linalg.solve(L.T, v)


def channel_rule(d: np.ndarray, S: np.ndarray, gradients, lossless: bool = True,
                 felt: np.ndarray | None = None) -> tuple[np.ndarray, bool]:
    """Which combination of the channels the ball is fitted in (the rule,
    in one place): the weights (BGR) and whether they are blind to white.

    ``d`` is the ball's colour minus the felt's (BGR, any scale: its
    direction), ``S`` the noise covariance, ``gradients()`` the ball's
    gradients' moments (:func:`ball_gradients`, computed only when needed).

    - Where the ball departs from the felt mainly in brightness
      (:func:`white_free` keeps less than ``WHITE_FREE_MIN`` of the
      separation): Fisher's discriminant along ``d``, ``S^-1 d``.
    - Where it departs in hue, the video is lossless (``lossless``) and no
      highlight is seen (:func:`off_colour_plane` finds fewer than ``HIGHLIGHT_PIXELS``
      pixels off the plane of the ball's and the felt's colours, or white
      added to the ball, over the samples): the channel that keeps most of the centre's information,
      learnt from the ball's image gradients (:func:`best_channel`), its
      rim and its shading.  The white-free channel discards the shading,
      which lies along the ball's own colour, white in part: on
      benchmarks/track.py realistic seed 0 shot 1 (a shaded blue ball on
      grey felt, FFV1) its bound was 3.12 times the bound from every
      channel (the best white-free channel's 3.08), the gradients' 1.17
      (the best linear combination's 1.17); RMSE 0.0264 -> 0.0122 px.
    - Where it departs in hue and a highlight is seen: the white-free
      channel (:func:`white_free`; the highlight, white, is invisible in
      it).  The gradients' channel takes the highlight in, which the look
      fits worse: sample_scenes(6, 7, realistic, FFV1)[0] (orange on red,
      specular 0.61, 1 s) RMSE 0.238 -> 0.316 px; (6, 6)[0] MJPG (blue on
      blue, specular 0.43) 100% found -> 26% and 9 false centres.  A lossy
      codec's error at the ball's rim leaves the plane too (MJPG: 9-90
      pixels a sample on balls without a highlight), and the gradients'
      channel was measured on lossless video only: on a lossy codec the
      white-free channel stays, by the codec, not by the codec's error
      tripping the highlight test (review 11b; docs/measurements.md, shade9).
      With ``felt`` (BGR levels; given where the white-free channel's ball
      fades into the felt, :func:`shade_match` over ``FELT_SHADE_MIN``):
      the channel blind to the felt's colour (:func:`felt_blind`) instead.
    - Luma (None here) where no ball was seen.
    """
    w = np.linalg.solve(S, d)
    blind = white_free(d, S)
    if blind is None:
        return w, False
    if not lossless:
        if felt is not None and (fb := felt_blind(d, S, felt)) is not None:
            return (fb if fb @ d > 0 else -fb), False
        return (blind if blind @ d > 0 else -blind), True
    hl: list = []
    A = gradients(hl)
    if A is None or sum(hl) >= HIGHLIGHT_PIXELS:
        return (blind if blind @ d > 0 else -blind), True
    g = best_channel(A, S)
    return (g if g @ d > 0 else -g), False


def learn_projection(samples: np.ndarray, radius_px, lossless: bool = True, blind_to_felt: bool = False,
                     chroma_block=1) -> Projection:
    """The channel combination that best separates the moving ball from the felt.

    Parameters
    ----------
    samples : ndarray, shape (n, h, w, 3), uint8
        BGR frames spread over the video (the background's samples).
    radius_px : float or RadiusMap
        The ball's radius (px), or its map over the image
        (:mod:`cuespin.track.radius`): only regions of motion a ball fits in
        count (a cue's or a shadow's colour is not the ball's).
    lossless : bool
        The video's codec is lossless (:func:`channel_rule`).
    blind_to_felt : bool
        On a lossy codec, the channel blind to the felt's colour (the
        samples' first frame's median) rather than to white
        (:func:`channel_rule`'s ``felt``; chosen by :func:`shade_match`).
    chroma_block : int or (int, int)
        The pixel blocks sharing one chroma sample, a square's side or
        (across, down) px
        (:attr:`cuespin.track.reader.VideoInfo.chroma_block`; the tracker
        passes it for an inter-frame codec only, track.video): on a lossy
        codec the channel is chosen under :func:`chroma_shared`'s noise.

    Returns
    -------
    Projection
        ``w`` chosen by :func:`channel_rule` (``S^-1 d``, the white-free
        channel or the ball's gradients' best), with ``d`` the dominant direction of
        (whitened) departures from each pixel's median over the samples:
        where the ball passes, the ball's colour minus the felt's (or its
        negative, where the ball rests most of the time).  Scaled so that
        the projected noise has the channels' mean variance, and offset to
        put the felt near ``FELT_LEVEL``.  Luma weights when nothing moved.
    """
    n = len(samples)
    S = noise_covariance(samples[0], samples[n // 2]) if n > 1 else np.eye(3) * ROUNDING_VAR
    L = np.linalg.cholesky(S)
    sd = np.sqrt(np.diag(S))
    ys, xs = np.nonzero(ball_wide(moved_boxes(samples, radius_px, sd), radius_px))
    w = None
    blind = False
    felt = median_counts(samples[0].reshape(-1, 3))
    if len(ys):
        votes: list = []
        e = ball_direction(samples, ys, xs, radius_px, L, votes)
        if e is not None:
            # The rule weighs the channels by the noise the centre's
            # information sees (a lossy codec's shared chroma counted as
            # such); the image is scaled below by the per-pixel noise.
            Si = S if lossless else chroma_shared(S, chroma_block)
            w, blind = channel_rule(L @ e, Si, lambda hl: ball_gradients(samples, ys, xs, votes[0], radius_px, L, hl),
                                    lossless, felt if blind_to_felt else None)
    if w is None:
        w = LUMA / np.sqrt(LUMA @ S @ LUMA)
    # Projected noise variance w^T S w = 1 here; give it the channels' mean
    # variance, so the projected image's noise reads like a channel's.
    w = w / np.sqrt(w @ S @ w) * np.sqrt(np.trace(S) / 3.0)
    if not blind and w.sum() < 0:  # keep bright things bright where it costs nothing (grey-like w)
        w = -w
    return Projection(w=w.astype(np.float32), offset=float(FELT_LEVEL - felt @ w), noise_cov=S)


__all__ = ["GREY", "Projection", "best_channel", "channel_rule", "chroma_shared", "learn_projection", "noise_covariance",
           "white_free"]
