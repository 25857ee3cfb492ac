"""Seeded sampling of realistic shots and the scenes that render them.

Every function takes a seed (or a ``numpy.random.Generator``) and returns the
scene with its truth; nothing touches global random state.
"""

from __future__ import annotations


import math

import numpy as np

from cuespin.data_gen.contacts import CONTACT_PRESETS, contact_render, sample_contact
from cuespin.physics.motion import BallParams, Shot, positions
from cuespin.physics.scene import Camera, Scene, Table, default_camera, motion_end, pinhole_camera
from cuespin.physics.straight import straight_frame
from cuespin.render import look as lk

PRESETS = ("random", "case1", "case2", "case3", "case4", "case5", "masse", "leaves_table",
           *CONTACT_PRESETS)
LOOKS = ("plain", "realistic")
CAMERAS = ("topdown", "tilted")
# Frame sizes of the realistic look's cameras (px): HD, qHD and 4:3.
FRAME_SIZES = ((1280, 720), (960, 540), (800, 600))

# Spin ratio k = R w0 . j_hat / v0 for each straight case of Figure 4.
_CASE_K = {
    "case1": (-4.0, -2.8),   # R w0 < -5/2 v0: reverses while sliding
    "case2": (-2.5, -2.5),   # stops exactly as sliding ends
    "case3": (-2.2, 0.8),    # slides, then rolls forward
    "case4": (1.0, 1.0),     # natural roll from the strike
    "case5": (1.3, 2.5),     # over-spun: speeds up while sliding
}
FPS_CHOICES = (60.0, 120.0, 240.0, 480.0)


def _rng(seed) -> np.random.Generator:
    return seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)


def _render_settings(rng: np.random.Generator, fps: float, noise: float | None = None,
                     blur: bool | None = None) -> tuple[dict, float]:
    """Renderer block and exposure (s) for a sampled scene."""
    if noise is None:
        noise = float(rng.uniform(0.0, 10.0))
    if blur is None:
        blur = bool(rng.random() < 0.5)
    exposure = float(rng.uniform(0.3, 1.0) / fps) if blur else 0.0
    render = {
        "noise_sigma": round(noise, 3),
        "felt_grey": float(rng.uniform(60, 110)),
        "ball_grey": float(rng.uniform(190, 235)),
        "gradient": float(rng.uniform(0, 20)),
        "gradient_angle": float(rng.uniform(0, 2 * np.pi)),
        "seed": int(rng.integers(0, 2**31 - 1)),
    }
    return render, exposure


def _start_and_heading(rng: np.random.Generator, table: Table, R: float):
    """A start point on the table and a unit heading towards a far target."""
    margin = 0.15
    x0 = rng.uniform([margin, margin], [table.length - margin, table.width - margin])
    for _ in range(20):
        target = rng.uniform([margin, margin], [table.length - margin, table.width - margin])
        if np.hypot(*(target - x0)) > 0.6:
            break
    d = target - x0
    return x0, d / np.hypot(*d)


def sample_shot(seed, preset: str = "random", params: BallParams | None = None,
                table: Table = Table()) -> tuple[Shot, BallParams]:
    """Sample one shot's initial conditions and friction.

    Parameters
    ----------
    seed : int or numpy.random.Generator
        Source of randomness (local; never global state).
    preset : str
        One of :data:`PRESETS`: ``random`` (speeds 0.2-5 m/s log-uniform, spin
        up to 2.5 v0/R in any planar direction), ``case1``..``case5`` (straight
        shots in each case of Figure 4), ``masse`` (strong spin along v0: a
        visibly curved path sliding for half a second or more) or ``leaves_table``
        (fast, aimed at a near cushion); ``cushion`` and ``ball_contact``
        (the first contact, 0.25-2.5 s after the strike, is a cushion or a
        resting ball: see ``data_gen/contacts.py``).
    params : BallParams, optional
        Fixed friction; sampled (mu_s 0.1-0.3, mu_r 0.005-0.02) when absent.
    table : Table
        Playing surface.

    Returns
    -------
    (Shot, BallParams)
        Initial conditions (``t0`` is the lead-in, 0.1-0.5 s) and constants.
    """
    if preset not in PRESETS:
        raise ValueError(f"unknown preset {preset!r}; choose from {', '.join(PRESETS)}")
    rng = _rng(seed)
    if preset in CONTACT_PRESETS:  # data_gen/contacts.py; the other balls are dropped here
        shot, params, _ = sample_contact(rng, preset, params, table)
        return shot, params
    if params is None:
        params = BallParams(mu_s=float(rng.uniform(0.1, 0.3)), mu_r=float(rng.uniform(0.005, 0.02)))
    R = params.R
    x0, heading = _start_and_heading(rng, table, R)
    t0 = float(rng.uniform(0.1, 0.5))
    if preset == "random":
        speed = float(np.exp(rng.uniform(np.log(0.2), np.log(5.0))))
        k = float(rng.uniform(0.0, 2.5))
        ang = float(rng.uniform(0.0, 2 * np.pi))
        w0 = k * speed / R * np.array([np.cos(ang), np.sin(ang)])
    elif preset in _CASE_K:
        speed = float(rng.uniform(0.5, 3.0))
        k = float(rng.uniform(*_CASE_K[preset]))
        _, j_hat = straight_frame(heading, np.zeros(2))
        w0 = k * speed / R * j_hat
    elif preset == "masse":
        # Strong spin along v0 (R w ~ 4-7 m/s, a steep cue) gives a large
        # v0 x u_hat: a visible bend, sliding for half a second or more.
        params = BallParams(R=R, mu_s=float(rng.uniform(0.1, 0.2)), mu_r=params.mu_r, g=params.g)
        speed = float(rng.uniform(0.5, 1.5))
        spin_par = float(rng.uniform(4.0, 7.0)) * rng.choice([-1.0, 1.0])
        spin_perp = float(rng.uniform(-1.0, 1.0)) * speed
        _, j_hat = straight_frame(heading, np.zeros(2))
        w0 = (spin_par * heading + spin_perp * j_hat) / R
    else:  # leaves_table
        speed = float(rng.uniform(2.5, 5.0))
        k = float(rng.uniform(0.0, 1.0))
        ang = float(rng.uniform(0.0, 2 * np.pi))
        w0 = k * speed / R * np.array([np.cos(ang), np.sin(ang)])
        # Start near the middle, heading for the nearest cushion.
        x0 = np.array([table.length / 2, table.width / 2]) + rng.uniform(-0.2, 0.2, 2)
        heading = np.array([0.0, rng.choice([-1.0, 1.0])])
    shot = Shot(x0=x0, v0=speed * heading, w0=w0, t0=t0)
    return shot, params


def make_scene(shot: Shot, params: BallParams, fps: float = 240.0, px_per_m: float = 500.0,
               exposure_s: float = 0.0, render: dict | None = None,
               table: Table = Table()) -> Scene:
    """A scene with truth for a shot, using the conventions' top-down camera."""
    camera = default_camera(fps=fps, px_per_m=px_per_m, table=table, exposure_s=exposure_s)
    return Scene(physics=params, camera=camera, table=table, render=dict(render or {}), truth=shot)


def _jitter(rng: np.random.Generator, bgr, rel: float = 0.08) -> list[float]:
    """A colour varied by up to ``rel`` per channel (lighting, dye, white balance)."""
    return [round(float(np.clip(c * rng.uniform(1 - rel, 1 + rel), 0, 255)), 1) for c in bgr]


def framed_camera(rng: np.random.Generator, fps: float, table: Table,
                  exposure_s: float = 0.0, size: tuple[int, int] | None = None) -> Camera:
    """A top-down camera that shows the whole table with its rails and a margin.

    The frame size is one of :data:`FRAME_SIZES`; the scale leaves
    ``CUSHION_WIDTH_M + RAIL_WIDTH_M`` plus 2-10 cm around the playing
    surface, which is centred.  ``size`` fixes the frame size ``(w, h)``.
    """
    w, h = FRAME_SIZES[int(rng.integers(len(FRAME_SIZES)))]
    if size is not None:
        w, h = size
    border = lk.CUSHION_WIDTH_M + lk.RAIL_WIDTH_M + float(rng.uniform(0.02, 0.10))
    s = min(w / (table.length + 2 * border), h / (table.width + 2 * border))
    u_off = 0.5 * (w - table.length * s)
    v_off = 0.5 * (h - table.width * s) + table.width * s
    H = ((s, 0.0, u_off), (0.0, -s, v_off), (0.0, 0.0, 1.0))
    return Camera(fps=float(fps), width=w, height=h, homography=H, exposure_s=float(exposure_s))


def tilted_camera(rng: np.random.Generator, fps: float, table: Table, exposure_s: float = 0.0,
                  size: tuple[int, int] | None = None) -> Camera:
    """A real camera as a phone on a stand would be: 1.5-3 m above the cloth,
    tilted 0-15 degrees from straight down, rolled up to 2 degrees, a wide
    lens with barrel distortion (k1 -0.25 to 0, k2 up to a fifth of it the
    other way), framed to show the rails with 2-10 cm to spare."""
    w, h = FRAME_SIZES[int(rng.integers(len(FRAME_SIZES)))] if size is None else size
    k1 = float(rng.uniform(-0.25, 0.0))
    return pinhole_camera(table, height_m=float(rng.uniform(1.5, 3.0)),
                          tilt_deg=float(rng.uniform(0.0, 15.0)), size=(w, h), k1=k1,
                          k2=float(-0.2 * k1 * rng.uniform(0, 1)), fps=fps, exposure_s=exposure_s,
                          roll_deg=float(rng.uniform(-2.0, 2.0)),
                          margin_m=lk.CUSHION_WIDTH_M + lk.RAIL_WIDTH_M + float(rng.uniform(0.02, 0.10)))


def _resting_balls(rng: np.random.Generator, shot: Shot, params: BallParams, table: Table,
                   fps: float, n: int) -> list[dict]:
    """Up to ``n`` balls at rest on open cloth, clear of the shot's path and the cue.

    Each keeps 2R + 3 cm from every point of the path (until the ball stops
    or leaves), from the cue's line behind the ball, from the other balls
    and from the pockets, so no contact happens in the forward model.
    """
    R = params.R
    end, _ = motion_end(shot, params, table, fps, 20.0)
    path = positions(shot, params, np.linspace(shot.t0, max(end, shot.t0), 400))
    v0 = np.asarray(shot.v0)
    back = -v0 / max(np.hypot(*v0), 1e-12)
    cue = np.asarray(shot.x0) + np.linspace(0, 1.5, 150)[:, None] * back
    keep = np.r_[path, cue]
    clear = 2 * R + 0.03
    pk = lk.pockets(table.length, table.width)
    balls: list[dict] = []
    for _ in range(50 * n):
        if len(balls) == n:
            break
        p = rng.uniform([R + 0.01, R + 0.01], [table.length - R - 0.01, table.width - R - 0.01])
        if np.hypot(*(keep - p).T).min() < clear:
            continue
        if any(math.hypot(p[0] - b["x"], p[1] - b["y"]) < 2 * R + 0.01 for b in balls):
            continue
        if any(math.hypot(p[0] - q[0], p[1] - q[1]) < q[2] + R for q in pk):
            continue
        name = list(lk.BALL_COLOURS)[int(rng.integers(len(lk.BALL_COLOURS)))]
        balls.append({"x": round(float(p[0]), 5), "y": round(float(p[1]), 5),
                      "colour": _jitter(rng, lk.BALL_COLOURS[name])})
    return balls


def realistic_look(rng: np.random.Generator, shot: Shot, params: BallParams, table: Table,
                   fps: float) -> dict:
    """Sample the realistic look's ``render`` keys (see :data:`cuespin.render.look.LOOK_DEFAULTS`).

    Ball and felt from the usual colours (any pair, so some have a grey-level
    contrast under 25: red on green, for one), lighting from any side at
    50-80 degrees elevation, a highlight in half the scenes, a 0.5-1 px lens
    PSF, textured felt under a lighting ramp, rails, 0-4 resting balls,
    markings on a third of the balls each, a cue in half the scenes.
    """
    ball = list(lk.BALL_COLOURS)[int(rng.integers(len(lk.BALL_COLOURS)))]
    felt = list(lk.FELT_COLOURS)[int(rng.integers(len(lk.FELT_COLOURS)))]
    look = {
        "look": "realistic",
        "ball_name": ball, "felt_name": felt,
        "ball_colour": _jitter(rng, lk.BALL_COLOURS[ball]),
        "felt_colour": _jitter(rng, lk.FELT_COLOURS[felt]),
        "rail_colour": [float(c) for c in lk.RAIL_COLOURS[int(rng.integers(len(lk.RAIL_COLOURS)))]],
        "ambient": round(float(rng.uniform(0.2, 0.5)), 3),
        "light_azimuth": round(float(rng.uniform(0, 2 * np.pi)), 4),
        "light_elevation": round(float(rng.uniform(0.87, 1.4)), 4),
        "specular": round(float(rng.uniform(0.2, 0.7)), 3) if rng.random() < 0.5 else 0.0,
        "shininess": round(float(rng.uniform(20, 80)), 1),
        "psf_sigma": round(float(rng.uniform(0.5, 1.0)), 3),
        "texture": round(float(rng.uniform(0.01, 0.06)), 4),
        "texture_scale": round(float(rng.uniform(0.8, 2.5)), 3),
        "ramp": round(float(rng.uniform(0.0, 0.3)), 3),
        "ramp_angle": round(float(rng.uniform(0, 2 * np.pi)), 4),
        "rails": True,
        "markings": ("none", "dots", "logo")[int(rng.integers(3))],
        "mark_colour": [float(c) for c in lk.MARK_COLOURS[int(rng.integers(len(lk.MARK_COLOURS)))]],
        "cue": bool(rng.random() < 0.5),
        "cue_gap": round(float(rng.uniform(0.04, 0.15)), 3),
        "cue_follow": round(float(rng.uniform(0.02, 0.06)), 3),
    }
    look["balls"] = _resting_balls(rng, shot, params, table, fps, int(rng.integers(0, 5)))
    return look


def sample_scene(seed, preset: str = "random", fps: float | None = None,
                 noise: float | None = None, blur: bool | None = None,
                 px_per_m: float = 500.0, codec: str | None = None, look: str = "plain",
                 camera: str = "topdown") -> Scene:
    """Sample a complete scene: shot, friction, camera and renderer settings.

    Parameters
    ----------
    seed : int or numpy.random.Generator
        Source of randomness.
    preset : str
        See :func:`sample_shot`.
    fps : float, optional
        Frame rate; sampled from 60, 120, 240, 480 when absent.
    noise : float, optional
        Sensor noise sigma (grey levels); sampled 0-10 when absent.
    blur : bool, optional
        Motion blur (exposure 0.3-1 frame); sampled when absent.
    px_per_m : float
        Camera scale (px per m).
    codec : str, optional
        FourCC for the video; the renderer's default when absent.
    look : str
        ``plain`` (grey disc on grey felt, the conventions' camera) or
        ``realistic`` (colour, shading, rails and the rest of
        :func:`realistic_look`, on a camera that shows the rails: ``px_per_m``
        is then set by the frame size; noise 1-8 per channel when not given).
    camera : str
        ``topdown`` (a similarity: the conventions' camera for the plain
        look, one framing the rails for the realistic look) or ``tilted``
        (a real camera with a pose and lens distortion, :func:`tilted_camera`).

    Returns
    -------
    Scene
        With ``truth`` set and a ``render`` block carrying its own seed.
    """
    if look not in LOOKS:
        raise ValueError(f"unknown look {look!r}; choose from {', '.join(LOOKS)}")
    if camera not in CAMERAS:
        raise ValueError(f"unknown camera {camera!r}; choose from {', '.join(CAMERAS)}")
    rng = _rng(seed)
    balls = None
    if preset in CONTACT_PRESETS:
        shot, params, balls = sample_contact(rng, preset)
    else:
        shot, params = sample_shot(rng, preset)
    if fps is None:
        fps = float(rng.choice(FPS_CHOICES))
    render, exposure = _render_settings(rng, fps, noise, blur)
    if codec is not None:
        render["codec"] = codec
    render["preset"] = preset
    if balls is not None:
        render.update(contact_render(balls))  # render.contacts on, render.balls listed
    table = Table()
    if look == "plain":
        scene = make_scene(shot, params, fps=fps, px_per_m=px_per_m, exposure_s=exposure,
                           render=render)
        if camera == "topdown":
            return scene
        # Drawn after the plain look's draws, so plain top-down datasets stay as they were.
        return Scene(physics=params, camera=tilted_camera(rng, fps, table, exposure), table=table,
                     render=render, truth=shot)
    cam = (framed_camera if camera == "topdown" else tilted_camera)(rng, fps, table, exposure)
    render.update(realistic_look(rng, shot, params, table, fps))
    if balls is not None:  # the struck ball first, in a colour of the look's
        name = list(lk.BALL_COLOURS)[int(rng.integers(len(lk.BALL_COLOURS)))]
        struck = [{**b, "colour": _jitter(rng, lk.BALL_COLOURS[name])} for b in contact_render(balls)["balls"]]
        render["balls"] = struck + render["balls"]
    for k in ("felt_grey", "ball_grey", "gradient", "gradient_angle"):
        render.pop(k, None)
    if noise is None:
        render["noise_sigma"] = round(float(rng.uniform(1.0, 8.0)), 3)
    return Scene(physics=params, camera=cam, table=table, render=render, truth=shot)


def sample_scenes(n: int, seed: int, preset: str | None = None, **kwargs) -> list[Scene]:
    """``n`` independent scenes from one seed (one child seed per scene).

    With ``preset=None`` the presets cycle so that a dataset holds every kind
    of shot: mostly ``random`` with each named preset mixed in.
    """
    return [scene_at(i, seed, preset, **kwargs) for i in range(n)]


def scene_at(i: int, seed: int, preset: str | None = None, **kwargs) -> Scene:
    """``sample_scenes(i + 1, seed, preset, **kwargs)[i]``, without sampling
    the ``i`` scenes before it: each scene has its own child seed
    (``SeedSequence(seed).spawn``'s ``i``-th, the same whatever the number
    spawned), so a benchmark's shot ``i`` costs one scene, not ``i + 1``
    (accuracy.py spent 13% of its per-shot CPU sampling the scenes before
    each shot on 40-shot runs; docs/measurements.md recspeed)."""
    child = np.random.SeedSequence(seed, spawn_key=(i,))
    # Contact shots only when asked for: the default mix is of shots on open cloth.
    mix = ["random"] * 4 + [p for p in PRESETS if p != "random" and p not in CONTACT_PRESETS]
    return sample_scene(np.random.default_rng(child), preset if preset is not None else mix[i % len(mix)], **kwargs)
