"""Per-frame ball finding and refinement (pure: frames in, observations out).

Once the ball is found the search looks only near the position predicted
from the last two; when that fails it falls back to the whole frame.  Every
frame gets a status: ``OK`` or the reason it was flagged rather than guessed.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import NamedTuple

import cv2
import numpy as np

from cuespin.track.background import DETECT_SIGMAS, SCORE_CAP, Background, band_extent, box_score, box_size
from cuespin.track.colour import GREY, Projection
from cuespin.track.model import (SphereLook, _coarse, _model_rows, block_area, block_patch, block_sides, blur_nodes,
                                 fit_disc, streak_from_moments, streak_model)
from cuespin.track.outline import OUTLINE_REFIT_PX, OutlineCache, is_similarity
from cuespin.track.radius import RadiusMap
from cuespin.track.sphere import STILL_PX as STILL_PX_SPHERE
from cuespin.track.sphere import Sample, learn_sphere, mean_sample, relearn_both_sides, still_members

OK, NO_BALL, PARTIAL, TWO_BLOBS, GONE, FIT_FAILED, PULLED, OFF_PATH, BLANK = 0, 1, 2, 3, 4, 5, 6, 7, 8
STATUS_TEXT = {OK: "ok", NO_BALL: "no ball", PARTIAL: "ball partly out of the frame",
               TWO_BLOBS: "two ball-like blobs", GONE: "ball has left the frame",
               FIT_FAILED: "refinement failed", PULLED: "fit pulled off the ball",
               OFF_PATH: "centre off the ball's path", BLANK: "blank"}
REFINERS = ("fit", "moments")
# Blur shorter than this (px over the exposure) is modelled at its predicted
# length, not fitted: a symmetric smear moves no centroid, and its image
# changes only to second order in the length, so fitting it is ill-posed.
FIT_BLUR_PX = 3.0
# A held blur this far (px) from the streak the fit's own step from the last
# centre gives is refitted at that streak (BallTracker._seen_blur): the
# prediction missed a change of speed (the strike).  A moving ball's
# prediction misses by its deceleration and noise: the second differences of
# found centres on realistic seed 0 shots 8, 13, 18 (FFV1, MJPG) are at most
# 0.13-0.3 px away from the strike (99th percentile 0.12-0.61), seed 7 shot 5
# (red on red, 60 fps) 1.19, and the exposure (at most a frame) scales them
# down; the strike's frames of shots 8 and 13 miss by 1.2-2.8 px.  Only a
# refit that explains its window better is kept.
SEEN_BLUR_PX = 1.0
# A blob within this distance (px) of one the previous frame's full search
# found has not moved (the score's peak moves by a pixel or so with noise).
STILL_PX = 1.5
# A pixel whose residual exceeds this many noise sigmas is something the
# ball's model does not hold (the cue, a highlight): left out of a refit.
# Gaussian noise passes it once in 1.7 million pixels.
OUTLIER_SIGMAS = 5.0
# Something else in the ball's window (the cue at the strike and in its
# follow-through, or a cue the felt model caught where the frame has none):
# a pixel beyond the ball's outline (its largest radius, half its blur and
# FOREIGN_GAP_PX for the optics' blur: the realistic look's PSF sigma is
# 0.5-1.5 px) that departs from the felt by more than OUTLIER_SIGMAS noise
# sigmas and FOREIGN_CONTRAST of the ball's contrast (a lossy codec flattens
# the felt's noise but not its error at the ball's edge; MJPG's chroma
# bleeds ~2 px).  Such pixels, in groups of at least FOREIGN_MIN_PX, grown by
# FOREIGN_GROW_PX (the object's blurred edge, and its part inside the gap:
# a cue tip touching the ball), are left out of the fit.  Measured on
# sample_scene(3, realistic, FFV1): the cue's tip at the ball's rear pulled
# the fit 1.5-6 px towards it, and 11 px in the follow-through.
FOREIGN_GAP_PX = 2.0
FOREIGN_CONTRAST = 0.25
FOREIGN_MIN_PX = 4
FOREIGN_GROW_PX = 3
# The flag (foreign_seen) asks more than the fit's mask: on H.264 its group
# holds more than one independent sample (SEEN_MIN_BLOCKS chroma blocks in a
# luma-blind channel, where 4:2:0's one sample is FOREIGN_MIN_PX pixels:
# 49/0's still frames' groups were 4-5 px, the cue's on 49/9 8-12; on MJPG
# the cue's were 1-2 samples in 49/1 and 49/9 and the rule is not applied:
# BallTracker.seen_block), and its
# threshold is at least
# SEEN_SPREAD_SIGMAS robust sd of the window's departure from the felt beyond
# the ball.  H.264 keeps a still scene's blocks frame to frame, so the noise
# read between two look-ahead samples is the codec's (0.26-0.82 levels on
# realistic seeds 48/49 at 6.7-7.1 per channel), while the felt learnt where
# the ball rested departs from the frozen frame by the felt's own noise:
# 4-pixel groups at 1-2.3 times the threshold flagged every still frame of
# 49/0, 48/6 and 48/7 (docs/measurements.md, foreign).
SEEN_SPREAD_SIGMAS = OUTLIER_SIGMAS
SEEN_MIN_BLOCKS = 2
MAD_TO_SD = 1.4826
# The search's detection threshold as a fraction of the ball's own score in
# the look-ahead samples (Background.score): the former rule, a quarter of
# the pixel contrast, assumed the score is ~0.8 of it (0.25 / 0.8); a shaded
# red ball on red felt in H.264 scores 0.26 of its contrast (28 of 106,
# sample_scene(14, realistic)) and was lost in most moving frames.
SCORE_FRACTION = 0.3
# A stick is not the ball: the pixels departing from the felt by more than
# the foreign threshold (foreign_threshold) that join the blob's core (within
# a radius of its peak) and run out of the window the ball could fill (its
# radius, half its expected blur and STICK_GAP_PX for the optics' blur), in
# a band narrower than STICK_WIDTH_RADII ball radii (the width of a uniform
# band with their second moments across it), are the cue's shaft.  A ball,
# even with the cue's tip at its rear, fills the window's middle a diameter
# wide.  Measured on sample_scenes(6, 6, realistic, FFV1)[0] (blue on blue,
# a tan cue darker than the felt in the tracker's combination, as the ball):
# the felt learnt under the still-looking shaft left a 35 px stretch behind
# the tip, 0.6 radii wide, departing 40-70 levels (threshold 32), tracked as
# the ball for 52 frames, 5-9 radii off.
# A cue lying still where the felt learnt it (held after the strike, in most
# of the look-ahead's samples) departs only where the frame's cue reaches
# beyond it: the 0.8-s clip of that shot, the cue at address 3.4 radii behind
# the ball and held 5.2 radii behind it after the strike, left a stretch 1.9
# radii long that ends inside the window, taken for the ball (5.4 radii off)
# when the ball was hidden, and "two ball-like blobs" in frames 0-10 when not.
# The felt's own departure from its level in the window (its median), the
# ball's sign and the same threshold, is the still cue: the blob's pixels
# joined to it run through the window in a band as the moving shaft's do.
STICK_GAP_PX = 4.0
STICK_WIDTH_RADII = 1.0
# The felt-joined pass (a stretch of cue joined to the felt's still cue) has
# its own, narrower limit: a half-lit ball alone is 0.92 r wide (a half
# disc's moments), a dim one's lit sliver less, so joined to a line, a
# cushion or a still cue of its sign in the felt it fell under 1.  Simulated
# (tests/test_track.py _felt_joined_cases, 2,000 pairs, seed 11; the cue
# clip's stretch 0.35-0.7 r wide, measured 0.45): balls newly called a stick
# 9.6% at 1.0, 4.7% at 0.92, 2.2% at 0.75, 1.5% at 0.7; stretches missed
# 0.8% at 0.8 and above (joined below the threshold), 1.1% at 0.75, 3.2% at
# 0.7, 12% at 0.65.
STICK_JOINED_WIDTH_RADII = 0.75
# The full search looks past at most this many sticks for the ball.
STICK_SKIPS = 8
# A fit is tried again from the centroid of the departure from the felt in
# either direction when that lies more than this many radii from its centre
# (red on red in a low light, sample_scenes(6, 7, realistic, MJPG)[5]: the
# dark rim's crescent was fitted, 1.3 radii off, in 43 of 81 frames).
RESTART_RADII = 0.25
# A streak fitted where the sharp fit failed (the moments' streak: the
# strike) is refused when its nearer end lies more than this (px, plus half
# the predicted streak) behind the predicted centre: a ball struck from rest
# streaks away from its rest spot, a resting ball's streak straddles it.
# Measured (found5, realistic seed 0 shot 4 FFV1, lens blur at 480 fps):
# kept streaks' nearer ends 1.13-1.25 px behind (0.013-0.058 R off the
# truth), refused ones 2.2-3.9 px (0.24-0.33 R off).
STREAK_BEHIND_PX = 1.0
# Markings on the ball (dots, a logo turning with its spin) are something the
# shaded model cannot hold: they pull its centre (a white ball with dots,
# 0.27-0.30 radii) or stop it converging (a blue ball with a logo at rest:
# 41 of 112 fits failed), and a fit with them in view explains its window 3-4
# times worse than one without (the pulled-fit rule then drops it).  Inside
# the ball (farther than MARK_RIM_PX within its outline: its edge locates
# it, and the shaded model's misfit is largest there), a pixel departing
# from the look fitted linearly at the fit's centre by more than
# MARK_CONTRAST of the ball's contrast and OUTLIER_SIGMAS noise sigmas, in a
# group of at least MARK_MIN_PX, is a marking: such pixels, grown by one
# (their antialiased edge), are left out and the centre refitted.  Measured
# (benchmarks/track.py realistic, seed 0, FFV1): dots and a logo depart by
# 0.5-0.9 of the contrast; the shaded model's misfit inside the rim of an
# unmarked ball by at most 0.3 (docs/measurements.md: the decision's
# false-trigger rate on unmarked balls).
MARK_CONTRAST = 0.35
MARK_RIM_PX = 1.5
MARK_MIN_PX = 3
# A fit with markings found that lies more than this many radii from the
# prediction (the last two centres' motion) is done again from there, and
# the better kept: the shaded fit of a white ball with a logo, 120 fps,
# stopped 0.36 radii off with the logo half in its window (rms 22.7; without
# the markings judged there 14.1), and from the prediction found the ball
# (0.013 radii, rms 6.8; benchmarks/track.py realistic seed 0 shot 8, frame
# 64).  A moving ball's prediction misses it by a few hundredths of a radius.
MARK_RETRY_RADII = 0.1
# A lit sphere's fit whose diffuse coefficient ``a`` (the ball's albedo
# under the video's fixed light, in the tracker's combination of channels:
# the same in every frame up to the lighting ramp) is below this fraction of
# the voting frames' median is tried again from the quadratic look's fit
# and the one that explains the window better kept.  The centroid the fit
# starts from lies towards the light, and under lens blur the sphere has a
# second minimum there: benchmarks/track.py realistic seed 0 shot 4 (an
# orange ball on red felt, PSF sigma 0.77 px, 480 fps, noise 6.6, FFV1): 20
# of its fits 0.26-0.35 radii towards the light with a = -23 to -0.9, against
# 39-65 (median 54) in the frames fitted at the ball; the quadratic look
# from the same start found all of them within 0.05 radii.
SPHERE_A_MIN = 0.5
# The lit sphere's refit of a marked frame (from the quadratic look's
# centre) may move it at most this far (radii): it refines that centre (by
# 0.06-0.1 px on realistic seed 0 shot 18), it does not relocate the ball
# (the lit sphere alone tracked a marked, highlighted ball 5.2 radii off).
SPHERE_MARK_MOVE_RADII = 0.1
# Markings at the rim (within MARK_RIM_PX of it, where the markings rule
# does not look: the quadratic look's misfit is largest there) are found
# against the lit sphere, which holds the rim: a pixel of the ball (its
# outline grown by half a pixel) departing from its fit by more than OUTLIER_SIGMAS
# noise sigmas, in a group of at least RIM_MARK_MIN_PX, grown by one; the
# sphere refitted without them, and the search done again from that refit
# (the first fit, pulled by the dot, departs beside it too), at most
# RIM_MARK_PASSES times.  Only on a marked ball (the frames whose markings
# the rule inside found, and MARKED_BALL_FRAMES's); that rule reads |res|,
# so a highlight's peak passes for a marking: on realistic seed 0's
# highlight shots 12 and 17 (no markings) the gate opened in every frame
# and the rim rule changed every frame's fit, RMSE 0.00825 -> 0.00795 and
# 0.01039 -> 0.01043 px (review 10c); but with the markings rule off
# altogether shot 12 is 0.00726 px (err/se 1.07 for 1.16; shot 7 the same,
# 0.00749): the gate costs 9% there, and dropping the markings the lit
# sphere's fit explains frame by frame did not recover it (0.00795; the
# learnt elevation moves with the gate, 1.0506 -> 1.0356 rad, and with the
# rule off only until the light is learnt shot 12 is 0.00726 px again: the
# voting frames' highlight left out as markings; docs/measurements.md,
# branch marks9; given back where the light learnt with them in explains
# them, marks_given_back: 0.00723 px).  A dark dot at the rim left in pulled the lit
# sphere's centre 0.08-0.16 px (simulated: r 12.2 px, noise 1.7, bound
# 0.004 px), left out 0.004-0.006 px.  A dot turning over the rim shows one
# or two pixels there (realistic seed 0 shot 18: -50 levels, noise 1.7):
# groups of one count, which Gaussian noise passes once in 1.7 million
# pixels, ~1e-4 a frame's rim (docs/measurements.md, branch marks7: shot 18
# RMSE 0.0088 px with groups of 3, 0.0032 with 1; the bound 0.0023).
RIM_MARK_PASSES = 2
RIM_MARK_MIN_PX = 1
# A logo turning over the rim shows as a crescent 2-3 px wide, each pixel
# under the rule above (realistic seed 0 shot 3, a blue ball with a logo:
# -5..-12 levels at noise 2.5, frames 130-133 and 171-172 pulled 0.03-0.09
# px towards it, 3-5 stated errors).  So the mean of the ball's pixels in
# each RIM_MARK_BOX x RIM_MARK_BOX square is judged too, at OUTLIER_SIGMAS
# of that mean's noise (sigma / sqrt(n), n of them on the ball, at least
# RIM_MARK_BOX), its pixels on the ball taken as the marking's: shot 3
# RMSE 0.0173 -> 0.0136 px (docs/measurements.md, branch marks9).  On the
# unmarked frames of that shot the largest such mean was 2.4-4.3 of its
# noise (76 frames).
RIM_MARK_BOX = 3
# On a frame (BallTracker._rim_unmarked) the rim rule takes one group a pass,
# the strongest: its departing pixels split by sign (a marking is darker or
# lighter than the ball, not both) into 8-connected groups, the one with the
# largest sum of squared departures (in noise sigmas) left out and the
# sphere refitted, the next pass judged from that refit.  Every departing
# pixel at once, from a fit the marking pulled, ran away: realistic seed 8
# shot 3 frame 39 (FFV1, a white ball with a red logo over its left rim, 17
# px at -13..-60 sigmas), the pulled first fit departs +3..+12 sigmas along
# half the rim, joined to the logo in one group; the first pass took 134 px,
# the refit moved 2.7 px, the second took 343 px of the 306-px ball, and the
# frame was 0.040 / 0.067 px off (ten of its neighbours' errors;
# docs/measurements.md, markgate).  The largest group first (88 px, the logo
# with the positive misfit beside it) ran off as well (2.7 px, rms 15.4 ->
# 19.8); the strongest group of one sign is the logo (39 px grown), its
# refit 0.015 / 0.007 px off (branch rim83).  From each refit every pixel
# is judged again, and the groups ranked by their new pixels alone (those
# that, grown by one, add to the mask): a dot's faint edge, under the rule
# from the pulled fit, joins its group from the refit (realistic seed 9
# shot 18 frame 21: 9 -> 16 px, its refit 0.066 -> 0.039 px off), and a taken
# group's slight growth does not come before another marking (seed 8 shot
# 3 frame 43).  The search stops at no new pixel, at a refit that states no
# error, at a group larger than any marking (RIM_MARK_ANGLE_RAD), or after
# RIM_MARK_GROUPS passes (stopping too at a refit whose rms rose, as
# BallTracker._unmarked's rule, stopped seed 8 shot 18's small dotted ball
# at noise-level rises, 6.516 -> 6.528, and left its dots in: RMSE 0.0385
# -> 0.0427 px): a bound on the
# cost (a logo's two discs or three dots in view, each its core and then
# its edge), not a figure measured to bind.
RIM_MARK_GROUPS = 6
# The largest marking a ball carries shows at most as a disc of radius R
# sin(RIM_MARK_ANGLE_RAD) px (R the ball's): the renderer's logo is a cap of
# angular radius 0.33 rad, its dots 0.17 (render/look.py, marks); grown by
# the mask's one pixel (a 3 x 3 dilation: up to sqrt(2) px).  A group larger
# than that is not a marking but a fit's misfit.
RIM_MARK_ANGLE_RAD = 0.33
# A ball whose markings the rule inside found in this many frames is a
# marked ball: its frames where the rule finds none (a logo turned away,
# what is still in view under the rule's threshold) get the lit sphere's
# rule (RIM_MARK_PASSES) too: realistic seed 0 shot 3 (a blue ball with a
# logo on blue felt) RMSE 0.0271 -> 0.0171 px (docs/measurements.md,
# branch marks7; misfit5 found its unmarked frames 2.1 stated errors off).
# Counted in frames (a frame refitted from another centre counts once; per
# fit, shot 17's 97 frames counted 174-194, review 10c, and the 8 fits this
# was first set at were about 4 frames).
MARKED_BALL_FRAMES = 4
# A ball at rest is not fitted again every frame (BallTracker._rest_step).
# Once two consecutive frames' fits lie within REST_STEP_PX of each other,
# the next frames are measured against the last one fitted (the reference)
# by one step from its converged fit, on its window, used pixels and
# Jacobian: the minimum's linear response to the window's change
# (``H^-1 J (y - m_ref)``, H the Hessian: rest_reference; a lit sphere's
# look is never stepped, _rest_eligible), so each frame keeps its own noise
# in its centre (the recovery's rest rule
# reads the rest's scatter: recover.measurements.group_covariance) for one
# product with the window (a fit iterates, and the frame's search, cue,
# markings and recentring passes are not run).  The step stands only while
# it stays near the reference: a centre moved more than REST_STEP_PX from
# it (sphere.STILL_PX: a resting ball's fitted centre scatters by
# 0.002-0.03 px, a moving one moves >= 0.1 px a frame once it has left the
# rest), a residual RMS above the reference's beyond REST_RMS_SIGMAS of its
# spread (the ratio of two residual variances on ``dof`` each: sd
# 2 / sqrt(dof)), or FOREIGN_MIN_PX or more pixels departing from the
# stepped model beyond the foreign threshold where the reference's did not
# (the cue reaching the ball, another ball) send the frame through the full
# search and fit, which then becomes the reference.  A creeping ball is
# thus followed by steps of at most REST_STEP_PX, whose linearisation
# error is second order in them (measured by simulation: docs/measurements.md,
# branch speed17).
REST_STEP_PX = STILL_PX_SPHERE
REST_RMS_SIGMAS = 6.0
# The centre's step (px) of the central differences that give the Hessian's
# centre rows (rest_reference): well inside REST_STEP_PX, and 1e-5 px of
# second-order error for a model curving over a pixel.
REST_HESSIAN_STEP_PX = 0.01
# A rest is fitted in full again every REST_REFIT_EVERY frames, each fit the
# new reference: the steps stay near the minimum they linearise, and the
# stepped frames' stated covariance is the mean of the rest's full fits'
# (one fit's sandwich varies by up to 50% frame to frame on MJPG's blocks).
REST_REFIT_EVERY = 32
# Frames whose two fits (disc and shaded) decide the look (config.look "auto").
LOOK_FRAMES = 12
# The shaded look is kept when its pooled residual reduction exceeds the
# chi-square quantile at this probability (3 parameters per frame).  A lossy
# codec's misfit on a uniform ball passes it too (MJPG, yellow on green,
# noise 3: 536 on 36 dof), and that is kept on purpose: requiring the shaded
# fit to move the centre as well (by one stated error; MJPG's misfit moves
# it 0.45) fitted such balls as discs, 25% faster, but the disc's per-pixel
# sandwich missed the codec's error shared along the path, which the shaded
# fit's nuisances and clustered sandwich absorb: on the same 14 MJPG shots
# the recovery's 95% coverage fell from 97.5% to 87.5% (RMS error 1.06 ->
# 1.30 of its stated errors), and on a realistic FFV1 render the resting
# ball's shift was under one error while the moving ball's was three.
LOOK_P = 1e-3


class LastFit(NamedTuple):
    """What a converged fit needs to be corrected for a better felt
    (track.video's felt correction, ``refit_shift``): the window's corner
    ``pu, pv`` (px) and size ``ph, pw``, the centre ``c`` and blur ``b`` (px),
    the ball's level ``G``, whether the blur was fitted, the look's shade
    parameters, the outline (None: the radius map's disc), the foreign
    pixels left out (None: none), the markings' pixels left out
    (:func:`marking_pixels`; None: none) and whether the foreign pixels hold
    something beyond the felt's ghost of the ball (:func:`foreign_seen`:
    the cue, another ball; ``TrackResult.foreign``)."""
    pu: int
    pv: int
    ph: int
    pw: int
    c: np.ndarray
    b: np.ndarray
    G: float
    fit_blur: bool
    shade: object
    outline: object
    foreign: np.ndarray | None
    marks: np.ndarray | None = None
    seen: bool = False


@dataclass(frozen=True)
class TrackerConfig:
    """Tracker settings.

    Attributes
    ----------
    refine : str
        ``fit`` (exact disc model, reaches the Cramer-Rao bound) or
        ``moments`` (grey-weighted centroid, faster, ~2.3x the bound).
    n_background : int
        Frames sampled over the video for the first background model.  It
        only has to find the ball: every fit is then corrected with the felt
        averaged over all tracked frames, so few (costly) seeks suffice.
    search_margin_px : float
        Extra search radius around the predicted position (px).
    threaded : bool
        Decode on a second thread, overlapping decoding with background
        learning and tracking.  Batches run one single-threaded process per
        core instead.
    look : str
        The ball's look in the fit: ``disc`` (one level), ``shaded`` (plus a
        lit side and a rim, :func:`cuespin.track.model.streak_model`) or
        ``auto``: learnt from the video, by fitting both to the first
        ``LOOK_FRAMES`` frames the ball is found in and keeping ``shaded``
        only if it explains them significantly better (chi-square, 0.1%).
        A shaded ball is then fitted as a lit sphere
        (:class:`cuespin.track.model.SphereLook`) whose light and
        shininess are learnt from those frames (``sphere`` True, and the
        video lossless: :func:`cuespin.track.video.track_video` turns it off
        on a lossy codec); False keeps the quadratic look.
    planes : bool or None
        Read a 4:2:0 video (MJPG, H.264, mp4v) as its planes and convert to
        BGR only the windows the tracker looks at
        (:class:`cuespin.track.reader.PlanarFrame`), by swscale's arithmetic:
        OpenCV's levels to the bit (checked on each video's first frame;
        where they differ, OpenCV's decoding), so the same tracks, for less
        CPU and memory (speed13 in docs/measurements.md).  None (the
        default): those of
        :data:`cuespin.track.reader.PLANAR_DEFAULT_PIX_FMTS` (all three).
    """

    refine: str = "fit"
    n_background: int = 9
    search_margin_px: float = 6.0
    threaded: bool = True
    look: str = "auto"
    sphere: bool = True
    planes: bool | None = None


@dataclass
class Observation:
    """One frame's result: status, centre (px), its covariance (px^2),
    standard errors (px, the root of the covariance's diagonal) and the
    fit's residual RMS (levels; NaN without a fit)."""

    status: int
    uv: np.ndarray
    stderr: np.ndarray
    cov: np.ndarray = None
    rms: float = float("nan")

    def __post_init__(self):
        if self.cov is None:
            self.cov = np.diag(np.square(self.stderr)) if np.all(np.isfinite(self.stderr)) \
                else np.full((2, 2), np.nan)


def look_vote(disc, shaded, n_pixels: int) -> tuple:
    """One frame's vote on the look from its disc and shaded fits
    (:class:`cuespin.track.model.DiscFit`) of a patch of ``n_pixels``:
    their residual sums, the degrees of freedom, and (for diagnostics) the
    centre's shift between them and the disc fit's covariance."""
    dof = n_pixels - 6
    return (disc.rms**2 * (dof + 3), shaded.rms**2 * dof, dof, disc.c - shaded.c, disc.cov)


def shaded_look(votes: list) -> bool:
    """The look decision from :func:`look_vote`'s votes: the shaded look
    explains the frames significantly better (pooled chi-square at
    ``LOOK_P``)."""
    # scipy.special, not scipy.stats: importing scipy.stats costs ~1.5 s
    # (measured), more than tracking a short shot; chdtri(df, p) is chi2.isf(p, df).
    from scipy.special import chdtri

    rss_d, rss_s, dofs = (np.array([v[i] for v in votes]) for i in range(3))
    stat = (rss_d - rss_s).sum() / (rss_s.sum() / dofs.sum())
    return bool(stat > chdtri(3 * len(rss_d), LOOK_P))


def kept_pixels(*left) -> np.ndarray | None:
    """A window's pixels a fit may use (:func:`~cuespin.track.model.fit_disc`'s
    ``valid``) with the boolean masks ``left`` (each None or a mask: another
    ball, the markings) left out; None when none is given (every pixel)."""
    given = [m for m in left if m is not None]
    return ~np.logical_or.reduce(given) if given else None


def segment_distance(shape, u0: int, v0: int, c, b) -> np.ndarray:
    """Distance (px) of each pixel of a window (``shape`` (h, w), top-left
    ``(u0, v0)``) from the ball's blur segment (centre ``c``, blur vector
    ``b``, px)."""
    h, w = shape
    c, b = np.asarray(c, float), np.asarray(b, float)
    L2 = float(b @ b)
    # Along each axis, broadcast (no index grids).
    px, py = (np.arange(u0, u0 + w) - c[0])[None, :], (np.arange(v0, v0 + h) - c[1])[:, None]
    s = np.clip((px * b[0] + py * b[1]) / L2, -0.5, 0.5) if L2 > 0 else 0.0
    return np.hypot(px - s * b[0], py - s * b[1])


def beyond_ball(shape, u0: int, v0: int, c, b, r_out: float) -> np.ndarray:
    """Pixels of a window (``shape`` (h, w), top-left ``(u0, v0)``) farther
    than ``r_out + FOREIGN_GAP_PX`` from the ball's blur segment (centre
    ``c``, blur vector ``b``, px): what they show is felt or something else,
    never the ball."""
    return segment_distance(shape, u0, v0, c, b) > r_out + FOREIGN_GAP_PX


def _marks_beyond(patch, felt, m0, JT, use, inner, thresh: float) -> np.ndarray:
    """:func:`marking_pixels`' two linear fits in numpy (the form
    :func:`cuespin.track.window.marks_beyond` reproduces): the pixels of
    ``inner`` departing from the look by more than ``thresh``, bool
    (h*w)."""
    y = (np.asarray(patch, np.float64) - felt - m0).ravel()
    A = JT[2:6].T  # level and the look's three: linear at a fixed centre
    bad = np.zeros(len(y), bool)
    for _ in range(2):
        # Compiled normal equations (~0.1 ms a fit less than numpy's copies
        # and SVD); the SVD where the Gram is near singular.
        theta, ok = _compiled().linear_fit(JT[2:6], y, use & ~bad)
        if not ok:
            theta = np.linalg.lstsq(A[use & ~bad], y[use & ~bad], rcond=1e-9)[0]
        bad = inner.ravel() & (np.abs(y - A @ theta) > thresh)
        if not bad.any():
            break  # a second fit would use the first's pixels: the same theta, none again
    return bad


def marking_pixels(patch, felt, u0: int, v0: int, c, b, r: float, r_in: float, sigma: float,
                   contrast: float, outline=None, valid=None) -> np.ndarray | None:
    """Pixels of a window (frame ``patch`` and ``felt``, top-left ``(u0,
    v0)``) that show markings on the ball (the rule at ``MARK_CONTRAST``):
    inside the ball of centre ``c``, blur ``b`` (px), radius ``r`` (the
    model's) and ``r_in`` (its smallest, px), departing from the ball's look
    (level, lit side, rim: linear at a fixed centre, fitted twice, the
    second time without the first's markings) by more than the threshold;
    grown by one pixel.  ``valid``: the pixels that may be used (False: the
    cue's).  None when there are none."""
    if not np.all(np.isfinite(c)) or not np.all(np.isfinite(b)):
        return None
    inner = segment_distance(felt.shape, u0, v0, c, b) < r_in - MARK_RIM_PX
    if inner.sum() < 12:
        return None
    # streak_model's rows without the blur's (never read here: its zero
    # columns cost two np.insert copies a frame, ~0.18 ms); the same values.
    m0, JT = _model_rows(c, b, 0.0, felt, r, u0, v0, blur_nodes(np.hypot(*b)), np.zeros(3), False, outline)
    use = np.ones(inner.size, bool) if valid is None else np.asarray(valid, bool).ravel().copy()
    thresh = max(MARK_CONTRAST * contrast, OUTLIER_SIGMAS * max(sigma, 0.5))
    # Compiled: the same pixels as numpy's form in one call (~0.2 ms a
    # frame less); numpy's where the compiled one cannot say.
    bad, n_bad, done = _compiled().marks_beyond(patch, felt, m0, JT, use, inner.ravel(), float(thresh))
    if not done:
        bad = _marks_beyond(patch, felt, m0, JT, use, inner, thresh)
        n_bad = int(bad.sum())
    if n_bad < MARK_MIN_PX:
        return None
    bad = bad.reshape(felt.shape).astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(bad, connectivity=8)
    big = np.nonzero(stats[1:, cv2.CC_STAT_AREA] >= MARK_MIN_PX)[0] + 1
    if not len(big):
        return None
    core = _members(n, big).view(np.uint8)[labels]
    # Along the blur only inside the rim: grown into it, the mask would take
    # the streak's ends, which locate the ball along the motion (a highlight
    # taken for a marking, seed 0 shot 17: one frame 2 px off).
    return (cv2.dilate(core, np.ones((3, 3), np.uint8)).astype(bool)
            | (cv2.dilate(core, smear_kernel(b)).astype(bool) & inner))


def _groups(bad: np.ndarray, min_px: int) -> np.ndarray | None:
    """The 8-connected groups of at least ``min_px`` pixels of the mask
    ``bad`` (uint8), as a uint8 mask; None when there are none."""
    if bad.sum() < min_px:
        return None
    n, labels, stats, _ = cv2.connectedComponentsWithStats(bad, connectivity=8)
    big = np.nonzero(stats[1:, cv2.CC_STAT_AREA] >= min_px)[0] + 1
    if not len(big):
        return None
    return _members(n, big).view(np.uint8)[labels]


def marking_cap_px(r: float, a: float) -> float:
    """The image area (px) of a cap of half-angle ``a`` (rad) on a ball of
    radius ``r`` (px) seen face on, grown by the mask's one pixel (up to
    sqrt(2) px)."""
    return np.pi * (r * np.sin(a) + np.sqrt(2.0)) ** 2


def markings_area_px(r: float) -> float:
    """The most of a ball of radius ``r`` (px) its markings can cover at
    once (px), each grown by the mask's one pixel (:func:`marking_cap_px`):
    the renderer's logo, a cap of RIM_MARK_ANGLE_RAD and one of 0.12 rad, or
    three of its six dots (0.17 rad; at most three face the camera)
    (render/look.py, marks)."""
    return max(marking_cap_px(r, RIM_MARK_ANGLE_RAD) + marking_cap_px(r, 0.12), 3 * marking_cap_px(r, 0.17))


def _strongest_group(bad: np.ndarray, z: np.ndarray, taken=None) -> np.ndarray | None:
    """Of the pixels ``bad`` (bool), split by the sign of their departure
    ``z`` (noise sigmas) into 8-connected groups of at least
    :data:`RIM_MARK_MIN_PX`, the group with the largest sum of ``z**2``
    over its new pixels (those that, grown by one pixel, reach outside
    ``taken``, bool; None: every pixel), as a uint8 mask; None when no
    group has one."""
    best, most = None, 0.0
    # A pixel is new where, grown by one as the mask is, it adds a pixel:
    # judged from the refit, a group taken before may grow.
    fresh = None if taken is None else cv2.dilate((~taken).astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    for side in (z > 0, z < 0):
        n, labels, stats, _ = cv2.connectedComponentsWithStats((bad & side).astype(np.uint8), connectivity=8)
        if n < 2:
            continue
        new = bad & side if fresh is None else bad & side & fresh
        z2 = np.bincount(labels.ravel(), weights=np.where(new, z * z, 0.0).ravel(), minlength=n)
        z2[0] = 0.0
        z2[stats[:, cv2.CC_STAT_AREA] < RIM_MARK_MIN_PX] = 0.0
        j = int(np.argmax(z2))
        if z2[j] > most:
            best, most = (labels == j).view(np.uint8), float(z2[j])
    return best


def rim_marking_pixels(patch, felt, u0: int, v0: int, g, r: float, sigma: float | None, left=None,
                       outline=None, sigma_min: float = 0.5, refit: bool = False,
                       strongest: bool = False, taken=None) -> np.ndarray | None:
    """Pixels on the ball (within half a pixel of its outline: the rim
    too, where :func:`marking_pixels` does not look) that depart from the
    lit sphere's fit ``g`` (a
    :func:`~cuespin.track.model.fit_disc` with a :class:`SphereLook`, on the
    window ``patch``, ``felt`` with top-left ``(u0, v0)``, ball radius ``r``
    px) as a marking does (:data:`RIM_MARK_PASSES`' rule), grown by one
    pixel; ``sigma`` the noise (levels; None: from the residual's median
    absolute value), at least ``sigma_min``; ``left``: pixels already left
    out (never returned); ``refit``: ``g`` is a refit without the pixels
    a pass before found (:data:`RIM_MARK_BOX`'s means are judged then too);
    ``strongest``: the strongest group of one sign alone
    (:data:`RIM_MARK_GROUPS`' rule) with a pixel outside ``taken`` (the
    groups earlier passes took: judged again from the refit, a group may
    grow).  None when there are none."""
    rr = r if outline is None else outline.radius  # fit_disc's scale of the sphere
    m, _ = _model_rows(g.c, g.b, g.G, felt, rr, u0, v0, blur_nodes(np.hypot(*g.b)), g.shade, False, outline)
    res = np.asarray(patch, np.float64) - felt - m
    near = segment_distance(felt.shape, u0, v0, g.c, g.b) < r + 0.5
    if left is not None:
        near &= ~left
    if sigma is None:  # the noise from the residual, robust to the markings' pixels (MAD)
        sigma = 1.4826 * float(np.median(np.abs(res if left is None else res[~left])))
    sig = max(sigma, sigma_min)
    bad = near & (np.abs(res) > OUTLIER_SIGMAS * sig)
    if refit or not bad.any():
        # A faint marking spread along the rim (RIM_MARK_BOX): each square's
        # mean of the ball's pixels at OUTLIER_SIGMAS of that mean's noise.
        # Not on a first fit where pixels pass alone: pulled by a dot it
        # departs along half its rim by a few levels (the refit without the
        # dot is judged again, RIM_MARK_PASSES).
        # The pixels that passed alone, grown by one, are not in the means
        # (a square beside a dot would take the dot's pixels for its own).
        k = np.ones((RIM_MARK_BOX, RIM_MARK_BOX), np.float64)
        rest = near & ~cv2.dilate(bad.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
        n = cv2.filter2D(rest.astype(np.float64), -1, k, borderType=cv2.BORDER_CONSTANT)
        s = cv2.filter2D(np.where(rest, res, 0.0), -1, k, borderType=cv2.BORDER_CONSTANT)
        bad |= rest & (n >= RIM_MARK_BOX) & (np.abs(s) > OUTLIER_SIGMAS * sig * np.sqrt(np.maximum(n, 1.0)))
    if strongest:
        bad = _strongest_group(bad, res / sig, None if taken is None else taken if left is None else taken | left)
    else:
        bad = _groups(bad.astype(np.uint8), RIM_MARK_MIN_PX)
    if bad is None:
        return None
    out = cv2.dilate(bad, np.ones((3, 3), np.uint8)).astype(bool)
    return out if left is None else out & ~left


# The noise (levels) :func:`rim_left_out`'s rule assumes at least on a still
# ball's mean window: its residual's MAD there is the noise over sqrt(n)
# (1.7 / sqrt(12) = 0.5), below the pixel-centred look's own misfit: on a
# simulated still ball (the look's own model, two faint dots at the rim, 12
# frames, /tmp/marks8/t7.py) a -3 level feature inside the ball was taken at
# 0.5; on realistic seed 0 shot 13's mean the misfit inside is 1.2 rms.
# With 1.0 (5 levels) shot 13's dots (-5..-13) are still left out (RMSE
# 0.00823 px with it and without it).
RIM_MEAN_SIGMA_MIN = 1.0


def rim_left_out(samples, look, marked, r: float, outline=None, block=1) -> list | None:
    """The lit sphere's voting frames (:class:`~cuespin.track.sphere.Sample`)
    with the markings at their rim (:func:`rim_marking_pixels`, against the
    look ``look`` fitted on each still ball's mean window, the noise from
    its residual) left out too, in the still balls with a frame whose
    markings were found (``marked``, a bool a sample); ``r`` the ball's
    radius (px).  None when none was found (or ``block`` > 1: the rule
    reads pixels).

    On the mean of a still ball's frames (:func:`~cuespin.track.sphere.still_members`,
    as :func:`~cuespin.track.sphere.learn_sphere` fits them), not on each:
    a dot at the rim departs 5-13 levels there, under the rule's 5 sigmas
    in one frame at noise 1.7 and far over them in the mean of 12
    (realistic seed 0 shot 13: none found frame by frame; on the mean the
    learnt elevation 1.372 -> 1.329 rad, the renderer's 1.318, RMSE 0.00902
    -> 0.00823 px; docs/measurements.md, marks8)."""
    if block_area(block) > 1:
        return None
    out, found = list(samples), False
    for idx in still_members(samples):
        if not any(marked[i] for i in idx):
            continue
        s = mean_sample([samples[i] for i in idx])
        left = None if s.valid is None else ~s.valid
        add = None
        # As BallTracker._rim_unmarked, each pass from the last refit: on a
        # mean window a centre pulled 0.05 px by the dots departs along half
        # the rim by more than the rule's 5 sigmas, and the first pass
        # takes that half rim too.
        for _ in range(RIM_MARK_PASSES):
            g = fit_disc(s.patch, s.felt, s.u0, s.v0, s.c, r, s.G, b0=s.b, fit_blur=s.fit_blur, shade=look,
                         valid=s.valid if add is None else kept_pixels(left, add), outline=outline, jackknife=False)
            if not g:
                break
            found_now = rim_marking_pixels(s.patch, s.felt, s.u0, s.v0, g, r, None, left, outline,
                                           sigma_min=RIM_MEAN_SIGMA_MIN)
            if found_now is None:
                break
            add = found_now
        if add is None:
            continue
        found = True
        for i in idx:
            v = samples[i].valid
            out[i] = samples[i]._replace(valid=kept_pixels(None if v is None else ~v, add))
    return out if found else None


# The markings the voting frames' rule found are given back to the light's
# learning (marks_given_back) only where the look learnt with them in did not
# bend to hold them: on a still ball's mean window, fitted on the same pixels
# (every one but the markings' and the foreign ones), the look learnt with
# them in explains those pixels as well as the look learnt without them, by
# the F test of the geometry's GIVE_BACK_GEOMETRY parameters (the light's
# azimuth and elevation, the shininess, the PSF; nested: the geometry held
# at the look's against free, the look learnt without them its minimum on
# those pixels), kept out at a false rate of GIVE_BACK_FALSE_RATE (the rate
# at which a look that is right on the ball's other pixels would be
# refused).  A highlight's peak taken for a marking is held by the look's
# highlight term (realistic seed 0 shot 12, yellow on green: F 3.51, p
# 0.0077: given back, as marks9 measured it should be).  Dark dots given
# back bend the whole look to hold them: realistic seed 8 shot 8 (a white
# ball with black dots on blue felt, 60 fps, FFV1), one dot at the resting
# ball's middle, the light learnt overhead (elevation 1.546 rad, the
# renderer's 1.052) and every moving frame 0.11 px off (docs/measurements.md,
# branch mark10); measured p 3e-18 and less there, and on the other marked
# shots whose still balls' markings the rule found (realistic seed 8 shots
# 3 and 18, seed 9 shots 3 and 18) from 4.3e-4 (seed 9 shot 18's weakest
# still ball) down; seed 0 shot 17's highlight 0.12-0.997, given back
# (docs/measurements.md, branch markgate).  The diffuse ratio this
# replaces (0.5, half-way between shot 12's 0.96 and shot 8's -0.54) would
# have given back the logos of seed 8 shot 3 and seed 9 shots 3 and 18
# (ratios 2-3.6), kept out by the check below alone.
GIVE_BACK_GEOMETRY = 4
GIVE_BACK_FALSE_RATE = 1e-3


def _window_rss(s, g, rr: float, valid, outline=None) -> tuple[float, int]:
    """The residual sum of squares (levels^2) of fit ``g`` on the window of
    :class:`~cuespin.track.sphere.Sample` ``s`` over its pixels ``valid``
    (None: all), and their count; ``rr`` the sphere's scale (px)."""
    m, _ = _model_rows(g.c, g.b, g.G, s.felt, rr, s.u0, s.v0, blur_nodes(np.hypot(*g.b)), g.shade, False, outline)
    res = np.asarray(s.patch, np.float64) - s.felt - m
    use = np.ones(res.shape, bool) if valid is None else np.asarray(valid, bool).reshape(res.shape)
    return float(np.sum(res[use] ** 2)), int(use.sum())


def look_bent(s, g, q, rr: float, valid, outline=None) -> float:
    """The p-value of the F test that fit ``g`` (a look learnt with the
    markings in) explains the pixels ``valid`` of the mean window ``s`` as
    well as ``q`` (the look learnt without them), both fitted on those
    pixels: ``F = ((RSS_g - RSS_q) / k) / (RSS_q / (n - k - 8))`` on ``(k,
    n - k - 8)`` degrees of freedom, ``k`` = :data:`GIVE_BACK_GEOMETRY`
    (the geometry's parameters), 8 the fit's own (centre, blur, level, the
    three coefficients); small where the look bent to hold the markings."""
    from scipy.special import fdtrc

    rss_g, _ = _window_rss(s, g, rr, valid, outline)
    rss_q, n = _window_rss(s, q, rr, valid, outline)
    dof = n - GIVE_BACK_GEOMETRY - 8
    if dof <= 0 or rss_q <= 0:
        return 1.0
    F = max(rss_g - rss_q, 0.0) / GIVE_BACK_GEOMETRY / (rss_q / dof)
    return float(fdtrc(GIVE_BACK_GEOMETRY, dof, F))


def marks_given_back(samples, look, marks, foreign, r: float, sigma: float, outline=None,
                     block=1, without=None) -> list | None:
    """The lit sphere's voting frames (:class:`~cuespin.track.sphere.Sample`)
    with the markings given back where the look ``look``, learnt with them
    in, explains them: on each still ball's mean window
    (:func:`~cuespin.track.sphere.still_members`) with a frame whose
    markings were found (``marks``, a mask or None a sample; ``foreign``
    likewise, the other pixels left out), the look fitted on every pixel
    but the foreign ones, and the markings given back when none of their
    pixels departs from it by ``OUTLIER_SIGMAS`` of a frame's noise
    ``sigma`` (levels).  ``r`` the ball's radius (px).  None when nothing
    is given back (or ``block`` > 1: the rule reads pixels).

    Only where the look holds them as it holds a highlight: on the mean
    window's other pixels ``look`` explains them as well as ``without``
    (the look learnt without the markings; None: not checked), by
    :func:`look_bent`'s F test at :data:`GIVE_BACK_FALSE_RATE`.

    The markings rule reads the quadratic look's misfit: a highlight's peak
    passes for a marking there, and the light learnt without it is off
    (realistic seed 0 shot 12, no markings: elevation 1.0506 with them left
    out, 1.0356 with the rule off while learning; RMSE 0.00795 -> 0.00726
    px; docs/measurements.md, branch marks9)."""
    if block_area(block) > 1:
        return None
    out, back = list(samples), False
    for idx in still_members(samples):
        if not any(marks[i] is not None for i in idx):
            continue
        s = mean_sample([samples[i] for i in idx])
        away = [foreign[i] for i in idx if foreign[i] is not None]
        left = np.logical_or.reduce(away) if away else None
        # Fitted with the markings in: the look's specular coefficient is
        # set by the highlight's own pixels (fitted without them, shot 12's
        # 15 pixels of the peak all departed from it).
        g = fit_disc(s.patch, s.felt, s.u0, s.v0, s.c, r, s.G, b0=s.b, fit_blur=s.fit_blur, shade=look,
                     valid=kept_pixels(left), outline=outline, jackknife=False)
        if not g:
            continue
        rr = r if outline is None else outline.radius  # fit_disc's scale of the sphere
        union = np.logical_or.reduce([marks[i] for i in idx if marks[i] is not None])
        if without is not None:
            rest = kept_pixels(left, union)
            q = fit_disc(s.patch, s.felt, s.u0, s.v0, s.c, r, s.G, b0=s.b, fit_blur=s.fit_blur, shade=without,
                         valid=rest, outline=outline, jackknife=False)
            gk = fit_disc(s.patch, s.felt, s.u0, s.v0, s.c, r, s.G, b0=s.b, fit_blur=s.fit_blur, shade=look,
                          valid=rest, outline=outline, jackknife=False)
            if not q or not gk or look_bent(s, gk, q, rr, rest, outline) < GIVE_BACK_FALSE_RATE:
                continue  # the look bent to hold them: markings
        m, _ = _model_rows(g.c, g.b, g.G, s.felt, rr, s.u0, s.v0, blur_nodes(np.hypot(*g.b)), g.shade, False,
                           outline)
        res = np.abs(np.asarray(s.patch, np.float64) - s.felt - m)
        # All or none of a still ball's markings, at the markings rule's own
        # threshold (a frame's noise ``sigma``): on the mean window's noise
        # the lit sphere's own misfit at the highlight's peak passes for a
        # marking (shot 12: 6 of its 15 pixels at 5 x the mean's MAD, floor
        # RIM_MEAN_SIGMA_MIN); a dot's edge departs less than its middle.
        if any(marks[i] is not None and (res[marks[i]] > OUTLIER_SIGMAS * sigma).any() for i in idx):
            continue
        for i in idx:
            if marks[i] is not None:
                back = True
                out[i] = samples[i]._replace(valid=kept_pixels(foreign[i]))
    return out if back else None


def smear_kernel(b) -> np.ndarray:
    """Structuring element (uint8) that grows a marking's pixels by one (its
    antialiased edge) and along the blur segment ``b`` (px) both ways by half
    its length.  Under motion blur a marking is smeared over the exposure's
    path: its ends depart from the ball's look by only the share of the
    exposure the marking spent there, below the rule's threshold, yet they
    pull the fitted blur and the centre along the motion (a white ball with
    a logo at 120 fps, 3.7 px of blur: fitted 6.2 px, the centre 0.62 px
    behind, in the frames the logo lay across the streak's end;
    benchmarks/track.py realistic seed 0 shot 8)."""
    b = np.asarray(b, float)
    h = int(np.ceil(0.5 * np.hypot(*b))) + 1
    k = np.zeros((2 * h + 1, 2 * h + 1), np.uint8)
    for s in np.linspace(-0.5, 0.5, 2 * h + 1):
        u, v = int(round(h + s * b[0])), int(round(h + s * b[1]))
        k[v - 1:v + 2, u - 1:u + 2] = 1
    return k


def _members(n: int, labels) -> np.ndarray:
    """Lookup table over the ``n`` labels of a labelling: True at ``labels``
    (``table[image]`` is ``np.isin(image, labels)``, without its sort)."""
    table = np.zeros(n, bool)
    table[labels] = True
    return table


def foreign_threshold(sigma: float, contrast: float) -> float:
    """Departure from the felt (levels) beyond which a pixel shows something
    (``FOREIGN_GAP_PX``'s rule), for noise ``sigma`` and the ball's ``contrast``."""
    return max(OUTLIER_SIGMAS * max(sigma, 0.5), FOREIGN_CONTRAST * contrast)


def felt_ghost(patch: np.ndarray, felt: np.ndarray, polarity: int, thresh: float) -> np.ndarray | None:
    """Pixels of a window (bool, its shape) where the felt model holds
    something of the ball's sign ``polarity`` that the frame ``patch`` does
    not show: the felt departs from its own median over the window by more
    than ``thresh`` (levels, :func:`foreign_threshold`) with the ball's sign,
    and the frame lies below the felt there by as much.  None where there
    are none (most windows: the first test alone, no median taken).

    The felt learnt around a ball at rest holds speckles of it (the look-ahead
    samples' median where the ball rested in most of them; 0.8 of a 480-fps
    shot's first half second, sample_scenes(6, 7, realistic, MJPG)[4]).  As
    the ball leaves, those pixels showed 150-210 levels less than the felt
    beside and under it, and the fit was held back towards the rest spot:
    frames 223-227 0.30-0.45 radii behind the ball (docs/measurements.md,
    false9).  They tell the fit nothing of the ball; it leaves them out.  A
    ball's own dark rim or markings over a clean felt are kept (the felt
    there is its median), as are a shaded ball's parts of either sign."""
    low = polarity * (patch - felt) < -thresh
    if not low.any():
        return None
    ghost = low & (polarity * (felt - np.median(felt)) > thresh)
    return ghost if ghost.any() else None


def foreign_pixels(D: np.ndarray, beyond: np.ndarray, sigma: float, contrast: float) -> np.ndarray | None:
    """Pixels of a ball-positive window ``D`` (frame less felt) that show
    something other than the ball or the felt (the rule at
    ``FOREIGN_GAP_PX``): groups of ``FOREIGN_MIN_PX`` or more beyond the
    ball, grown by ``FOREIGN_GROW_PX``.  None when there are none."""
    bad = _groups((beyond & (np.abs(D) > foreign_threshold(sigma, contrast))).astype(np.uint8), FOREIGN_MIN_PX)
    if bad is None:
        return None
    g = 2 * FOREIGN_GROW_PX + 1
    return cv2.dilate(bad, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (g, g))).astype(bool)


def foreign_seen(D: np.ndarray, u0: int, v0: int, c, b, r_out: float, sigma: float, contrast: float,
                 ghost: np.ndarray | None, block=1) -> bool:
    """Whether a window ``D`` shows something beyond the ball with the felt's
    ghost of it (:func:`felt_ghost`'s mask ``ghost``) left out: something
    else in view (the cue, another ball), not the felt's memory of the rest
    spot, whose pixels depart by the ball's whole contrast (|D|) and would
    flag every frame leaving the rest.

    A group of ``FOREIGN_MIN_PX`` pixels and at least ``SEEN_MIN_BLOCKS``
    chroma blocks of ``block`` (:func:`~cuespin.track.model.block_sides`;
    a luma-blind channel's, else 1) beyond the foreign threshold and beyond
    ``SEEN_SPREAD_SIGMAS`` of the window's own robust spread of ``D``
    beyond the ball (the felt's departure from its model where ``sigma``,
    read between two frames, is not it; docs/measurements.md, foreign).
    Only the flag (``TrackResult.foreign``) reads this; the fit leaves out
    :func:`foreign_near`'s pixels as before."""
    beyond = beyond_ball(D.shape, u0, v0, c, b, r_out)
    if ghost is not None:
        beyond = beyond & ~ghost
    x = D[beyond]
    if x.size < FOREIGN_MIN_PX:
        return False
    spread = MAD_TO_SD * float(np.median(np.abs(x - np.median(x))))
    thresh = max(foreign_threshold(sigma, contrast), SEEN_SPREAD_SIGMAS * spread)
    min_px = max(FOREIGN_MIN_PX, SEEN_MIN_BLOCKS * block_area(block))
    return _groups((beyond & (np.abs(D) > thresh)).astype(np.uint8), min_px) is not None


def foreign_near(D: np.ndarray, u0: int, v0: int, c, b, r_out: float, sigma: float,
                 contrast: float) -> np.ndarray | None:
    """:func:`foreign_pixels` of a window ``D`` (top-left ``(u0, v0)``)
    beyond the ball (:func:`beyond_ball`): None at once when fewer than
    ``FOREIGN_MIN_PX`` pixels pass its first test, as in most frames
    (counted compiled, :func:`cuespin.track.window.foreign_count`)."""
    n = _compiled().foreign_count(D, u0, v0, float(c[0]), float(c[1]), float(b[0]), float(b[1]),
                                  r_out + FOREIGN_GAP_PX, foreign_threshold(sigma, contrast))
    if n < FOREIGN_MIN_PX:
        return None
    return foreign_pixels(D, beyond_ball(D.shape, u0, v0, c, b, r_out), sigma, contrast)


def stick_through(D: np.ndarray, u0: int, v0: int, c, r: float, thresh: float,
                  felt: np.ndarray | None = None) -> bool:
    """Whether a ball-positive window ``D`` (top-left ``(u0, v0)``, its
    border where the ball can no longer reach) shows a stick through its
    blob at ``c`` (px; ``STICK_GAP_PX``'s rule): the pixels departing by
    more than ``thresh`` that join those within ``r`` (px, the ball's
    radius) of ``c`` reach the border, in a band under ``STICK_WIDTH_RADII``
    radii wide.  ``felt``: the felt in the same window (float32, times the
    ball's polarity): where the blob alone ends inside the window, its pixels
    joined to those of the felt departing from its median by more than
    ``thresh`` (a cue lying still that the felt learnt; the comment at
    ``STICK_GAP_PX``) are tried too, in a band under
    ``STICK_JOINED_WIDTH_RADII`` radii wide."""
    on = D > thresh
    felt_departs = False
    if felt is not None:
        lo, hi = cv2.minMaxLoc(felt)[:2]
        felt_departs = hi - lo > thresh  # else no felt pixel departs from its median by that: the same blob
    if not felt_departs and not _reaches_border(on):
        return False  # no pixel over the threshold on the border (most frames): no blob reaches it
    blob = _joined_blob(on, u0, v0, c, r)
    if blob is None:
        return False
    limit = STICK_WIDTH_RADII
    if not _reaches_border(blob) and felt_departs:
        blob = _joined_blob(on | (felt - np.median(felt) > thresh), u0, v0, c, r)
        limit = STICK_JOINED_WIDTH_RADII  # a half-lit ball is under STICK_WIDTH_RADII wide
    if not _reaches_border(blob):
        return False  # the blob ends where a ball could: not a stick through it
    y, x = np.nonzero(blob)
    if len(x) < 3:
        return False
    return bool(band_extent(x, y)[0] < limit * r)  # a uniform band's width


def _joined_blob(on: np.ndarray, u0: int, v0: int, c, r: float) -> np.ndarray | None:
    """The pixels of ``on`` (bool window, top-left ``(u0, v0)``) 8-connected
    to those within ``r`` (px) of ``c``; None when none lie there."""
    n, labels = cv2.connectedComponents(on.astype(np.uint8), connectivity=8)
    if n < 2:
        return None
    h, w = on.shape
    # Open grids broadcast (no full index grids) and a label lookup table
    # instead of np.isin (which sorts): the same pixels, ~0.2 ms less a frame.
    ys, xs = np.ogrid[v0:v0 + h, u0:u0 + w]
    core = labels[(np.hypot(xs - c[0], ys - c[1]) <= r) & (labels > 0)]
    if not len(core):
        return None
    return _members(n, core)[labels]


def _reaches_border(blob: np.ndarray) -> bool:
    return bool(blob[0].any() or blob[-1].any() or blob[:, 0].any() or blob[:, -1].any())


def centroid(D: np.ndarray, u0: int, v0: int, c0, radius: float, n_iter: int = 3) -> np.ndarray:
    """:func:`cuespin.track.model.moments`, compiled
    (:func:`cuespin.track.window.centroid`)."""
    return np.array(_compiled().centroid(D, u0, v0, float(c0[0]), float(c0[1]), float(radius), n_iter))


_WINDOW = None


def _compiled():
    """:mod:`cuespin.track.window`, imported on first use (numba's import
    costs ~0.5 s, which only tracking should pay)."""
    global _WINDOW
    if _WINDOW is None:
        from cuespin.track import window
        _WINDOW = window
    return _WINDOW


# A fit whose residual RMS exceeds PULLED_RMS_FACTOR times the track's
# typical one (its PULLED_REF_PERCENTILE-th percentile over the found frames)
# explains its window far worse than the ball's model does elsewhere: it was
# pulled (by the cue's tip, a highlight with turning markings, the dark rim
# of a shaded ball close to the felt's colour) and is dropped, not reported.
# The factor is large because a realistic ball at rest is fitted 1.6-2.5
# times worse than the same ball moving (its look sharp, not blurred):
# at 1.5, 126 correct frames of 15 realistic MJPG tracks were dropped; at 3,
# none (README, Known limits).
PULLED_RMS_FACTOR = 3.0
PULLED_REF_PERCENTILE = 25
PULLED_MIN_FRAMES = 10
# ... and only when it also lies beyond the spread of the track's own fits:
# more than PULLED_SPREAD_IQRS interquartile ranges above their upper
# quartile (Tukey's far-out fence).  The 25th percentile is the track's
# best-explained frames; a ball whose look changes from frame to frame
# (dots rolling into view at the rim, where the markings rule does not look,
# MARK_RIM_PX) is fitted worse in a share of its frames by the look alone.
# Measured on sample_scenes(6, 6, realistic, FFV1)[1] (2 s, 240 fps, a
# rolling dotted ball, the lit sphere's learnt PSF): the frames' RMS spread
# 1.3-8.3 (quartiles 1.98, 4.18) and 35 correct frames (within 0.007 R)
# with no marking found reached 7.3-8.3, beyond 3 x 1.98: dropped, the set
# under issue 10's 99%.  The fence there is 10.8; those frames need 1.9
# IQRs.  A fit held 0.25 R off (issue 10's false centre) on the same
# frames' windows explains them with an RMS of at least 22.8 (8.5 IQRs):
# still dropped (docs/measurements.md, pulled7).  The quartiles are taken
# over the fits within PULLED_RMS_FACTOR times the reference only (review
# 10a): from all of them, a run of pulled fits over a quarter of a group
# (false centres come in runs) moved the upper quartile into the run and
# the fence kept every one of them.  The value 3 is Tukey's convention,
# checked on that one shot only (it needs 1.9; a held fit reaches 8.5).
PULLED_SPREAD_IQRS = 3.0
# A fit is also pulled when its centre is ill determined and it explains its
# window worse than the track's best: its stated standard error (the larger
# axis) beyond ILL_SE_FACTOR times the track's median, and its RMS beyond
# ILL_RMS_FACTOR times its group's reference (above).  Red on red in a low
# light (sample_scenes(6, 7, realistic, FFV1)[5]): three centres 0.25-0.31 R
# off (frames 33, 56, 59) fitted as well as their neighbours by RMS (1.26-1.65
# times the reference; the rule above needs 3) and on their path (track.path
# passes them even at 0.15 R), but stating 0.19-0.33 px against the track's
# median 0.036 (5.4-9.1 times): a shallow valley between the dark rim and the
# felt, the centre not pinned.  Either alone is common in correct fits: of
# 13610 correct fits of 31 recorded tracks (docs/measurements.md, red8), 30
# state more than 4 times their track's median (a streak's length, a window
# with the cue left out) and many fit 1.2 times worse (a rest's sharp look),
# but only one both (0.163 R off, the same track): the correct fits with a
# large stated error fit at most 1.07 times the reference, the false ones at
# least 1.26.  The factors lie in those gaps (4 under 5.4; 1.15 between 1.07
# and 1.26): the margins are thin and measured on one track's four false fits.
ILL_SE_FACTOR = 4.0
ILL_RMS_FACTOR = 1.15


def pulled_fits(rms: np.ndarray, ok: np.ndarray, still: np.ndarray | None = None,
                se: np.ndarray | None = None) -> np.ndarray:
    """Frames (bool, shape (n,)) whose fit's residual RMS ``rms`` (levels,
    NaN without a fit) is beyond ``PULLED_RMS_FACTOR`` times the typical
    one among the ``ok`` frames and beyond the spread of those frames' RMS
    (``PULLED_SPREAD_IQRS`` interquartile ranges above the upper quartile):
    a centre pulled off the ball.  None flagged with fewer than
    ``PULLED_MIN_FRAMES`` fitted frames.

    With ``still`` (bool, the ball at rest there) the frames at rest and the
    moving ones are each held to their own typical fit where each has
    ``PULLED_MIN_FRAMES``: a ball's sharp look at rest (a logo, dots) is
    fitted worse than its blurred look in motion, and against the moving
    frames' typical fit every frame of a rest was dropped (a blue ball with
    a logo on blue felt, 240 fps: 90 of 152 frames, benchmarks/track.py
    realistic seed 0 shot 3).

    With ``se`` (px, shape (n,), each fit's stated standard error, its
    larger axis) a fit is also pulled when its centre is ill determined and
    it explains its window worse than its group's typical fit: ``se`` beyond
    ``ILL_SE_FACTOR`` times the median over the ``ok`` frames and ``rms``
    beyond ``ILL_RMS_FACTOR`` times its group's reference."""
    rms = np.asarray(rms, float)
    have = np.asarray(ok, bool) & np.isfinite(rms)
    out = np.zeros(len(rms), bool)
    if have.sum() < PULLED_MIN_FRAMES:
        return out
    groups = [have] if still is None else [have & still, have & ~still]
    ill = np.zeros(len(rms), bool)
    if se is not None:
        se = np.asarray(se, float)
        stated = have & np.isfinite(se)
        if stated.any():
            ill = stated & (se > ILL_SE_FACTOR * np.median(se[stated]))
    for g in groups:
        ref_set = g if g.sum() >= PULLED_MIN_FRAMES else have
        ref = np.percentile(rms[ref_set], PULLED_REF_PERCENTILE)
        limit = PULLED_RMS_FACTOR * ref
        # The spread of the fits that pass the factor alone: the suspects
        # cannot widen the fence that judges them.
        q1, q3 = np.percentile(rms[ref_set & (rms <= limit)], [25, 75])
        out |= g & (rms > max(limit, q3 + PULLED_SPREAD_IQRS * (q3 - q1)))
        out |= g & ill & (rms > ILL_RMS_FACTOR * ref)
    return out


class RestReference(NamedTuple):
    """A resting ball's reference fit for :func:`rest_step`: the fit
    (:class:`LastFit`), the side of the blocks it fitted (1: pixels;
    :func:`~cuespin.track.model.block_patch`), its window's values as
    fitted ``y`` (the projected pixels or their blocks' means, flat), the
    residual ``res`` and model rows ``JT`` (k, len(y)) at its minimum,
    ``P = (J J^T)^-1 J`` and ``p0 = P res``, the degrees of freedom, the
    largest residual variance a step keeps (``var_max``, levels^2), the
    values already beyond the foreign threshold ``thresh`` (``out``), and
    the centre's stated error and covariance (px, px^2).  ``use`` (0/1,
    flat) the values the fit used."""
    fit: LastFit
    block: tuple
    y: np.ndarray
    use: np.ndarray
    res: np.ndarray
    JT: np.ndarray
    P: np.ndarray
    p0: np.ndarray
    dof: int
    var_max: float
    thresh: float
    out: np.ndarray
    stderr: np.ndarray
    cov: np.ndarray


def _rest_values(block, lf: LastFit, patch) -> np.ndarray:
    """A window's values as the fit of ``lf`` saw them (flat float64): its
    pixels, or its blocks' means (:func:`~cuespin.track.model.block_patch`)."""
    if block_area(block) > 1:
        return np.ravel(block_patch(block, lf.pu, lf.pv, patch)[1][0])
    return np.asarray(patch, np.float64).ravel()


def rest_reference(patch, felt_image, lf: LastFit, obs, r: float, thresh: float,
                   block=1, valid=None) -> RestReference | None:
    """The :class:`RestReference` of a sharp fit ``lf`` (every pixel of its
    window used, on ``block`` x ``block`` blocks' means if ``block`` > 1;
    ``patch`` its window, ``obs`` its Observation, ``r`` the ball's radius
    (px), ``thresh`` the foreign threshold, levels; ``valid`` (bool, the
    window's shape) the pixels it used, None: all), or None if its rows are
    singular.  The model is taken as :func:`~cuespin.track.model.fit_disc`
    fits it: on the blocks' grid (``_coarse``), the lit sphere's look scaled
    by the outline's radius where there is one."""
    felt = felt_image[lf.pv:lf.pv + lf.ph, lf.pu:lf.pu + lf.pw]
    c, b, ol, u0, v0 = lf.c, lf.b, lf.outline, lf.pu, lf.pv
    if block_area(block) > 1:
        (u0, v0), (felt, valid) = block_patch(block, lf.pu, lf.pv, felt,
                                              None if valid is None else np.asarray(valid, bool))
        c, r, b, ol = _coarse(block, c, r, b, ol)
    if lf.shade is not None and len(lf.shade) > 3 and ol is not None:
        r = ol.radius
    m, JT = _model_rows(c, b, lf.G, felt, r, u0, v0, blur_nodes(float(np.hypot(*b))), lf.shade, False, ol)
    y = _rest_values(block, lf, patch)
    f = np.asarray(felt, np.float64).ravel()
    res = y - f - m.ravel()
    use = np.ones(res.size) if valid is None else np.asarray(valid, float).ravel()
    Ju = JT * use
    # The minimum's response to the window's values, dc/dy = H^-1 J (the
    # implicit function theorem), H the residual sum's Hessian: J J^T less
    # sum r d2m, which a model that misses the ball by much more than the
    # noise (MJPG's blocks: RMS 15 levels at noise 3) makes count; with
    # J J^T alone (Gauss-Newton's) the step followed 0.7-0.8 of the fits'
    # moves (branch speed17).  The model is linear in all but the centre:
    # H's centre rows and columns by central differences of J^T r.
    H = Ju @ JT.T
    taus = blur_nodes(float(np.hypot(*b)))
    for j in range(2):
        e = np.zeros(2)
        e[j] = REST_HESSIAN_STEP_PX / block_sides(block)[j]
        g = []
        for sgn in (1.0, -1.0):
            mj, Jj = _model_rows(np.asarray(c, float) + sgn * e, b, lf.G, felt, r, u0, v0, taus, lf.shade, False, ol)
            g.append((Jj * use) @ (y - f - mj.ravel()))
        H[:, j] = H[j, :] = -(g[0] - g[1]) / (2.0 * e[j])
    try:
        P = np.linalg.solve(H, Ju)
    except np.linalg.LinAlgError:
        return None
    if not np.all(np.linalg.eigvalsh(0.5 * (H + H.T)) > 0):  # not a minimum's: fit in full
        return None
    dof = max(int(use.sum()) - JT.shape[0], 1)
    var = max(float(obs.rms) ** 2, float(use @ (res * res)) / dof)
    return RestReference(lf, block_sides(block), y, use, res, JT, P, P @ res, dof,
                         var * (1.0 + REST_RMS_SIGMAS * 2.0 / np.sqrt(dof)), thresh, np.abs(res) > thresh,
                         np.asarray(obs.stderr, float), np.asarray(obs.cov, float))


def rest_step(ref: RestReference, patch) -> tuple[np.ndarray, float] | None:
    """One Newton step (``H^-1 J``, rest_reference) from the reference fit ``ref`` on the window
    ``patch`` (projected levels, the reference's window): the centre (px)
    and the residual RMS (levels, on the blocks if the fit was), or None
    where the ball has moved or its window changed (:data:`REST_STEP_PX`'s
    rule)."""
    d = _rest_values(ref.block, ref.fit, patch) - ref.y
    theta = ref.p0 + ref.P @ d
    dc = np.array(ref.block, float) * theta[:2]  # the blocks' grid is (bx, by) px a unit
    if np.hypot(dc[0], dc[1]) > REST_STEP_PX:
        return None
    res = ref.res + d - ref.JT.T @ theta
    var = float(ref.use @ (res * res)) / ref.dof
    if var > ref.var_max:
        return None
    if np.count_nonzero((np.abs(res) > ref.thresh) & ~ref.out) >= FOREIGN_MIN_PX:
        return None
    return ref.fit.c + dc, float(np.sqrt(var))


def _lost(status: int) -> Observation:
    return Observation(status, np.full(2, np.nan), np.full(2, np.nan), np.full((2, 2), np.nan))


class BallTracker:
    """Finds and refines the ball frame by frame.

    Parameters
    ----------
    background : Background
        The video's felt model.
    radius_px : float
        Ball radius in pixels (from ``physics.R`` and the homography).
    exposure_frames : float
        Exposure as a fraction of the frame interval (for the blur model).
    config : TrackerConfig
    projection : Projection
        Frame (grey or BGR) to the one channel the background is learnt in.
    search_mask : ndarray of bool, shape (h, w), optional
        Where the ball's centre may be (the playing surface, with a margin);
        a search finds nothing outside it (rails, pockets, sights).
    max_step_px : float
        Farthest the ball can move in one frame (px): a blob found further
        from the last centre, a few frames on, is not the ball.
    surface : ndarray of bool, shape (h, w), optional
        The playing surface itself (``search_mask`` less its margin): where
        the ball is first found: a shot is struck from rest on open cloth
        (CONVENTIONS.md), so a first find beyond the cushions' line, in the
        search mask's margin, is something else (red9: the cue's joint on the
        rail).  None: anywhere
        in ``search_mask``.
    camera : Camera, optional
        The scene's camera, with ``R`` the ball's radius (m): under
        perspective each frame's fit uses the ball's outline there
        (:func:`cuespin.track.outline.local_outline`, an ellipse from the
        camera at the ball's position) in place of the disc of
        ``radius_px``.  None, or a similarity camera: the disc.
    radii : RadiusMap, optional
        The ball's radius over the image (:mod:`cuespin.track.radius`): the
        search's filter, its two-blob and reach rules and the moments start
        are sized by the ball where it is.  None: ``radius_px`` everywhere.
    chroma_block : int or (int, int)
        The pixel blocks, a square's side or (across, down) px, the fits
        model the video's chroma on
        (:attr:`cuespin.track.reader.VideoInfo.fit_block`): with a
        projection blind to luma (:attr:`Projection.luma_blind`) every fit
        models the blocks' means.
    """

    def __init__(self, background: Background, radius_px: float, exposure_frames: float,
                 config: TrackerConfig = TrackerConfig(), projection: Projection = GREY,
                 search_mask: np.ndarray | None = None, max_step_px: float = np.inf,
                 camera=None, R: float | None = None, radii: RadiusMap | None = None, chroma_block=1,
                 inter_frame: bool = False, surface: np.ndarray | None = None):
        if config.refine not in REFINERS:
            raise ValueError(f"refine must be one of {REFINERS}, got {config.refine!r}")
        self.bg = background
        self._ghost_of = None  # (patch, felt, felt_ghost's mask) of the last window fitted
        self.pol = background.polarity or 1
        self.r = float(radius_px)
        self.exposure_frames = float(exposure_frames)
        self.cfg = config
        self.proj = projection
        # A luma-blind channel of a video storing colour in blocks is those
        # blocks' means: the fits model them (fit_disc's ``block``).
        self.block = block_sides(chroma_block) if projection.luma_blind else (1, 1)
        # The foreign flag's group counts those blocks on an inter-frame
        # codec (H.264) only, whose still felt the noise read between two
        # frames does not hold (foreign_seen): on MJPG the cue's flags were
        # 1-2 chroma samples (docs/measurements.md, foreign).
        self.seen_block = self.block if inter_frame else (1, 1)
        self.cap = np.float32(SCORE_CAP * max(background.contrast, 1.0))
        self.H, self.W = background.image.shape
        self.radii = radii if radii is not None else RadiusMap((self.H, self.W), self.r)
        # The matched filter's box and ring per scale of the radius map (one
        # scale, the disc's, for a similarity camera).
        self.boxes = [(box_size(r), box_size(2 * r) | 1) for r in self.radii.scales]
        # Box-filtered noise of a frame minus a (slightly noisy) background;
        # the smallest box's, the noisiest, for every scale.
        k_min = min(k for k, _ in self.boxes)
        # Above the noise (pockets, felt) and a fraction of the ball's own
        # score; without a learnt score (a Background made by hand), a
        # quarter of its contrast.
        ball = SCORE_FRACTION * background.score if background.score > 0 else 0.25 * background.contrast
        self.thresh = max(DETECT_SIGMAS * max(background.sigma, 0.5) * 1.1 / k_min, ball)
        self.mask = search_mask
        self.surface = surface
        self.max_step_px = float(max_step_px)
        # The projected window of the last converged fit, for the felt average.
        self.last_patch: tuple | None = None
        self.history: list[tuple[int, np.ndarray]] = []
        # What each converged disc fit needs to be corrected for a better felt.
        self.last_fit: LastFit | None = None
        self.gone = False
        self.was_partial_edge = False
        self.shade = {"disc": False, "shaded": True}.get(config.look)  # None: learning
        self._look_votes: list[tuple[float, float, int]] = []
        # The voting frames' fits, refitted with the lit sphere once it is learnt.
        self._look_fits: list[tuple] = []
        self._sphere_samples: list = []  # the Samples the lit sphere was learnt from
        self._sphere_marked: list = []  # theirs whose markings were found (rim_left_out)
        self._sphere_outline = None  # and their outline
        self._sphere_a = None  # the voting frames' median diffuse coefficient (SPHERE_A_MIN)
        self._marked = set()  # frames whose markings the rule found (a marked ball: MARKED_BALL_FRAMES)
        self._k = -1  # the frame step() tracks
        self._candidates: tuple = ()  # the last full search's blobs
        self._at_departure = False  # this frame's search placed the ball at its departure's centroid
        self._bands = None  # the radius map's bands on the search mask (multi-scale search)
        self._pred = None  # this frame's predicted centre (px), None without history
        self._pred_blur = np.zeros(2)  # and the streak (px) its velocity predicts
        # The ball's outline from the camera; None: the disc everywhere.
        self.outline_of = None if is_similarity(camera) or R is None else OutlineCache(camera, R, self.r)
        self.outline = None  # this frame's (Ellipse or None)
        self._rest = None  # the rest step's reference (RestReference), None: every frame fitted
        self._rest_cand = None  # the last full fit that may become it: (k, patch, LastFit, Observation)
        self._rest_covs: list = []  # this rest's full fits' covariances (px^2), since its first step
        self._rest_cov = None  # their mean and its root diagonal (px^2, px), made once a fit joins them
        self._rest_n = 0  # frames stepped from the reference

    # -- search ---------------------------------------------------------
    def _velocity(self, k: int):
        """Predicted centre at frame ``k`` and velocity (px/frame), or None."""
        if not self.history:
            return None, np.zeros(2)
        k1, c1 = self.history[-1]
        if len(self.history) >= 2 and k - k1 <= 3:
            k0, c0 = self.history[-2]
            vel = (c1 - c0) / (k1 - k0)
        else:
            vel = np.zeros(2)
        return c1 + vel * (k - k1), vel

    def _score(self, D: np.ndarray, j: int = 0) -> np.ndarray:
        """Ball-likeness at every pixel of a ball-positive image: the mean
        over a box the ball fills less the mean over the ring of felt
        around it, sized for scale ``j`` of the radius map.  A stick (the
        cue) or an edge fills the ring as much as the box and scores near 0;
        the ball scores ~0.8 of its contrast.  No pixel counts for more than
        ``SCORE_CAP`` of the ball's contrast: the cue's end (its ivory
        ferrule, its chalked tip), which departs from the felt by up to twice
        as much as a low-contrast ball and half fills the box, outscored the
        ball it touched."""
        k, K = self.boxes[j]
        return box_score(np.clip(D, -self.cap, self.cap), k, K)

    def _peak(self, frame: np.ndarray, u0: int, v0: int, u1: int, v1: int, j: int = 0):
        """Peak of :meth:`_score` at scale ``j`` in a window: the score
        there, its peak's value and place.  The filters see half the ring's width beyond the window, so
        the score near its edges is not the image border's."""
        m = self.boxes[j][1] // 2
        U0, V0 = max(u0 - m, 0), max(v0 - m, 0)
        U1, V1 = min(u1 + m, self.W), min(v1 + m, self.H)
        k, K = self.boxes[j]
        # :meth:`_score` over the window and cut, compiled in one call
        # (the same bits as OpenCV's filters: window.peak_score).
        sm = _compiled().peak_score(self.proj(frame, V0, V1, U0, U1), self.bg.image[V0:V1, U0:U1], self.pol,
                                    self.cap, k, K, v0 - V0, v1 - V0, u0 - U0, u1 - U0)
        if self.mask is not None:
            sm[~self.mask[v0:v1, u0:u1]] = -np.inf
        _, val, _, loc = cv2.minMaxLoc(sm)
        return sm, val, np.array([loc[0] + u0, loc[1] + v0], float)

    def _stick(self, frame, loc, blur=None) -> bool:
        """Whether the blob at ``loc`` (px) is a stick (:func:`stick_through`:
        the cue's shaft), not the ball; ``blur`` (px) the streak expected
        there (None: none, the ball at rest)."""
        r = self.radii.at(loc)
        half = int(np.ceil(r + STICK_GAP_PX + (0.0 if blur is None else 0.5 * np.hypot(*blur))))
        u0, v0 = max(int(round(loc[0])) - half, 0), max(int(round(loc[1])) - half, 0)
        u1, v1 = min(int(round(loc[0])) + half + 1, self.W), min(int(round(loc[1])) + half + 1, self.H)
        felt = self.pol * self.bg.image[v0:v1, u0:u1]
        D = self.pol * self.proj(frame, v0, v1, u0, u1) - felt
        return stick_through(D, u0, v0, loc, r, foreign_threshold(self.bg.sigma, self.bg.contrast), felt)

    def _full_search(self, frame, blur=None):
        """The most ball-like blob (:meth:`_score`) on the playing surface,
        each pixel scored at its own scale of the radius map, that is not a
        stick (:meth:`_stick`, for the streak ``blur`` (px) expected; None:
        none)."""
        D = self.pol * (self.proj(frame) - self.bg.image)
        if len(self.radii.scales) == 1:
            sm = self._score(D)
        else:
            sm = np.full((self.H, self.W), -np.inf, np.float32)
            if self._bands is None:  # the scales' bands on the playing surface, once
                self._bands = list(self.radii.bands(self.mask))
            for j, _, (v0, v1, u0, u1), on in self._bands:
                k, K = self.boxes[j]
                m = K // 2  # the ring's half width beyond the band
                V0, V1, U0, U1 = max(v0 - m, 0), min(v1 + m, self.H), max(u0 - m, 0), min(u1 + m, self.W)
                # _score's formula in two OpenCV passes (a band's box covers
                # much of the frame: numpy's temporaries cost 5x the filters).
                inner = cv2.blur(D[V0:V1, U0:U1], (k, k))
                outer = cv2.boxFilter(D[V0:V1, U0:U1], -1, (K, K), normalize=False)
                ring = float(K * K - k * k)
                part = cv2.addWeighted(inner, 1.0 + k * k / ring, outer, -1.0 / ring, 0.0)
                np.copyto(sm[v0:v1, u0:u1], part[v0 - V0:v1 - V0, u0 - U0:u1 - U0], where=on)
        if self.mask is not None:
            sm[~self.mask] = -np.inf
        blobs = []  # the two best blobs that are not sticks (the cue's shaft), value and place
        departed = []  # blobs placed at their departure's centroid: the fit starts there (_refine's at_loc)
        for _ in range(STICK_SKIPS + 2):
            _, val, _, at = cv2.minMaxLoc(sm)
            if val < self.thresh:
                break
            loc = np.array(at, float)
            if not self._stick(frame, loc, blur):
                blobs.append((val, loc))
            else:
                # A shaded ball's dark rim, its lit middle on the felt's other
                # side, peaks the score at the rim, and the window centred
                # there cuts the crescent into a band (RESTART_RADII's shot,
                # FFV1: the resting ball called a stick in 8 of its 10 frames
                # before the strike).  The window centred on the departure's
                # centroid in either direction holds the whole ball.
                r_at = self.radii.at(loc)
                alt = self._departure_centre(frame, loc, r_at)
                if np.hypot(*(alt - loc)) > RESTART_RADII * r_at and not self._stick(frame, alt, blur):
                    blobs.append((val, alt))
                    departed.append(alt)
            if len(blobs) == 2:
                break
            # The next blob away from this one.
            mask = np.zeros_like(sm, dtype=np.uint8)
            cv2.circle(mask, (int(loc[0]), int(loc[1])), int(2.5 * self.radii.at(loc) + 4), 1, -1)
            sm[mask.astype(bool)] = -np.inf
        if not blobs:
            return None, NO_BALL
        val, loc = blobs[0]
        self._at_departure = any(loc is a for a in departed)
        val2, at2 = blobs[1] if len(blobs) == 2 else (-np.inf, None)
        # A second ball-like blob away from the first: flag, don't guess.
        if val2 >= max(self.thresh, 0.5 * val):
            # Two blobs.  Before the strike the ball rests while the cue
            # moves: the one that stayed put since the last frame is the ball.
            loc2 = np.array(at2, float)
            prev, self._candidates = self._candidates, (loc, loc2)
            still = [c for c in (loc, loc2) if any(np.hypot(*(c - p)) <= STILL_PX for p in prev)]
            if len(still) == 1:
                return still[0], OK
            return loc, TWO_BLOBS
        self._candidates = (loc,)
        return loc, OK

    # -- per frame ------------------------------------------------------
    def nothing(self, status: int = NO_BALL) -> Observation:
        """A frame in which no ball is reported, with ``status`` (``BLANK``:
        a blank frame, :func:`cuespin.track.reader.blank_frame`, never stepped)."""
        return _lost(status)

    def step(self, k: int, frame: np.ndarray) -> Observation:
        """Track frame ``k`` (8-bit grey or BGR, full size)."""
        if self.gone:
            return _lost(GONE)
        self._k = k
        self._at_departure = False
        pred, vel = self._velocity(k)
        self._pred = pred
        blur = self._pred_blur = vel * self.exposure_frames
        if self._rest is not None or self._rest_cand is not None:
            obs = self._rest_step(k, frame)
            if obs is not None:
                self.history = (self.history + [(k, obs.uv)])[-2:]
                return obs
        self._rest = None
        r_here = self.radii.at(pred) if pred is not None else self.r
        reach = r_here + 0.5 * np.hypot(*blur) + self.cfg.search_margin_px + 0.5 * np.hypot(*vel)
        loc = None
        if pred is not None:
            u0, v0 = max(int(pred[0] - reach), 0), max(int(pred[1] - reach), 0)
            u1, v1 = min(int(pred[0] + reach) + 2, self.W), min(int(pred[1] + reach) + 2, self.H)
            j = self.radii.scale_of(r_here)  # the window is small: one scale, the prediction's
            k_box = self.boxes[j][0]
            if u1 - u0 > k_box and v1 - v0 > k_box:
                _, val, at = self._peak(frame, u0, v0, u1, v1, j)
                if val >= self.thresh and not self._stick(frame, at, blur):
                    loc = at
        if loc is None:
            loc, status = self._full_search(frame, blur)
            if loc is None:
                if self.was_partial_edge:
                    self.gone = True
                    return _lost(GONE)
                return _lost(status)
            if status != OK:
                return _lost(status)
            if self.history and k - self.history[-1][0] <= 3:
                # The ball cannot have gone further than its top speed allows:
                # a blob beyond that is something else (the cue's tip).
                k1, c1 = self.history[-1]
                if np.hypot(*(loc - c1)) > self.max_step_px * (k - k1) + self.radii.at(loc):
                    return _lost(NO_BALL)
            # No velocity to predict the blur.  Before the ball is first found
            # it rests (a shot is struck from rest), and a streak measured from
            # the image there would take the cue, or the ball's shading, for
            # motion: try it sharp first.  Once lost in flight, measure it.
            blur = np.zeros(2) if not self.history else None
        self.last_fit = None
        self.last_patch = None
        at_loc = self._at_departure
        obs = self._refine(frame, loc, blur, at_loc=at_loc)
        if obs.status != OK and blur is not None and not self.history:
            obs = self._refine(frame, loc, None, at_loc=at_loc)
        if obs.status == OK and self.mask is not None and not self._on_surface(obs.uv):
            # The search's peak lies on the playing surface but the fit left
            # it: no ball's centre is there (a ball drawn rolling over the
            # cushion, sample_scene(14, realistic, H.264): the fit 3.3 px,
            # 0.28 radii, off where the felt's model no longer holds).
            self.last_fit = self.last_patch = None
            return _lost(NO_BALL)
        if obs.status == OK and not self.history and self.surface is not None \
                and not self._on_surface(obs.uv, self.surface):
            # The ball is first found where a shot starts: at rest on the
            # cloth, its centre at least R inside the cushions' line, so
            # beyond that line by more than the homography's error (the
            # search mask's margin) no ball is first found.  Realistic seed 5
            # shot 9 (--mix, a red ball on red felt): the channel learnt from
            # the cue, the ball ~0 in it, and the cue's joint over the rail
            # (its centre 0.75 R past the cushion's line) was taken for the
            # ball in 8 frames, 255-314 px off (docs/measurements.md, red9).
            self.last_fit = self.last_patch = None
            return _lost(NO_BALL)
        if obs.status == OK:
            self.history = (self.history + [(k, obs.uv)])[-2:]
            self._rest_cand = (k, self.last_patch, self.last_fit, obs) if self._rest_eligible() else None
        return obs

    # -- a ball at rest ---------------------------------------------------
    def _rest_eligible(self) -> bool:
        """Whether the frame just fitted may be the rest step's reference
        (:data:`REST_STEP_PX`): the look settled and the blur held (a
        ball at rest is fitted sharp), and not the lit sphere: its look has
        kinks every ~0.02 px of the centre (model.KINK_STEP_PX), where no
        linearisation holds (realistic seed 0 shot 12, FFV1: the rest's
        stepped centres 0.29 of their stated errors from main's fits in
        median, 3.1 at most), and track.video fits each of its frames again
        once the look is learnt again, so a step would save nothing there."""
        lf = self.last_fit
        return (self.cfg.refine == "fit" and self.shade is not None and not isinstance(self.shade, SphereLook)
                and lf is not None and self.last_patch is not None and not lf.fit_blur
                and (lf.shade is None or len(lf.shade) <= 3))

    def _rest_step(self, k: int, frame: np.ndarray) -> Observation | None:
        """Frame ``k`` measured by one step from the rest's reference fit
        (:data:`REST_STEP_PX`), or None: the frame is fitted in full.  The
        reference is made from the last full fit when it and the frame
        before it lie within REST_STEP_PX; every REST_REFIT_EVERY frames a
        full fit is made again (and becomes the reference)."""
        if self._rest is None:
            (kc, patch, lf, obs), self._rest_cand = self._rest_cand, None
            if not (k == kc + 1 and len(self.history) == 2 and self.history[0][0] == kc - 1
                    and np.hypot(*(self.history[1][1] - self.history[0][1])) <= REST_STEP_PX):
                self._rest_covs = []
                return None
            thresh = foreign_threshold(self.bg.sigma, self.bg.contrast)
            # The pixels its fit used: the markings' and foreign ones left
            # out, and the felt's ghost (_fit_disc's rule, asked again here).
            felt = self.bg.image[lf.pv:lf.pv + lf.ph, lf.pu:lf.pu + lf.pw]
            ghost = felt_ghost(patch[0], felt, self.pol, thresh)
            valid = kept_pixels(lf.foreign, lf.marks, ghost)
            self._rest = rest_reference(patch[0], self.bg.image, lf, obs, self.r, thresh, self.block, valid)
            if self._rest is None:
                self._rest_covs = []
                return None
            self._rest_covs.append(self._rest.cov)
            # The stepped frames' covariance, made once a reference rather
            # than every frame (np.mean of the list: ~15 us a frame).
            cov = np.mean(self._rest_covs, axis=0)
            self._rest_cov = (cov, np.sqrt(np.diag(cov)))
            self._rest_n = 0
        if self._rest_n >= REST_REFIT_EVERY:
            self._rest = None  # a full fit, the rest's next reference
            return None
        ref = self._rest
        lf = ref.fit
        patch = self.proj(frame, lf.pv, lf.pv + lf.ph, lf.pu, lf.pu + lf.pw)
        step = rest_step(ref, patch)
        if step is None:
            self._rest, self._rest_covs = None, []
            return None
        self._rest_n += 1
        c, rms = step
        self.last_fit = lf._replace(c=c)
        self.last_patch = (patch, lf.pu, lf.pv)
        cov, se = self._rest_cov
        return Observation(OK, c, se.copy(), cov.copy(), rms)

    def _fit_disc(self, patch, felt, *args, valid=None, **kw):
        """:func:`~cuespin.track.model.fit_disc` without the window's pixels
        where the felt holds what the frame does not show (:func:`felt_ghost`).
        The mask is found once a window: a frame's fits share it (the test
        costs 5-10% of a sharp fit's CPU)."""
        if self._ghost_of is None or self._ghost_of[0] is not patch or self._ghost_of[1] is not felt:
            self._ghost_of = (patch, felt, felt_ghost(patch, felt, self.pol,
                                                      foreign_threshold(self.bg.sigma, self.bg.contrast)))
        ghost = self._ghost_of[2]
        if ghost is not None:
            valid = ~ghost if valid is None else np.asarray(valid, bool) & ~ghost
        return fit_disc(patch, felt, *args, valid=valid, **kw)

    def _window_level(self, D, felt, u0: int, v0: int, c, r: float) -> float:
        """A fit's start level (projected levels) from the window: the felt's
        mean plus the 75th percentile of the departure ``D`` within ``r`` (px)
        of ``c``, the learnt contrast's statistic taken in this frame."""
        vv, uu = np.mgrid[v0:v0 + D.shape[0], u0:u0 + D.shape[1]]
        inside = np.hypot(uu - c[0], vv - c[1]) <= r
        dep = float(np.percentile(D[inside], 75)) if inside.any() else 0.0
        return float(felt.mean()) + self.pol * max(dep, 1.0)

    def _on_surface(self, uv, where=None) -> bool:
        """The centre ``uv`` (px) lies where the search mask (or the mask
        ``where``) lets a ball's centre be."""
        where = self.mask if where is None else where
        u, v = int(round(uv[0])), int(round(uv[1]))
        return 0 <= v < self.H and 0 <= u < self.W and bool(where[v, u])

    def _max_blur_px(self, frame, loc, r: float) -> float:
        """Longest streak (px) the exposure allows, from the extent of the
        blob of a ball of radius ``r`` (px): the blob's extent less the
        ball's diameter, and 0 where the blob is no longer than the ball
        (a streak has no negative length; a blob narrower than the ball,
        a lit part of it above the threshold, gave one of -14.7 px and a
        window of negative half-width, whose empty felt crashed the fit:
        realistic case4 MJPG seed 48 shot 5, frame 354)."""
        if self.exposure_frames <= 0:
            return 0.0
        k = 4 * int(r) + 1
        u0, v0 = max(int(loc[0]) - k, 0), max(int(loc[1]) - k, 0)
        roi = self.pol * (self.proj(frame, v0, int(loc[1]) + k, u0, int(loc[0]) + k)
                          - self.bg.image[v0:int(loc[1]) + k, u0:int(loc[0]) + k])
        on = roi > 0.25 * max(self.bg.contrast, 1.0)  # the streak's faint ends count
        if not on.any():
            return 0.0
        ys, xs = np.nonzero(on)
        return max(float(max(xs.max() - xs.min(), ys.max() - ys.min()) - 2 * r + 2), 0.0)

    def _without_outliers(self, patch, felt, u0, v0, f, r, G0, blur, fit_blur, shade):
        """Refit without the pixels the model cannot explain (beyond
        ``OUTLIER_SIGMAS`` of the noise, and their neighbours): the cue in the
        ball's window, a specular highlight.  The fit unchanged when there
        are none."""
        m, _ = streak_model(f.c, f.b, f.G, felt, r, u0, v0, blur_nodes(np.hypot(*f.b)),
                            f.shade if shade else None, outline=self.outline)
        res = (patch - felt) - m
        bad = np.abs(res) > OUTLIER_SIGMAS * max(self.bg.sigma, 0.5)
        if bad.sum() < 3:
            return f
        bad = cv2.dilate(bad.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
        g = self._fit_disc(patch, felt, u0, v0, f.c, r, f.G, b0=f.b, fit_blur=fit_blur, shade=shade, valid=~bad,
                     outline=self.outline, block=self.block)
        return g if g else f

    def _ball_contrast(self, f, felt, G0=None) -> float:
        """The ball's contrast (levels) the markings rule is scaled by: the
        background's (``Background.contrast``), or the fit's own level
        against the felt in its window where that is larger.  Only a fit
        with the quadratic look states that level (its ``G`` is the disc's
        mean; the lit sphere's is its unlit part, and taking it changed a
        blue ball with a logo on FFV1, shot 3: RMSE 0.0278 -> 0.0354 px);
        ``G0`` given: a fit that did not converge, whose level may have run
        off, keeps the background's.  On a lossy codec the background's can
        be a small fraction of the ball's: a yellow ball with a highlight on
        green felt at 480 fps, MJPG, read 8.8 where the fitted level stands
        ~140 above the felt (benchmarks/track.py realistic seed 0 shot 12),
        and the rule, at 0.35 of 8.8, took most of the ball for markings in
        122 of 348 fits (docs/measurements.md, branch marks3)."""
        quadratic = f.shade is not None and np.size(f.shade) == 3
        own = self.pol * (f.G - float(felt.mean())) if quadratic and G0 is None and np.isfinite(f.G) else 0.0
        return max(self.bg.contrast, own)

    def _unmarked(self, patch, felt, u0, v0, f, r, fit_blur, ol, foreign, G0=None, shade=True):
        """The fit ``f`` (converged or not: from where it stopped, with the
        level ``G0``, as its own may have run off) again without the
        markings' pixels (:func:`marking_pixels`) and the ``foreign`` ones:
        (fit, markings, whether it fitted the blur), or ``(f, None,
        fit_blur)`` when there are none or the refit fails.  A refit that
        fails fitting the blur is tried with it held: a blur fitted at rest
        (from the moments of a shaded, marked ball) has no derivatives.
        ``shade``: the look the refit uses (:func:`fit_disc`'s; the lit
        sphere once learnt)."""
        r_in = r if ol is None else min(r, 1.0 / np.sqrt(np.linalg.eigvalsh(ol.Qm)[1]))
        marks = marking_pixels(patch, felt, u0, v0, f.c, f.b, r, r_in, self.bg.sigma,
                               self._ball_contrast(f, felt, G0), ol, None if foreign is None else ~foreign)
        if marks is None:
            return f, None, fit_blur
        valid = kept_pixels(marks, foreign)
        G = f.G if G0 is None else G0
        for fb in (True, False) if fit_blur else (False,):
            g = self._fit_disc(patch, felt, u0, v0, f.c, r, G, b0=f.b, fit_blur=fb, shade=shade, valid=valid, outline=ol,
                         block=self.block)
            # Left out, the markings' pixels can only lower the residual: a
            # refit that explains its fewer pixels worse than the fit with
            # them ran off (seed 0 shot 12 MJPG of the realistic benchmark,
            # a highlighted ball: rms 136 and 72 against ~40).
            if g and (not f or g.rms <= f.rms):
                return g, marks, fb
        return f, None, fit_blur

    def _rim_unmarked(self, patch, felt, u0, v0, f, r, fit_blur, ol, marks, foreign, pred=None):
        """The lit sphere's fit ``f`` of a marked frame again without the
        markings at its rim (:func:`rim_marking_pixels`, at most
        :data:`RIM_MARK_PASSES` times, each from the last refit; where that
        leaves out more than the markings could cover, the strongest group a
        pass, at most :data:`RIM_MARK_GROUPS`): (fit,
        markings with those at the rim), or ``(f, marks)`` when there are
        none, a refit fails or it moves more than
        :data:`SPHERE_MARK_MOVE_RADII` and lands no nearer than
        :data:`MARK_RETRY_RADII` to the prediction ``pred`` (px; None: not
        known)."""
        if block_area(self.block) > 1:
            return f, marks
        left = kept_pixels(marks, foreign)
        left = None if left is None else ~left

        def passes(n: int, strongest: bool):
            # Each pass from the last refit; with ``strongest`` the strongest
            # group a pass, added to those before, none over a marking's cap.
            cap = marking_cap_px(r, RIM_MARK_ANGLE_RAD) if strongest else None  # px
            g, rim = f, None
            for _ in range(n):
                add = rim_marking_pixels(patch, felt, u0, v0, g, r, self.bg.sigma, left, ol, refit=rim is not None,
                                         strongest=strongest, taken=rim)
                if add is None or (strongest and add.sum() > cap):
                    break
                add = add if rim is None or not strongest else rim | add
                h = self._fit_disc(patch, felt, u0, v0, f.c, r, f.G, b0=f.b, fit_blur=fit_blur, shade=self.shade,
                                   valid=kept_pixels(marks, add, foreign), outline=ol, block=self.block)
                if not (h and h.stated):
                    break
                g, rim = h, add
            return g, rim

        g, rim = passes(RIM_MARK_PASSES, False)
        if rim is not None and rim.sum() > markings_area_px(r):
            # More than the markings could cover: the passes ran away
            # (RIM_MARK_GROUPS); the strongest group a pass instead.
            g, rim = passes(RIM_MARK_GROUPS, True)
        # A refit that moves farther than a refinement does is kept only
        # where the ball's motion puts it: a logo lying on the rim pulled the
        # first fit 1.3-2.3 px (0.11-0.2 R), and without it the refit landed
        # 0.03-0.05 px from the truth, beside the prediction (realistic seed
        # 7 shot 3, FFV1, frames 36-41, dropped as pulled before).
        if rim is None or (np.hypot(*(g.c - f.c)) > SPHERE_MARK_MOVE_RADII * r
                           and (pred is None or np.hypot(*(g.c - pred)) > MARK_RETRY_RADII * r)):
            return f, marks
        return g, rim if marks is None else marks | rim

    @staticmethod
    def _explains_better(patch, felt, u0, v0, g, f, marks, foreign, r, fit_blur, shade, ol, block=1) -> bool:
        """Whether the fit ``g`` explains the window better than ``f``, both
        refitted on the same pixels (every marking either found left out)
        from their own centres: each fit's own residual leaves out its own
        markings, so the one that left out more of its worst pixels would
        look better whatever its centre (review).  Falls back to the own
        residuals when a refit fails."""
        valid = kept_pixels(marks, foreign)
        # Their residuals only: no covariance needed (fit_disc's jackknife).
        a = fit_disc(patch, felt, u0, v0, f.c, r, f.G, b0=f.b, fit_blur=fit_blur, shade=shade, valid=valid, outline=ol,
                     block=block, jackknife=False)
        b = fit_disc(patch, felt, u0, v0, g.c, r, g.G, b0=g.b, fit_blur=fit_blur, shade=shade, valid=valid, outline=ol,
                     block=block, jackknife=False)
        if a and b:
            return b.rms < a.rms
        return g.rms < f.rms

    def _sphere_checked(self, patch, felt, u0, v0, f, c, r, G0, blurs, ol, fit_blur):
        """The lit sphere's fit ``f`` (from ``c``), or, when its diffuse
        coefficient is under ``SPHERE_A_MIN`` of the voting frames' (the
        sphere's second minimum towards the light), the sphere fitted again
        from the quadratic look's fit (or that fit, when the sphere does not
        converge from it) if that explains the window better.
        ``blurs``: the (blur, whether fitted) pairs the quadratic look
        tries, the first that converges kept (the streak measured from the
        moments, then the prediction's: a resting shaded ball's moments
        make a streak its fit may not converge with).  Returns the fit and
        whether its blur was fitted (``fit_blur``: that of ``f``), which the
        refits after it (markings, foreign pixels) and the track keep."""
        a = self._sphere_a
        if a is None or f.shade[0] * a >= SPHERE_A_MIN * a * a:
            return f, fit_blur
        for blur, q_fit_blur in blurs:
            q = self._fit_disc(patch, felt, u0, v0, c, r, G0, b0=blur, fit_blur=q_fit_blur, shade=True, outline=ol,
                         block=self.block)
            if q:
                g = self._fit_disc(patch, felt, u0, v0, q.c, r, G0, b0=q.b, fit_blur=q_fit_blur, shade=self.shade,
                             outline=ol, block=self.block)
                # When the sphere does not converge there either, the
                # quadratic look, as for a frame whose sphere fit fails.
                g = g if g else q
                return (g, q_fit_blur) if g.rms < f.rms else (f, fit_blur)
        return f, fit_blur

    def _learn_look(self, patch, felt, u0, v0, f_shaded, r, G0, blur, fit_blur, marks=None, foreign=None):
        """One frame's vote on the look: the disc fit's residual sum against
        the shaded one's; decided once ``LOOK_FRAMES`` frames have voted."""
        d = self._fit_disc(patch, felt, u0, v0, f_shaded.c, r, G0, b0=blur, fit_blur=fit_blur, outline=self.outline,
                     block=self.block)
        if not d:
            return
        if f_shaded.ok and (marks is not None or foreign is not None):
            # Both looks on the same pixels (every one, as the disc's): the
            # frame's own shaded fit left some out, and its residual over
            # fewer pixels is no vote against the disc's over all of them.
            f_shaded = self._fit_disc(patch, felt, u0, v0, f_shaded.c, r, G0, b0=blur, fit_blur=fit_blur, shade=True,
                                outline=self.outline, block=self.block)
            if not f_shaded:
                return
        # (the blocks' fits have a pixel a block: their residuals' count)
        self._look_votes.append(look_vote(d, f_shaded, patch.size // block_area(self.block)))
        if len(self._look_votes) >= LOOK_FRAMES:
            self.shade = shaded_look(self._look_votes)
            if self.shade and self.cfg.sphere:
                self._learn_sphere()
            self._look_fits = []

    def _keep_for_sphere(self, f, patch, felt, u0, v0, fit_blur, foreign, last_fit) -> None:
        """Hold a voting frame's fit (and the arrays its Observation and
        LastFit share) for :meth:`_learn_sphere`."""
        if self.cfg.sphere and self.shade is None:
            # The pixels the frame's own fit left out (another ball, the
            # markings) stay out of the light's learning and the refit: two
            # dots left in put a learnt elevation 0.18 rad off and the
            # refitted still frames 0.044 px off, ~8 of their errors
            # (review, 12 still frames with two dots).
            valid = kept_pixels(foreign, None if last_fit is None else last_fit.marks)
            self._look_fits.append((Sample(patch.copy(), felt.copy(), u0, v0, f.c.copy(), f.b.copy(), f.G, bool(fit_blur),
                                           f.shade, valid), f, last_fit))

    def _learn_sphere(self) -> None:
        """Learn the lit sphere's geometry from the voting frames and refit
        them with it: their centres and covariances are updated in place
        (the arrays their Observations and LastFits hold), so the track
        reports every frame with the same look."""
        if not self._look_fits:
            return
        samples = [s for s, _, _ in self._look_fits]
        look, _ = learn_sphere(samples, self.r, self.outline, block=self.block)
        if look is None:
            return
        marks = [None if lf is None else lf.marks for _, _, lf in self._look_fits]
        foreign = [None if lf is None else lf.foreign for _, _, lf in self._look_fits]
        back = None
        if any(m is not None for m in marks) and block_area(self.block) == 1:
            whole = [s._replace(valid=kept_pixels(fo)) for s, fo in zip(samples, foreign)]
            lit, _ = learn_sphere(whole, self.r, self.outline, block=self.block)
            back = None if lit is None else marks_given_back(samples, lit, marks, foreign, self.r, self.bg.sigma,
                                                             self.outline, self.block, without=look)
        if back is not None:
            again, _ = learn_sphere(back, self.r, self.outline, start=lit, block=self.block)
            if again is not None:
                look, samples = again, back
                self._look_fits = [(s, f, lf) for s, (_, f, lf) in zip(samples, self._look_fits)]
                marks = [None if (v is None or m is None) else m & ~v for m, v in
                         zip(marks, (s.valid for s in samples))]
                marks = [m if m is not None and m.any() else None for m in marks]
        self._sphere_marked = [m is not None for m in marks]
        rim = rim_left_out(samples, look, self._sphere_marked, self.r, self.outline, self.block)
        if rim is not None:
            # Learnt again without the markings at the rim, which the first
            # look's fits show: left in, they tilted the light (realistic
            # seed 0 shot 18: elevation 0.9075 for the renderer's 0.9245,
            # every moving frame then ~0.011 px off, away from the light).
            again, _ = learn_sphere(rim, self.r, self.outline, start=look, block=self.block)
            if again is not None:
                look, samples = again, rim
                self._look_fits = [(s, f, lf) for s, (_, f, lf) in zip(samples, self._look_fits)]
        self.shade = look
        self._sphere_samples, self._sphere_outline = samples, self.outline
        diffuse = []
        prev = None
        for s, f, lf in self._look_fits:
            # From the frame's first fit and from the previous frame's refit,
            # the one that explains the window better (same pixels, same
            # look): the first fits with the quadratic look are up to 0.23
            # radii off, and from there the PSF's model has a second minimum
            # (sample_scene(3) FFV1, frame 4 at rest: 2.5 px off, rms 7.71,
            # from its neighbour's centre 0.01 px off, rms 7.18).
            g = None
            for c0 in (s.c, prev):
                if c0 is None:
                    continue
                h = self._fit_disc(s.patch, s.felt, s.u0, s.v0, c0, self.r, s.G, b0=s.b, fit_blur=s.fit_blur,
                             shade=look, valid=s.valid, outline=self.outline, block=self.block)
                if h and h.stated and (g is None or h.rms < g.rms):
                    g = h
            if g and lf is not None and lf.marks is not None:
                # A marked voting frame as a later marked frame is fitted:
                # its markings at the rim left out too (_rim_unmarked), and
                # the LastFit told every pixel left out, so that the felt's
                # refit (track.video) fits the same pixels.  With the
                # quadratic look's markings alone, realistic seed 0 shot 18's
                # six voting frames were refitted with dots at the rim in:
                # 0.09 px off (30 stated errors), RMS twice the rest's, and
                # dropped as ill determined (96.9% found).
                left = None if s.valid is None else ~s.valid
                g, left = self._rim_unmarked(s.patch, s.felt, s.u0, s.v0, g, self.r, s.fit_blur, self.outline,
                                             left, None)
                if left is not None:
                    lf.marks[...] = left
            prev = g.c.copy() if g else None
            if g:  # a refit that stated its error; else the frame keeps its first fit, which did
                diffuse.append(g.shade[0])
                f.c[:], f.stderr[:], f.cov[:] = g.c, g.stderr, g.cov
                if lf is not None:
                    lf.c[:] = g.c
        self._sphere_a = float(np.median(diffuse)) if diffuse else None

    def relearn_sphere(self, felt: np.ndarray) -> SphereLook | None:
        """The lit sphere learnt again from the same voting frames against a
        better felt (the whole image, e.g. track.video's felt averaged over
        the track), from the look learnt before: the first felt, learnt
        while the ball rested, still holds its imprint at the rest spot,
        and the geometry learnt against it absorbs it (realistic shot 1,
        seed 0: elevation 1.46 rad for the renderer's 1.38).  Sets and
        returns the new look; None (the look unchanged) without one."""
        if not isinstance(self.shade, SphereLook) or not self._sphere_samples:
            return None
        samples = [s._replace(felt=felt[s.v0:s.v0 + s.patch.shape[0], s.u0:s.u0 + s.patch.shape[1]])
                   for s in self._sphere_samples]
        look, _ = relearn_both_sides(samples, self.r, self.shade, self._sphere_outline, self.block)
        if look is not None:
            # The rim's markings against the better felt too (realistic seed 0
            # shot 13: the elevation 1.353 -> 1.329 rad, the renderer's
            # 1.318; RMSE 0.00847 -> 0.00822 px).
            rim = rim_left_out(samples, look, self._sphere_marked, self.r, self._sphere_outline, self.block)
            again = None if rim is None else learn_sphere(rim, self.r, self._sphere_outline, start=look,
                                                          block=self.block)[0]
            if again is not None:
                look, samples = again, rim
            self.shade = look
            # The second minimum's check (SPHERE_A_MIN) against the new
            # look's diffuse coefficient, not the first look's.
            diffuse = [g.shade[0] for g in (self._fit_disc(s.patch, s.felt, s.u0, s.v0, s.c, self.r, s.G, b0=s.b,
                                                     fit_blur=s.fit_blur, shade=look, valid=s.valid,
                                                     outline=self._sphere_outline, block=self.block,
                                                     jackknife=False)  # the looks' coefficients only
                                        for s in samples) if g]
            self._sphere_a = float(np.median(diffuse)) if diffuse else None
        return look

    @staticmethod
    def _streak_leaves(f, pred, pred_blur) -> bool:
        """Whether the streak fitted in ``f`` (centre ``f.c``, blur ``f.b``,
        px) may be the ball's since ``pred`` (px, the predicted centre; None:
        no prediction), where a streak ``pred_blur`` (px) was predicted.  A
        ball struck from rest at ``pred`` streaks away from it: both of the
        streak's ends lie on one side of it, the nearer at most
        ``STREAK_BEHIND_PX`` plus half the predicted streak behind.  A
        streak fitted under ``FIT_BLUR_PX`` is kept (as a sharp ball)."""
        if pred is None:
            return True
        half = 0.5 * np.hypot(*f.b)
        if 2.0 * half <= FIT_BLUR_PX:
            return True  # no streak: its length is ill-posed, its centre the sharp fit's
        along = abs(float(np.dot(f.c - pred, f.b))) / (2.0 * half)
        return along >= half - STREAK_BEHIND_PX - 0.5 * np.hypot(*pred_blur)

    def _seen_blur(self, f, blur, fit_blur) -> np.ndarray | None:
        """The streak (px) the fit ``f``'s own step from the last found
        centre gives over the exposure, where it departs from the held
        ``blur`` (px; not fitted: ``fit_blur`` False) by more than
        ``SEEN_BLUR_PX``; None otherwise (no fit, a fitted blur, no recent
        centre)."""
        if not f or fit_blur or self.exposure_frames <= 0 or not self.history:
            return None
        k1, c1 = self.history[-1]
        if not 0 < self._k - k1 <= 3:
            return None
        seen = (f.c - c1) / (self._k - k1) * self.exposure_frames
        return seen if np.hypot(*(seen - blur)) > SEEN_BLUR_PX else None

    def _departure_centre(self, frame, c, r_ball: float) -> np.ndarray:
        """Centroid (px) of the departure from the felt in either direction,
        beyond the noise, within ``r_ball + 2`` px of a centre iterated from
        ``c``: the whole ball's, whatever the sign of each part (lit middle,
        dark rim)."""
        half = int(np.ceil(2 * r_ball)) + 2
        u, v = int(round(c[0])), int(round(c[1]))
        u0, v0 = max(u - half, 0), max(v - half, 0)
        u1, v1 = min(u + half + 1, self.W), min(v + half + 1, self.H)
        # Compiled: numpy's form was 0.3 ms a frame (track.window).
        cu, cv = _compiled().departure_centroid(self.proj(frame, v0, v1, u0, u1), self.bg.image[v0:v1, u0:u1],
                                                OUTLIER_SIGMAS * max(self.bg.sigma, 0.5), u0, v0, float(c[0]),
                                                float(c[1]), r_ball + 2.0, 5)
        return np.array([cu, cv])

    def radius_with(self, outline) -> float:
        """The ball's largest radius (px) with this frame's outline (None:
        the disc's): what a window around it must hold."""
        return self.r if outline is None else max(self.r, outline.max_radius)

    def _refine(self, frame, loc, blur, recentre: bool = True, at_loc: bool = False) -> Observation:
        r = self.r
        # The ball's outline here, from the camera (None: the disc of r).
        ol = self.outline = self.outline_of(loc) if self.outline_of is not None else None
        r_out = self.radius_with(ol)  # what the patch must hold
        # The ball's own largest radius here: the moments' window and the
        # blob's extent are sized by it (a ball twice the disc's size, near a
        # tilted camera, was cut by the disc's window).
        r_ball = r if ol is None else ol.max_radius
        unknown_blur = blur is None
        if unknown_blur:  # size the patch for the longest blur the exposure allows
            blur = np.zeros(2)
            half = int(np.ceil(r_out + 3)) + int(np.ceil(self._max_blur_px(frame, loc, r_ball)))
        else:
            half = int(np.ceil(r_out + 0.5 * np.hypot(*blur) + 3))
        u0, v0 = int(round(loc[0])) - half, int(round(loc[1])) - half
        u1, v1 = u0 + 2 * half + 1, v0 + 2 * half + 1
        if u0 < 0 or v0 < 0 or u1 > self.W or v1 > self.H:
            self.was_partial_edge = True
            return _lost(PARTIAL)
        patch = self.proj(frame, v0, v1, u0, u1)
        felt = self.bg.image[v0:v1, u0:u1]
        D = self.pol * (patch - felt)
        # The fit starts at the window's centroid, or at ``loc`` itself when
        # that is already a centroid of the whole ball (the recentring below).
        c = np.asarray(loc, float) if at_loc else \
            centroid(D, u0, v0, loc, half - 1 if unknown_blur else r_ball + 2 + 0.5 * np.hypot(*blur))
        if unknown_blur and self.exposure_frames > 0:
            blur = streak_from_moments(D, u0, v0, c, r)
        if self.cfg.refine == "moments":
            se, cov, rms = np.full(2, np.nan), np.full((2, 2), np.nan), float("nan")
        else:
            fit_blur = np.hypot(*blur) > FIT_BLUR_PX
            G0 = float(felt.mean()) + self.pol * max(self.bg.contrast, 1.0)
            # The lit sphere once learnt; before, the quadratic look (or none).
            shade = self.shade if isinstance(self.shade, SphereLook) else self.shade is not False
            f = first = self._fit_disc(patch, felt, u0, v0, c, r, G0, b0=blur, fit_blur=fit_blur, shade=shade, outline=ol,
                                 block=self.block)
            first_blur, blurs = fit_blur, [(blur, fit_blur)]
            if not f and not fit_blur and self.exposure_frames > 0:
                # A streak the prediction missed (the strike, a sudden turn).
                m_blur = streak_from_moments(D, u0, v0, c, r)
                m_fit_blur = np.hypot(*m_blur) > FIT_BLUR_PX
                g = self._fit_disc(patch, felt, u0, v0, c, r, G0, b0=m_blur, fit_blur=m_fit_blur, shade=shade,
                             outline=ol, block=self.block)
                # A streak whose ends straddle where the ball was predicted
                # is no strike but a resting ball the sharp fit did not
                # converge on: its moments' streak, fitted, can converge off
                # the ball (realistic seed 0 shot 4, FFV1, frame 90: 2.2 px).
                if not (g and m_fit_blur) or self._streak_leaves(g, self._pred, self._pred_blur):
                    f, blur, fit_blur = g, m_blur, m_fit_blur
                    blurs.insert(0, (blur, fit_blur))
            seen = self._seen_blur(f, blur, fit_blur)
            if seen is not None:
                # The fit's centre says the ball moved faster than the
                # prediction's last two centres did (the frame after the
                # strike's, whose centre had moved only part of a step): its
                # streak is the one the fit's own step gives.  Held at the
                # predicted length instead, realistic seed 0 shot 8's frame
                # 53 (FFV1) took 144 of the streak's pixels for markings and
                # stated 3 times its neighbours' error (dropped, 0.13 px off;
                # refitted 0.022 px), and shot 1's frame 27 fitted with RMS
                # 12.9 against ~3.3 (dropped; refitted RMS 3.7, 0.0105 px off).
                s_fit_blur = np.hypot(*seen) > FIT_BLUR_PX
                g = self._fit_disc(patch, felt, u0, v0, f.c, r, f.G, b0=seen, fit_blur=s_fit_blur, shade=shade,
                                   outline=ol, block=self.block)
                if g and g.stated and g.rms < f.rms:
                    f, blur, fit_blur = g, seen, s_fit_blur
                    blurs.insert(0, (blur, fit_blur))
            if not f:
                # Started from the window's own level: the learnt contrast
                # is the track's, not this frame's (H.264 of
                # sample_scene(12, realistic): 3 frames failed from 188, the
                # ball's 75th percentile over the samples, and converged
                # from their own).
                f = self._fit_disc(patch, felt, u0, v0, c, r, self._window_level(D, felt, u0, v0, c, r_ball),
                             b0=blur, fit_blur=fit_blur, shade=shade, outline=ol, block=self.block)
            if f and isinstance(shade, SphereLook):
                f, fit_blur = self._sphere_checked(patch, felt, u0, v0, f, c, r, G0, blurs, ol, fit_blur)
            if not f and isinstance(shade, SphereLook):
                # The sphere's fit failed (2 of 37 frames of
                # sample_scenes(2, 5, realistic, MJPG)[1], at the strike):
                # the quadratic look, whose basis is smooth, as before.
                shade = True
                f = self._fit_disc(patch, felt, u0, v0, c, r, G0, b0=blur, fit_blur=fit_blur, shade=shade, outline=ol,
                             block=self.block)
            marks = None
            # A frame with markings is refitted with the quadratic look, as
            # on the markings' branch: with the lit sphere the refit without
            # the dots did not converge in 33 frames of a white ball with
            # dots (17% lost) and a blue ball with dots and a highlight was
            # tracked 5.2 radii off (the slow realistic test, seed 6 FFV1).
            mark_look = True
            if not f and shade:
                # Markings can stop the shaded fit converging (it stops near
                # the ball's centre): without them, from where the first
                # fit stopped.
                f, marks, fit_blur = self._unmarked(patch, felt, u0, v0, first, r, first_blur, ol, None, G0,
                                                    shade=mark_look)
            if not f:
                return _lost(FIT_FAILED)
            foreign = foreign_near(D, u0, v0, f.c, f.b, r_out, self.bg.sigma, self.bg.contrast)
            if foreign is not None:
                g = self._fit_disc(patch, felt, u0, v0, f.c, r, f.G, b0=f.b, fit_blur=fit_blur, shade=shade,
                             valid=kept_pixels(foreign, marks), outline=ol, block=self.block)
                if not g:
                    return _lost(FIT_FAILED)
                f = g
            if shade and marks is None:
                f, marks, fit_blur = self._unmarked(patch, felt, u0, v0, f, r, fit_blur, ol, foreign, shade=mark_look)
            pred = self._pred
            # On a marked ball a frame whose markings were not found (or
            # whose refit without them explained less) may be as pulled: a
            # logo lying on the rim moved the first fit 1.7-2.5 px (0.14-0.21
            # R), its pixels judged from there were refused, and the frame
            # was dropped as pulled (realistic seed 7 shot 3, FFV1, frames
            # 19-21 and 36-41; from the prediction the fit lands 0.05 px off).
            marked_ball = len(self._marked) >= MARKED_BALL_FRAMES
            if (marks is not None or marked_ball) and pred is not None \
                    and np.hypot(*(f.c - pred)) > MARK_RETRY_RADII * r \
                    and u0 <= pred[0] <= u1 - 1 and v0 <= pred[1] <= v1 - 1:
                # Markings' pixels judged from a centre they pulled are not
                # theirs alone: from the prediction too, the better kept.
                g, m2, fb2 = self._unmarked(patch, felt, u0, v0, replace(f, c=np.array(pred, float)), r, fit_blur,
                                            ol, foreign, shade=mark_look)
                if m2 is not None and self._explains_better(patch, felt, u0, v0, g, f,
                                                            m2 if marks is None else marks | m2, foreign, r,
                                                            fit_blur, mark_look, ol, self.block):
                    f, marks, fit_blur = g, m2, fb2
            if marks is not None and isinstance(shade, SphereLook):
                # The refit without the markings used the quadratic look
                # (above); the lit sphere on the same pixels, from there, is
                # kept when it explains them better (both have three look
                # coefficients): a strongly shaded white ball with dots
                # (realistic seed 0 shot 18, ambient 0.25) was 0.06-0.1 px
                # off across the motion in every frame with the quadratic.
                g = self._fit_disc(patch, felt, u0, v0, f.c, r, f.G, b0=f.b, fit_blur=fit_blur, shade=shade,
                             valid=kept_pixels(marks, foreign), outline=ol, block=self.block)
                if g and g.stated and g.rms < f.rms and np.hypot(*(g.c - f.c)) <= SPHERE_MARK_MOVE_RADII * r:
                    f = g
                    f, marks = self._rim_unmarked(patch, felt, u0, v0, f, r, fit_blur, ol, marks, foreign, pred)
            elif marks is None and isinstance(shade, SphereLook) and marked_ball:
                f, marks = self._rim_unmarked(patch, felt, u0, v0, f, r, fit_blur, ol, None, foreign, pred)
            if marks is not None:
                self._marked.add(self._k)
            if recentre:
                # The ball's middle may lie on the other side of the felt
                # than its rim (a shaded ball close to the felt's colour):
                # the search's blob and the fit from it are then the rim's
                # crescent.  Where the departure in either direction centres
                # elsewhere, the fit from there is tried too.  When it lands
                # near the first, they agree; when elsewhere, the one that
                # explains its window better is kept if that is the second,
                # and otherwise (it failed, or explains less) the frame is
                # dropped: two places a quarter radius apart and no way to
                # tell which is the ball's -- unless the ball is marked and
                # the first lies beside the prediction and explains more.
                alt = self._departure_centre(frame, f.c, r_ball)
                if np.hypot(*(alt - f.c)) > RESTART_RADII * r_ball:
                    # Started at the departure's centroid itself: the
                    # window's centroid of the signed departure, taken again
                    # from there, walked 3.4-3.5 R off (the red ball's bright
                    # middle and dark rim; sample_scenes(6, 7, realistic,
                    # FFV1)[5]) and the fit failed in 20 frames of its rest
                    # (red8: 29 -> 52 of 81 found, none off by 0.25 R).
                    other = self._refine(frame, alt, f.b, recentre=False, at_loc=True)
                    self.outline = ol
                    apart = other.status != OK or np.hypot(*(other.uv - f.c)) > RESTART_RADII * r_ball
                    # A marked ball's fit beside the prediction is where the
                    # ball's motion puts it (MARK_RETRY_RADII, as the retry
                    # and the rim's refit): a second fit elsewhere that
                    # explains less does not make it pulled.  Realistic seed 7
                    # shot 3 cut to 0.36 s, FFV1, frame 20: the fit 0.06 px
                    # off (rms 8.2, 0.4 px from the prediction); the second,
                    # from the departure's centre, 3 px off (rms 26.4): the
                    # frame was dropped.
                    beside = marked_ball and pred is not None and other.status == OK and other.rms >= f.rms \
                        and np.hypot(*(f.c - pred)) <= MARK_RETRY_RADII * r
                    # Agreeing once the look is learnt, they are two fits of
                    # the same ball and the one that explains its window
                    # better is the measurement: a logo on the rim, the
                    # first 0.23 px off at RMS 20.4 (then dropped as
                    # pulled), the second 0.01 px at 7.9, the track's
                    # typical 7.8 (realistic seed 7 shot 3 FFV1, frame 39).
                    # Not while the look is voted on: the second's fit has
                    # voted already, and the swap changed the learnt look
                    # (that shot's rest: 3 more frames dropped, measured).
                    if other.status == OK and other.rms < f.rms and (apart or self.shade is not None):
                        return other
                    if apart and not beside:
                        self.last_fit = self.last_patch = None
                        return _lost(PULLED)
            if recentre and ol is not None and np.hypot(*(f.c - self.outline_of.at)) > OUTLINE_REFIT_PX:
                # Fitted away from where its outline was taken (a ball larger
                # than the search's box): again with the outline there, on a
                # patch centred there.
                again = self._refine(frame, f.c, f.b, recentre=False)
                if again.status == OK:
                    return again
            if not f.stated:
                # No stated error is no measurement: a zero covariance would
                # weigh the frame infinitely downstream (9 frames of seed 0
                # shot 12 of the realistic benchmark, MJPG, a highlighted
                # ball refitted without "markings" that were the codec's
                # blocks).
                return _lost(FIT_FAILED)
            c, se, cov, rms = f.c, f.stderr, f.cov, f.rms
            ghost = self._ghost_of[2] if self._ghost_of is not None and self._ghost_of[0] is patch else None
            seen = foreign is not None and foreign_seen(D, u0, v0, f.c, f.b, r_out, self.bg.sigma, self.bg.contrast,
                                                        ghost, self.seen_block)
            self.last_fit = LastFit(u0, v0, v1 - v0, u1 - u0, f.c.copy(), f.b.copy(), f.G, bool(fit_blur),
                                    f.shade, ol, foreign, marks, seen)
            if self.shade is None:
                self._keep_for_sphere(f, patch, felt, u0, v0, fit_blur, foreign, self.last_fit)
                self._learn_look(patch, felt, u0, v0, f, r, G0, blur, fit_blur, marks, foreign)
            self.last_patch = (patch, u0, v0)
        # The whole ball must lie inside the frame for the centre to be trusted.
        eu, ev = (r, r) if ol is None else ol.half_extent
        if (c[0] - eu < -0.5 or c[1] - ev < -0.5 or c[0] + eu > self.W - 0.5
                or c[1] + ev > self.H - 0.5):
            self.was_partial_edge = True
            return _lost(PARTIAL)
        self.was_partial_edge = False
        return Observation(OK, c, se, cov, rms)
