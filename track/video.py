"""Tracking the ball through a video: the tracker's I/O edge.

Frames stream from the decoder (a second thread, :mod:`cuespin.track.reader`)
and are never sought: the first ones are held in a look-ahead buffer
bounded in bytes, the background and the channel that best separates the
ball from the felt are learnt from frames spread over it, and from then on
each frame is tracked as it arrives and dropped.  When nothing moves within
the look-ahead (a late strike), its older half is given up (reported as
no ball) and the buffer slides on.  Memory is capped by the buffer,
whatever the video's length; the cost per frame is the tracker's.
"""

from __future__ import annotations

import csv
import os
import threading
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import cv2
import numpy as np

from cuespin.physics.scene import Scene
from cuespin.videoio import quiet_native_stderr
from cuespin.track.background import Background, FeltAccumulator, learn_background
from cuespin.track.colour import FELT_SHADE_MIN, GREY, Projection, learn_projection, shade_match
from cuespin.track.projection import projected_centres
from cuespin.track.misfit import LookMisfit, codec_variance, error_ar1, look_misfit
from cuespin.track.path import off_path
from cuespin.track.radius import RadiusMap
from cuespin.track.model import SphereLook, fit_disc, refit_shift, warm_up
from cuespin.track.reader import FrameSource, ThreadedFrames, TrackError, blank_frame, frame_times, probe
from cuespin.track.tracker import (BLANK, OFF_PATH, OK, PULLED, STATUS_TEXT, STICK_WIDTH_RADII, STILL_PX, BallTracker,
                                   TrackerConfig,
                                   beyond_ball, foreign_near, foreign_threshold, kept_pixels, pulled_fits)

# Bytes of decoded frames held before the background is learnt: 437 grey or
# 145 BGR frames at 1280 x 720 (at 240 fps, 1.8 s or 0.6 s of video; the
# realistic look's strike comes 0.1-0.5 s in).  A fixed cap: memory does not
# grow with the video's length.
LOOKAHEAD_BYTES = 384 * 2**20
LOOKAHEAD_MIN_FRAMES = 24
# Bytes the decoder may run ahead while the background is learnt and the
# look-ahead tracked, so that it does not stall meanwhile.
QUEUE_BYTES = 96 * 2**20
# The fastest a struck ball moves (m/s): a hard break is 8-11 m/s.
MAX_SPEED_M_S = 12.0
# The look-ahead slides on until what moved in it, where a ball fits,
# covers this many of the ball's areas (a ball that moved by about its
# diameter), so that the felt, the polarity and the channel are learnt from
# the ball's motion.  A crescent (the ball moved 4 px at the look-ahead's end,
# sample_scenes(6, 7, realistic, MJPG)[1]) gave a contrast of 9 where the
# ball's is ~250, and a resting ball's codec flicker became the ball.
LEARN_MOVED_AREA = 2.0
# What moved in a look-ahead is the cue, not the ball, when its pixels form
# a band narrower than STICK_WIDTH_RADII radii (tracker's stick rule) and
# longer than this many: a ball's sweep narrower than a radius is a crescent
# no longer than its diameter.  Realistic seed 9 shot 1 (--mix, a draw shot
# that stops 6.6 px from its rest spot, the cue withdrawing over a pocket):
# the ball's crescent 0.94 r wide, 1.80 r long; the look-ahead after it, the
# ball at rest throughout, saw only the cue's withdrawal, 0.91 r wide and
# 4.33 r long, and its model (the felt under the resting ball learnt as the
# ball, the channels the cue's) lost 70% of the frames.  The value from 42
# generated cue scenes (cue10, benchmarks/cue_rules.py, seeds 100-101, colour
# and grey, 436 look-aheads): nothing of the ball's narrower than a radius
# was longer than 1.73 r (626 moved parts, 343 moved bands; seed 9 shot 1's
# crescent 1.80), while the cue's moved bands narrower than a radius were
# 1.0-53 r long, 5 of the 18 2.2-3.0 r: at 3 r the rule caught 10 of 59
# cue-only look-aheads and 13 of 167 cue parts beside the ball, at 2.5 r 14
# and 15, none of the ball's either way.  (The width is what misses the rest:
# the cue's moved bands are 0.6-1.8 r wide, the ball's long ones from 1.07 r.)
STICK_MOVED_RADII = 2.5


def cue_band(band: tuple, r: float) -> bool:
    """Whether moved pixels of ``band`` = (width, length) (px,
    :func:`~cuespin.track.background.band_extent`) are a stick (the cue),
    not a ball of radius ``r`` (px): :data:`STICK_MOVED_RADII`."""
    width, length = band
    return width < STICK_WIDTH_RADII * r and length > STICK_MOVED_RADII * r


def cue_moved(bg: Background, r: float) -> bool:
    """Whether what moved in ``bg``'s samples is a stick (the cue), not a
    ball of radius ``r`` (px): :func:`cue_band`."""
    return cue_band(bg.moved_band, r)
# Every this many frames the whole decoded frame joins the felt average
# (cv2.accumulate: ~1 ms for a 1280 x 720 BGR frame, a quarter of it per frame).
FULL_FELT_EVERY = 4
# Within this many ball radii of the ball, a whole frame's pixels that show
# something other than the felt (the cue lying over the path behind the ball
# at the strike and in its follow-through, 4-5 cm past the contact point:
# 1.4-1.8 radii past the rest spot's centre) stay out of the felt's average.
# Farther away the frame is not projected (~10 ms a 1280 x 720 frame).
FOREIGN_REACH_RADII = 8.0
# The lit sphere is learnt again (track.sphere) against the felt averaged
# over the track where at least this many frames showed it, not the 20 of
# the fits' correction: the rest spot, where it is learnt, is shown only by
# the frames after the ball left, 5-38 on realistic shot 1 (seed 0, 60 fps,
# 0.8 s), and the sampled background there holds the resting ball's
# imprint (1.28 levels mean, 11.9 at most, off the renderer's felt; the
# mean of >= 5 frames 0.82 and 4.6, of >= 20 the imprint stays): the light's
# elevation learnt against it 1.464 rad, against this felt 1.404, against
# the renderer's own 1.402 (true 1.383).  Its noise (sigma / sqrt(5)) is a
# pattern no lit sphere matches; the imprint is the ball's shape.
SPHERE_FELT_FRAMES = 5


@dataclass
class TrackResult:
    """The ball's track through a video.

    Attributes
    ----------
    t : ndarray, shape (n,)
        Frame timestamps (s): ``k / fps``, or the container's presentation
        times where they depart from it (CONVENTIONS.md).
    uv : ndarray, shape (n, 2)
        Centre of the ball's image (px); NaN where not ``ok``.
    xy : ndarray, shape (n, 2)
        Centre on the table (m) through the inverse homography; NaN where not ok.
    ok : ndarray of bool, shape (n,)
    status : ndarray of int8, shape (n,)
        ``track.tracker`` status codes.
    stderr_px : ndarray, shape (n, 2)
        Standard error of ``uv`` from the disc fit (px), the root of
        ``cov_px``'s diagonal; NaN with ``moments``.
    radius_px : float
    background : Background
    error : str
        Empty, or what went wrong: the video ended early (truncated or
        corrupt; the frames before it are still here) or no ball was found.
    seconds : dict
        Wall time of the background model and of the tracking pass (s).
    lossless : bool
        The video's codec is lossless.  A lossy codec's error is a function
        of the image, so frames of a resting ball share it: they are one
        measurement, not many.
    inter_frame : bool
        The lossy codec predicts frames from others (H.264...): a moving
        ball's error is shared between neighbouring frames too.
    cov_px : ndarray, shape (n, 2, 2)
        Covariance of ``uv`` (px^2) by the sandwich over the fit, times
        ``look_factor`` on every frame (the recovery takes it off the
        rests it groups on a lossless codec:
        :func:`cuespin.recover.measurements.build_measurements`); convert
        to metres with
        ``scene.camera.cov_to_table(xy, cov_px)``.
    look_factor : float
        What the per-frame fits' covariances were multiplied by: the track's
        own measure of what the ball's model misses (a realistic ball's
        shading, highlight and turning markings: an error shared by
        neighbouring frames), :func:`cuespin.track.misfit.look_misfit`,
        measured on a shaded look and on any look on a lossy codec; 1
        when the stated errors hold (a ball the model describes) or on a
        disc on lossless video, which is left as stated.
    look_rho : float
        Lag-1 correlation between consecutive frames of the error that
        factor adds (0: none added, or independent): the errors are then
        correlated along the track, and a resting ball's frames share it.
    look_shaded : bool
        The fits modelled the ball's look (shaded, or still learning it:
        ``track.tracker`` chose it because the first frames showed the disc
        does not describe the ball); False: the disc.
    projection : Projection
        The channel the ball was tracked in (weights on B, G, R learnt from
        the video; ``w`` None for grey video).
    camera : Camera or None
        The scene's camera, its size filled from the video where absent.
    fit_rms : ndarray, shape (n,), or None
        Each frame's fit residual RMS (projected levels; NaN where no fit
        converged), including the frames dropped as pulled
        (:func:`cuespin.track.tracker.pulled_fits`).
    touched : ndarray of bool, shape (n,), or None
        Frames whose fit found something other than the felt beside the ball
        (the cue at the strike, another ball) and left it out, or whose
        window still holds the spot the ball rested on (:func:`leaving_rest`);
        the recovery leaves out the first frames after the strike only where
        these show it (``recover_track(touched=...)``).
    foreign : ndarray of bool, shape (n,), or None
        The frames of ``touched`` whose fit found something other than the
        felt beside the ball (the cue at the strike, another ball), apart
        from those leaving the rest and from the felt's ghost of the rest
        spot (:func:`~cuespin.track.tracker.foreign_seen`): only a run of
        these may start a frame or two after the strike
        (``recover_track(foreign=...)``, recover.measurements.touched_run_s).
    warning : str
        Empty, or why the stated errors (``stderr_px``, ``cov_px``) are not
        calibrated for this video (:attr:`cuespin.track.reader.VideoInfo.error_warning`:
        4:1:1 and 4:1:0 chroma); the track itself is used as on any video.
    """

    t: np.ndarray
    uv: np.ndarray
    xy: np.ndarray
    ok: np.ndarray
    status: np.ndarray
    stderr_px: np.ndarray
    radius_px: float
    background: Background
    error: str = ""
    seconds: dict = field(default_factory=dict)
    lossless: bool = False
    inter_frame: bool = False
    cov_px: np.ndarray | None = None
    projection: Projection = GREY
    camera: object = None
    look_factor: float = 1.0
    look_rho: float = 0.0
    look_shaded: bool = False
    fit_rms: np.ndarray | None = None
    touched: np.ndarray | None = None
    foreign: np.ndarray | None = None
    warning: str = ""

    def __post_init__(self):
        if self.cov_px is None:
            cov = np.zeros((len(self.stderr_px), 2, 2))
            cov[:, 0, 0], cov[:, 1, 1] = np.square(self.stderr_px).T
            self.cov_px = cov

    @property
    def n_frames(self) -> int:
        return len(self.t)

    @property
    def independent_errors(self) -> bool:
        """Each frame's error is its own: a lossless codec and a ball the
        disc describes (not ``look_shaded``, ``look_factor`` 1).  Otherwise
        the error is a function of the image (a lossy codec's, a look the
        model misses), shared by a resting ball's frames: what the recovery
        passes as ``independent`` (a rest one measurement; the codec's
        unstated share is measured from the fit's residuals only on a lossy
        codec, ``lossless``).

        A shaded look counts even when the track shows no misfit (look
        factor 1): what the model misses of a still ball is the same in
        every frame of its rest and differs from a moving ball's (blur,
        markings turning), which displaces the path from the rest as a
        sideways slip would.  Measured against the truth on 22 realistic
        FFV1 renders rolling from the strike (benchmarks/accuracy.py --look
        realistic --preset case4, seed 4): the moving ball's median error
        across its path minus the first rest's mean, RMS 0.7 (up to 1.5) of
        one frame's stated error; as independent frames the rest's mean
        states 1/sqrt(n) of it, and free slip was chosen on 6 of 24 (3
        answered ok, v0 10-13 stated errors off); as one measurement of one
        frame's error, and the cue's frames left out
        (recover.measurements.CUE_CLEAR_R), on 2 (degenerate), none ok."""
        return bool(self.lossless) and self.look_factor == 1.0 and not self.look_shaded

    @property
    def error_ar1(self) -> float:
        """Lag-1 correlation of the AR(1) error model equivalent to the
        stated error (``cov_px``, the look's correlated share;
        :func:`cuespin.track.misfit.error_ar1`): what the recovery passes as
        ``ar1_floor``."""
        return error_ar1(self.look_factor, self.look_rho)

    @property
    def centroid_noise_px(self) -> float:
        """Typical per-axis standard error of a centroid (px), NaN if unknown."""
        se = self.stderr_px[self.ok]
        return float(np.nanmedian(se)) if se.size and np.isfinite(se).any() else float("nan")

    def status_counts(self) -> dict[str, int]:
        """How many frames had each status."""
        vals, counts = np.unique(self.status, return_counts=True)
        return {STATUS_TEXT[int(v)]: int(c) for v, c in zip(vals, counts)}


def open_video(path) -> cv2.VideoCapture:
    """An OpenCV capture that decodes to BGR (the tracker's own decoder
    settings; for decode-only baselines), or :class:`TrackError`."""
    info = probe(path)
    if info.backend != "cv2":
        raise TrackError(f"{path}: OpenCV cannot open the video (PyAV can: {info.codec})")
    with quiet_native_stderr():
        return cv2.VideoCapture(str(path), cv2.CAP_FFMPEG)


def decode_seconds(path) -> tuple[float, int]:
    """Decode every frame of a video to BGR with :func:`open_video` and
    nothing else: the decode-only baseline the benchmarks time tracking and
    recovery against.  Returns (seconds, frames); opening is not timed."""
    cap = open_video(path)
    clock = time.perf_counter()
    n = 0
    while cap.read()[0]:
        n += 1
    seconds = time.perf_counter() - clock
    cap.release()
    return seconds, n


def search_mask(cam, table, R: float, shape, grow_px: float | None = None) -> np.ndarray:
    """Pixels where the ball's centre may be: the playing surface's image, grown by R.

    Centres lie within the table's rectangle (a ball touching a cushion has
    its centre R inside it); R more of margin covers a homography that is a
    little off.  Rails, pockets and sights outside are never searched.
    ``grow_px``: the margin in px (default R at the image centre's scale;
    under perspective the largest ball's radius, :class:`RadiusMap`).
    """
    h, w = shape
    n = 16  # points per side: a lens bends the table's edges
    s = np.linspace(0.0, 1.0, n, endpoint=False)
    L, W = table.length, table.width
    pts = np.concatenate([np.c_[s * L, 0 * s], np.c_[L + 0 * s, s * W], np.c_[L - s * L, W + 0 * s],
                          np.c_[0 * s, W - s * W]])
    uv = np.asarray(cam.to_pixels(pts), float)
    mask = np.zeros((h, w), np.uint8)
    if not np.all(np.isfinite(uv)):
        return np.ones((h, w), bool)
    cv2.fillPoly(mask, [np.round(uv).astype(np.int32)], 1)
    centre = cam.to_table([[w / 2, h / 2]])[0]
    grow = int(np.ceil(R * cam.px_per_m(centre) if grow_px is None else grow_px)) + 1
    mask = cv2.dilate(mask, np.ones((2 * grow + 1, 2 * grow + 1), np.uint8))
    return mask.astype(bool)


def _warm_up() -> None:
    """The compiled fit's and window kernels' warm-up (:func:`cuespin.track.model.warm_up`,
    :func:`cuespin.track.window.warm_up`); a failure is left for the tracker's own call."""
    warm_up()
    try:
        from cuespin.track import window
        window.warm_up()
    except Exception:  # the tracker's own call reports it
        pass


def learn_model(frames: list, radius_px, n_samples: int,
                where: np.ndarray | None = None, lossless: bool = True,
                blind_to_felt: bool = False, chroma_block=1) -> tuple[Projection, Background]:
    """The projection and the background from ``n_samples`` frames spread over
    ``frames`` (the look-ahead), plus as many again where a resting ball hid
    the felt from most of the first ones.  ``radius_px``: the ball's radius
    (px) or its :class:`~cuespin.track.radius.RadiusMap`; ``where``: the
    playing surface (:func:`search_mask`); ``lossless``: the video's codec
    is lossless (:func:`~cuespin.track.colour.channel_rule`);
    ``blind_to_felt``: on a lossy codec the channel blind to the felt's
    colour (:func:`~cuespin.track.colour.learn_projection`);
    ``chroma_block``: the pixels sharing one chroma sample, a square's side
    or (across, down) (the reader's ``VideoInfo.chroma_block``).  Blank frames
    (:func:`~cuespin.track.reader.blank_frame`: a black lead-in, a fade) are
    left out: they would teach a felt and a colour projection of black."""
    n = len(frames)
    idx = np.unique(np.linspace(0, n - 1, n_samples).round().astype(int))
    # The clean video's samples less the blank ones, not spread again: a
    # black first frame respaced the samples and left the strike frame
    # pulled (FFV1 test, blank1).  Spread over the frames that are not
    # blank when fewer than half the samples are left (a long black lead-in).
    seen = np.array([not blank_frame(frames[i]) for i in idx])
    if 2 * seen.sum() < len(idx):
        frames = [f for f in frames if not blank_frame(f)] or frames
        n = len(frames)
        idx = np.unique(np.linspace(0, n - 1, n_samples).round().astype(int))
    else:
        idx = idx[seen]
    colour = frames[0].ndim == 3
    samples = np.stack([frames[i] for i in idx])
    proj = learn_projection(samples, radius_px, lossless, blind_to_felt, chroma_block) if colour else GREY
    P = proj.many(samples) if colour else samples
    bg = learn_background(P, radius_px, where)
    if bg.weak_samples.any():
        # Sample the stretch whose frames showed the hidden felt, reaching
        # half a spacing beyond it on each side.
        shown = idx[bg.weak_samples]
        gap = max(n // max(n_samples - 1, 1), 1)
        lo, hi = max(shown.min() - gap // 2, 0), min(shown.max() + gap // 2, n - 1)
        extra = np.setdiff1d(np.linspace(lo, hi, n_samples).round().astype(int), idx)
        extra = extra[[not blank_frame(frames[i]) for i in extra]]
        if len(extra):
            more = np.stack([frames[i] for i in extra])
            P = np.concatenate([P, proj.many(more) if colour else more])
            bg = learn_background(P, radius_px, where)
    return proj, bg


def track_video(path, scene: Scene, config: TrackerConfig = TrackerConfig(),
                progress=None) -> TrackResult:
    """Track the ball through a video.

    Parameters
    ----------
    path : str or Path
        Any video OpenCV or PyAV reads, in any pixel format.
    scene : Scene
        ``physics``, ``table`` and ``camera`` are used (never ``render``).
    config : TrackerConfig
    progress : callable, optional
        ``progress(n)`` after each ``n`` frames.

    Returns
    -------
    TrackResult

    Raises
    ------
    TrackError
        Missing or unreadable file, zero frames, or a frame size that
        disagrees with the scene.  A video that ends early or shows no ball
        still returns a result, with ``error`` saying so.
    """
    info = probe(path)
    w, h = info.width, info.height
    if info.n_frames <= 0 and w == 0:
        raise TrackError(f"{path}: the video has no frames")
    cam = scene.camera.with_size(w, h)  # a scene may leave the size to the video (CONVENTIONS.md)
    if (w, h) != (cam.width, cam.height):
        raise TrackError(f"{path}: frames are {w}x{h} but the scene's camera says "
                         f"{cam.width}x{cam.height}; is this the right scene file?")
    R = scene.physics.R
    center = cam.to_table([[cam.width / 2, cam.height / 2]])[0]
    radius_px = R * cam.px_per_m(center)
    mask = search_mask(cam, scene.table, R, (h, w))
    # The ball's size over the image (one radius for a similarity camera),
    # and the playing surface grown by the largest.
    radii = RadiusMap((h, w), radius_px, cam, R, region=mask)
    if radii.r_max > radius_px:
        mask = search_mask(cam, scene.table, R, (h, w), grow_px=radii.r_max)
    # The playing surface and a pixel (search_mask adds one to the margin): where the ball is first found.
    surface = search_mask(cam, scene.table, R, (h, w), grow_px=0.0)

    source = FrameSource(path, info, planes=config.planes)
    frame_bytes = max(w * h * 3, 1)
    feed = ThreadedFrames(source, QUEUE_BYTES // frame_bytes) if config.threaded else source
    if config.threaded and config.refine == "fit":
        # The compiled fit loads (numba: ~0.7 s of CPU a process; after an
        # install it compiles, ~13 s once) on a helper thread while the
        # look-ahead fills, when this thread only waits for frames.
        threading.Thread(target=_warm_up, daemon=True).start()
    frames = iter(feed)
    error = ""
    ended = False
    k_read = 0

    def pull():
        nonlocal error, ended, k_read
        if ended:
            return None
        try:
            img = next(frames)
        except StopIteration:
            ended = True
            return None
        except Exception as exc:  # a decoding failure ends the video here
            error = f"decoding failed at frame {k_read}: {exc}"
            ended = True
            return None
        if img.shape[:2] != (h, w):
            error = f"frame {k_read} has size {img.shape[1]}x{img.shape[0]}"
            ended = True
            return None
        k_read += 1
        return img

    uv, cov, status, rms = [], [], [], []
    t_start = time.perf_counter()
    try:
        first = pull()
        if first is None:
            raise TrackError(f"{path}: the video has no frames that decode")
        # Counted as decoded 8-bit frames (a PlanarFrame holds half of that).
        ahead = max(LOOKAHEAD_MIN_FRAMES, LOOKAHEAD_BYTES // int(np.prod(first.shape)))
        buf = [first]
        while len(buf) < ahead and (img := pull()) is not None:
            buf.append(img)
        n_dropped = 0
        best = None  # the model of the look-ahead where the ball moved most

        def saw_move(bg) -> bool:
            # The smallest ball in view: under perspective a far ball moving a
            # diameter sweeps less than the image centre's would.
            return bool(bg.polarity) and not cue_moved(bg, radii.r_min) and \
                bg.moved_px >= LEARN_MOVED_AREA * np.pi * radii.r_min**2

        # The channel is chosen with the chroma's error shared by its block
        # (colour.chroma_shared) on an inter-frame codec (H.264) only: an
        # intra-frame codec's chroma channel is fitted on its blocks, its
        # error stated with JPEG_CHROMA_VAR (track.misfit), and moved off it
        # realistic seed 9 shot 4 (white on blue, MJPG) was stated 2.13
        # times short (1.08 on the chroma; docs/measurements.md, chroma36).
        shared = info.chroma_block if info.inter_frame else 1
        while True:
            proj, bg = learn_model(buf, radii, max(config.n_background, 2), mask, bool(info.lossless),
                                   chroma_block=shared)
            if bg.polarity and not cue_moved(bg, radii.r_min) and (best is None or bg.moved_px > best[1].moved_px):
                best = (proj, bg)
            if saw_move(bg):
                # The ball's shaded side fades into the felt in the codec's
                # chroma (colour.FELT_SHADE_MIN): the channel blind to the
                # felt's colour, judged on the model that saw the ball move
                # (on a look-ahead where it rested, another mover's colours
                # are judged: sample_scenes(6, 5, realistic, MJPG)[5]'s
                # first look-ahead read 0.92, and the felt-blind channel
                # learnt there tracked something 68 radii off).
                if proj.luma_blind and not info.lossless and \
                        FELT_SHADE_MIN < shade_match(proj, bg.polarity, bg.contrast) < 1.0:
                    fb = learn_model(buf, radii, max(config.n_background, 2), mask, False, blind_to_felt=True,
                                     chroma_block=shared)
                    if saw_move(fb[1]):
                        proj, bg = fb
                break
            if ended:  # the ball never moved a diameter: the most it did
                if best is not None:
                    proj, bg = best
                break
            # The ball has not moved enough within the look-ahead: slide on
            # past its older half, decoded again once the model is learnt.
            drop = len(buf) // 2
            n_dropped += drop
            buf = buf[drop:]
            while len(buf) < ahead and (img := pull()) is not None:
                buf.append(img)
        t_bg = time.perf_counter() - t_start
        # The top speed in px at the largest scale in view (the scale goes
        # with the ball's radius): near a tilted camera a px is fewer metres.
        max_step = MAX_SPEED_M_S / cam.fps * cam.px_per_m(center) * radii.r_max / radius_px
        # The lit sphere on lossless video only: on a lossy codec its errors
        # are the codec's bias (15-130x the lossless bound), it stated them
        # worse than the quadratic look (err/se 1.3-4.6) and found centres
        # 0.25 R off in 10 frames of a highlighted ball at 480 fps (seed 0
        # shot 12 of the realistic benchmark, MJPG; 0 with the quadratic).
        sphere_cfg = replace(config, sphere=config.sphere and bool(info.lossless))
        tracker = BallTracker(bg, radius_px, cam.exposure_s * cam.fps, sphere_cfg, projection=proj,
                              search_mask=mask, max_step_px=max_step, camera=cam, R=R, radii=radii,
                              chroma_block=info.fit_block, inter_frame=bool(info.inter_frame), surface=surface)
        felt = FeltAccumulator(first.shape)
        foreign_level = foreign_threshold(bg.sigma, bg.contrast)
        fits = []  # (frame index, the fit's state) for the final background correction
        patches = {}  # frame index: its window (a lit sphere's fits, refitted with the felt correction)
        t_start = time.perf_counter()
        k = len(status)
        buf.reverse()  # pop() from the end: the oldest first, each dropped once tracked
        # The frames slid past (a long rest before the strike) from a second
        # pass over the video's start: they are tracked like any other.
        again = iter(FrameSource(path, info, planes=config.planes)) if n_dropped else None
        while True:
            if k < n_dropped:
                item = next(again, None)
                if item is None:  # the second pass ended early: the rest of it lost
                    uv.append(np.full(2, np.nan))
                    cov.append(np.full((2, 2), np.nan))
                    status.append(1)  # NO_BALL
                    rms.append(np.nan)
                    k += 1
                    continue
            else:
                item = buf.pop() if buf else pull()
            if item is None:
                break
            # With nothing moving there is no ball to separate from the felt.
            obs = tracker.step(k, item) if bg.polarity else tracker.nothing()
            # A blank frame where no ball was found is reported as blank.  A
            # frame is not left out before it is stepped: a grey ball 30
            # levels off its felt with no rails in view spans <= 32 levels
            # in some frames and is found there (dbg3 greyfirstok: 2 of 60
            # frames lost when blank frames were not stepped).
            if obs.status != OK and blank_frame(item):
                obs = tracker.nothing(BLANK)
            if obs.status == OK and tracker.last_patch is not None:
                blur_len = np.hypot(*tracker.last_fit.b)
                patch, pu, pv = tracker.last_patch
                # The ball's own size there, under perspective.
                mask_r = tracker.radius_with(tracker.last_fit.outline) + 0.5 * blur_len + 1.5
                felt.add(patch, pu, pv, obs.uv, mask_r, tracker.last_fit.foreign, bg.image, foreign_level)
                if k % FULL_FELT_EVERY == 0:
                    felt.add_frame(item, obs.uv, mask_r, bg.image, proj if proj.w is not None else None,
                                   foreign_level, FOREIGN_REACH_RADII * radius_px)
                fits.append((k, tracker.last_fit))
                if isinstance(tracker.shade, SphereLook) or tracker.shade is None:
                    patches[k] = patch  # refitted once the lit sphere is learnt again
            uv.append(obs.uv)
            cov.append(obs.cov)
            status.append(obs.status)
            rms.append(obs.rms)
            k += 1
            if progress is not None and k % 64 == 0:
                progress(64)
        if again is not None:
            again.close()  # releases its decoder
    finally:
        if config.threaded:
            feed.close()
    if progress is not None and k % 64:
        progress(k % 64)
    # The container's frame count is exact for intact files; a stream that
    # ends well short of it was cut off or is corrupt.
    n_hint = info.n_frames
    if not error and n_hint > 0 and k < n_hint - 1:
        error = f"the video ends at frame {k} of {n_hint} (truncated or corrupt)"
    uv = np.array(uv, float).reshape(-1, 2)
    cov = np.array(cov, float).reshape(-1, 2, 2)
    if fits and felt.n >= 20:
        # The felt averaged over the tracked frames: correct each fit for it.
        better = felt.felt(bg.image, proj)
        # The lit sphere learnt again against the felt (BallTracker.relearn_sphere),
        # taken where at least SPHERE_FELT_FRAMES frames showed it; the frames
        # are then refitted with it rather than shifted.
        # (Only with the lit sphere: relearn_sphere does nothing without it,
        # and the felt's whole-frame passes cost ~50 ms a 1280 x 640 video.)
        look = tracker.relearn_sphere(felt.felt(bg.image, proj, SPHERE_FELT_FRAMES)) \
            if patches and isinstance(tracker.shade, SphereLook) else None
        for kk, (pu, pv, ph, pw, c, b, G, fb, shade, outline, foreign, marks, _) in fits:
            old = bg.image[pv:pv + ph, pu:pu + pw]
            new = better[pv:pv + ph, pu:pu + pw]
            # Beyond the ball the fit's frame agreed with the old felt (else
            # those pixels were left out as foreign): where the averaged felt
            # departs from it as much, it holds something the frame does not
            # (a cue resting there in many frames), and the old felt stays.
            r_out = tracker.radius_with(outline)
            changed = foreign_near(bg.polarity * (new - old), pu, pv, c, b, r_out, bg.sigma, bg.contrast)
            if changed is not None:
                new = np.where(changed & beyond_ball(old.shape, pu, pv, c, b, r_out), old, new)
            valid = kept_pixels(foreign, marks)
            g = None
            if look is not None and kk in patches:
                g = fit_disc(patches[kk], new, pu, pv, c, radius_px, G, b0=b, fit_blur=fb, shade=look,
                             valid=valid, outline=outline, block=tracker.block)
            # A refit that explains its window worse than the frame's first
            # fit stopped in another minimum: the lit sphere's PSF model has one
            # ~0.26 radii along the shot line (sample_scene(3) FFV1, frame 60:
            # rms 8.55 -> 8.73 and 2.4 px off, every other frame's rms fell or
            # its centre moved < 0.2 px); it is shifted instead.
            if g and g.stated and g.rms <= rms[kk]:  # else shifted: its first fit stated its error
                uv[kk], cov[kk], rms[kk] = g.c, g.cov, g.rms
            else:
                uv[kk] = c + refit_shift(old, new, pu, pv, c, b, G, radius_px, fb, shade, outline, valid,
                                         tracker.block)
        bg = replace(bg, image=better)
    t_track = time.perf_counter() - t_start
    status = np.array(status, np.int8)
    rms = np.array(rms, float)
    # A false centre is worse than a missing one: fits that explain their
    # window much worse than the track's typical fit are dropped.
    found = status == OK
    step = np.full(len(uv), np.inf)  # the distance to the nearer found neighbour (px)
    d = np.hypot(*(uv[1:] - uv[:-1]).T)
    d = np.where(found[1:] & found[:-1], d, np.inf)
    step[1:] = d
    step[:-1] = np.minimum(step[:-1], d)
    se_px = np.sqrt(np.clip(np.diagonal(cov, axis1=1, axis2=2), 0, None)).max(axis=1)
    pulled = pulled_fits(rms, found, still=step < STILL_PX, se=se_px)
    status[pulled] = PULLED
    uv[pulled] = np.nan
    cov[pulled] = np.nan
    # Nor is a centre none of its neighbours can account for (the cue's tip
    # at the strike, a shaded ball's rim): the path decides (track.path).
    t = frame_times(path, info, k, cam.fps)
    jumped = off_path(uv, status == OK, radius_px, t=t, cov=cov)
    status[jumped] = OFF_PATH
    uv[jumped] = np.nan
    cov[jumped] = np.nan
    ok = status == OK
    # Frames whose fit found something other than the felt beside the ball
    # (the cue at the strike, another ball) and left those pixels out, and
    # those leaving the rest: the recovery leaves out the strike's first
    # frames only where the track flags them (recover.estimate, cue_clear_s).
    # The two kinds are kept apart as well: a run of the cue's may start a
    # frame or two late, the rest spot's may not (recover.measurements.touched_run_s).
    # ``touched`` keeps every frame whose fit left pixels out; ``foreign`` only those whose left-out pixels
    # hold something beyond the felt's ghost of the rest spot (the cue, another ball: LastFit.seen; fixvis).
    foreign = np.zeros(len(ok), bool)
    left_out = np.zeros(len(ok), bool)
    for kk, lf in fits:
        foreign[kk] |= lf.seen
        left_out[kk] |= lf.foreign is not None
    touched = leaving_rest(uv, ok, radius_px) | left_out
    if not ok.any():
        why = (" (the ball never moved, or is not in view; do physics.R and the camera "
               "match the video?)")
        error = f"no ball found in any of {k} frames" + (f"; {error}" if error else why)
    # The share of MJPG's error on the chroma's blocks that each frame's
    # sandwich leaves out (track.misfit.JPEG_CHROMA_VAR, measured against the
    # truth): before the look's factor, so that the track does not measure
    # it a second time.
    cov[ok] *= codec_variance(info.lossless, info.inter_frame, tracker.block)
    # What the ball's model misses, seen along the track (its stated errors
    # are the per-frame fits' own; see track.misfit).  Where the fits
    # modelled the look (shaded: the first frames showed the disc does not
    # describe the ball), and on a lossy codec whatever the look: a disc on
    # lossless video that does describe the ball is left as stated (its
    # err/se 0.91-1.02, benchmarks/track.py accuracy), and the kinks of a
    # short, low-noise track cannot then pass for a misfit; on H.264 the
    # disc's errors were 2.1-2.8 times too small, 1.1-1.4 with the factor
    # (docs/measurements.md, offv).
    if ok.any():
        uv[ok] = projected_centres(cam, uv[ok], R)  # the centre's image, not the silhouette's
    xy = np.full_like(uv, np.nan)
    xy[ok] = cam.to_table(uv[ok])
    # Measured on the path on the table, where the motion is a parabola or a
    # line: its image under perspective and a lens is not, and the third
    # differences of pixels kept the projection's curvature (1.5 m, 15 deg,
    # k1 +0.25: factor ~900, stated errors 30 times the real ones).  Table
    # metres at the image centre's scale, so that the misfit's thresholds
    # stay in px (a similarity camera: the same numbers as in px).
    misfit = LookMisfit()
    if bg.polarity and (tracker.shade is not False or not info.lossless) and ok.any():
        s = cam.px_per_m(center)
        cov_t = np.full_like(cov, np.nan)
        cov_t[ok] = cam.cov_to_table(xy[ok], cov[ok]) * s**2
        # frame times only at a variable rate: at k / fps the weights are
        # (-1, 3, -3, 1) and the constant-rate path is kept bit for bit
        variable = len(t) > 1 and np.ptp(np.diff(t)) > 1e-9 * np.mean(np.diff(t))
        misfit = look_misfit(xy * s, cov_t, ok, t=t if variable else None)
    # On every frame, as the moving ball's look: where a still ball's look is
    # one error shared by its rest (a lossless codec), the recovery takes the
    # factor off that rest's frames, the rest it groups (seg.t2, t0:
    # recover.measurements.build_measurements(look_factor=)), so that one
    # rule says what is still.
    cov[ok] *= misfit.factor
    se = np.sqrt(np.clip(np.diagonal(cov, axis1=1, axis2=2), 0, None))
    return TrackResult(t=t, uv=uv, xy=xy, ok=ok, status=status,
                       stderr_px=se, radius_px=radius_px, background=bg, error=error,
                       seconds={"background": t_bg, "track": t_track}, lossless=info.lossless,
                       inter_frame=info.inter_frame, cov_px=cov, projection=proj, camera=cam,
                       look_factor=misfit.factor, look_rho=misfit.rho, look_shaded=tracker.shade is not False,
                       fit_rms=rms, touched=touched, foreign=foreign, warning=info.error_warning)


def leaving_rest(uv, ok, radius_px: float) -> np.ndarray:
    """Frames, shape (n,), of a ball leaving the spot where the track's first
    frames show it still (within ``STILL_PX``), while it is within two radii
    ``radius_px`` of it: its window still holds that spot, where the felt
    was learnt around the resting ball.  On realistic renders with no cue
    in view (sample_scenes(22, 4, case4, realistic) shots 4, 19), the first
    two such frames were 1.5-3.2 stated errors off along the path, and free
    slip took them; the recovery leaves them out (``recover_track(touched=)``).

    A ball not found in the video's first frame has not been seen where it
    rested: its first found frames, while within two radii of where it was
    first found, are flagged (the spot it left lies behind it, within
    reach).  Three first frames within ``STILL_PX`` do not show it still
    when it moves under a pixel a frame: realistic MJPG seed 43 shot 32 at
    480 fps, lost until 2 frames after the strike, then 0.8 px a frame, its
    first three found frames (4.5-5.7 stated errors off along the path)
    taken for the rest and the spot's flags starting after them, unbridged:
    free slip at LR 264, rolling at 0.66 with these flags
    (docs/measurements.md, slipfix)."""
    out = np.zeros(len(ok), bool)
    found = np.flatnonzero(ok)
    if len(found) and not ok[0]:
        d = np.hypot(*(uv - uv[found[0]]).T)
        out[found[0]:] = ok[found[0]:] & (d[found[0]:] < 2.0 * radius_px)
        return out
    first = found[:3]
    if len(first) < 3:
        return out
    rest = np.median(uv[first], axis=0)
    d = np.hypot(*(uv - rest).T)
    if not np.all(d[first] < STILL_PX):
        return out
    moved = np.flatnonzero(ok & (d > STILL_PX))
    if len(moved):
        out[moved[0]:] = ok[moved[0]:] & (d[moved[0]:] < 2.0 * radius_px)
    return out


def write_track_csv(path, result: TrackResult) -> None:
    """Write ``frame,t,u_px,v_px,x_m,y_m,ok`` (CONVENTIONS.md), atomically.

    Rows with ``ok`` 0 have empty coordinates.
    """
    path = Path(path)
    tmp = path.with_name(path.name + ".part")
    with open(tmp, "w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(["frame", "t", "u_px", "v_px", "x_m", "y_m", "ok"])
        for k in range(result.n_frames):
            if result.ok[k]:
                u, v = result.uv[k]
                x, y = result.xy[k]
                w.writerow([k, repr(float(result.t[k])), repr(float(u)), repr(float(v)),
                            repr(float(x)), repr(float(y)), 1])
            else:
                w.writerow([k, repr(float(result.t[k])), "", "", "", "", 0])
    os.replace(tmp, path)


def read_track_csv(path) -> dict[str, np.ndarray]:
    """Read a track CSV; empty coordinates become NaN."""
    data = np.genfromtxt(path, delimiter=",", names=True, filling_values=np.nan)
    return {name: np.atleast_1d(data[name]) for name in data.dtype.names}


__all__ = ["TrackError", "TrackResult", "open_video", "read_track_csv", "search_mask",
           "track_video", "write_track_csv"]
