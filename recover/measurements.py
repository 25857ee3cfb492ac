"""A track turned into the measurements a fit uses: the one place that says
which frames count, as what, and with what error.

Shared by the maximum-likelihood fit, its Cramer-Rao bound
(pipeline.measure.mle_bound), the accuracy benchmark and the experiments,
so all of them weight, leave out and count the same measurements.

- Each frame's error is a 2x2 covariance in table metres (the tracker's
  pixel covariance through the camera's Jacobian at the ball's position,
  ``scene.camera.cov_to_table``); per-axis standard errors are accepted too.
- Frames whose exposure holds the strike are left out by a mask (never by a
  huge error): their image is a ball still for part of the exposure and
  streaking for the rest, which no tracker model describes.  So are the
  frames just after it whose ball the cue's tip still touches
  (:data:`CUE_CLEAR_R`).
- With a lossy codec, the frames of a resting ball share their compression
  error as far as their images are the same: their mean is one
  measurement, with one frame's covariance when fewer than 10 frames, else
  its covariance from its frames' scatter (what of the stated error they
  do not show is shared), at least :data:`SHARED_REST_MIN_SHARE` of one
  frame's.  With a lossless codec a rest of 10 frames or more is one
  measurement too, its covariance from its frames' scatter alone (at low
  noise the same 8-bit rounding of the same image is shared); other
  frames are their own measurements.
- Degrees of freedom are counted from the measurements: 2 per measurement.
- A codec's own error lives in the image: it is one variance in px^2 for
  every frame, carried to metres like the tracker's through the camera's
  Jacobian at each frame's position (``px_to_m``, :func:`pixel_to_table`);
  without a camera (simulated tracks) it is one variance in m^2.

Pure functions of arrays.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import math

import numpy as np
from scipy.optimize import brentq
from scipy.sparse import csr_array
from scipy.stats import chi2, f as f_dist

from cuespin.fit.segment import noise_from_track

# Frames within this many frame intervals of the strike, beyond half the
# exposure, are left out as well: the margin for the strike time's own
# error (the first fit places it to a small fraction of a frame).  At any
# exposure, while the cue's window is open, it starts this far before the
# strike found (strike_window; seed 43 shot 51's refit t0 0.12 frames late).
STRIKE_MARGIN_FRAMES = 0.25
# The cue follows the departing ball through the strike (on the realistic
# look at half its speed, render.draw.cue_tip; a real cue's follow-through
# trails the ball too), so the first frames after it can show the cue's tip
# inside the ball's blurred outline, where the tracker cannot keep it out
# (its foreign-pixel mask starts track.tracker.FOREIGN_GAP_PX beyond the
# outline); and the tracker's first frames off the rest are off along the
# path without any cue in view (sample_scenes(22, 4, case4, realistic)
# shots 4, 19: 1.5-3.2 stated errors; track.video.leaving_rest): frames
# whose exposure starts before the ball has moved this many radii from
# where it was struck are left out where the track flags them
# (recover.estimate, ``touched``).  Measured against the
# truth on 38 realistic rolling-from-the-strike renders (benchmarks/
# accuracy.py --look realistic --preset case4 --codec FFV1, seeds 3-5, two
# tracks lost at the strike left out): the error along the path, in stated
# errors, of frames whose exposure started with the ball moved 0-0.25 R: RMS
# 2.9, up to 11 (the first frame after the strike: 0.1-0.66 px ahead of or
# behind the ball); 0.25-0.5 R: 1.7, up to 3.8; 0.5-1 R: 1.25, up to 4.2;
# beyond 1 R 0.99, up to 3.8 (by frame: the first RMS 2.9, the next three
# 1.1-1.3).  At most CUE_CLEAR_FRAMES frame intervals: a longer gap after
# the strike lets the free-slip fit hide a slip in it (uncapped, a plain
# 0.38 m/s shot at 480 fps lost its whole 60-ms slide to the gap and was
# answered 13 stated errors off) and widens the unseen slip a rolling
# answer states (recover.mle.unseen_slip counts from the first frame used;
# at 60 fps 2 frames take a 0.5 m/s shot's bound from 0.11 to 0.20 of
# |v0|).  On 40 realistic renders (seeds 3-5), a resting shaded ball one
# measurement (track.video): free slip chosen on none answered ok (2
# degenerate) with 1 R and 2 frames at most, on 1 (v0 10 stated errors
# off) with 1 frame at most.  The price on 25 plain MJPG shots (seed 0):
# one rolling shot (240 fps) taken for sliding (degenerate, likelihood
# ratio 12.2 against 9.2; rolling with 1 frame at most).  The cap is on this
# distance rule only: a run of frames the tracker flags from the strike on
# is left out whole (touched_run_s; slip12, docs/measurements.md): on 51
# realistic MJPG rolling renders (seed 41, 1-s clips) the tracker flagged
# 3-27 frames after the strike on 22, and capped at 2 the rest of the run
# (the spot the ball left still in its window: up to 10 stated errors
# behind along the path) passed for slip on 2 (free slip 5 of 51 -> 3);
# on the realistic mix (MJPG seed 21, FFV1 seeds 21-22: 52 tracks, sliding
# shots among them) no sliding shot called rolling, coverage 72/76 and
# 54/56 -> 72/76 and 53/56; on 200 generator slides with a flagged run of
# 3-24 frames, 2 more called rolling (the slide inside the run) and 6 more
# degenerate, coverage 95.8% -> 95.7%.
CUE_CLEAR_R = 1.0
CUE_CLEAR_FRAMES = 2.0
# The tracker's flags after the strike come with holes: on fresh realistic
# case4 MJPG clips (seed 43, 26 kept tracks; docs/measurements.md, slip11)
# the run began 1-3 frames after the strike on 8 (the first frame's ball
# still inside the strike's blur, not flagged) and was broken by one
# unflagged frame on 2 (shot 0 at 240 fps, shot 20 at 480 fps), so the run
# "unbroken from the first frame after the strike" left out none or one
# frame of it and the cue's tip, pulling the centre 0.2-0.5 px forward for
# 20 frames, was fitted (shot 20: slip LR 81.6, free slip).  A run bridges
# unflagged frames in a row, at its start too, only while they span at
# most this time (s): a hole is time the ball moves on, so a bridge counted
# in frames (slip11's 2) left out 33 ms of early slide at 60 fps and turned
# a correct held-out sliding shot degenerate (H.264 seed 71 shot 13, flags
# from the 2nd frame after the strike; fixgap, docs/measurements.md).  5 ms
# bridges slip11's 2 frames at 480 fps (4.2 ms: every run seen at 480 fps
# but shot 10's, 3 frames late, LR 1.8 either way), 1 at 240 fps (4.2 ms:
# shot 0's hole, the 1-frame late starts), none at 120 or 60 fps (8.3 ms, a
# frame: seed 43 shot 30's hole at 60 fps stays unbridged).  Only holes
# between flags are bridged, not unflagged frames before the first: a plain
# shot with no cue (the noise experiment's seed-1 shot at 240 fps, a 70-ms
# slide) has the spot the ball left flagged from the 2nd frame after the
# strike through the whole slide, and bridging its first frame left the
# slide out, `degenerate` where 0cfbece answered it at chi2/dof 1.00 (the
# lead's bisection, caught by tests/test_experiments.py).  A run holding the
# cue's flags (the fit saw foreign pixels, ``TrackResult.foreign``) may
# start late by as much (touched_run_s): on the 56 seed-43 clips retracked
# (cueflag, docs/measurements.md) the cue's runs started 1-2 frames after
# the strike the fit placed (2.1-4.2 ms) on 7 of 12 at 480 fps, 3 frames
# (6.25 ms) once, at a first fit's t0 whose second pass saw 2 (free slip
# 7 -> 3 of 55); a rest spot's runs started 1-3 frames late too (4 plain
# shots at 480 fps, 2 at 240) and stay unbridged.
TOUCHED_GAP_S = 5e-3
# A codec's measured share may lower the stated errors (see codec_excess)
# to no less than this fraction of them: MJPG at low noise measured the
# tracker's stated errors 1.2-1.4 times the real ones (README), so 0.5 is
# far outside what was seen and only guards against a wild estimate.
MIN_NOISE_FRACTION = 0.5
# A resting ball's frames share what is the same in every one of them: a
# lossy codec's compression of the same image, and, at low noise, the 8-bit
# rounding of the same image (sensor noise under about 0.3 grey levels no
# longer dithers it).  On a lossless codec their scatter about their mean
# shows their independent part, and what of one frame's stated error it
# does not show is shared (group_covariance).  Measured against the truth
# (benchmarks/accuracy.py's kept FFV1 tracks, seed 0, 31 ok shots, frames
# before the strike, as independent frames): the rest's mean was off by
# 1.47 of its stated errors in RMS, one shot at noise 0.03 grey levels by
# 7.  On MJPG the scatter does not separate the codec's share by a test: a
# rest kept as independent frames unless the scatter is significantly short
# (a significance rule at 1%) cut the 60 seed-0 shots' coverage from 97.3% to
# 91.5% (RMS error in stated errors 0.91 -> 1.14).  A scatter needs this
# many frames.
MIN_REST_SCATTER_FRAMES = 10
# A lossy codec's rest (shared errors) gets the scatter rule below, with at
# least this share of one frame's error shared.  Measured against the truth
# (the strike position, benchmarks/accuracy.py's fresh MJPG tracks of seed 0
# and seed 1 --noise-max 0.5, the rest before the strike, 50-55 frames in
# median), the rest's mean's squared error in one frame's variance: noise
# < 0.5, 0.85 (44 rests: nearly the whole error shared, as the scatter
# rule says, l = 0.09; its variance 0.93 of it); noise 0.5-3, 0.45 (11
# rests; the scatter rule's variance 0.92 of it); noise 3-11, 0.079 (42
# rests; the scatter rule alone, l = 0.97, stated 1/2.55 of it): a shared share of 0.061 +- 0.012 beyond the
# frames' own scatter (the same still image on the pixel grid, compressed
# alike).  One frame's covariance for every lossy rest (before) stated the
# noise 3-11 rests 13 times their error, so the strike position, and v0
# with it, too wide: on the 60 fresh seed-0 MJPG shots RMS error / stated
# 0.80 (bootstrap 0.67-0.92), now 0.87 (0.74-1.01).  Without the floor (the
# scatter rule alone) 0.90, but one of 5 rolling-from-the-strike shots
# passed for sliding (likelihood ratio 2.1 -> 13.9 against 9.2).
SHARED_REST_MIN_SHARE = 0.06
# The shared part is estimated without a significance test: the rest's
# variance is linear in it, so (1 - l)+ gives that variance about right
# (review, simulated rests of 10-30 frames with a shared share of 0.3-0.9:
# stated / true 1.00-1.04, coverage 91-95%), where claiming it only below
# the 1% point of independent frames' scatter (kappa l) stated 0.23-0.71 of
# the true variance at shares 0.3-0.6 (coverage 63-89%).  The price:
# independent frames' rests are stated 2-3 times their variance (coverage
# 97.6%).
# That price is paid where the frames are independent: a lossless codec's
# rest at sensor noise of half a grey level or more, most of the accuracy
# benchmark's FFV1 shots.  There (the kept FFV1 tracks of seeds 0, 1, 3,
# 47 shots answered ok at noise >= 0.5) the rests' means were stated 2.0
# times their squared error against the truth (58 rests), and the answers'
# errors 0.78 of their stated ones in RMS (coverage 98.9%); with each rest's
# variance C / n, 1.25 times and 0.93 (94.7%).  So a lossless rest (no
# shared error known, ``min_share`` 0) shares only when its frames' scatter
# lies below the REST_SHARED_LEVEL point of independent frames' (chi^2(2(n
# - 1)) / (2(n - 1))), with (1 - l) then; a lossy one always gets the rule
# above.  Simulated rests of n = 10-150 frames (stated / true variance,
# coverage of the mean's 95% region; before -> after): independent,
# 2.2-5.8 (97.4%) -> 1.15-1.6 (95%); shared share 0.6-0.9, unchanged at
# n >= 30 (0.81 at n = 10, f 0.6); the price is a share of 0.05-0.3 the
# scatter of a rest cannot show (stated 0.4-0.9 of its variance, coverage
# 36-94%, against 1.0-1.7 and 77-94% before): a lossless codec's share is
# the 8-bit rounding, only partly shared in a narrow band of noise (about
# 0.1-0.5 grey levels).
# The level holds only if the stated C is exact; the tracker overstated it
# on FFV1 at noise < 0.5 (moving frames' chi2/dof 0.72, 1.18 times in
# error), and there independent rests were called shared at n = 10, 40,
# 100: 12%, 50%, 91% (review 6).  So l is measured against the moving
# frames' own scale s (the first fit's chi2/dof over single-frame
# measurements, :func:`moving_scale`): a share is claimed when l / s lies
# below the F(2(n - 1), dof_s) REST_SHARED_LEVEL point, f = 1 - l / s.
REST_SHARED_LEVEL = 0.025
# A lossless codec's shaded ball (a realistic look the tracker models:
# TrackResult.independent_errors False) at rest: its look is the same in
# every frame of the rest, one error of about one frame's stated size, and
# its frames' scatter shows only the sensor's noise, which the scatter rule
# above would take for independent frames (share 0.06).  So the whole of
# one frame's stated covariance (the tracker's, without the look's factor,
# which build_measurements(look_factor=) takes off the rest's frames) is
# shared.  Chosen and checked on the same 18 realistic FFV1 renders (seed
# 21, 11 answered ok; docs/measurements.md, rec9 and rec11): in sample.
# The rests' means' squared error per axis in one frame's stated variance,
# median 0.87, against 0.69 (chi2(1)'s median) expected were that variance
# right: the share slightly understates.  The MLE's coverage 100% -> 95.5%
# (RMS error / stated 0.60 -> 1.32, RMS / bound 0.82) with the factor off
# the rests and this share, 87.5% (1.70) with the scatter rule instead.
LOOK_REST_SHARE = 1.0
# A shaded ball at rest on a lossy codec (realistic MJPG, case 4, the
# kept tracks of seeds 43, 45 and 47, branch rest47; docs/measurements.md):
# the rest's mean is off the truth by one constant error over the whole
# rest (the rest's quarters agree to 0.01-0.03 mm on 47/16 and 47/4, no
# lag-1 correlation, no cue in 47/4's video), about 0.1 px per axis
# whatever the frames' stated error: where the rest's stated sd was below
# 0.06 px its error was 2.6 times it (RMS), above 0.13 px 0.85 times.  The
# ball's look as the tracker models it, the same image in every frame:
# not the sensor's noise, not the codec's, and not the cue.  So each rest's
# mean of a shaded lossy track has this variance (px^2 per axis, through
# its frames' metres per pixel) added, shared by its frames
# (still_look_covariance).  Calibrated on seed 43's 51 rests alone (102
# axes, each squared error of the rest's mean against the truth in the
# variance the fit states for it): the maximum-likelihood value of an
# added variance 0.0015 px^2, the same where the share beyond chi^2(1)'s
# 1% point comes to 1% (2.9% -> 1.0%) and where the mean comes to 1 (1.23
# -> 0.95; median 0.54 -> 0.44).  Held out: seed 45 (53 rests) mean 1.29
# -> 0.99, beyond the 1% point 2.8% -> 0.9%; seed 47 (52) 2.95 -> 1.64 and
# 7.7% -> 4.8%: still understated there (its own estimate is 0.008 px^2),
# so this is a floor measured on two seeds of three, not the whole tail.
# Lossless shaded rests (LOOK_REST_SHARE) were not measured and get none;
# nor do inter-frame codecs' (H.264), not calibrated there: on held37's
# H.264 tracks it turned two true slides (37/25 at 480 fps, 38/33 at 60
# fps) from free slip to rolling (reviews of rest47).  The seeds' own
# values differ (43: 0.0015, 45: 0.0029, 47: 0.0083 px^2; one common value
# rejected, p = 0.002): the error is heavy-tailed per rest, which one
# added variance only partly states.
STILL_LOOK_VAR_PX2 = 0.0015
# A shaded ball at rest on a lossy codec (realistic MJPG, case 4, the
# kept tracks of seeds 43, 45 and 47; docs/measurements.md, rest47,
# light47, restfloor): the rest's mean is off the truth by one constant
# error over the whole rest, the JPEG quantiser's at the ball's place on
# the 8 x 8 grid, the same in every frame of a still ball (the sensor's
# noise does not dither it): FFV1 leaves 0.01 px, MJPG 0.0033-0.0096 px^2
# per axis over grid places, covered at moved places by one frame's
# stated covariance (RMS 0.85 of its sd; light47).  So the frames' mean
# keeps one frame's error whole: each such rest's mean is stated at least
# one frame's stated covariance (its frames' mean of the tracker's, before
# the codec's excess), the rest's own covariance (group_covariance plus
# STILL_LOOK_VAR_PX2) raised to it in the Loewner order
# (rest_floor_covariance).  Measured, not fitted (no parameter; restfloor):
# on main the fit stated the rest below one frame's covariance on 60% of
# 152 rests (smallest eigenvalue; below 0.8 of it on 36%, below 0.5 on
# 12%: the scatter rule's share, median 0.91, p10 0.51, and a negative
# codec excess, 45% of the rests' frames shrunk below 0.95 of stated).
# The rests' squared errors in the stated variance, main -> this, seeds
# 43 / 45 / 47: beyond chi^2(1)'s 1% point 1.9 / 0 / 5.7% -> 1.0 / 0 /
# 3.8%, median 0.41 / 0.40 / 0.31 -> 0.29 / 0.33 / 0.22 (stated wider
# than their typical error; chi^2(1) 0.45); free slip on rolling 6 / 166
# unchanged.  The floor without STILL_LOOK_VAR_PX2 turned 47/4 (its rest
# 3.1 frame sd off) to free slip: the constant stays.  Lossless shaded
# rests (LOOK_REST_SHARE) and inter-frame codecs' (H.264) get neither.
# A frame whose stated covariance is numerically singular, or states an
# error of the table's size, carries no measurement: it is left out
# (stated_frames), never weighted by a near-zero weight.  Realistic MJPG
# seed 45 shot 28 (case 4, roll45's kept track) had five `ok` frames whose
# jackknife covariance was the inverse of a near-singular normal matrix:
# eigenvalues up to 1.9e24 px^2 (5e9 m), condition numbers up to 1.1e16;
# the codec's floor against them reached -3.2e22 and `cov + floor K`
# cancelled to a zero eigenvalue (codec_excess's Cholesky failed; crash28,
# docs/measurements.md).  On the 191 other kept realistic tracks
# (roll45's seed 45 MJPG, cueflag's seed 43 MJPG and seed 34 H.264,
# h264new's seed 36 FFV1/MJPG/H.264) every `ok` frame's condition number
# was at most 393 and its largest error at most 13 px (about 5 cm); shot
# 28's singular frames 4e12-1.1e16 and 2e3-5e9 m, so both limits below sit
# orders of magnitude from either side.  The condition number: an inverse
# whose smaller eigenvalue is rounding of the larger (float64's 1e-16
# leaves 1e-10 of it at 1e6).  The error: 1 m, 40% of the table's length:
# a centre known only to the table's size is no measurement.
MAX_COV_CONDITION = 1e6
MAX_STATED_SD_M = 1.0
# Frames needed with a finite stated error before the stated errors are
# used; otherwise the spread of the track itself (the moments refinement
# states no error).
MIN_STATED_FRAMES = 8


def as_covariance(stderr_or_cov, n: int) -> np.ndarray:
    """Per-frame covariance (m^2), shape (n, 2, 2), from a covariance
    (n, 2, 2), per-axis standard errors (n, 2) or one error per frame (n,)."""
    a = np.asarray(stderr_or_cov, dtype=float)
    if a.ndim == 3:
        return a.copy()
    se = np.broadcast_to(a[:, None] if a.ndim == 1 else a, (n, 2))
    cov = np.zeros((n, 2, 2))
    cov[:, 0, 0], cov[:, 1, 1] = se[:, 0] ** 2, se[:, 1] ** 2
    return cov


def stated_frames(stderr_or_cov) -> np.ndarray:
    """Which frames state their error, shape (n,) bool: a finite, positive
    definite covariance (m^2; or finite positive per-axis errors, m) whose
    condition number is at most :data:`MAX_COV_CONDITION` and whose largest
    standard error is at most :data:`MAX_STATED_SD_M`.  The others carry no
    measurement and are left out (masked), never weighted: an indefinite
    one made the measurements' Cholesky fail (a tracker's relearnt fits,
    seed 22 realistic shot 16, FFV1, before the tracker checked them too),
    a numerically singular one the codec's (seed 45 shot 28, MJPG)."""
    a = np.asarray(stderr_or_cov, dtype=float)
    c = as_covariance(a, len(a))
    with np.errstate(invalid="ignore"):
        ok = (np.all(np.isfinite(c), axis=(1, 2)) & (c[:, 0, 0] > 0) & (c[:, 1, 1] > 0)
              & (c[:, 0, 0] * c[:, 1, 1] - c[:, 0, 1] * c[:, 1, 0] > 0))
    lam = np.linalg.eigvalsh(0.5 * (c[ok] + np.swapaxes(c[ok], -1, -2)))
    ok[ok] = (lam[:, 0] > 0) & (lam[:, 1] <= MAX_COV_CONDITION * lam[:, 0]) & (lam[:, 1] <= MAX_STATED_SD_M**2)
    return ok


def table_covariance(camera, xy, stderr_px) -> np.ndarray:
    """Per-frame covariance in table metres (m^2), shape (n, 2, 2), from the
    tracker's per-axis pixel errors (n, 2) or pixel covariances (n, 2, 2),
    through the camera's Jacobian at each frame's position
    (``camera.cov_to_table``); NaN where the frame has no position."""
    xy = np.asarray(xy, dtype=float)
    cov_px = as_covariance(stderr_px, len(xy))
    out = np.full((len(xy), 2, 2), np.nan)
    good = np.all(np.isfinite(xy), axis=1)
    if good.any():
        out[good] = camera.cov_to_table(xy[good], cov_px[good])
    return out


def pixel_to_table(camera, xy) -> np.ndarray:
    """Metres per pixel at each ball position, shape (n, 2, 2): the inverse of
    the camera's Jacobian ``d uv / d xy`` (``camera.jacobian``), so that a
    pixel error ``e`` is ``B e`` on the table and a pixel covariance ``C``
    is ``B C B^T``; NaN where the frame has no position."""
    xy = np.asarray(xy, dtype=float)
    out = np.full((len(xy), 2, 2), np.nan)
    good = np.all(np.isfinite(xy), axis=1)
    if good.any():
        out[good] = np.linalg.inv(camera.jacobian(xy[good]))
    return out


def fill_covariance(cov, xy) -> np.ndarray:
    """Per-frame covariances with unknown (non-finite) ones filled: by the
    median stated one when enough frames state one, else all from the
    track's own scatter (:func:`noise_from_track`)."""
    cov = np.array(cov, dtype=float)
    known = np.all(np.isfinite(cov.reshape(len(cov), -1)), axis=1)
    known &= (cov[:, 0, 0] > 0) & (cov[:, 1, 1] > 0)
    if known.sum() >= max(MIN_STATED_FRAMES, 0.5 * len(cov)):
        cov[~known] = np.median(cov[known], axis=0)
        return cov
    s = noise_from_track(xy)
    return np.broadcast_to(np.eye(2) * s**2, cov.shape).copy()


@dataclass(frozen=True)
class Measurements:
    """The measurements a fit uses, from one track.

    Attributes
    ----------
    t : ndarray, shape (n,)
        Times (s) of the frames where the ball was found.
    xy : ndarray, shape (n, 2)
        Their centres (m).
    cov : ndarray, shape (n, 2, 2)
        Each frame's covariance (m^2), the codec's share included.
    group : ndarray of int, shape (n,)
        Which measurement each frame belongs to (frames sharing one are
        averaged into it); -1 for frames left out (the strike's).
    W : ndarray, shape (m, 2, 2)
        Inverse Cholesky factor of each measurement's covariance (its
        whitener); made by :func:`_make`.
    px_to_m : ndarray, shape (n, 2, 2), or None
        Metres per pixel at each frame (:func:`pixel_to_table`): a codec's
        variance is in px^2 and goes to metres through it; None: in m^2.
    rest_scatter : bool
        A rest's frames' scatter measures their independent part
        (:func:`group_covariance`); False: a rest shares one frame's error.
    rest_min_share : float
        The least share of one frame's error a rest's frames share (a lossy
        codec's: :data:`SHARED_REST_MIN_SHARE`; 0 lossless).
    rest_scale, rest_scale_dof : float
        The moving frames' measured scale of their stated errors (chi2/dof,
        :func:`moving_scale`) and its degrees of freedom, against which a
        lossless rest's scatter is judged (:func:`group_covariance`); 1 and
        inf: the stated errors taken as exact.
    rest_look_px2 : float
        Per-axis variance (px^2, through ``px_to_m``) every rest's mean has
        beyond its frames' (:func:`still_look_covariance`); 0: none.
    rest_floor : ndarray, shape (m, 2, 2), optional
        Per measurement, the least covariance (m^2) its mean is stated
        (:func:`rest_floor_covariance`): a shaded lossy rest's one frame's
        stated covariance, zero for the others; None: none.
    touched : ndarray of bool, shape (n,), or None
        The frames the tracker flags (``TrackResult.touched``), carried for
        the strike-in-view rule (fit.decide.strike_in_view: a flagged frame
        before t0 does not show the ball still); None: none given.
    """

    t: np.ndarray
    xy: np.ndarray
    cov: np.ndarray
    group: np.ndarray
    W: np.ndarray
    px_to_m: np.ndarray | None = None
    rest_scatter: bool = False
    rest_min_share: float = 0.0
    rest_scale: float = 1.0
    rest_scale_dof: float = float("inf")
    rest_look_px2: float = 0.0
    rest_floor: np.ndarray | None = None
    touched: np.ndarray | None = None

    @property
    def used(self) -> np.ndarray:
        """Mask of the frames that enter some measurement."""
        return self.group >= 0

    @cached_property
    def n(self) -> int:
        """Number of measurements (each a 2-vector)."""
        return int(self.group.max()) + 1 if len(self.group) and self.group.max() >= 0 else 0

    @cached_property
    def _grouping(self):
        """The used frames' measurement, each measurement's frame count and
        the used frames' centres: made once (the measurements are frozen),
        for the fits' every residual (:meth:`whiten`)."""
        g = self.group[self.used]
        return g, np.bincount(g, minlength=self.n), self.xy[self.used]

    @cached_property
    def averaging(self):
        """The used frames' averaging into their measurements, a sparse (m,
        k) matrix of ``1 / count`` (:meth:`_means` as a product, for the
        Jacobians: recover.mle.jacobian_map); made once (scipy's sparse
        construction ~0.6 ms, and a recovery makes 6-10 fits)."""
        g, cnt, _ = self._grouping
        return csr_array((1.0 / cnt.astype(float)[g], (g, np.arange(len(g)))), shape=(self.n, len(g)))

    def dof(self, n_par: int) -> int:
        """Degrees of freedom of a fit of ``n_par`` parameters: 2 per measurement."""
        return max(2 * self.n - n_par, 1)

    @property
    def t_used(self) -> np.ndarray:
        return self.t[self.used]

    @property
    def touched_used(self) -> np.ndarray | None:
        """The tracker's flags (``touched``) of the used frames; None: none given."""
        return None if self.touched is None else self.touched[self.used]

    def _means(self, v):
        g, cnt, _ = self._grouping
        m = self.n
        out = np.empty((m, 2))
        for d in (0, 1):  # each axis's sums over the count: np.stack's then divided, the same numbers
            np.divide(np.bincount(g, weights=v[:, d], minlength=m), cnt, out=out[:, d])
        return out

    def whiten(self, model_used) -> np.ndarray:
        """Whitened residuals, shape (m, 2), in measurement order (time order):
        ``L^-1 (mean observed - mean model)`` for each measurement, with
        ``L L^T`` its covariance; ``model_used`` is the model at the used
        frames (``t_used``), shape (k, 2)."""
        d = self._means(self._grouping[2] - np.asarray(model_used, dtype=float))
        return np.einsum("mij,mj->mi", self.W, d)

    def whiten_many(self, models_used) -> np.ndarray:
        """:meth:`whiten` of several models, shape (P, k, 2) -> (P, m, 2):
        the same numbers (each measurement's sums in frame order, as
        bincount takes them; the whitener's products summed as einsum does)."""
        g, cnt, xy = self._grouping
        m = self.n
        v = xy[None] - np.asarray(models_used, dtype=float)
        P = v.shape[0]
        index = (g[None, :] + m * np.arange(P)[:, None]).ravel()
        d = [np.bincount(index, weights=v[:, :, k].ravel(), minlength=P * m).reshape(P, m) / cnt for k in (0, 1)]
        W = self.W
        return np.stack([W[:, i, 0] * d[0] + W[:, i, 1] * d[1] for i in (0, 1)], axis=-1)

    def whiten_delta(self, delta_used) -> np.ndarray:
        """The whitened measurements' change, shape (m, 2), when the model
        at the used frames changes by ``delta_used`` (linear; for Jacobians)."""
        return np.einsum("mij,mj->mi", self.W, self._means(np.asarray(delta_used, dtype=float)))

    @property
    def single(self) -> np.ndarray:
        """Mask over measurements: those of one frame (moving-ball frames)."""
        g = self.group[self.used]
        return np.bincount(g, minlength=self.n) == 1

    @property
    def t_means(self) -> np.ndarray:
        """Each measurement's time (s), the mean of its frames', shape (m,)."""
        g = self.group[self.used]
        return np.bincount(g, weights=self.t_used, minlength=self.n) / np.bincount(g, minlength=self.n)

    @property
    def t_single(self) -> np.ndarray:
        """Times (s) of the frames measured one by one (the moving ball's), in frame order."""
        return self.t_used[self.single[self.group[self.used]]]

    def median_sigma(self) -> float:
        """The used frames' median per-axis position error (m); 0 without frames."""
        cov = self.cov[self.used]
        return float(np.median(np.sqrt(0.5 * (cov[:, 0, 0] + cov[:, 1, 1])))) if len(cov) else 0.0

    def codec_shape(self) -> np.ndarray:
        """Each frame's covariance (m^2) per unit of codec variance, shape
        (n, 2, 2): ``B B^T`` with ``B`` its metres per pixel, or the identity
        without a camera."""
        if self.px_to_m is None:
            return np.broadcast_to(np.eye(2), self.cov.shape).copy()
        return self.px_to_m @ np.swapaxes(self.px_to_m, -1, -2)

    def codec_factor(self) -> np.ndarray:
        """Per measurement, shape (m, 2, 2), a factor ``F`` of its codec
        covariance per unit variance (``F F^T``): a single frame's metres per
        pixel (the same pixel error seen through it: between frames the
        codec's shared error is ``rho F_i F_j^T``), a rest's Cholesky factor
        of its frames' mean :meth:`codec_shape`."""
        g = self.group[self.used]
        m = self.n
        if self.px_to_m is None:
            return np.broadcast_to(np.eye(2), (m, 2, 2)).copy()
        K = np.zeros((m, 2, 2))
        np.add.at(K, g, self.codec_shape()[self.used])
        K /= np.bincount(g, minlength=m)[:, None, None]
        F = np.linalg.cholesky(K)
        frame = np.zeros(m, dtype=int)
        frame[g[::-1]] = np.flatnonzero(self.used)[::-1]  # each measurement's first frame
        one = self.single
        F[one] = self.px_to_m[frame[one]]
        return F

    def codec_m2(self, codec_var: float) -> float:
        """The codec's per-axis variance ``codec_var`` in table m^2 at the
        median frame (for a single figure; the fit weights each frame by its own)."""
        K = self.codec_shape()
        return float(codec_var * np.median(0.5 * (K[:, 0, 0] + K[:, 1, 1]))) if len(K) else 0.0

    def codec_floor(self) -> np.ndarray:
        """Per frame, shape (n,), the most negative codec variance it takes:
        ``-(1 - MIN_NOISE_FRACTION^2) lambda_min`` with ``lambda_min`` the
        smallest generalised eigenvalue of its stated covariance against its
        :meth:`codec_shape` (``cov v = lambda K v``), so ``cov + c K`` stays
        at or above ``MIN_NOISE_FRACTION^2 cov`` in every direction (under a
        tilted camera the two are correlated in x and y, and a floor on the
        diagonal alone could leave a matrix that is no covariance)."""
        K = self.codec_shape()
        Li = np.linalg.inv(np.linalg.cholesky(K))
        lam = np.linalg.eigvalsh(Li @ self.cov @ np.swapaxes(Li, -1, -2))[:, 0]
        return -(1.0 - MIN_NOISE_FRACTION**2) * lam

    def with_codec(self, codec_var: float) -> "Measurements":
        """The same measurements with a codec's per-axis error variance
        ``codec_var`` (px^2 through ``px_to_m``, else m^2; signed: negative
        takes back an overstatement) added to every frame, each frame's share
        no more negative than :meth:`codec_floor` (its covariance then stays
        at least ``MIN_NOISE_FRACTION^2`` of the stated: continuous in
        ``codec_var``, so recover.measurements.codec_excess can solve for it
        with the floor inside the equation)."""
        c = np.maximum(float(codec_var), self.codec_floor())
        cov = self.cov + c[:, None, None] * self.codec_shape()
        return _make(self.t, self.xy, cov, self.group, self.px_to_m, self.rest_scatter, self.rest_min_share,
                     self.rest_scale, self.rest_scale_dof, self.rest_look_px2, self.rest_floor, self.touched)


def group_scatter(xy, group, measured: bool = True) -> np.ndarray:
    """Per measurement, shape (m, 2, 2), the scatter (sample covariance,
    m^2) of its frames' centres about their mean; NaN for a measurement of
    fewer than :data:`MIN_REST_SCATTER_FRAMES` frames, or for every one when
    not ``measured`` (a lossy codec's rest: one shared error)."""
    used = group >= 0
    g, p = group[used], np.asarray(xy, dtype=float)[used]
    m = int(g.max()) + 1 if len(g) else 0
    cnt = np.bincount(g, minlength=m)
    mean = np.stack([np.bincount(g, weights=p[:, d], minlength=m) for d in (0, 1)], 1) / np.maximum(cnt, 1)[:, None]
    d = p - mean[g]
    S = np.zeros((m, 2, 2))
    np.add.at(S, g, d[:, :, None] * d[:, None, :])
    S /= np.maximum(cnt - 1, 1)[:, None, None]
    S[(cnt < MIN_REST_SCATTER_FRAMES) | (not measured)] = np.nan
    return S


def group_covariance(frame_cov_used, g, m: int, scatter, min_share: float = 0.0, scale: float = 1.0,
                     scale_dof: float = float("inf")) -> np.ndarray:
    """Each measurement's covariance, shape (m, 2, 2), from its frames'
    (``frame_cov_used``, the used frames', group ``g``): a single frame's
    own; a rest's mean ``(1 - f) C / n + f C`` with ``C`` its frames' mean
    stated covariance and ``f`` the share of it they have in common: with
    ``l`` the frames' ``scatter`` (:func:`group_scatter`) in units of ``C``
    (half the trace of ``C^-1 S``, distributed as ``chi^2(2(n - 1)) / (2(n -
    1))`` for independent frames), ``f = (1 - l)+``: the rest's variance is
    linear in ``f``, so this states it about right whatever the shared part
    (identical frames: ``C``; independent frames: ``C / n`` or somewhat more),
    ``f`` at least ``min_share``.  With ``min_share`` 0 (no shared error
    known: a lossless codec's rest) ``l`` is taken in units of the moving
    frames' measured ``scale`` of ``C`` (chi2/dof on ``scale_dof`` degrees
    of freedom; 1 and inf: ``C`` exact) and ``f = 1 - l / scale`` only when
    ``l / scale`` lies below the :data:`REST_SHARED_LEVEL` point of
    independent frames' (``F(2(n - 1), scale_dof)``), else 0.  Where the
    scatter is not measured, ``C`` (one shared error)."""
    c, f = group_shares(frame_cov_used, g, m, scatter, min_share, scale, scale_dof)
    return shares_covariance(c, f, g, m)


def shares_covariance(c, f, g, m: int) -> np.ndarray:
    """Each measurement's covariance, shape (m, 2, 2), from its frames' mean
    stated covariance ``c`` and their shared share ``f``
    (:func:`group_shares`; group ``g`` of the used frames): ``(1 - f) c / n
    + f c`` for its ``n`` frames (:func:`group_covariance`)."""
    n = np.bincount(g, minlength=m).astype(float)
    return c * ((1.0 - f) / n + f)[:, None, None]


def group_shares(frame_cov_used, g, m: int, scatter, min_share: float = 0.0, scale: float = 1.0,
                 scale_dof: float = float("inf")) -> tuple[np.ndarray, np.ndarray]:
    """Each measurement's frames' mean stated covariance ``C`` (m^2, shape
    (m, 2, 2)) and the share ``f`` of it they have in common (shape (m,): 0
    for a single frame), as :func:`group_covariance` has them (the same
    arguments): two frames of one rest have covariance ``f C``."""
    cnt = np.bincount(g, minlength=m)
    c = np.empty((m, 2, 2))
    for i, j in ((0, 0), (0, 1), (1, 0), (1, 1)):  # np.add.at's sums: each in frame order, from zero
        c[:, i, j] = np.bincount(g, weights=frame_cov_used[:, i, j], minlength=m)
    c /= np.maximum(cnt, 1)[:, None, None]
    share = np.zeros(m)
    share[cnt > 1] = 1.0  # a scatter not measured: one shared error
    rest = (cnt > 1) & np.all(np.isfinite(scatter.reshape(m, 4)), axis=1)
    if rest.any():
        n = cnt[rest].astype(float)
        lam = 0.5 * np.trace(np.linalg.solve(c[rest], scatter[rest]), axis1=1, axis2=2)
        f = np.clip(1.0 - lam, min_share, 1.0)
        if not min_share > 0:
            # l / scale of independent frames: F(k, scale_dof) (chi^2(k) / k for an exact C)
            k = 2.0 * (n - 1.0)
            r = lam / scale
            q = chi2.ppf(REST_SHARED_LEVEL, k) / k if np.isinf(scale_dof) else f_dist.ppf(REST_SHARED_LEVEL, k, scale_dof)
            f = np.where(r < q, 1.0 - r, 0.0)
        share[rest] = f
    return c, share


def linear_covariance(meas: Measurements, weights, ar1: float = 0.0, scale: float = 1.0,
                      acf: tuple | None = None) -> np.ndarray:
    """Covariance (m^2) of estimates linear in the track's centres, ``x_a =
    sum_i weights[a, i] xy[i]`` (the same weights on both axes), or with
    per-axis weights (shape (k, n, 2)) the scalars ``q_a = sum_i weights[a,
    i] . xy[i]``, under the errors ``meas`` states: each frame's covariance
    (the codec's share included), and between two frames of one rest their
    share of it (:func:`group_shares`, as the fit has them).  With ``ar1``,
    the frames outside every rest (the moving ball's, used by the fit or
    left out of it: the strike's window, the cue's touched run; time order)
    correlated as the maximum-likelihood fit has its own
    (recover.mle.ar1_prewhiten: ``ar1^k`` between frames ``k`` apart, in
    their whitened errors); with ``acf``, as an inter-frame codec shares
    them (recover.mle.codec_sandwich: ``rho(dt)`` of
    recover.mle.time_correlation between their whitened errors); all of it
    times ``scale`` (the factor the fit's own errors carry:
    recover.estimate.mle_noise).

    Parameters
    ----------
    meas : Measurements
    weights : ndarray, shape (k, n) or (k, n, 2)
        Per estimate, its weight on each of the track's ``n`` frames (both
        axes alike), or per axis (a scalar estimate).
    ar1 : float
        The errors' lag-1 correlation between neighbouring frames (0: independent).
    scale : float
        Factor on the stated variances (the fit's residuals' own, when larger).
    acf : tuple, optional
        An inter-frame codec's correlation in time,
        ``(a, b, tau, tau_long)`` (recover.mle.INTER_CODEC_ACF, the
        recovery's CodecCorrelation.acf); None: none.

    Returns
    -------
    ndarray, shape (2k, 2k) or (k, k)
        Ordered ``(x_0, y_0, x_1, y_1, ...)``; per-axis weights: ``(q_0, q_1, ...)``.
    """
    Wt = np.asarray(weights, dtype=float)
    if Wt.ndim == 2:
        # Both axes alike: estimate a's x and y as two scalars (2a, 2a + 1).
        G = np.zeros((2 * len(Wt), Wt.shape[1], 2))
        G[0::2, :, 0] = G[1::2, :, 1] = Wt
    else:
        G = Wt
    # Every frame's own covariance: sum_i G_a,i^T C_i G_b,i.
    out = np.einsum("aij,ijk,bik->ab", G, meas.cov, G)
    used = meas.used
    if used.any():
        g = meas.group[used]
        m = meas.n
        c, f = group_shares(meas.cov[used], g, m, group_scatter(meas.xy, meas.group, meas.rest_scatter),
                            meas.rest_min_share, meas.rest_scale, meas.rest_scale_dof)
        # Pairs of frames within one rest: f (S_a^T C S_b - sum_i G_a,i^T C G_b,i) per rest.
        Gu = G[:, used]
        S = np.stack([np.stack([np.bincount(g, weights=Gu[a, :, j], minlength=m) for j in range(2)], -1)
                      for a in range(len(G))])
        fc = f[:, None, None] * c
        out += np.einsum("amj,mjk,bmk->ab", S, fc, S) - np.einsum("aij,ijk,bik->ab", Gu, fc[g], Gu)
        # The still look's error, and a rest's rise to its floor: each one
        # error shared by all the rest's frames.
        _, shared = rest_covariance(shares_covariance(c, f, g, m),
                                    still_look_covariance(meas.group, meas.px_to_m, meas.rest_look_px2),
                                    meas.rest_floor)
        out += np.einsum("amj,mjk,bmk->ab", S, shared, S)
        if ar1 > 0:
            out += _ar1_extra(meas, G, float(ar1))
        if acf is not None:
            out += _shared_extra(meas, G, acf)
    return scale * out


def _single_frames(meas: Measurements, G):
    """The frames outside every rest, in frame order: those the fit measured
    one by one (the moving ball's) and those it left out (the strike's
    window, the cue's touched run), which the paper's segmentation may
    weight; and each estimate's share of their whitened errors, ``Y``
    (frames, k, 2): ``L_i^T G_a,i`` with ``L_i`` the frame's Cholesky
    factor.  (Before, only the fit's frames: the codec's correlation
    between a left-out frame and its neighbours was dropped; in the
    reviewer's lc.py, 120 fps, x0 from a slide's first 30 frames, the sd
    came out 1.48 / 1.80 times too small with a 50 / 100 ms window left out.)"""
    rest = np.zeros(len(meas.group), bool)
    used = meas.used
    rest[used] = ~meas.single[meas.group[used]]
    one = np.flatnonzero(~rest)
    L = np.linalg.cholesky(meas.cov[one] + 1e-30 * np.eye(2))
    return one, np.einsum("aij,ijl->ial", G[:, one], L)


def _shared_extra(meas: Measurements, G, acf) -> np.ndarray:
    """What an inter-frame codec's error shared in time adds to
    :func:`linear_covariance`'s independent sum, shape (k, k): ``sum_(i !=
    j) rho(t_j - t_i) (L_i^T G_a,i) . (L_j^T G_b,j)`` over the single-frame
    measurements, ``rho`` recover.mle.time_correlation's off its diagonal,
    as the fit's recover.mle.shared_sandwich has it between them."""
    from cuespin.recover.mle import time_correlation
    one, Y = _single_frames(meas, G)
    if len(one) < 2:
        return 0.0
    rho = time_correlation(meas.t[one], acf)
    np.fill_diagonal(rho, 0.0)
    # rho Y first (one matrix product), then the pairs' sum: the three-way
    # einsum looped over (i, j, a, b, l), 0.1 s a 360-frame track.
    Z = (rho @ Y.reshape(len(one), -1)).reshape(Y.shape)
    return np.einsum("ial,ibl->ab", Y, Z)


def _ar1_extra(meas: Measurements, G, rho: float) -> np.ndarray:
    """What AR(1) errors of lag-1 ``rho`` along the single-frame measurements
    add to :func:`linear_covariance`'s independent sum, shape (k, k):
    ``sum_(i != j) rho^|k_i - k_j| (L_i^T G_a,i) . (L_j^T G_b,j)`` with
    ``L_i`` each frame's Cholesky factor, over the frame lattice as
    recover.mle._ar1_cov_times sums it (a forward and a backward filter)."""
    one, Y = _single_frames(meas, G)  # Y: estimate a's share of frame i's whitened errors
    if len(one) < 2:
        return 0.0
    pos = frame_lattice(meas.t[one])
    S = lattice_ar1_sums(pos, Y, rho, own=0)  # sum over j != i of rho^|i - j| Y_j
    return np.einsum("ial,ibl->ab", Y, S)


def lattice_ar1_sums(pos, Y, rho: float, own: int) -> np.ndarray:
    """``sum_j rho^|k_i - k_j| Y_j`` for each row ``i`` of ``Y`` (rows at
    frame-lattice places ``pos``, increasing: :func:`frame_lattice`), the
    frame's own term counted ``own`` times (1: the AR(1) correlation
    matrix times ``Y``; 0: its off-diagonal part), by a forward and a
    backward first-order filter over the lattice (each holds the own term
    once), O(lattice) instead of the pairs' O(n^2)."""
    from scipy.signal import lfilter
    lattice = np.zeros((pos[-1] + 1,) + Y.shape[1:])
    lattice[pos] = Y
    fwd = lfilter([1.0], [1.0, -rho], lattice, axis=0)
    bwd = lfilter([1.0], [1.0, -rho], lattice[::-1], axis=0)[::-1]
    return (fwd + bwd - (2 - own) * lattice)[pos]


def frame_lattice(ts) -> np.ndarray:
    """Each frame's place on the frame lattice (int, the first at 0): its
    time in median frame steps from the one before, rounded, at least 1 (a
    dropped frame leaves a gap; recover.mle's AR(1) model and
    :func:`linear_covariance` count lags on it)."""
    ts = np.asarray(ts, dtype=float)
    if len(ts) < 2:
        return np.zeros(len(ts), dtype=int)
    dt = float(np.median(np.diff(ts)))
    steps = np.maximum(np.rint(np.diff(ts) / dt), 1.0) if dt > 0 else np.ones(len(ts) - 1)
    return np.r_[0, np.cumsum(steps)].astype(int)


def still_look_applies(shaded: bool, lossless: bool, inter_frame: bool) -> bool:
    """Whether a track's rests carry the still look's own error
    (:data:`STILL_LOOK_VAR_PX2`, ``build_measurements(still_look=)``): a
    look the tracker shaded on a lossy intra-frame codec (MJPG); not
    measured on lossless video nor calibrated on an inter-frame codec
    (H.264).  One rule for the fit (recover.estimate) and its bound
    (pipeline.measure)."""
    return bool(shaded) and not lossless and not inter_frame


def still_look_covariance(group, px_to_m, var_px2: float) -> np.ndarray:
    """Per measurement, shape (m, 2, 2), the still look's covariance (m^2)
    of a rest's mean: ``var_px2`` per axis in pixels through its frames'
    mean ``B B^T`` (``px_to_m``, :func:`pixel_to_table`), one error shared
    by all its frames (:data:`STILL_LOOK_VAR_PX2`); zero for a single
    frame, for ``var_px2`` 0, and without ``px_to_m`` (no pixels known)."""
    used = group >= 0
    g = group[used]
    m = int(g.max()) + 1 if len(g) else 0
    out = np.zeros((m, 2, 2))
    if not var_px2 > 0 or px_to_m is None or m == 0:
        return out
    B = np.asarray(px_to_m, dtype=float)[used]
    K = B @ np.swapaxes(B, -1, -2)
    np.add.at(out, g, K)
    cnt = np.bincount(g, minlength=m)
    out *= float(var_px2) / np.maximum(cnt, 1)[:, None, None]
    out[cnt < 2] = 0.0
    return out


def rest_floor_covariance(base, floor) -> np.ndarray:
    """Per measurement, shape (m, 2, 2), what a rest's mean needs beyond its
    covariance ``base`` (m^2, shape (m, 2, 2): :func:`group_covariance`'s) to
    be stated at least ``floor`` (m^2, shape (m, 2, 2): one frame's stated
    covariance, :data:`Measurements.rest_floor`): ``(floor - base)``'s
    positive part in ``base``'s whitened frame, so ``base`` plus it is the
    least covariance above both (the Loewner order) on that frame, shared
    by all the rest's frames; zero where ``base`` already covers ``floor``
    and without a floor (None)."""
    base = np.asarray(base, dtype=float)
    out = np.zeros_like(base)
    if floor is None or len(base) == 0:
        return out
    floor = np.asarray(floor, dtype=float)
    L = np.linalg.cholesky(base)
    Li = np.linalg.inv(L)
    M = Li @ floor @ np.swapaxes(Li, -1, -2)
    M = 0.5 * (M + np.swapaxes(M, -1, -2))
    w, U = np.linalg.eigh(M)
    E = (U * np.maximum(w - 1.0, 0.0)[:, None, :]) @ np.swapaxes(U, -1, -2)
    return L @ E @ np.swapaxes(L, -1, -2)


def rest_covariance(base, look, floor) -> tuple[np.ndarray, np.ndarray]:
    """Each measurement's covariance (m^2, shape (m, 2, 2)) from its frames'
    (``base``: :func:`group_covariance`'s) and the errors all a rest's
    frames share beyond them: its still look's (``look``:
    :func:`still_look_covariance`'s) and its rise to its ``floor``
    (:func:`rest_floor_covariance`; None: none).  The one place the fit's
    whiteners (:func:`_make`), the codec's excess (:func:`codec_excess`) and
    the covariance of linear estimates (:func:`linear_covariance`) add them.

    Returns
    -------
    cov : ndarray, shape (m, 2, 2)
        ``base`` with both.
    shared : ndarray, shape (m, 2, 2)
        Both alone: one error shared by all the rest's frames.
    """
    c = base + look
    rise = rest_floor_covariance(c, floor)
    return c + rise, look + rise


def _make(t, xy, cov, group, px_to_m=None, rest_scatter: bool = False, rest_min_share: float = 0.0,
          rest_scale: float = 1.0, rest_scale_dof: float = float("inf"), rest_look_px2: float = 0.0,
          rest_floor=None, touched=None) -> Measurements:
    """Measurements with their whiteners: each measurement's covariance
    (:func:`group_covariance`, a rest's with its still look's,
    :func:`still_look_covariance`, raised to its floor,
    :func:`rest_floor_covariance`) inverted through its Cholesky factor."""
    used = group >= 0
    g = group[used]
    m = int(g.max()) + 1 if len(g) else 0
    c, _ = rest_covariance(group_covariance(cov[used], g, m, group_scatter(xy, group, rest_scatter),
                                            rest_min_share, rest_scale, rest_scale_dof),
                           still_look_covariance(group, px_to_m, rest_look_px2), rest_floor)
    W = np.linalg.inv(np.linalg.cholesky(c)) if m else np.zeros((0, 2, 2))
    return Measurements(t=t, xy=xy, cov=cov, group=group, W=W, px_to_m=px_to_m, rest_scatter=rest_scatter,
                        rest_min_share=rest_min_share, rest_scale=rest_scale, rest_scale_dof=rest_scale_dof,
                        rest_look_px2=float(rest_look_px2), rest_floor=rest_floor,
                        touched=None if touched is None else np.asarray(touched, dtype=bool))


def cue_clear_s(speed: float, R: float, frame_dt: float) -> float:
    """Time (s) after the strike until the ball, leaving at ``speed`` (m/s),
    has moved :data:`CUE_CLEAR_R` radii ``R`` (m) from the cue's tip, at
    most :data:`CUE_CLEAR_FRAMES` frame intervals ``frame_dt`` (s); 0 when
    the speed is unknown."""
    speed = float(speed) if speed is not None else float("nan")
    if not (np.isfinite(speed) and speed > 0):
        return 0.0
    return min(CUE_CLEAR_R * float(R) / speed, CUE_CLEAR_FRAMES * float(frame_dt))


def touched_run_s(t, touched, t0: float, exposure_s: float, frame_dt: float, foreign=None) -> float:
    """Time (s) after the strike ``t0`` through which the frames the tracker
    flags (``touched``) run from the first frame after it, bridging
    unflagged frames in a row between flagged ones only while they span at
    most :data:`TOUCHED_GAP_S` (as many frame intervals ``frame_dt``, s): a
    window :func:`strike_window` given it leaves out that whole run, the
    cue's tip or the spot the ball left still in its window (0 when no
    flagged frame is reached).  The first frame after the strike must be
    flagged, unless the cue is flagged where the run starts (``foreign``,
    shape (n,): ``TrackResult.foreign``, the fit saw foreign pixels; on the
    strike's own frame, the last at or before ``t0``, or in the run's first
    ``max_gap + 1`` frames, ``max_gap`` the frames :data:`TOUCHED_GAP_S`
    spans) and the unflagged frames before it span at most
    :data:`TOUCHED_GAP_S`: a run of the spot the ball left alone is never
    bridged to, nor one that only ends in a cue flag (a sliding shot's
    rest spot flagged through its slide, then the cue's one frame: bridged,
    it left the slide out; fixslip, docs/measurements.md).  The rest spot's
    flags may come first (seed 43 shot 20: the cue's frame at the strike,
    a hole, 6 of the rest spot's, then the cue's; at the refit's t0 the
    cue's frame is the strike's).  Used beside :func:`cue_clear_s`'s
    distance rule (recover.estimate), not capped by
    :data:`CUE_CLEAR_FRAMES`: the flags are the tracker's, frame by frame,
    not a guess from the speed."""
    t = np.asarray(t, dtype=float)
    if touched is None or t0 is None or not np.isfinite(t0) or len(t) == 0:
        return 0.0
    touched = np.asarray(touched, dtype=bool)
    # whole frames whose intervals fit in the time (1e-9: 2 frames at 480 fps
    # against a time set at a round 5 ms must not hinge on rounding)
    max_gap = int(np.floor(TOUCHED_GAP_S / frame_dt + 1e-9)) if frame_dt > 0 else 0
    after = np.flatnonzero(t > t0)

    def run_end(frames):  # the last flagged frame of the run from frames[0], holes bridged
        last, gap = None, 0
        for k in frames:
            if touched[k]:
                last, gap = k, 0
                continue
            gap += 1
            if last is None or gap > max_gap:
                break
        return last

    last = run_end(after)
    flagged = np.flatnonzero(touched[after])
    if last is None and foreign is not None and len(flagged):
        late = flagged[0]  # unflagged frames before the run's first flag
        end = run_end(after[late:]) if late <= max_gap else None
        # the cue's flag where the run starts (its first max_gap + 1 frames),
        # or on the strike's own frame just before the first after it
        lo = after[0] - 1 if after[0] > 0 and t[after[0] - 1] > t0 - frame_dt else after[late]
        if end is not None and np.any(np.asarray(foreign, dtype=bool)[lo:min(after[late] + max_gap, end) + 1]):
            last = end
    if last is None:
        return 0.0
    # just past the last flagged frame's exposure start, short of the next's
    return float(t[last]) - 0.5 * exposure_s - t0 + 0.1 * frame_dt


def strike_window(t, t0: float, exposure_s: float, frame_dt: float, clear_s: float = 0.0) -> np.ndarray:
    """Mask of the frames whose exposure may hold the strike at ``t0``, or
    starts within ``clear_s`` seconds after it (the cue's tip still on the
    ball: :func:`cue_clear_s`); the one definition of the strike's window.
    While that window is open (``clear_s`` > 0) it starts
    :data:`STRIKE_MARGIN_FRAMES` before ``t0`` at any exposure: an
    instantaneous frame that close before the strike found may be after the
    true one, the cue's tip on the ball (seed 43 shot 51, 120 fps: the refit's
    t0 0.12 frames late, the cue's flagged frame 0.05 frames before it and
    0.07 after the true strike, 8.7 of its free-slip LR 10.3; docs/
    measurements.md, roll45)."""
    t = np.asarray(t, dtype=float)
    if t0 is None or not np.isfinite(t0):
        return np.zeros(len(t), bool)
    start = t0 - STRIKE_MARGIN_FRAMES * frame_dt if clear_s > 0 else t0
    cue = (t > start) & (t - 0.5 * exposure_s < t0 + clear_s)
    if exposure_s <= 0:
        return cue
    half = 0.5 * exposure_s + STRIKE_MARGIN_FRAMES * frame_dt
    return (np.abs(t - t0) < half) | cue


def build_measurements(t, xy, cov, *, t0: float | None = None, t_rest: float | None = None,
                       exposure_s: float = 0.0, frame_dt: float | None = None,
                       shared_rest: bool = False, px_to_m=None, clear_s: float = 0.0,
                       group_rest: bool = True, rest_scale: float = 1.0,
                       rest_scale_dof: float = float("inf"), look_rest: bool = False,
                       look_factor: float = 1.0, still_look: bool = False, cue=None,
                       touched=None) -> Measurements:
    """Turn a track into the measurements a fit uses.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Frame times (s) of the frames where the ball was found.
    xy : ndarray, shape (n, 2)
        Centres (m).
    cov : ndarray, shape (n, 2, 2), (n, 2) or (n,)
        Per-frame covariance (m^2), or per-axis standard errors (m).
    t0 : float, optional
        Strike time (s): the frames whose exposure holds it are left out,
        and the frames before it are the first rest.
    t_rest : float, optional
        Time (s) from which the ball rests at the end of the track.
    exposure_s : float
        Exposure (s).
    frame_dt : float, optional
        Frame interval (s); the median of ``diff(t)`` when absent.
    shared_rest : bool
        The codec's error is shared by a still ball's frames (lossy): each
        rest becomes one measurement, the mean of its frames, sharing at
        least :data:`SHARED_REST_MIN_SHARE` of a frame's error.
    px_to_m : ndarray, shape (n, 2, 2), optional
        Metres per pixel at each frame (:func:`pixel_to_table`), through
        which a codec's pixel variance reaches the table
        (:meth:`Measurements.with_codec`); without it that variance is in m^2.
    clear_s : float
        Time (s) after ``t0`` for the ball to clear the cue's tip
        (:func:`cue_clear_s`): frames whose exposure starts before then are
        left out.
    group_rest : bool
        A lossless rest's frames as one measurement from their scatter
        (default); False keeps them one by one, for a fit under AR(1)
        errors, whose model already carries their correlation (grouped as
        well, the slip test's false positives on AR(1) null tracks rose
        from 3 to 8-13 of 408, tests/test_decide.py).
    rest_scale, rest_scale_dof : float
        The moving frames' measured chi2/dof and its degrees of freedom
        (:func:`moving_scale`, from a first fit) against which a lossless
        rest's scatter is judged; default 1 and inf (stated errors exact).
    look_rest : bool
        With ``shared_rest``: each rest shares :data:`LOOK_REST_SHARE` of its
        frames' stated covariance whatever their scatter (a lossless codec's
        shaded ball: the still look's error).
    look_factor : float
        With ``look_rest``: the factor the tracker put on every frame's
        covariance for the moving ball's look (``TrackResult.look_factor``),
        taken off the frames of the rests grouped here, and only those: the
        one rule of what is still (a rest from ``t0`` and ``t_rest``), whose
        error is the shared look's, of one frame's stated size.
    still_look : bool
        With ``shared_rest``: the tracker shaded the ball's look
        (``TrackResult.look_shaded``) on a lossy codec, and each rest's mean
        has the still look's own error, :data:`STILL_LOOK_VAR_PX2`
        (:func:`still_look_covariance`, with ``px_to_m``), beyond its
        frames', and is stated at least one frame's stated covariance, its
        frames' mean of ``cov`` (``Measurements.rest_floor``,
        :func:`rest_floor_covariance`): the codec's error at a still ball's
        place, the same in every frame.
    cue : ndarray of bool, shape (n,), optional
        The frames the tracker flags as the cue's (``TrackResult.foreign``):
        those before ``t0`` are left out, never part of the first rest.  A
        ball the cue's tip is pressed against is moving (the strike placed
        late: realistic MJPG seed 45 shot 55 at 480 fps, the ball first
        found 5 frames after the strike, the first fit's t0 7.6 frames
        late, its two cue-flagged frames, one 11.8 stated errors off, taken
        as the rest: free slip at LR 13.1, rolling at 2.9 without them), and
        beside a still ball the cue's pixels are no part of its look
        (docs/measurements.md, slipfix).
    touched : ndarray of bool, shape (n,), optional
        The tracker's flags (``TrackResult.touched``), kept on the result
        (``Measurements.touched``) for the strike-in-view rule; they change
        no measurement.

    Returns
    -------
    Measurements
    """
    t = np.asarray(t, dtype=float)
    xy = np.asarray(xy, dtype=float)
    cov = fill_covariance(as_covariance(cov, len(t)), xy)
    if px_to_m is not None:
        px_to_m = np.array(px_to_m, dtype=float)
        bad = ~np.all(np.isfinite(px_to_m.reshape(len(t), -1)), axis=1)
        if bad.all():
            px_to_m = None
        elif bad.any():
            px_to_m[bad] = np.median(px_to_m[~bad], axis=0)
    if frame_dt is None:
        frame_dt = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    use = ~strike_window(t, t0, exposure_s, frame_dt, clear_s) if t0 is not None else np.ones(len(t), bool)
    if cue is not None and t0 is not None and np.isfinite(t0):
        use &= ~(np.asarray(cue, dtype=bool) & (t < t0))
    key = np.arange(len(t), dtype=float)
    # A rest is one measurement (group_covariance): with a lossy codec
    # always, with a lossless one when its frames' scatter is measured.
    least = 2 if shared_rest else (MIN_REST_SCATTER_FRAMES if group_rest else len(t) + 1)
    rests = []
    if t0 is not None and np.isfinite(t0):
        rests.append(use & (t < t0 - 0.5 * exposure_s - 0.5 * frame_dt))
    if t_rest is not None and np.isfinite(t_rest):
        rests.append(use & (t > t_rest + 0.5 * exposure_s + 0.5 * frame_dt))
    for rest in rests:
        if rest.sum() >= least:
            key[rest] = key[rest][0]
            if look_rest and shared_rest:
                cov = cov.copy()  # the caller's array stays as given
                cov[rest] = cov[rest] / float(look_factor)
    group = np.full(len(t), -1)
    _, inv = np.unique(key[use], return_inverse=True)
    group[use] = inv
    rest_floor = None
    if still_look and shared_rest:
        # One frame's stated covariance per rest (its frames' mean); none
        # for a single frame (the codec's excess is its own to measure).
        g = group[group >= 0]
        m = int(g.max()) + 1 if len(g) else 0
        rest_floor, _ = group_shares(cov[group >= 0], g, m, np.full((m, 2, 2), np.nan))
        rest_floor[np.bincount(g, minlength=m) < 2] = 0.0
    return _make(t, xy, cov, group, px_to_m, rest_scatter=True,
                 rest_min_share=(LOOK_REST_SHARE if look_rest else SHARED_REST_MIN_SHARE) if shared_rest else 0.0,
                 rest_scale=float(rest_scale), rest_scale_dof=float(rest_scale_dof),
                 rest_look_px2=STILL_LOOK_VAR_PX2 if (still_look and shared_rest) else 0.0, rest_floor=rest_floor,
                 touched=touched)


def moving_scale(meas: Measurements, whitened_residuals, n_par: int) -> tuple[float, float]:
    """The moving frames' chi2/dof: a fit's whitened residuals summed over
    the single-frame measurements, over ``2 m_single - n_par`` (all the
    fit's parameters charged to them: the rests hold few).

    Returns
    -------
    (float, float)
        The scale of the stated errors' variance and its degrees of freedom;
        (1, inf), the stated errors taken as exact, when fewer than
        :data:`MIN_REST_SCATTER_FRAMES` degrees of freedom remain.
    """
    r = np.asarray(whitened_residuals, dtype=float)
    if r.shape[0] != meas.n:
        return 1.0, float("inf")
    single = meas.single
    dof = 2 * int(single.sum()) - int(n_par)
    if dof < MIN_REST_SCATTER_FRAMES:
        return 1.0, float("inf")
    return float(np.sum(r[single] ** 2) / dof), float(dof)


# The codec noise a fit may add to the tracker's stated error and still be
# an answer, as a ratio of per-axis standard deviations (codec_noise_ratio).
# Measured on the project's realistic renders (cached tracks of
# benchmarks/accuracy.py: MJPG seeds 21 and 41, plain MJPG seed 5, low
# noise seed 7; 181 shots, docs/measurements.md "guard1"): at most 2.8 on
# a correct answer, the median 0.0; a wrong friction on a real H.264 video
# needed 40-54 (auto15).  Beyond it the model does not explain the track
# (a wrong friction, an unlevel table, a collision), and the codec term
# would only hide the misfit (chi2/dof 0.65-0.95 there).
MAX_CODEC_NOISE_RATIO = 10.0


# A track that steps: the fit's misfit averaged over STEP_FRAMES
# measurements before a point and over as many after differs by more than
# MAX_STEP_R ball radii.  The tracker's centre lies within the ball, so a
# run of frames a radius or more to one side of the fitted path and the
# next run the other way are not the same ball's centre: the cue's tip
# taken for the ball, seen before and after the strike (H.264 realistic
# seed 23 shot 36: the tip 17-32 px = 1.4-2.7 R beside the ball in frames
# 10-114, the ball itself from frame 128; the fit bent its path through
# both, v0 163% off at chi2/dof 1.36 and codec noise 3.4x stated, so
# neither MAX_CHI2_PER_DOF nor MAX_CODEC_NOISE_RATIO refused it).
# Measured on 138 `ok` answers of kept realistic tracks (H.264 seeds 23
# and 24, MJPG case 4 seed 41, MJPG seed 21, FFV1 seeds 21 and 22;
# docs/measurements.md "cov13"): 1.27 R on that shot, at most 0.50 R on
# the 133 with their errors covered (z < 5), so 1.0 leaves 2x above the
# correct answers' largest and is the radius the argument gives.  Five
# measurements: the shot's false run after the strike is 9-18 frames; a
# single frame's outlier (a lossless track's strike frame, 70 stated
# errors and 0.4 R on FFV1 seed 22 shot 1) is averaged down by them.
STEP_FRAMES = 5
MAX_STEP_R = 1.0


def track_step(meas: Measurements, model_used, k: int = STEP_FRAMES) -> float:
    """The largest step (m) in the fit's misfit along the track: over every
    point between measurements (time order), the distance between the mean
    misfit (observed less model, :meth:`Measurements.whiten` unwhitened)
    of the ``k`` measurements before it and of the ``k`` after.

    Parameters
    ----------
    meas : Measurements
    model_used : ndarray, shape (k_used, 2)
        The fitted model's centre (m) at the used frames (``meas.t_used``).
    k : int
        Measurements averaged on each side.

    Returns
    -------
    float
        0 with fewer than ``2 k`` measurements.
    """
    if meas.n < 2 * k:
        return 0.0
    r = meas.whiten(model_used)
    d = np.linalg.solve(meas.W, r[..., None])[..., 0][np.argsort(meas.t_means, kind="stable")]
    c = np.vstack([np.zeros((1, 2)), np.cumsum(d, axis=0)])
    b = np.arange(k, len(d) - k + 1)
    step = (c[b] - c[b - k]) / k - (c[b + k] - c[b]) / k
    return float(np.max(np.hypot(step[:, 0], step[:, 1])))


def codec_noise_ratio(meas: Measurements, codec_var: float, sigma: float) -> float:
    """The codec's measured error over the tracker's stated one: per-axis
    standard deviations at the median frame, ``sqrt(codec_m2) / sigma``
    (signed like ``codec_var``: negative when the residuals are smaller than
    stated).

    Parameters
    ----------
    meas : Measurements
        The measurements the codec variance was solved on (its camera).
    codec_var : float
        The codec's per-axis variance (px^2 through ``px_to_m``, else m^2;
        :func:`codec_excess`).
    sigma : float
        The track's stated per-axis error at the median frame (m).

    Returns
    -------
    float
        0 when ``sigma`` is not a positive number.
    """
    if not (sigma > 0) or codec_var == 0:
        return 0.0
    c = meas.codec_m2(codec_var)
    return float(math.copysign(math.sqrt(abs(c)), c) / sigma)


def codec_excess(meas: Measurements, whitened_residuals, n_par: int) -> float:
    """Per-axis error variance a lossy codec adds beyond the stated one
    (px^2 when ``meas`` carries ``px_to_m``, else m^2).

    Measured from a fit's residuals over all its measurements (a rest's
    mean included: its shared compression error is the codec's too): the
    variance ``c`` for which the residuals, weighted by the measurements
    :meth:`Measurements.with_codec` makes of it (the codec's share through
    each frame's metres per pixel, and the floor at ``MIN_NOISE_FRACTION``
    of the stated errors), match the fit's degrees of freedom,
    ``sum |W_c r|^2 = 2m - n_par`` (a weighted moment equation: the stated
    errors vary along the track, and an unweighted excess is ruled by the
    largest).  Solved on the very covariances the fit then uses, so the
    floor is inside the equation, not applied after it (where it left the
    weighted residuals short of the degrees of freedom).  Signed: negative
    when the residuals are smaller than stated (MJPG at low noise, where
    the tracker states 1.2-1.4 times its real error); no lower than puts
    every frame on its floor.

    Returns
    -------
    float
        0 when too few measurements.
    """
    r = np.asarray(whitened_residuals, dtype=float)
    m = meas.n
    dof = 2 * m - n_par
    if r.shape[0] != m or dof <= 2:
        return 0.0
    raw = np.einsum("mij,mj->mi", np.linalg.inv(meas.W), r)      # (m, 2), m
    used = meas.used
    g = meas.group[used]
    cov, K, floor = meas.cov[used], meas.codec_shape()[used], meas.codec_floor()[used]
    scatter = group_scatter(meas.xy, meas.group, meas.rest_scatter)
    look = still_look_covariance(meas.group, meas.px_to_m, meas.rest_look_px2)

    def excess_chi2(c):
        # As with_codec(c).whiten, without building the Measurements; NaN
        # where a measurement's covariance is numerically no covariance.
        C, _ = rest_covariance(group_covariance(cov + np.maximum(c, floor)[:, None, None] * K, g, m, scatter,
                                                meas.rest_min_share, meas.rest_scale, meas.rest_scale_dof),
                               look, meas.rest_floor)
        try:
            w = np.linalg.solve(np.linalg.cholesky(C), raw[:, :, None])[:, :, 0]
        except np.linalg.LinAlgError:
            return float("nan")
        return float(np.sum(w * w)) - dof

    s2 = np.diagonal(cov, axis1=1, axis2=2)                          # stated per-axis variances
    k = np.diagonal(K, axis1=1, axis2=2)                             # per unit codec variance
    lo = float(floor.min())                                          # every frame on its floor
    hi = max(float(np.sum(raw * raw) / k.min()), float((s2 / k).max()))
    at_lo = excess_chi2(lo)
    if not np.isfinite(at_lo):
        # The floor cancels some frame's covariance in rounding (stated_frames
        # leaves such frames out; a caller's own Measurements may not): the
        # bracket starts at the lowest c found valid between it and 0 (the
        # stated covariances, which _make already factored).
        ok = 0.0
        for _ in range(64):
            mid = 0.5 * (lo + ok)
            if np.isfinite(excess_chi2(mid)):
                ok = mid
            else:
                lo = mid
        lo, at_lo = ok, excess_chi2(ok)
        if not np.isfinite(at_lo):
            return 0.0
    if at_lo <= 0:
        return lo
    if not excess_chi2(hi) < 0:
        return hi
    # The sum falls as c grows, continuously (Measurements.codec_floor).
    return float(brentq(excess_chi2, lo, hi, xtol=1e-12 * (hi - lo), rtol=1e-12))
