"""A picture of one shot: the track over the video, each method's fitted path, the residuals.

Drawn from the public recover result (docs/output.md) and the forward model
(``cuespin.physics``) only: each method's ``x0, v0, w0, t0`` (and its
friction when it fitted one) is run through the model and compared with the
track, so the picture shows what the answer predicts, not how it was found.
Where the residuals leave the band of a few stated errors is where a bad
calibration, a cushion contact or a missed strike shows.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np

STYLE = {"paper": {"color": "tab:orange", "marker": "s"}, "mle": {"color": "tab:blue", "marker": "o"}}
OTHER = {"color": "tab:green", "marker": "^"}
# Frames read for the background picture: their median hides a moving ball.
BACKGROUND_FRAMES = 15
# Residual axis limit (stated errors): beyond it the points are drawn on the edge.
RESID_LIMIT = 8.0
# Seconds of travel the v0 arrow shows (so its length reads as a speed).
ARROW_S = 0.15
# Gauss-Legendre nodes over the exposure: the model averaged as the sensor does.
_GL = np.polynomial.legendre.leggauss(4)
_EXPOSURE_NODES, _EXPOSURE_WEIGHTS = 0.5 * _GL[0], 0.5 * _GL[1]


def method_shot(m: dict, params):
    """The shot and friction a method's answer states, or None when it states none.

    Parameters
    ----------
    m : dict
        One entry of the recover result's ``methods``.
    params : BallParams
        The scene's friction, replaced by the method's own ``mu_s``/``mu_r``
        when it fitted them.

    Returns
    -------
    (Shot, BallParams) or None
    """
    from cuespin.physics.motion import Shot

    if not isinstance(m, dict) or any(m.get(k) is None for k in ("x0", "v0", "w0", "t0")):
        return None
    p = params
    if m.get("mu_s") is not None and m.get("mu_r") is not None:
        p = replace(params, mu_s=float(m["mu_s"]), mu_r=float(m["mu_r"]))
    return Shot(tuple(m["x0"]), tuple(m["v0"]), tuple(m["w0"]), float(m["t0"])), p


def predicted_xy(shot, params, t, exposure_s: float = 0.0) -> np.ndarray:
    """The forward model's centre (m) at times ``t`` (s), averaged over the exposure (s)."""
    from cuespin.physics.motion import positions

    t = np.atleast_1d(np.asarray(t, dtype=float))
    if exposure_s <= 0:
        return positions(shot, params, t)
    tt = (t[:, None] + exposure_s * _EXPOSURE_NODES[None, :]).ravel()
    xy = positions(shot, params, tt).reshape(len(t), len(_EXPOSURE_NODES), 2)
    return np.einsum("nkd,k->nd", xy, _EXPOSURE_WEIGHTS)


def background_frame(video, n_frames: int, k: int = BACKGROUND_FRAMES) -> np.ndarray:
    """Median of ``k`` frames spread over the video (grey, uint8): the felt, a moving ball gone."""
    import cv2

    from cuespin.videoio import quiet_native_stderr

    n = max(int(n_frames), 1)
    want = set(np.unique(np.linspace(0, n - 1, min(k, n)).round().astype(int)).tolist())
    frames = []
    with quiet_native_stderr():
        cap = cv2.VideoCapture(str(video))
        try:
            for i in range(max(want) + 1):
                if not cap.grab():
                    break
                if i in want:
                    ok, img = cap.retrieve()
                    if ok:
                        frames.append(img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_BGR2GRAY))
        finally:
            cap.release()
    if not frames:
        raise ValueError(f"{video}: no frame could be read")
    return np.median(np.stack(frames), axis=0).astype(np.uint8)


def _camera(tr, scene):
    """The track's camera (its size filled from the video), else the scene's."""
    return getattr(tr, "camera", None) or scene.camera


def seen_until(result: dict, tr) -> float:
    """Time (s) of the last frame the analysis used: the last tracked one, or the contact."""
    ok = np.asarray(tr.ok, bool)
    t = np.asarray(tr.t, float)
    t_seen = float(t[ok][-1]) if ok.any() else float(t[-1])
    c = (result.get("track") or {}).get("contact")
    if isinstance(c, dict) and c.get("t") is not None:
        t_seen = min(t_seen, float(c["t"]))
    return t_seen


def residuals(result: dict, tr, scene) -> dict:
    """Each method's normalised residuals: (track - its prediction) / stated error, per axis.

    Returns
    -------
    dict
        ``{method: (t, r)}`` with ``t`` (s), shape (n,), and ``r``, shape (n, 2),
        over the tracked frames up to the last the analysis used (a contact
        ends it).  Stated errors are the tracker's, carried to the table by
        the camera (``pipeline.run.track_stderr_m``).
    """
    from cuespin.pipeline.run import track_stderr_m

    se = track_stderr_m(tr, _camera(tr, scene))
    t = np.asarray(tr.t, float)
    xy = np.asarray(tr.xy, float)
    use = np.asarray(tr.ok, bool) & np.all(np.isfinite(xy), axis=1) & (t <= seen_until(result, tr) + 1e-9)
    fill = np.nanmedian(se) if np.isfinite(se).any() else np.nan
    se = np.where(np.isfinite(se), se, fill)
    out = {}
    for name, m in (result.get("methods") or {}).items():
        sp = method_shot(m, scene.physics)
        if sp is None or not use.any():
            continue
        pred = predicted_xy(sp[0], sp[1], t[use], _camera(tr, scene).exposure_s)
        out[name] = (t[use], (xy[use] - pred) / se[use])
    return out


def _draw_path(ax, cam, shot, params, t_seen, style, label):
    """The method's sliding parabola (solid) and rolling line (dashed) in pixels;
    the part after the last frame seen is drawn faint (a prediction)."""
    from cuespin.physics.motion import phases

    ph = phases(shot, params)
    t2 = ph.t2 if math.isfinite(ph.t2) else t_seen + 2.0
    for (a, b), ls, part in (((shot.t0, ph.t1), "-", "sliding"), ((ph.t1, t2), "--", "rolling")):
        if not b > a:
            continue
        t = np.linspace(a, b, 200)
        uv = cam.to_pixels(predicted_xy(shot, params, t))
        seen = t <= t_seen
        if seen.any():
            ax.plot(uv[seen, 0], uv[seen, 1], ls, color=style["color"], lw=1.4, label=f"{label}: {part}")
        if (~seen).any():
            ax.plot(uv[~seen, 0], uv[~seen, 1], ls, color=style["color"], lw=1.0, alpha=0.35,
                    label=None if seen.any() else f"{label}: {part} (predicted)")
    return ph


def _arrow(ax, cam, x, d, color, lw=1.8, head="-|>"):
    """An arrow from table point ``x`` along table vector ``d`` (m), drawn in pixels."""
    a, b = cam.to_pixels(np.array([x, np.asarray(x) + d]))
    ax.annotate("", xy=b, xytext=a, arrowprops=dict(arrowstyle=head, color=color, lw=lw))


def _angle_se(vec, se) -> float:
    """Standard error (rad) of a 2-vector's direction, from per-axis standard errors."""
    vec, se = np.asarray(vec, float), np.asarray(se, float)
    n = np.hypot(*vec)
    if n == 0 or not np.all(np.isfinite(se)):
        return math.nan
    perp = np.array([-vec[1], vec[0]]) / n
    return float(np.sqrt(np.sum((perp * se) ** 2)) / n)


def _wedge(ax, cam, x, d, ang_se, color):
    """The arrow's direction +/- 2 standard errors, as a shaded wedge."""
    if not np.isfinite(ang_se) or ang_se <= 0:
        return
    half = min(2 * ang_se, math.pi / 2)
    base = math.atan2(d[1], d[0])
    ang = np.linspace(base - half, base + half, 30)
    pts = np.vstack([x, np.asarray(x) + np.hypot(*d) * np.stack([np.cos(ang), np.sin(ang)], axis=1), x])
    uv = cam.to_pixels(pts)
    ax.fill(uv[:, 0], uv[:, 1], color=color, alpha=0.25, lw=0)


def _pm(se, key):
    v = se.get(key)
    return f" ± {np.hypot(*v):.1g}" if v is not None and all(c is not None for c in v) else ""


def draw_shot(result: dict, tr, scene, background: np.ndarray, png) -> None:
    """Write the picture of one shot (see the module's docstring) to ``png``."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cam = _camera(tr, scene)
    R = scene.physics.R
    methods = {k: v for k, v in (result.get("methods") or {}).items() if isinstance(v, dict)}
    res = residuals(result, tr, scene)
    n_res = max(len(res), 1)
    fig = plt.figure(figsize=(10, 6.0 + 1.6 * n_res))
    gs = fig.add_gridspec(1 + n_res, 1, height_ratios=[4.5] + [1.4] * n_res, hspace=0.5)
    ax = fig.add_subplot(gs[0])
    ax.imshow(background, cmap="gray", vmin=0, vmax=255, interpolation="nearest")
    ok = np.asarray(tr.ok, bool)
    uv = np.asarray(tr.uv, float)
    t_seen = seen_until(result, tr)
    ax.plot(uv[ok, 0], uv[ok, 1], ".", ms=2.5, color="w", mec="k", mew=0.3, label="tracked centres")
    pts = [uv[ok]] if ok.any() else []
    text = []
    first_name = next((n for n in methods if method_shot(methods[n], scene.physics)), None)
    for name, m in methods.items():
        sp = method_shot(m, scene.physics)
        if sp is None:  # no path without w0; the strike and v0 when the method states them
            style = STYLE.get(name, OTHER)
            if m.get("x0") is not None:
                u = cam.to_pixels(np.atleast_2d(m["x0"]))[0]
                pts.append(u[None])
                ax.plot(*u, style["marker"], ms=7, color=style["color"])
                if m.get("v0") is not None:
                    _arrow(ax, cam, np.asarray(m["x0"]), np.asarray(m["v0"]) * ARROW_S, style["color"])
            v0 = f"|v0| {np.hypot(*m['v0']):.4f}{_pm(m.get('stderr') or {}, 'v0')} m/s, " if m.get("v0") else ""
            text.append((f"{name} ({m.get('status')}): {v0}no path drawn (w0 not determined)", style["color"]))
            continue
        style = STYLE.get(name, OTHER)
        shot, p = sp
        ph = _draw_path(ax, cam, shot, p, t_seen, style, f"{name} ({m.get('status')})")
        marks = [("x0", np.asarray(shot.x0), shot.t0)]
        if math.isfinite(ph.t1):
            marks.append(("x1", ph.x1, ph.t1))
        if math.isfinite(ph.t2) and np.all(np.isfinite(ph.x2)):
            marks.append(("x2", ph.x2, ph.t2))
        for lab, x, tx in marks:
            u = cam.to_pixels(np.atleast_2d(x))[0]
            pts.append(u[None])
            beyond = tx > t_seen + 0.5 / cam.fps
            ax.plot(*u, style["marker"], ms=7, mfc="none" if beyond else style["color"], mec=style["color"])
            if name == first_name or beyond:  # the methods' marks nearly coincide: label them once
                ax.annotate(lab + (" (predicted)" if beyond else ""), u, fontsize=8, color=style["color"],
                            xytext=(6, 6 if name == first_name else -12), textcoords="offset points")
        se = m.get("stderr") or {}
        v0, w0 = np.asarray(shot.v0), np.asarray(shot.w0)
        speed, wn = float(np.hypot(*v0)), float(np.hypot(*w0))
        _arrow(ax, cam, shot.x0, v0 * ARROW_S, style["color"])
        if se.get("v0"):
            _wedge(ax, cam, shot.x0, v0 * ARROW_S, _angle_se(v0, se["v0"]), style["color"])
        if wn > 0:
            d = w0 / wn * (0.6 * speed * ARROW_S + 4 * R)
            _arrow(ax, cam, shot.x0, d, style["color"], lw=0.9, head="-[")
            if se.get("w0"):
                _wedge(ax, cam, shot.x0, d, _angle_se(w0, se["w0"]), style["color"])
        text.append((f"{name} ({m.get('status')}): |v0| {speed:.4f}{_pm(se, 'v0')} m/s, "
                     f"|w0| {wn:.2f}{_pm(se, 'w0')} rad/s, t0 {shot.t0:.4f} s", style["color"]))
    for i, (line, color) in enumerate(text):
        ax.text(0.01, 0.03 + 0.07 * (len(text) - 1 - i), line, transform=ax.transAxes, fontsize=8, color=color,
                bbox=dict(facecolor="white", alpha=0.8, lw=0, pad=1.5))
    c = (result.get("track") or {}).get("contact")
    if isinstance(c, dict) and c.get("t") is not None and ok.any():
        k = int(np.argmin(np.where(ok, np.abs(np.asarray(tr.t, float) - float(c["t"])), np.inf)))
        ax.plot(*uv[k], "X", ms=11, color="tab:red", mec="k", label=f"contact ({c.get('kind', 'unknown')})")
    allp = np.vstack(pts) if pts else np.zeros((0, 2))
    allp = allp[np.all(np.isfinite(allp), axis=1)]
    if len(allp):  # frame the shot, not the whole table
        pad = 6 * R * cam.px_per_m(np.array([scene.table.length / 2, scene.table.width / 2]))
        lo, hi = allp.min(axis=0) - pad, allp.max(axis=0) + pad
        ax.set_xlim(max(lo[0], -0.5), min(hi[0], cam.width - 0.5))
        ax.set_ylim(min(hi[1], cam.height - 0.5), max(lo[1], -0.5))
    ax.set_xlabel("u (px)")
    ax.set_ylabel("v (px)")
    ax.legend(fontsize=7, loc="best", framealpha=0.8)
    ax.set_title(f"{result.get('video', '')}: solid = sliding, dashed = rolling, faint = after the last frame seen "
                 f"(predicted); markers x0, x1, x2 (hollow: predicted)\narrows from x0: v0 (length {ARROW_S:g} s of "
                 f"travel) and the spin axis w0 (bar head); shaded wedges: direction ± 2 std err; "
                 f"best: {result.get('best') or 'none'}", fontsize=8)
    first = None
    for i, (name, (t, r)) in enumerate(res.items()):
        a = fig.add_subplot(gs[1 + i], sharex=first)
        first = first or a
        style = STYLE.get(name, OTHER)
        for j, (axis, mk) in enumerate((("x", "o"), ("y", "^"))):
            a.plot(t, np.clip(r[:, j], -RESID_LIMIT, RESID_LIMIT), mk, ms=2.2, color=style["color"],
                   alpha=0.8 if j == 0 else 0.5)
        a.axhspan(-2, 2, color="0.88", zorder=0)
        a.axhline(0, color="k", lw=0.6)
        m = methods[name]
        for key, ls in (("t0", ":"), ("t1", "--"), ("t2", "-.")):
            if m.get(key) is not None:
                a.axvline(m[key], color="0.4", ls=ls, lw=0.8)
        beyond = int(np.sum(np.any(np.abs(r) > RESID_LIMIT, axis=1)))
        rms = float(np.sqrt(np.nanmean(r**2))) if r.size else math.nan
        a.set_ylim(-RESID_LIMIT * 1.05, RESID_LIMIT * 1.05)
        a.set_ylabel("resid / s.e.", fontsize=8)
        a.set_title(f"{name} ({m.get('status')}): (track - its prediction) / stated error; x circles, y triangles; "
                    f"RMS {rms:.2f}; {beyond} frames beyond ±{RESID_LIMIT:g} drawn on the edge; grey band ±2; "
                    "t0 dotted, t1 dashed, t2 dash-dot", fontsize=7)
        a.tick_params(labelsize=7)
    if first is not None:
        fig.axes[-1].set_xlabel("t (s)")
        t_all = np.asarray(tr.t, float)
        first.set_xlim(t_all[0] - 0.5 / cam.fps, t_all[-1] + 0.5 / cam.fps)
    fig.savefig(png, dpi=90, bbox_inches="tight")
    plt.close(fig)


def write_overlay_video(video, out, result: dict, tr, scene) -> int:
    """The video with the track and each method's fitted path drawn on every frame (H.264 MP4).

    Each method's whole path (from the forward model) is a thin line and its
    predicted centre at the frame's time a dot; the tracked centre is a white
    ring.  Returns the number of frames written.
    """
    import av
    import cv2

    from cuespin.physics.motion import phases
    from cuespin.videoio import quiet_native_stderr

    cam = _camera(tr, scene)
    paths = {}
    for name, m in (result.get("methods") or {}).items():
        sp = method_shot(m, scene.physics)
        if sp is None:
            continue
        shot, p = sp
        ph = phases(shot, p)
        t_end = ph.t2 if math.isfinite(ph.t2) else float(tr.t[-1])
        tt = np.linspace(shot.t0, max(t_end, shot.t0 + 1e-6), 300)
        poly = cam.to_pixels(predicted_xy(shot, p, tt))
        poly = poly[np.all(np.isfinite(poly), axis=1)]
        paths[name] = (sp, np.round(poly).astype(np.int32))
    colors = {"paper": (14, 127, 255), "mle": (180, 119, 31)}  # BGR of the picture's orange and blue
    radius = int(round(tr.radius_px)) + 2 if np.isfinite(tr.radius_px) else 10
    n = 0
    with quiet_native_stderr():
        cap = cv2.VideoCapture(str(video))
        container = av.open(str(out), mode="w")
        try:
            stream = container.add_stream("libx264", rate=max(int(round(cam.fps)), 1))
            # H.264 in yuv420p needs even sizes.
            stream.width, stream.height = cam.width + cam.width % 2, cam.height + cam.height % 2
            stream.pix_fmt = "yuv420p"
            stream.options = {"crf": "20", "preset": "veryfast"}
            while True:
                ok, img = cap.read()
                if not ok:
                    break
                if img.ndim == 2:
                    img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
                t = float(tr.t[n]) if n < len(tr.t) else n / cam.fps
                for name, ((shot, p), poly) in paths.items():
                    col = colors.get(name, (80, 200, 80))
                    if len(poly) > 1:
                        cv2.polylines(img, [poly.reshape(-1, 1, 2)], False, col, 1, cv2.LINE_AA)
                    if t >= shot.t0:
                        u = cam.to_pixels(predicted_xy(shot, p, [t], cam.exposure_s))[0]
                        if np.all(np.isfinite(u)):
                            cv2.circle(img, tuple(int(round(c)) for c in u), 3, col, -1, cv2.LINE_AA)
                if n < len(tr.ok) and tr.ok[n]:
                    cv2.circle(img, tuple(int(round(v)) for v in tr.uv[n]), radius, (255, 255, 255), 1, cv2.LINE_AA)
                cv2.putText(img, f"t = {t:.3f} s", (10, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (255, 255, 255), 1,
                            cv2.LINE_AA)
                if img.shape[:2] != (stream.height, stream.width):
                    img = cv2.copyMakeBorder(img, 0, stream.height - img.shape[0], 0, stream.width - img.shape[1],
                                             cv2.BORDER_REPLICATE)
                for packet in stream.encode(av.VideoFrame.from_ndarray(img, format="bgr24")):
                    container.mux(packet)
                n += 1
            for packet in stream.encode():
                container.mux(packet)
        finally:
            container.close()
            cap.release()
    return n


def show_shot(video, scene, png=None, result=None, video_out=None, track=None) -> dict:
    """Recover (unless ``result`` is given) and draw one shot.

    Parameters
    ----------
    video : str or Path
        The video.
    scene : Scene
        Its scene.
    png : str or Path, optional
        Picture to write.
    result : dict, optional
        The recover result for this video (``pipeline.run.run_recover``).
    video_out : str or Path, optional
        MP4 to write with the fit overlaid.
    track : TrackResult, optional
        The video's track, if at hand (tracked here otherwise).

    Returns
    -------
    dict
        The recover result drawn.
    """
    from cuespin.pipeline.run import run_recover
    from cuespin.track.tracker import TrackerConfig
    from cuespin.track.video import track_video

    if result is None:
        result, track = run_recover(video, scene, return_track=True)
    elif track is None:
        track = track_video(video, scene, TrackerConfig())
    if png is not None:
        draw_shot(result, track, scene, background_frame(video, track.n_frames), Path(png))
    if video_out is not None:
        write_overlay_video(video, Path(video_out), result, track, scene)
    return result
