"""The felt without the ball, learnt from frames spread over the video.

A plain per-pixel median keeps the ball wherever it rests for most of the
video (before a late strike, after a slow shot stops), and a slow ball
overlaps itself from sample to sample.  What does hold: the ball is a disc
of one grey level, on one side of the felt (brighter or darker: its
polarity), so at every pixel the samples showing felt are the ones at the
far end from the ball.  Hence:

1. Pixels whose samples spread more than noise can explain lie on the
   ball's path (or its rest spots); elsewhere the plain mean is the felt.
2. Polarity: on the path, the ball is the outlier on one side of the
   median in most pixels (a moving ball covers each pixel briefly).
3. On the path, a first felt estimate is the extreme sample away from the
   ball; the felt is then the mean of the samples within noise of it
   (pixels partly covered by the ball fall outside), re-estimated once
   against that (unbiased) mean.

The mean rather than the median, since the subtraction's own noise adds to
every frame's.  A pixel that the ball covers in every sample cannot be
recovered this way; it keeps the extreme sample (the ball never left it).

Pure functions of arrays; no video I/O.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from cuespin.track.radius import as_radius_map

# Detection threshold in units of the box-filtered noise's standard deviation.
DETECT_SIGMAS = 8.0
# A blob smaller than this fraction of the ball's area is noise or texture.
MIN_AREA_FRACTION = 0.3
# A path pixel whose felt is the mean of fewer samples than this adds noise
# (variance sigma^2 / count) to every frame's subtraction there.
MIN_FELT_SAMPLES = 10


@dataclass(frozen=True)
class Background:
    """Background model of a video.

    Attributes
    ----------
    image : ndarray, shape (h, w), float32
        Felt without the ball (grey levels).
    sigma : float
        Per-pixel noise standard deviation in a frame (grey levels).
    polarity : int
        +1 if the ball is brighter than the felt, -1 if darker.
    contrast : float
        Typical |ball - felt| (grey levels).
    n_samples : int
        Frames the model was learnt from.
    path_pixels : int
        Pixels where the samples disagree: the ball's path and rest spots.
    weak_samples : ndarray of bool, shape (n,)
        The samples that show felt at the path pixels where fewer than
        ``MIN_FELT_SAMPLES`` do (a resting ball hid the felt in the rest):
        more frames from around these would sharpen the model there.  All
        False when every path pixel is well covered.
    moved_px : int
        Pixels where something a ball fits in moved (:func:`ball_wide`).
    moved_band : tuple of float
        Those pixels' width and length (px), as a uniform band's with their
        second moments (:func:`band_extent`): the cue's withdrawal is a long
        band narrower than the ball (:data:`cuespin.track.video.STICK_MOVED_RADII`).
        (0, 0) when nothing moved.
    score : float
        The ball's search score (:func:`box_score`, levels) in the samples:
        the largest over them of the peak on the swept path (the ball where
        it rests or rolls).  0 when nothing moved.
    """

    image: np.ndarray
    sigma: float
    polarity: int
    contrast: float
    n_samples: int
    path_pixels: int
    weak_samples: np.ndarray
    moved_px: int = 0
    score: float = 0.0
    moved_band: tuple = (0.0, 0.0)


def band_extent(xs: np.ndarray, ys: np.ndarray) -> tuple[float, float]:
    """The width and length (px) of the pixels at ``xs``, ``ys`` across and
    along their long axis: a uniform band's with their second moments,
    sqrt(12 lambda); (0, 0) for fewer than 3 pixels."""
    if len(xs) < 3:
        return 0.0, 0.0
    lam = np.linalg.eigvalsh(np.cov(np.c_[xs, ys].T.astype(float), bias=True))
    w, length = np.sqrt(12 * np.maximum(lam, 0.0))
    return float(w), float(length)


# Where the ball moved, the samples disagree over a region a disc of this
# fraction of the ball's radius fits in; a cue (about a quarter of the
# ball's diameter wide) or its shadow does not, so its motion is not taken
# for the ball's (polarity, contrast, colour, the felt's far side).
BALL_WIDE_FRACTION = 0.6


def ball_wide(mask: np.ndarray, radius_px) -> np.ndarray:
    """The parts of ``mask`` (bool, h x w) that a disc of
    ``BALL_WIDE_FRACTION`` of the ball's radius fits in (a morphological opening).

    ``radius_px`` is one radius (px) or a :class:`~cuespin.track.radius.RadiusMap`:
    under perspective each pixel is opened with the ball's size there (a
    cue a quarter of a near ball's width is wider than 0.6 of the image
    centre's radius when the near ball is twice that size).
    """
    radii = as_radius_map(radius_px, mask.shape)
    m8 = mask.astype(np.uint8)
    out = np.zeros(mask.shape, bool)
    H, W = mask.shape
    for _, r, (v0, v1, u0, u1), on in radii.bands():
        d = max(3, int(round(2 * BALL_WIDE_FRACTION * r)) | 1)
        k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (d, d))
        if on is None:
            return cv2.morphologyEx(m8, cv2.MORPH_OPEN, k).astype(bool)
        # The opening of a band needs the mask a disc's width beyond it.
        V0, V1, U0, U1 = max(v0 - d, 0), min(v1 + d, H), max(u0 - d, 0), min(u1 + d, W)
        opened = cv2.morphologyEx(m8[V0:V1, U0:U1], cv2.MORPH_OPEN, k).astype(bool)
        out[v0:v1, u0:u1] |= opened[v0 - V0:v1 - V0, u0 - U0:u1 - U0] & on
    return out


def noise_sigma(a: np.ndarray, b: np.ndarray) -> float:
    """Robust per-frame noise sigma from two frames: MAD of their difference / sqrt 2."""
    d = (a.astype(np.float32) - b.astype(np.float32)).ravel()
    mad = 1.4826 * np.median(np.abs(d - np.median(d)))
    # The MAD of integer-valued differences is coarse (0 without noise);
    # refine with the standard deviation of the inliers (5 sigma keeps
    # 99.99994% of them; the ball's pixels are far outside).
    inl = d[np.abs(d) <= max(5 * mad, 1.5)]
    return float(inl.std() / np.sqrt(2.0))


def felt_band(sigma: float) -> float:
    """Grey levels within which a sample still shows felt (noise ``sigma``
    plus a level for rounding); a pixel the ball partly covers lies beyond."""
    return 3.0 * sigma + 1.5


# A lossy codec's error is heavy-tailed: MJPG codes flat felt identically
# from frame to frame (noise read as 0.43 where the sensor's is 3.7) but not
# its texture or block edges, and the samples' span over the table was
# above the noise's 7.5 sigmas at 12% of its pixels (median 1.1, 90th
# percentile 6.8, 99th 15; sample_scenes(6, 7, realistic, MJPG)[1]): the
# whole felt "moved" and the polarity was the noise's.  A static pixel's span
# is at most SPAN_P90_FACTOR times the 90th percentile of all (Gaussian
# noise, 9 samples: 7.5 sigma is 1.8 times it), and a ball's path covers
# far less than 10% of a frame.
SPAN_P90_FACTOR = 1.8


def spread_threshold(span: np.ndarray, noise_threshold: float, step: int = 4) -> float:
    """The span (levels) over the samples beyond which a pixel moved: the
    noise's ``noise_threshold``, or ``SPAN_P90_FACTOR`` times the 90th
    percentile of the spans ``span`` (h, w) where that is larger (of every
    ``step``-th row and column; 1 for spans already taken so)."""
    sub = span[::step, ::step]
    return max(float(noise_threshold), SPAN_P90_FACTOR * float(np.percentile(sub, 90)))


# A lossy codec's error at a pixel of a still scene scales with the image's
# contrast around it: the edges of balls at rest, sights and pockets spanned
# 15-35 levels over the samples (MJPG, sample_scenes(6, 7, realistic,
# MJPG)[1]) where their contrast is ~250.  Where something moved, the span
# is the mover's contrast, as large as the range of the samples' mean over
# the pixel's neighbourhood (FLICKER_PX square) or larger.
FLICKER_FRACTION = 0.5
FLICKER_PX = 5


def flicker(span: np.ndarray, image: np.ndarray) -> np.ndarray:
    """Pixels whose ``span`` over the samples is under ``FLICKER_FRACTION``
    of the range of the samples' mean ``image`` around them: a still edge's
    codec error, not motion."""
    k = np.ones((FLICKER_PX, FLICKER_PX), np.uint8)
    img = image.astype(np.float32)
    return span < FLICKER_FRACTION * (cv2.dilate(img, k) - cv2.erode(img, k))


def ball_side(samples: np.ndarray, felt: np.ndarray, ys: np.ndarray, xs: np.ndarray, radius_px: float) -> int:
    """The ball's polarity (+1 brighter than the felt, -1 darker) from where
    it moved (pixels ``ys``, ``xs``): the sign of the sum, over them, of each
    one's most extreme departure from ``felt`` (h, w) among the samples,
    averaged over the search's box (:func:`box_size`).

    Averaged as the search scores it, not voted pixel by pixel: a shaded
    ball whose colour is close to the felt's is brighter in its lit middle
    and darker at its rim, and the rim's pixels outnumber the middle's
    (red on red, sample_scenes(6, 7, realistic, MJPG)[5]: the vote said
    darker, and the search found the felt where the ball came to rest).
    """
    if not len(ys):
        return 1
    k = box_size(radius_px)
    v0, v1 = max(ys.min() - k, 0), ys.max() + k + 1
    u0, u1 = max(xs.min() - k, 0), xs.max() + k + 1
    f = felt[v0:v1, u0:u1].astype(np.float32)
    boxed = np.stack([cv2.blur(s[v0:v1, u0:u1].astype(np.float32) - f, (k, k)) for s in samples])
    b = boxed[:, ys - v0, xs - u0]
    ext = np.take_along_axis(b, np.abs(b).argmax(axis=0)[None], axis=0)[0]
    return int(np.sign(ext.sum()) or 1)


def felt_around(image: np.ndarray, path: np.ndarray, radius_px: float) -> np.ndarray:
    """The mean of ``image`` over the pixels off ``path`` (bool) within a box
    two ball diameters wide around each pixel; NaN where the box holds none."""
    k = 4 * int(np.ceil(radius_px)) + 1
    off = (~path).astype(np.float32)
    num = cv2.boxFilter(image.astype(np.float32) * off, -1, (k, k), normalize=False)
    den = cv2.boxFilter(off, -1, (k, k), normalize=False)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0.5, num / np.maximum(den, 1e-6), np.nan).astype(np.float32)


def box_size(radius_px: float) -> int:
    """Odd box-filter size matched to the ball: about the inscribed square."""
    return max(3, int(round(1.4 * radius_px)) | 1)


# The search's score clips each pixel's departure from the felt at this
# multiple of the ball's contrast (Background.contrast, the 75th percentile
# of the path's largest departures: the ball's lit middle).  Measured on
# sample_scenes(6, 6, realistic, MJPG)[0] (blue on blue, contrast 56): the
# ferrule, 106 levels off the felt, scored 34 at the window's edge against
# the ball's 33, and was tracked for 44 frames after the strike.
SCORE_CAP = 1.0


def box_score(D: np.ndarray, k: int, K: int) -> np.ndarray:
    """Ball-likeness at every pixel of a ball-positive image ``D`` (levels,
    float32, already clipped): the mean over the ``k`` x ``k`` box the ball
    fills less the mean over the ring of felt out to ``K`` x ``K``.  A stick
    (the cue) or an edge fills the ring as much as the box and scores near 0."""
    inner = cv2.blur(D, (k, k))
    outer = cv2.boxFilter(D, -1, (K, K), normalize=False)
    return inner - (outer - inner * (k * k)) / (K * K - k * k)


def ball_score(samples: np.ndarray, image: np.ndarray, polarity: int, contrast: float,
               swept: np.ndarray, radius_px: float) -> float:
    """The ball's :func:`box_score` in the samples (levels): per sample the
    peak over the swept path, the largest over the samples (a sample the
    ball has left scores the felt's noise there, one with it rolling its
    blurred score).  Sized for ``radius_px``; departures clipped at
    ``SCORE_CAP`` of ``contrast``, as the search does."""
    k, K = box_size(radius_px), box_size(2 * radius_px) | 1
    ys, xs = np.nonzero(swept)
    if not len(ys):
        return 0.0
    H, W = image.shape
    m = K // 2 + 1  # the ring's reach beyond the path
    v0, v1, u0, u1 = max(ys.min() - m, 0), min(ys.max() + m + 1, H), max(xs.min() - m, 0), min(xs.max() + m + 1, W)
    on = swept[v0:v1, u0:u1]
    cap = SCORE_CAP * max(contrast, 1.0)
    best = 0.0
    for f in samples:
        D = np.clip(polarity * (f[v0:v1, u0:u1].astype(np.float32) - image[v0:v1, u0:u1]), -cap, cap)
        best = max(best, float(box_score(D, k, K)[on].max()))
    return best


# A path pixel showed the felt in some sample when its extreme nearer the
# felt around the path lies within the noise's band of it, or within this
# fraction of the other extreme's departure (a textured felt under a ramp
# is only approximately its surroundings' mean).
FELT_SEEN_FRACTION = 0.25


def learn_background(samples: np.ndarray, radius_px, where: np.ndarray | None = None) -> Background:
    """Learn the felt from frames spread over a video.

    Parameters
    ----------
    samples : ndarray, shape (n, h, w), uint8 or float32
        Grey (or projected colour, :mod:`cuespin.track.colour`) frames
        spread over the video.
    radius_px : float or RadiusMap
        Expected ball radius (px), or its map over the image under
        perspective (:mod:`cuespin.track.radius`).
    where : ndarray of bool, shape (h, w), optional
        Where the ball may be (the playing surface): the polarity and the
        contrast are learnt there only.

    Returns
    -------
    Background
        ``polarity`` and ``contrast`` are 0 when nothing moved (no ball seen
        anywhere, or it never left its rest spot).
    """
    n, H, W = samples.shape
    radii = as_radius_map(radius_px, (H, W))
    sigma = noise_sigma(samples[0], samples[n // 2]) if n > 1 else 0.0
    lo = samples.min(axis=0)
    hi = samples.max(axis=0)
    image = samples.mean(axis=0, dtype=np.float32)
    # The range of n Gaussian samples exceeds ~7.5 sigma in about 1 pixel in
    # 10^4 for n = 25; those few noise pixels are harmless below.
    span = hi.astype(np.float32) - lo.astype(np.float32)
    spread = (span > spread_threshold(span, 7.5 * max(sigma, 0.5) + 2)) & ~flicker(span, image)
    spread = cv2.dilate(spread.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    ys, xs = np.nonzero(spread)
    wide = ball_wide(spread, radii)
    if wide.sum() < MIN_AREA_FRACTION * np.pi * radii.r_min**2:  # no ball-like thing moved
        return Background(image=image, sigma=sigma, polarity=0, contrast=0.0, n_samples=n,
                          path_pixels=int(len(ys)), weak_samples=np.zeros(n, bool))
    S = samples[:, ys, xs].astype(np.float32)  # (n, m) samples on the path
    med = np.median(S, axis=0)
    # The ball's side of each path pixel is its samples' extreme farther from
    # the felt around the path (the felt is smooth over a few ball widths),
    # not from their median: a ball resting through most of the samples is
    # their median where it rests (a late strike: 121 of 145 look-ahead
    # frames at 480 fps, sample_scenes(6, 7, realistic, MJPG)[1]), and the
    # vacated and newly covered crescents then voted evenly and chose the
    # wrong side by noise.
    ref_img = felt_around(image, spread, radii.r_max)  # a window no ball fills
    ref = ref_img[ys, xs]
    ref = np.where(np.isfinite(ref), ref, med)
    up = S.max(axis=0) - ref
    down = ref - S.min(axis=0)
    # Only where some sample showed the felt there: a ball at rest (or a
    # sight, a pocket) whose edge a lossy codec makes flicker stays on one
    # side of the felt in every sample, and voted for its own colour.
    near, far = np.minimum(np.abs(up), np.abs(down)), np.maximum(np.abs(up), np.abs(down))
    felt_seen = near <= np.maximum(felt_band(sigma), FELT_SEEN_FRACTION * far)
    strong = (np.abs(up - down) > 4 * max(sigma, 0.5)) & wide[ys, xs] & felt_seen
    if where is not None:
        strong &= where[ys, xs]
    strong &= ~stick_parts(xs, ys, strong, radii.r_min, (H, W))
    polarity = ball_side(samples, np.where(np.isfinite(ref_img), ref_img, image), ys[strong], xs[strong],
                         radii.r_min)  # a box every ball fills
    P = polarity * S  # ball is high in P
    felt0 = felt_nearest(P, felt_band(sigma), polarity * ref)
    # Where the ball came and went: samples span a good part of its contrast
    # (a resting ball's rim spreads by the codec's error at an edge).  The
    # scale is the largest spans: a lossy codec smooths the noise the spread
    # test is set by (MJPG, 4.5 per channel: sigma read as 1.2) but not its
    # error at edges, so the rims of balls at rest spread too.
    span = P.max(axis=0) - felt0
    swept = np.zeros((H, W), bool)
    if strong.any():
        swept[ys, xs] = span > SWEPT_FRACTION * np.percentile(span[strong], SWEPT_PERCENTILE)
    # The contrast is the ball's lit middle among the swept pixels only: on
    # MJPG the pockets' and sights' flicker, the ball's ringing halo (the far
    # side of the felt) and the dilated path's rim passed as moved, half of
    # them within 11 levels of the felt, and the 75th percentile over all fell
    # to 8.8 where the ball departs ~190 (realistic seed 0 shot 12, MJPG: 2295
    # pixels, 269 swept; shot 7: 110 against 400).  On FFV1: shots 12 and 7
    # 138 -> 141, 135 -> 139; shot 3 (a blue logo ball on blue) 72 -> 90.
    ball = strong & swept[ys, xs]
    contrast = float(np.percentile(span[ball], 75)) if ball.any() else 0.0
    # Felt samples lie within noise of the felt; a pixel partly covered by
    # the ball lies between, so the band is set by the noise, not the contrast.
    band = felt_band(sigma)
    felt = felt0
    for slack in (2.5 * sigma, 0.0):  # felt0 is one sample: ~2 sigma off the felt's mean
        keep = np.abs(P - felt) < band + slack
        felt = np.where(keep.any(axis=0),
                        (P * keep).sum(axis=0) / np.maximum(keep.sum(axis=0), 1), felt0)
    # Away from where the ball went, what moved (a cue, its shadow) may lie on
    # either side of the felt: there the felt is the samples near the median
    # (the felt shows in most of them), not the far side from the ball.
    near = cv2.dilate(wide.astype(np.uint8), np.ones((7, 7), np.uint8)).astype(bool)[ys, xs]
    if not near.all():
        Pm = P[:, ~near]
        keep_m = np.abs(Pm - np.median(Pm, axis=0)) < band
        felt_m = (Pm * keep_m).sum(axis=0) / np.maximum(keep_m.sum(axis=0), 1)
        felt[~near] = felt_m
        keep[:, ~near] = keep_m
    image[ys, xs] = polarity * felt
    # The hidden-felt window must be one the largest ball cannot fill.
    image = fill_unseen(image, hidden_ball(image, swept, polarity, contrast, sigma, radii.r_max))
    count = keep.sum(axis=0)
    weak = (count < MIN_FELT_SAMPLES) & (count < n)
    weak_samples = keep[:, weak].any(axis=1) if weak.any() else np.zeros(n, bool)
    # The ball's own search score where it is in the samples: the detection
    # threshold is set from it (BallTracker), not from the pixel contrast,
    # which a shaded ball's box score need not follow (red on red, H.264,
    # sample_scene(14, realistic): contrast 106, the ball's score 28).
    # On the playing surface only, as the search is: the ball crossing the
    # cushion there scored 54 against the rail's cloth.
    on = swept & where if where is not None else swept
    r_path = float(np.median(radii.image()[on])) if on.any() else radii.r_centre
    score = ball_score(samples, image, polarity, contrast, on, r_path)
    return Background(image=image, sigma=sigma, polarity=polarity, contrast=contrast,
                      n_samples=n, path_pixels=int(len(ys)), weak_samples=weak_samples,
                      moved_px=int(strong.sum()), score=score,
                      moved_band=band_extent(xs[strong], ys[strong]))


# Moved pixels within this many ball radii of each other are one part (one
# mover): the cue's withdrawal over a pocket left 16 pieces of 1-295 px within
# 3-8 px (0.3-0.7 r) of each other (realistic --mix seed 9 shot 1, grey FFV1,
# r = 11.9 px); the ball's vacated and newly covered crescents lie a diameter
# less its move apart.  Kernels of 7, 13 and 25 px gave the same two parts.
PART_GAP_RADII = 1.0


def stick_parts(xs: np.ndarray, ys: np.ndarray, strong: np.ndarray, r: float, shape: tuple) -> np.ndarray:
    """Which ``strong`` moved pixels at ``xs``, ``ys`` belong to a part that is
    a stick (:func:`cuespin.track.video.cue_band`), when some other part is
    not: the cue's motion is then left out of what the ball is learnt from.

    Parts are the pixels within ``PART_GAP_RADII`` ball radii ``r`` (px) of
    each other.  When every part is a stick nothing is left out (the look-ahead
    saw only the cue, :func:`cuespin.track.video.cue_moved` judges it whole).
    Realistic --mix seed 9 shot 1 on grey FFV1: one look-ahead holds the whole
    video, the cue (11.5 x 42.8 px) and the ball's crescents (19.5 x 35.1 px)
    together were 16.8 x 720 px, and the model learnt from both lost 189 of
    193 frames.
    """
    from cuespin.track.video import cue_band  # video imports this module

    out = np.zeros(len(xs), bool)
    if not strong.any():
        return out
    m = np.zeros(shape, np.uint8)
    m[ys[strong], xs[strong]] = 1
    d = max(3, int(round(PART_GAP_RADII * r)) | 1)  # r / 2 each side: gaps under r joined
    n, lab = cv2.connectedComponents(cv2.dilate(m, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (d, d))))
    part = np.where(strong, lab[ys, xs], 0)
    stick = np.zeros(n, bool)
    for i in range(1, n):
        on = part == i
        stick[i] = cue_band(band_extent(xs[on], ys[on]), r)
    if stick[1:].all():
        return out
    return stick[part] & strong


# Samples that must agree (within felt_band) for a sample to count as the
# felt: a thin object crossing a path pixel in one sample (the cue's chalked
# tip, darker than the felt, measured on sample_scene(3, realistic, FFV1))
# was taken for the felt there.
FELT_SUPPORT = 2


def felt_nearest(P: np.ndarray, band: float, ref: np.ndarray) -> np.ndarray:
    """The felt's first estimate at each path pixel (column) of ``P`` (n, m):
    among the samples that ``FELT_SUPPORT - 1`` others lie within ``band``
    of, the one nearest ``ref`` (m,), the felt around the path; the sample
    nearest ``ref`` where none is so supported (the ball covered the pixel
    in all samples but one).

    Nearest the felt around, not the samples' far side from the ball: a
    shaded ball close to the felt's colour is brighter in its middle and
    darker at its rim, so no side of the felt is the ball's everywhere (red
    on red, sample_scenes(6, 7, realistic, MJPG)[5]: the ball's middle where
    it came to rest was taken for felt, and found as a ball in every frame
    before it got there).
    """
    d = np.abs(P - ref)
    support = np.stack([(np.abs(P - P[j]) <= band).sum(axis=0) for j in range(len(P))])
    d_sup = np.where(support >= FELT_SUPPORT, d, np.inf)
    j = np.where(np.isfinite(d_sup.min(axis=0)), d_sup.argmin(axis=0), d.argmin(axis=0))
    return np.take_along_axis(P, j[None], axis=0)[0]


def median_u8(img: np.ndarray, k: int) -> np.ndarray:
    """OpenCV's k x k median (uint8 only for large k) of a float image, mapped
    affinely onto 0..255 and back (projected colour levels may leave 0..255);
    the step is at most one level for grey images."""
    lo, hi = float(img.min()), float(img.max())
    scale = max((hi - lo) / 255.0, 1.0)
    u8 = np.clip(np.rint((img - lo) / scale), 0, 255).astype(np.uint8)
    return cv2.medianBlur(u8, k).astype(np.float32) * scale + lo


# A pixel the ball came and went over spans more than this fraction of the
# contrast over the samples (a shaded ball's rim is darker than its middle).
SWEPT_FRACTION = 0.25
# The percentile of the spans over the moving ball-wide pixels that gives the
# ball's own span (the ball's sweep covers well over 1% of them).
SWEPT_PERCENTILE = 99
# The ring (px wide) around a candidate hidden region, and the fraction of it
# that must lie on the path: the lens a slow ball covers in every sample is
# ringed by path all round but at the lens's tips; a resting ball the moving
# one passes close to touches the path on one side at most (< 0.5).
HIDDEN_RING_PX = 2
HIDDEN_RING_ON_PATH = 0.6


def hidden_ball(image: np.ndarray, path: np.ndarray, polarity: int, contrast: float, sigma: float,
                radius_px: float) -> np.ndarray:
    """Pixels near the ball's path that no sample showed as felt.

    ``path`` is where the ball came and went (samples spanning a good part
    of its contrast).  A ball that moves less than its radius between its
    rests covers some pixels in every sample; they show no spread, so the learnt "felt" there
    is ball, the tracker finds nothing at either rest, and the frames it
    does find are biased (measured: v0 42% off on a 14-px shot).  Such
    pixels stand out from the felt around them (a median over a window
    twice the ball's width, which the ball cannot fill) by the ball's
    contrast; the pixels around them partly covered in every sample, by
    more than :func:`felt_band`.

    Returns
    -------
    ndarray of bool, shape (h, w)
        For :func:`fill_unseen`; all False when nothing is hidden.
    """
    hidden = np.zeros(image.shape, bool)
    if not path.any() or contrast <= 0:
        return hidden
    k = 4 * int(np.ceil(radius_px)) + 1
    vs, us = np.nonzero(path)
    v0, v1 = max(vs.min() - k, 0), min(vs.max() + k + 1, image.shape[0])
    u0, u1 = max(us.min() - k, 0), min(us.max() + k + 1, image.shape[1])
    patch = image[v0:v1, u0:u1]
    local = median_u8(patch, k)
    excess = polarity * (patch - local)
    core = (excess > 0.5 * contrast).astype(np.uint8)
    if not core.any():
        return hidden
    near = cv2.dilate(core, np.ones((5, 5), np.uint8)).astype(bool)
    cand = core.astype(bool) | (near & (excess > felt_band(sigma)))
    # Only what the path surrounds was hidden by the ball: the pixels the ball
    # covered in every sample are ringed by those it covered in some (which
    # spread).  Anything else that stands out (another ball at rest, a
    # sight, a pocket) is part of the scene and stays in the felt: filled in,
    # it became a ball-like blob the tracker followed (realistic MJPG, seed 5:
    # a resting yellow ball tracked 211 px off the struck one; a red one
    # outscoring a white ball in every frame).
    n, labels = cv2.connectedComponents(cand.astype(np.uint8), connectivity=8)
    on_path = path[v0:v1, u0:u1]
    ring_k = np.ones((2 * HIDDEN_RING_PX + 1,) * 2, np.uint8)
    for j in range(1, n):
        blob = labels == j
        ring = cv2.dilate(blob.astype(np.uint8), ring_k).astype(bool) & ~blob
        if ring.any() and on_path[ring].mean() >= HIDDEN_RING_ON_PATH:
            hidden[v0:v1, u0:u1] |= blob
    return hidden


# Whole frames summed in 16 bits before they are carried into float32:
# 257 * 255 = 65535 is the most a uint16 holds.
FULL_CARRY = 257


_NO_WINDOW = np.zeros((1, 1), np.float32)
_NO_MASK = np.zeros((1, 1), bool)


class FeltAccumulator:
    """Running mean of the felt over the tracked frames, the ball masked out.

    The sampled background's error (noise / sqrt(samples)) is the same in
    every frame, so frames that see the same pixels (the rest before the
    strike, slow rolling, the final rest) share it as a common bias, which
    a fit of the whole track would read as signal.  Averaging hundreds of
    frames' felt makes that bias negligible.  Two kinds of frames are added:
    every fit's projected window (cheap, the felt each fit needs, but only
    around where the ball is now), and every ``FULL_EVERY``-th whole frame as
    decoded (BGR or grey; the felt under a rest spot is seen by the frames
    before the ball arrives there and after it leaves).  A linear projection
    commutes with the mean, so whole frames are projected once, at the end.
    """

    def __init__(self, shape):
        self.total = np.zeros(shape[:2], np.float32)
        self.count = np.zeros(shape[:2], np.int32)
        self.full = np.zeros(shape, np.float32)
        # Whole frames are summed in 16 bits first (numpy's add, u8 into u16:
        # 0.45 ms a 1280 x 640 BGR frame against cv2.accumulate's 0.7-0.9 ms
        # into float32) and carried into ``full`` every FULL_CARRY frames,
        # before 255 * n could overflow; sums of whole levels, so exact either way.
        self._partial = np.zeros(shape, np.uint16)
        self._n_partial = 0
        # Whole frames that hid each pixel (the ball over it): the count of
        # frames showing it is n_full less this, with no full-size pass per frame.
        self.full_hidden = np.zeros(shape[:2], np.int32)
        self.n = 0
        self.n_full = 0

    @staticmethod
    def _disc(u0, v0, h, w, centre, radius):
        # The squares along each axis, broadcast (no full-size index grids:
        # mgrid cost 0.5 ms a whole-frame call's region; the same values).
        dx2 = (np.arange(u0, u0 + w) - centre[0]) ** 2
        dy2 = (np.arange(v0, v0 + h) - centre[1]) ** 2
        return dx2[None, :] + dy2[:, None] <= radius * radius

    def add(self, patch: np.ndarray, u0: int, v0: int, centre, radius: float, exclude=None,
            reference=None, tolerance: float = np.inf) -> None:
        """Add a projected window whose top-left pixel is ``(u0, v0)``, the
        ball (centre, radius in px) masked out, and the pixels ``exclude``
        (bool, the window's shape: something else there, the cue) too, and
        those departing from ``reference`` (the sampled felt, the frame's
        shape) by more than ``tolerance``."""
        h, w = patch.shape
        H, W = self.total.shape
        if u0 < 0 or v0 < 0 or u0 + w > W or v0 + h > H:
            return
        self.n += 1
        if patch.dtype == np.float32 and (reference is None or reference.dtype == np.float32) \
                and (exclude is None or exclude.dtype == bool):
            # Compiled (track.window.felt_add), the same sums; the tolerance
            # rounded to the dtype numpy's comparison below takes (a Python
            # float to float32, a numpy float64 not).
            from cuespin.track import window
            # The compiled loop does no bounds checks where numpy raised.
            assert exclude is None or exclude.shape == patch.shape, (exclude.shape, patch.shape)
            assert reference is None or reference.shape == self.total.shape, (reference.shape, self.total.shape)
            tol = float(np.result_type(patch.dtype, tolerance).type(tolerance))
            window.felt_add(self.total, self.count, patch, _NO_MASK if exclude is None else exclude,
                            exclude is not None, _NO_WINDOW if reference is None else reference,
                            reference is not None, tol, int(u0), int(v0), float(centre[0]), float(centre[1]),
                            float(radius))
            return
        self.add_numpy(self.total, self.count, patch, u0, v0, centre, radius, exclude, reference, tolerance)

    @staticmethod
    def add_numpy(total, count, patch, u0, v0, centre, radius, exclude=None, reference=None,
                  tolerance: float = np.inf) -> None:
        """:meth:`add`'s sums in numpy, into ``total`` and ``count``: its
        path for other dtypes, and the reference the compiled pass
        (track.window.felt_add) is held to bit for bit."""
        h, w = patch.shape
        felt = ~FeltAccumulator._disc(u0, v0, h, w, centre, radius)
        if exclude is not None:
            felt &= ~exclude
        if reference is not None:  # something other than felt: the cue, the ball's blurred rim
            felt &= np.abs(patch - reference[v0:v0 + h, u0:u0 + w]) <= tolerance
        total[v0:v0 + h, u0:u0 + w] += np.where(felt, patch, 0).astype(np.float32)
        count[v0:v0 + h, u0:u0 + w] += felt

    def add_frame(self, frame: np.ndarray, centre, radius: float, reference=None, projection=None,
                  tolerance: float = np.inf, reach: float = 0.0) -> None:
        """Add a whole decoded frame (uint8, grey or BGR), the ball masked out,
        and within ``reach`` (px) of it the pixels whose projected value
        (``projection``) departs from ``reference`` (the sampled felt) by
        more than ``tolerance``: the cue over the path at the strike."""
        if self._n_partial == FULL_CARRY:
            self._carry()
        from cuespin.track import window
        img = np.asarray(frame)  # (a PlanarFrame converted whole once)
        if img.dtype == np.uint8 and img.shape == self._partial.shape:
            # compiled, over the levels in memory order (a 4-channel frame's
            # BGR view copied first): the same sums
            window.add_levels(self._partial.reshape(-1), np.ascontiguousarray(img).reshape(-1))
        else:
            np.add(self._partial, frame, out=self._partial)
        self._n_partial += 1
        self.n_full += 1
        H, W = self.total.shape
        r = int(np.ceil(max(radius, reach if reference is not None else 0.0))) + 1
        u, v = int(round(centre[0])), int(round(centre[1]))
        u0, v0, u1, v1 = max(u - r, 0), max(v - r, 0), min(u + r + 1, W), min(v + r + 1, H)
        if u1 <= u0 or v1 <= v0:
            return
        P = None
        if reference is not None:
            P = projection(frame, v0, v1, u0, u1) if projection is not None else frame[v0:v1, u0:u1]
        # Taken back out where the ball (or the cue) was: those pixels only,
        # from the 16-bit sum, which holds this frame's levels (no wrap-around).
        if reference is None or reference.dtype == np.float32:
            # Compiled: numpy's masks, nonzero and fancy indexing over the
            # window of FOREIGN_REACH_RADII were ~1 ms a call (track.window).
            three = np.atleast_3d  # a grey frame and its sum as one channel (views, written through)
            window.hidden_pixels(three(self._partial), self.full_hidden, three(img),
                                 _NO_WINDOW if P is None else P, P is not None,
                                 _NO_WINDOW if reference is None else reference, float(tolerance),
                                 u0, v0, u1, v1, float(centre[0]), float(centre[1]), float(radius))
            return
        out = self._disc(u0, v0, v1 - v0, u1 - u0, centre, radius)
        out |= np.abs(P - reference[v0:v1, u0:u1]) > tolerance
        ys, xs = np.nonzero(out)
        self._partial[v0:v1, u0:u1][ys, xs] -= frame[v0:v1, u0:u1][ys, xs]
        self.full_hidden[v0:v1, u0:u1] += out

    def _carry(self) -> None:
        self.full += self._partial
        self._partial[:] = 0
        self._n_partial = 0

    def felt(self, fallback: np.ndarray, projection, min_frames: int = 20) -> np.ndarray:
        """The mean felt where at least ``min_frames`` frames showed it, else
        ``fallback`` (the sampled background); felt that no whole frame
        showed (a shot stopping within a diameter of its strike) is filled by
        :func:`fill_unseen`.

        ``projection`` maps the whole frames' sum to the windows' channel
        (:class:`cuespin.track.colour.Projection`; its offset counts once per frame).
        """
        self._carry()
        full_count = self.n_full - self.full_hidden
        full = projection(self.full) if self.full.ndim == 3 else self.full
        if projection.w is not None:  # the offset was added once to a sum of many
            full = full + np.float32(projection.offset) * (full_count - 1)
        total = self.total + np.where(full_count > 0, full, 0)
        count = self.count + full_count
        mean = total / np.maximum(count, 1)
        out = np.where(count >= min_frames, mean, fallback).astype(np.float32)
        # The windows left out what was not felt (the ball, the cue, anything
        # departing from the sampled felt); the whole frames could not (that
        # needs them projected, ~10 ms each at 1280 x 720) and hold the cue
        # where it lay over the path at the strike and in its follow-through
        # (measured on sample_scene(3, realistic, FFV1): up to 84 levels off at
        # the rest spot, which moved the fits there 1-12 px).  Where enough
        # windows saw the felt, their mean alone is the felt.
        windows = self.count >= min_frames
        out[windows] = (self.total[windows] / self.count[windows]).astype(np.float32)
        if self.n_full:  # felt no whole frame showed: a ball that never left it
            out = fill_unseen(out, (full_count == 0) & ~windows)
        return out


# Width (px) of the ring of seen felt a plane is fitted to around unseen pixels.
FILL_RING_PX = 4


def fill_unseen(felt: np.ndarray, unseen: np.ndarray) -> np.ndarray:
    """Felt at pixels no frame showed, from a plane through the felt around them.

    When a shot stops less than a diameter from where it was struck, the two
    rests and the path between cover a lens of pixels in every frame.  The
    samples there hold ball, or ball partly covering the felt, and a disc fit
    at either rest, subtracting that as felt, is pulled towards the other
    rest (measured: 0.03 px, ten times the stated error, on a 25-px shot).
    The felt is smooth over a ball's width (flat grey and lighting
    gradient), so each unseen patch gets the least-squares plane through the
    seen pixels in a ring ``FILL_RING_PX`` wide around it; a textured felt
    keeps an error of its texture's size there.

    Parameters
    ----------
    felt : ndarray, shape (h, w), float32
        Felt (grey levels), trusted where ``unseen`` is False.
    unseen : ndarray of bool, shape (h, w)

    Returns
    -------
    ndarray, shape (h, w), float32
        A copy of ``felt`` with unseen pixels replaced (unchanged when there
        are none, or no seen pixel around them).
    """
    if not unseen.any():
        return felt
    out = felt.copy()
    n, labels = cv2.connectedComponents(unseen.astype(np.uint8), connectivity=8)
    kernel = np.ones((2 * FILL_RING_PX + 1,) * 2, np.uint8)
    for k in range(1, n):
        vs, us = np.nonzero(labels == k)
        v0, v1 = max(vs.min() - FILL_RING_PX, 0), min(vs.max() + FILL_RING_PX + 1, felt.shape[0])
        u0, u1 = max(us.min() - FILL_RING_PX, 0), min(us.max() + FILL_RING_PX + 1, felt.shape[1])
        blob = (labels[v0:v1, u0:u1] == k).astype(np.uint8)
        ring = cv2.dilate(blob, kernel).astype(bool) & ~unseen[v0:v1, u0:u1]
        rv, ru = np.nonzero(ring)
        if len(rv) < 3:
            continue
        A = np.column_stack([np.ones(len(rv)), ru, rv]).astype(float)
        coef = np.linalg.lstsq(A, felt[v0:v1, u0:u1][ring].astype(float), rcond=None)[0]
        out[vs, us] = coef[0] + coef[1] * (us - u0) + coef[2] * (vs - v0)
    return out
