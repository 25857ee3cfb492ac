"""Measuring the tracker against truth and the Cramer-Rao bound on rendered video.

Shared by the tests, the benchmarks and the experiments: one definition of
"RMSE over moving frames" and of the bound it is compared with.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cuespin.physics.scene import Scene
from cuespin.render import FrameRenderer, render_video
from cuespin.render.draw import FrameTruth
from cuespin.track.bound import centroid_crb
from cuespin.track.tracker import FIT_BLUR_PX, TrackerConfig
from cuespin.track.video import TrackResult, track_video


@dataclass
class TrackerAccuracy:
    """Per-axis centroid RMSE over moving frames (px) beside the bound (px),
    and the RMS of the errors in the tracker's own stated errors
    (``stated_z``: 1 when its per-frame errors are honest)."""

    result: TrackResult
    truth: FrameTruth
    rmse: float
    crb: float
    stated_z: float = float("nan")

    @property
    def ratio(self) -> float:
        return self.rmse / self.crb


def tracker_accuracy(scene: Scene, video: Path, refine: str = "fit", n_eval: int = 12,
                     settle_s: float = 0.02) -> TrackerAccuracy:
    """Render ``scene`` to ``video``, track it, and compare with truth and the bound.

    Frames count from ``settle_s`` after the strike (the strike frame itself
    holds a half-still, half-moving ball that no disc model describes).  The
    bound is averaged (RMS) over ``n_eval`` of those frames, with the blur as
    a nuisance wherever the tracker fits it.
    """
    truth = render_video(scene, video)
    res = track_video(video, scene, TrackerConfig(refine=refine))
    r = FrameRenderer(scene)
    moving = np.flatnonzero(res.ok & (truth.t > scene.truth.t0 + settle_s))
    err = res.uv[moving] - truth.uv[moving]
    s = r.settings
    bounds = []
    for k in moving[np.linspace(0, len(moving) - 1, n_eval).astype(int)]:
        nodes = r._uv_nodes[k]
        # The tracker's blur estimate is the path over the exposure.
        blur_len = np.hypot(*(nodes[-1] - nodes[0])) * (1 + 1 / max(len(nodes) - 1, 1))
        bounds.append(centroid_crb(nodes, r.radius_px, s["ball_grey"], r.background,
                                   s["noise_sigma"], blur_len > FIT_BLUR_PX))
    with np.errstate(invalid="ignore", divide="ignore"):
        z = err / res.stderr_px[moving]  # NaN with refine="moments", which states none
    return TrackerAccuracy(result=res, truth=truth, rmse=float(np.sqrt(np.mean(err**2))),
                           crb=float(np.sqrt(np.mean(np.square(bounds)))),
                           stated_z=float(np.sqrt(np.mean(z**2))))


def mle_bound(scene: Scene, track, mle: dict | None = None, independent: bool = False, ar1: float | None = None,
              acf=None):
    """Cramer-Rao covariance of ``(x0, t0, v0[, w0])`` at the scene's truth.

    The inverse Fisher information of the maximum-likelihood fit's model
    (its Jacobian at the truth) for the measurements it used
    (recover.measurements): pass the fit's own
    :class:`~cuespin.recover.measurements.Measurements` as ``track``
    (``recover_track(..., return_estimate=True)`` gives them), or a
    TrackResult and the fit's JSON ``mle``, from which they are rebuilt
    the same way (strike window at its ``t0``, the rest after its ``t2``
    shared for a lossy codec, its ``codec_noise_px`` added through the
    camera, or ``codec_noise_m`` when it has none); nothing is
    segmented again.  Under the error model the fit used: its AR(1)
    correlation ``ar1`` (default the JSON's ``mle["ar1"]``; 0 when neither
    gives one); with ``acf`` (an inter-frame codec's correlation in time,
    recover.mle.INTER_CODEC_ACF) the frames' errors correlated as the fit's
    covariance takes them (recover.mle.crb_covariance).  With ``independent``, the tracker's errors with every
    frame its own, independent measurement, the bound a lossy codec's
    shared errors put out of reach (a reference).

    Returns
    -------
    (cov, rolling) : (ndarray, bool)
        ``rolling`` when the shot rolls from the strike (w0 then follows
        from v0, and ``cov`` is 5 x 5).

    Raises
    ------
    numpy.linalg.LinAlgError
        When the information matrix is singular.
    """
    from cuespin.physics import contact_velocity
    from cuespin.recover.measurements import (Measurements, build_measurements, pixel_to_table, stated_frames,
                                              table_covariance)
    from cuespin.recover.mle import crb_covariance

    truth, p, cam = scene.truth, scene.physics, scene.camera
    rolling = bool(np.hypot(*contact_velocity(np.array(truth.v0), np.array(truth.w0), p.R)) < 1e-9)
    if isinstance(track, Measurements):
        meas = track
        if independent:
            meas = build_measurements(meas.t, meas.xy, meas.cov)
    else:
        cov = table_covariance(cam, track.xy, track.cov_px)
        ok = track.ok & stated_frames(cov)  # the frames recover_track fits
        t, xy, cov = track.t[ok], track.xy[ok], cov[ok]
        mle = mle or {}
        if independent or mle.get("t0") is None:
            meas = build_measurements(t, xy, cov)
        else:
            in_px = mle.get("codec_noise_px") is not None
            c = (mle["codec_noise_px"] if in_px else mle.get("codec_noise_m")) or 0.0
            meas = build_measurements(t, xy, cov, t0=mle["t0"], t_rest=mle.get("t2"),
                                      exposure_s=cam.exposure_s, frame_dt=1.0 / cam.fps,
                                      shared_rest=not getattr(track, "independent_errors", track.lossless),
                                      look_rest=bool(track.lossless) and not getattr(track, "independent_errors",
                                                                                     track.lossless),
                                      look_factor=float(getattr(track, "look_factor", 1.0)),
                                      still_look=bool(getattr(track, "look_shaded", False)) and not track.lossless,
                                      px_to_m=pixel_to_table(cam, xy) if in_px else None,
                                      clear_s=mle.get("cue_clear_s") or 0.0,
                                      cue=None if getattr(track, "foreign", None) is None
                                      else np.asarray(track.foreign, dtype=bool)[ok],
                                      # under the AR(1) model the fit kept a lossless rest frame by frame
                                      group_rest=not mle.get("ar1"),
                                      rest_scale=mle.get("rest_scale") or 1.0,
                                      rest_scale_dof=mle.get("rest_scale_dof") or float("inf"),
                                      ).with_codec(np.sign(c) * c * c)
    if ar1 is None:
        ar1 = (mle or {}).get("ar1") or 0.0
    return crb_covariance(truth, p, meas, cam.exposure_s, rolling=rolling,
                          ar1=0.0 if independent else float(ar1), acf=None if independent else acf), rolling
