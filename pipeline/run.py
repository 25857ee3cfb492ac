"""One shot from video to answer: track, recover, and say what was seen and what predicted.

The library side of ``cuespin recover`` (and of batch, experiments and the
Python API): no argument parsing here, so the command line, batch runs and
experiments all import this module and none imports another.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

# Fields of a method's answer that name a moment (or the place at it) after
# the strike, in the order the motion reaches them (paper section 1).
EVENTS = (("t1", "x1"), ("t2", "x2"))


def track_stderr_m(tr, camera) -> np.ndarray:
    """Per-axis standard error of each tracked centre on the table (m), shape (n, 2).

    The square root of the diagonal of :func:`track_covariance_m`; NaN where
    the frame has no centre.
    """
    cov = track_covariance_m(tr, camera)
    return np.sqrt(np.stack([cov[:, 0, 0], cov[:, 1, 1]], axis=1))


def track_covariance_m(tr, camera) -> np.ndarray:
    """Each tracked centre's covariance on the table (m^2), shape (n, 2, 2).

    The tracker states its errors in pixels (``cov_px``); each frame's is
    carried to the table through the camera's Jacobian at that frame's
    centre (:func:`cuespin.recover.measurements.table_covariance`), so a
    tilted camera's varying scale and shear reach the weights.
    """
    from cuespin.recover.measurements import table_covariance

    return table_covariance(camera, tr.xy, tr.cov_px)


def contact_cut(tr, scene, camera):
    """Where a track's analysed motion ends (CONVENTIONS.md, "What a shot is"):
    ``(contact, n)``, the first contact (``fit.contact.Contact`` or None) and
    how many leading frames the fit may use (``fit.contact.analysed_frames``).

    The one cut every caller makes (the user's path here, and
    benchmarks/accuracy.py, which must measure what the user gets).  An
    inter-frame lossy codec's errors are correlated in time as the recovery
    takes them (``recover.mle.time_correlation``, INTER_CODEC_ACF): the
    change test reads them so, or their shared drift is taken for a contact.

    Parameters
    ----------
    tr : TrackResult or namespace
        ``t``, ``xy`` (m), ``ok``, ``cov_px``, ``lossless``, ``inter_frame``.
    scene : Scene
        Its ``table``, ``physics.R`` and the resting balls of ``render``.
    camera : Camera
        Converts the stated pixel errors to metres.
    """
    from cuespin.fit.contact import analysed_frames, find_contact
    from cuespin.physics.contact import scene_balls
    from cuespin.recover.mle import time_correlation

    correlated = bool(getattr(tr, "inter_frame", False)) and not bool(getattr(tr, "lossless", True))
    contact = find_contact(tr.t, tr.xy, tr.ok, track_stderr_m(tr, camera), scene.table, scene.physics.R,
                           scene_balls(scene.render), time_corr=time_correlation if correlated else None)
    return contact, analysed_frames(tr.t, contact, camera.exposure_s)


def _num(x):
    return None if x is None or not math.isfinite(x) else float(x)


def last_tracked_t(tr) -> float | None:
    """Time (s) of the last frame in which the ball was found, None if none was."""
    ok = np.asarray(tr.ok, dtype=bool)
    return float(np.asarray(tr.t)[ok][-1]) if ok.any() else None


def mark_predictions(methods: dict, t_seen: float | None, frame_dt: float, params) -> dict:
    """Say which of each method's moments lie beyond what the video showed.

    A method's ``t1``/``x1`` (end of sliding) and ``t2``/``x2`` (rest) come
    from the fitted forward model; when such a moment is after the last frame
    the analysis used (by more than half a frame), it was never seen: it is a
    prediction, listed in the method's ``predicted`` field.  A missing ``x1``
    or ``x2`` is filled from the forward model (``physics.phases``) when the
    method has ``x0``, ``v0``, ``w0`` and ``t0``, so every method states where
    its ball ends sliding and stops.  Changes ``methods`` in place and
    returns it.

    Parameters
    ----------
    methods : dict
        The ``methods`` object of the recover result.
    t_seen : float or None
        Time (s) of the last frame the analysis could see: the last tracked
        frame, or the contact if one came first.
    frame_dt : float
        Frame interval (s).
    params : BallParams
    """
    from cuespin.physics.motion import Shot, phases

    for m in methods.values():
        if not isinstance(m, dict):
            continue
        if all(m.get(k) is not None for k in ("x0", "v0", "w0", "t0")) and \
                any(m.get(x) is None and m.get(t) is not None for t, x in EVENTS):
            p = params  # the method's own friction when it fitted one (--fit-friction)
            if m.get("mu_s") is not None and m.get("mu_r") is not None:
                p = replace(params, mu_s=float(m["mu_s"]), mu_r=float(m["mu_r"]))
            try:
                ph = phases(Shot(tuple(m["x0"]), tuple(m["v0"]), tuple(m["w0"]), float(m["t0"])), p)
                for (t, x), pos in zip(EVENTS, (ph.x1, ph.x2)):
                    if m.get(x) is None and m.get(t) is not None and np.all(np.isfinite(pos)):
                        m[x] = [float(v) for v in pos]
            except (ValueError, FloatingPointError, ZeroDivisionError):
                pass
        predicted = []
        for t, x in EVENTS:
            tv = m.get(t)
            if tv is not None and (t_seen is None or tv > t_seen + 0.5 * frame_dt):
                predicted += [k for k in (t, x) if m.get(k) is not None]
        m["predicted"] = predicted
    return methods


def run_recover(video, scene, method="all", fit_friction=False, refine="fit", progress=None,
                return_track=False, config=None):
    """Track a video and recover the shot: the JSON object of CONVENTIONS.md.

    Parameters
    ----------
    video : str or Path
        The video file.
    scene : Scene
        Its scene (only ``physics`` and ``camera`` are used).
    method : {"all", "paper", "mle"}
        Which recovery to run.
    fit_friction : bool
        Estimate mu_s and mu_r too (maximum likelihood only).
    refine : {"fit", "moments"}
        Tracker refinement; ignored when ``config`` is given.
    progress : callable, optional
        ``progress(n)`` after each ``n`` frames tracked.
    return_track : bool
        Return ``(result, TrackResult)`` instead of the result alone.
    config : TrackerConfig, optional
        Full tracker settings.

    Returns
    -------
    dict
        ``video``, ``track``, ``methods`` (each with ``predicted``), ``best``
        and ``timing_s``; every field is described in docs/output.md.

    Raises
    ------
    TrackError
        The video cannot be read at all (see ``cuespin.track.video.track_video``).
    """
    from cuespin.recover.api import recover_track
    from cuespin.recover.calibration import add_calibration_error
    from cuespin.recover.measurements import pixel_to_table
    from cuespin.track.tracker import TrackerConfig
    from cuespin.track.video import track_video

    clock = time.perf_counter()
    if config is None:
        config = TrackerConfig(refine=refine)
    tr = track_video(video, scene, config, progress=progress)
    t_track = time.perf_counter() - clock
    cam = getattr(tr, "camera", None) or scene.camera  # its size filled from the video where the scene leaves it
    cov_m = track_covariance_m(tr, cam)
    # The analysed motion ends at the first contact (CONVENTIONS.md): fit only the frames before it.
    contact, n = contact_cut(tr, scene, cam)
    out, est = recover_track(tr.t[:n], tr.xy[:n], tr.ok[:n], cov_m[:n], scene.physics, cam.exposure_s,
                             method, fit_friction, lossless=tr.lossless, independent=tr.independent_errors,
                             ar1_floor=tr.error_ar1, look_factor=tr.look_factor,
                             shaded=tr.look_shaded,
                             inter_frame=tr.inter_frame, px_to_m=pixel_to_table(cam, tr.xy[:n]),
                             touched=None if tr.touched is None else tr.touched[:n],
                             foreign=None if tr.foreign is None else tr.foreign[:n],
                             uncalibrated=tr.warning, return_estimate=True)
    if scene.calibration:
        # Each refit keeps this fit's decisions: the share measures the camera alone.
        add_calibration_error(out["methods"],
                              lambda c: _refit_through(c, tr, n, scene, method, fit_friction, est.decided),
                              scene.calibration)
    out["contact"] = None if contact is None else {"t": contact.t, "kind": contact.kind}
    noise = tr.centroid_noise_px
    track = {"frames": int(tr.n_frames), "ok_frames": int(tr.ok.sum()),
             "centroid_noise_px": _num(noise), "last_tracked_t": last_tracked_t(tr),
             "look_factor": float(getattr(tr, "look_factor", 1.0))}
    # Fields the recovery adds to the track block (top level or in its own "track").
    for key in ("contact",):
        if key in out:
            track[key] = out[key]
        elif isinstance(out.get("track"), dict) and key in out["track"]:
            track[key] = out["track"][key]
    if tr.error:
        track["error"] = tr.error
    if tr.warning:
        track["warning"] = tr.warning
    t_seen = track["last_tracked_t"]
    contact_t = (track.get("contact") or {}).get("t") if isinstance(track.get("contact"), dict) else None
    if contact_t is not None and (t_seen is None or contact_t < t_seen):
        t_seen = float(contact_t)
    mark_predictions(out["methods"], t_seen, 1.0 / cam.fps, scene.physics)
    result = {"video": Path(video).name, "track": track, "methods": out["methods"], "best": out["best"],
              "timing_s": {"track": t_track, **out["timing_s"]}}
    return (result, tr) if return_track else result


def _refit_through(camera, tr, n: int, scene, method: str, fit_friction: bool, keep=None) -> dict:
    """The methods' answers for the first ``n`` frames of a track seen through
    another camera (the tracked pixels converted anew), keeping the
    decisions ``keep`` (recover.estimate.Decided) of the fit through the scene's."""
    from cuespin.recover.api import recover_track
    from cuespin.recover.measurements import pixel_to_table, table_covariance

    uv = np.asarray(tr.uv, dtype=float)[:n]
    xy = np.full_like(uv, np.nan)
    good = np.all(np.isfinite(uv), axis=1)
    xy[good] = camera.to_table(uv[good])
    cov = table_covariance(camera, xy, np.asarray(tr.cov_px)[:n])
    return recover_track(tr.t[:n], xy, np.asarray(tr.ok)[:n], cov, scene.physics, scene.camera.exposure_s,
                         method, fit_friction, lossless=tr.lossless, independent=tr.independent_errors,
                         ar1_floor=tr.error_ar1, look_factor=tr.look_factor,
                         shaded=bool(getattr(tr, "look_shaded", False)),
                         inter_frame=tr.inter_frame,
                         px_to_m=pixel_to_table(camera, xy), keep=keep)["methods"]


MODEL_TEXT = {"full": "slip fitted (sliding, then rolling)", "rolling": "rolling from the strike (no slip)"}


def format_recover(result: dict, truth=None, params=None) -> str:
    """A readable table of a recover result (and the truth beside it, if known).

    Every line is described in docs/output.md.  Moments after the last
    tracked frame (predictions of the fitted model, never seen) carry a
    ``*``.

    Parameters
    ----------
    result : dict
        What :func:`run_recover` returns.
    truth : Shot, optional
        The scene's truth, printed as the first row.
    params : BallParams, optional
        Friction for the truth's t1 and t2 (left blank without it).
    """
    def vec(v, nd=4, fmt="f"):
        return "null" if v is None else "[" + ", ".join(f"{c:.{nd}{fmt}}" for c in v) + "]"

    def tcol(m, key):
        v = m.get(key)
        if v is None:
            return f"{'null':>8}"
        return f"{v:7.3f}" + ("*" if key in (m.get("predicted") or ()) else " ")

    tr = result["track"]
    noise = tr.get("centroid_noise_px")
    lines = [f"{result['video']}: ball found in {tr['ok_frames']} of {tr['frames']} frames"
             + (f" (last at {tr['last_tracked_t']:.3f} s)" if tr.get("last_tracked_t") is not None else "")
             + "; tracker's stated error of a centre, median: "
             + ("unknown" if noise is None else f"{noise:.4f} px per axis")]
    if tr.get("warning"):
        lines.append(f"warning: {tr['warning']}")
    contact = tr.get("contact")
    if isinstance(contact, dict):
        lines.append(f"contact ({contact.get('kind', 'unknown')}) at {contact.get('t', float('nan')):.3f} s: "
                     "later frames are not used")
    lines.append(f"{'method':6} {'status':10} {'v0 (m/s)':>22} {'w0 (rad/s)':>24} {'t0 (s)':>8} "
                 f"{'t1 (s)':>8} {'t2 (s)':>8}")
    if truth is not None:
        t1 = t2 = "        "
        if params is not None:
            from cuespin.physics.motion import phases
            ph = phases(truth, params)
            t1, t2 = f"{ph.t1:7.3f} ", f"{ph.t2:7.3f} "
        lines.append(f"{'truth':6} {'':10} {vec(truth.v0):>22} {vec(truth.w0, 2):>24} {truth.t0:8.4f} {t1}{t2}")
    any_predicted = False
    for name, m in result["methods"].items():
        t0 = m.get("t0")
        lines.append(f"{name:6} {m['status']:10} {vec(m.get('v0')):>22} {vec(m.get('w0'), 2):>24} "
                     + (f"{'null':>8}" if t0 is None else f"{t0:8.4f}") + f" {tcol(m, 't1')}{tcol(m, 't2')}")
        se = m.get("stderr") or {}
        if se.get("v0") or se.get("w0"):
            lines.append(f"{'':6} {'1 std err':10} {vec(se.get('v0'), 1, 'e'):>22} {vec(se.get('w0'), 1, 'e'):>24}"
                         + (f" {se['t0']:8.1e}" if isinstance(se.get("t0"), float) else ""))
        if m.get("model"):
            lines.append(f"{'':6} model: {MODEL_TEXT.get(m['model'], m['model'])}")
        elif m.get("trajectory"):
            lines.append(f"{'':6} sliding path: {m['trajectory']}")
        if m.get("reason"):
            lines.append(f"{'':6} reason: {m['reason']}")
        any_predicted |= bool(m.get("predicted"))
    if any_predicted:
        lines.append("* after the last tracked frame: predicted by the fitted model, not seen in the video")
    best = result.get("best")
    lines.append(f"best: {best if best else 'none (no method answered ok)'}; time (s): "
                 + ", ".join(f"{k} {v:.3f}" for k, v in result["timing_s"].items()))
    return "\n".join(lines)
