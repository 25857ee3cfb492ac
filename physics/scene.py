"""The scene file of CONVENTIONS.md as frozen dataclasses, validated in one place.

``parse_scene`` turns the decoded JSON object into a :class:`Scene` or raises
:class:`SceneError` with one line naming the offending key; ``scene_to_dict``
is its inverse.  Reading and writing the file itself is left to the edges
(``pipeline.io``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cuespin.physics.camera import (  # noqa: F401  (re-exported: the camera's old home)
    Camera,
    apply_homography,
    as_tuple,
    default_camera,
    homography_jacobian,
    is_mirrored,
    pinhole_camera,
)
from cuespin.physics.motion import BallParams, Shot, phases, positions

SCHEMA = 1


class SceneError(ValueError):
    """A scene that breaks the contract; the message is one line naming the key."""


@dataclass(frozen=True)
class Table:
    """Playing surface size (m): x along ``length``, y along ``width``."""

    length: float = 2.54
    width: float = 1.27

    def contains(self, xy, margin: float = 0.0):
        """True where points (m), shape (n, 2), lie at least ``margin`` inside."""
        xy = np.asarray(xy, dtype=float)
        return ((xy[..., 0] >= margin) & (xy[..., 0] <= self.length - margin)
                & (xy[..., 1] >= margin) & (xy[..., 1] <= self.width - margin))


def motion_end(shot: Shot, params: BallParams, table: Table, fps: float,
               max_duration: float) -> tuple[float, bool]:
    """When the scene's motion ends: the ball stops, or its centre leaves the table.

    Returns
    -------
    (float, bool)
        The end time (s, absolute; capped at ``max_duration``) and whether the
        ball left the table.
    """
    ph = phases(shot, params)
    horizon = min(ph.t2, max_duration)
    t = np.arange(math.floor(shot.t0 * fps), math.ceil(horizon * fps) + 1) / fps
    inside = table.contains(positions(shot, params, t, ph))
    if not inside.all():
        return float(t[np.argmin(inside)]), True
    return float(horizon), False



@dataclass(frozen=True)
class Scene:
    """One shot: physics, table, camera, renderer settings and (optionally) truth.

    The camera's ``centre_height`` is set to ``physics.R`` here, so the plane
    the camera converts in is always the ball's centre plane of this scene.
    ``defaulted`` lists the ``(key, value)`` pairs :func:`parse_scene` filled
    in because the file left them out (the reader says so on stderr); it
    takes no part in comparisons.  ``calibration`` holds the cameras of the
    file's ``calibration.perturbed`` list (``cuespin calibrate`` writes them:
    the camera re-solved with one corner coordinate moved by its stated
    error, each in turn, or with the corners and k1 moved jointly along their
    covariance's directions), from which the recovery carries the calibration's
    error into its own (empty: the camera is taken as exact).
    """

    physics: BallParams
    camera: Camera
    table: Table = Table()
    render: dict = field(default_factory=dict)
    truth: Shot | None = None
    defaulted: tuple = field(default=(), compare=False)
    calibration: tuple = ()

    def __post_init__(self):
        R = float(self.physics.R)
        object.__setattr__(self, "camera", self.camera.with_centre_height(R))
        object.__setattr__(self, "calibration", tuple(c.with_centre_height(R) for c in self.calibration))


def _number(d: dict, key: str, path: str, default=None, *, positive=False, nonneg=False,
            integer=False) -> float:
    if key not in d:
        if default is None:
            raise SceneError(f"{path}.{key}: required key is missing")
        return default
    val = d[key]
    if isinstance(val, bool) or not isinstance(val, (int, float)):
        raise SceneError(f"{path}.{key}: expected a number, got {json_repr(val)}")
    if not math.isfinite(val):
        raise SceneError(f"{path}.{key}: must be finite, got {val}")
    if positive and val <= 0:
        raise SceneError(f"{path}.{key}: must be > 0, got {val}")
    if nonneg and val < 0:
        raise SceneError(f"{path}.{key}: must be >= 0, got {val}")
    if integer and val != int(val):
        raise SceneError(f"{path}.{key}: must be a whole number, got {val}")
    return int(val) if integer else float(val)


def _vector(d: dict, key: str, path: str, shape: tuple, also: tuple = ()) -> np.ndarray:
    """A numeric array of ``shape``; shapes in ``also`` (what OpenCV returns, e.g.
    a (3, 1) rvec) are accepted and flattened to it."""
    if key not in d:
        raise SceneError(f"{path}.{key}: required key is missing")
    try:
        arr = np.array(d[key], dtype=float)
    except (TypeError, ValueError):
        raise SceneError(f"{path}.{key}: expected numbers of shape {shape}, got {json_repr(d[key])}")
    if arr.shape in also:
        arr = arr.reshape(shape)
    if arr.shape != shape:
        raise SceneError(f"{path}.{key}: expected shape {list(shape)}, got {list(arr.shape)}")
    if not np.all(np.isfinite(arr)):
        raise SceneError(f"{path}.{key}: must be finite, got {json_repr(d[key])}")
    return arr


def _block(d: dict, key: str, required: bool) -> dict | None:
    if key not in d:
        if required:
            raise SceneError(f"{key}: required key is missing")
        return None
    if not isinstance(d[key], dict):
        raise SceneError(f"{key}: expected an object, got {json_repr(d[key])}")
    return d[key]


def json_repr(val: Any, limit: int = 40) -> str:
    """Short one-line repr of a JSON value for error messages."""
    text = repr(val).replace("\n", " ")
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _parse_camera(cam: dict, table: Table, R: float) -> Camera:
    """The ``camera`` block: timing, size, and a homography or a real camera."""
    fps = _number(cam, "fps", "camera", positive=True)
    size = [None if k not in cam else _number(cam, k, "camera", positive=True, integer=True)
            for k in ("width", "height")]
    K = dist = rvec = tvec = None
    if "intrinsics" in cam:
        K = _vector(cam, "intrinsics", "camera", (3, 3))
        if not (K[0, 0] > 0 and K[1, 1] > 0 and K[0, 1] == 0 and K[1, 0] == 0
                and K[2, 0] == 0 and K[2, 1] == 0 and K[2, 2] == 1):
            raise SceneError("camera.intrinsics: expected [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] "
                             "with fx, fy > 0 (OpenCV's camera matrix)")
    if "distortion" in cam:
        if K is None:
            raise SceneError("camera.distortion: needs camera.intrinsics (the camera matrix "
                             "from the same lens calibration)")
        dist = _vector(cam, "distortion", "camera", (5,), also=((1, 5),))
    for key in ("rvec", "tvec"):
        if key in cam and K is None:
            raise SceneError(f"camera.{key}: a pose needs camera.intrinsics (the camera matrix)")
    if ("rvec" in cam) != ("tvec" in cam):
        missing = "tvec" if "rvec" in cam else "rvec"
        raise SceneError(f"camera.{missing}: required with camera.{'rvec' if missing == 'tvec' else 'tvec'}")
    if "rvec" in cam:
        rvec = _vector(cam, "rvec", "camera", (3,), also=((3, 1), (1, 3)))
        tvec = _vector(cam, "tvec", "camera", (3,), also=((3, 1), (1, 3)))
    H = None
    if rvec is None:
        # With a pose the homography is ignored (CONVENTIONS.md); without, it is required.
        H = _vector(cam, "homography", "camera", (3, 3))
        if abs(np.linalg.det(H)) < 1e-12 * max(1.0, np.abs(H).max()) ** 3:
            raise SceneError("camera.homography: matrix is singular")
    tup = as_tuple
    camera = Camera(fps=fps, width=size[0], height=size[1], homography=tup(H),
                    exposure_s=_number(cam, "exposure_s", "camera", 0.0, nonneg=True),
                    intrinsics=tup(K), distortion=tup(dist), rvec=tup(rvec), tvec=tup(tvec),
                    centre_height=R)
    corners = np.array([[0.0, 0.0], [table.length, 0.0], [table.length, table.width], [0.0, table.width]])
    if camera.is_pinhole:
        # The table must lie in front of a camera above the ball-centre plane.
        if camera.centre[2] <= R:
            raise SceneError(f"camera.tvec: the camera's centre is {camera.centre[2]:.3g} m above "
                             f"the cloth, not above the ball (R = {R:g} m); is the pose inverted?")
        depth = (np.column_stack([corners, np.full(4, R)]) @ camera.rotation.T + tvec)[:, 2]
        if not np.all(depth > 0):
            raise SceneError("camera.rvec: the table is (partly) behind the camera; is the pose "
                             "the table-to-camera one OpenCV's solvePnP returns?")
    else:
        Hn = np.asarray(H)
        den = corners @ Hn[2, :2] + Hn[2, 2]
        if not (np.all(den > 0) or np.all(den < 0)):
            raise SceneError("camera.homography: the table's corners straddle the horizon line")
        if is_mirrored(camera.H, [table.length / 2, table.width / 2]):
            raise SceneError("camera.homography: mirrored (orientation-reversing: the table seen "
                             "from below, or corners in mirrored order); spin signs would flip")
    return camera


def parse_scene(d: Any) -> Scene:
    """Validate a decoded scene object (CONVENTIONS.md) and build a :class:`Scene`.

    Parameters
    ----------
    d : dict
        The decoded JSON object.

    Returns
    -------
    Scene

    Raises
    ------
    SceneError
        One line naming the key: a missing required key, a wrong shape, a
        non-finite number, ``R <= 0``, ``mu_s <= 0``, ``mu_r < 0``, ``g <= 0``,
        ``fps <= 0``, a singular or mirrored homography, and the real camera's
        keys (see :func:`_parse_camera`).

    Notes
    -----
    ``camera.width``/``height`` may be left out (None: the video's size is
    used, :meth:`Camera.with_size`); ``physics.R``, ``mu_s``, ``mu_r`` left
    out take the conventions' defaults and are listed in ``Scene.defaulted``.
    """
    if not isinstance(d, dict):
        raise SceneError(f"scene: expected a JSON object, got {json_repr(d)}")
    if "schema" in d and d["schema"] != SCHEMA:
        raise SceneError(f"schema: this program reads schema {SCHEMA}, got {json_repr(d['schema'])}")
    ph = _block(d, "physics", required=True)
    dflt = BallParams()
    params = BallParams(R=_number(ph, "R", "physics", dflt.R, positive=True),
                        mu_s=_number(ph, "mu_s", "physics", dflt.mu_s, positive=True),
                        mu_r=_number(ph, "mu_r", "physics", dflt.mu_r, nonneg=True),
                        g=_number(ph, "g", "physics", dflt.g, positive=True))
    # R, mu_s and mu_r change the answer (a pool ball's R on a 61.5 mm ball moved
    # w0 by 7-9%): the reader tells the user which were assumed.  g is a constant.
    defaulted = tuple((f"physics.{k}", getattr(params, k)) for k in ("R", "mu_s", "mu_r") if k not in ph)
    tb = _block(d, "table", required=False) or {}
    table = Table(length=_number(tb, "length", "table", Table.length, positive=True),
                  width=_number(tb, "width", "table", Table.width, positive=True))
    camera = _parse_camera(_block(d, "camera", required=True), table, params.R)
    render = _block(d, "render", required=False) or {}
    calibration = _perturbed_cameras(d, table, params.R)
    tr = _block(d, "truth", required=False)
    truth = None
    if tr is not None:
        truth = Shot(x0=_vector(tr, "x0", "truth", (2,)), v0=_vector(tr, "v0", "truth", (2,)),
                     w0=_vector(tr, "w0", "truth", (2,)), t0=_number(tr, "t0", "truth", nonneg=True))
    return Scene(physics=params, camera=camera, table=table, render=dict(render), truth=truth,
                 defaulted=defaulted, calibration=calibration)


def _perturbed_cameras(d: dict, table: Table, R: float) -> tuple:
    """The cameras of ``calibration.perturbed`` (optional), each validated as
    ``camera`` is, with the main camera's fps and size."""
    cal = _block(d, "calibration", required=False)
    if cal is None or "perturbed" not in cal:
        return ()
    lst = cal["perturbed"]
    if not isinstance(lst, list):
        raise SceneError(f"calibration.perturbed: expected a list of cameras, got {json_repr(lst)}")
    base = {k: d["camera"][k] for k in ("fps", "width", "height") if k in d["camera"]}
    out = []
    for k, cam in enumerate(lst):
        if not isinstance(cam, dict):
            raise SceneError(f"calibration.perturbed[{k}]: expected an object, got {json_repr(cam)}")
        try:
            out.append(_parse_camera({**base, **cam}, table, R))
        except SceneError as exc:
            raise SceneError(str(exc).replace("camera.", f"calibration.perturbed[{k}].", 1))
    return tuple(out)


def camera_to_dict(c: Camera, geometry_only: bool = False) -> dict:
    """The ``camera`` object of a :class:`Camera`: only the keys it has (a
    size left to the video stays out; a pose camera has no homography).
    ``geometry_only`` leaves out fps, size and exposure (a perturbed camera
    of ``calibration.perturbed`` shares them with the main one)."""
    cam = {"fps": c.fps}
    if c.width is not None:
        cam["width"] = c.width
    if c.height is not None:
        cam["height"] = c.height
    if c.homography is not None and not c.is_pinhole:
        cam["homography"] = [list(r) for r in c.homography]
    cam["exposure_s"] = c.exposure_s
    for key in ("intrinsics", "distortion", "rvec", "tvec"):
        val = getattr(c, key)
        if val is not None:
            cam[key] = [list(r) for r in val] if key == "intrinsics" else list(val)
    if geometry_only:
        cam = {k: v for k, v in cam.items() if k not in ("fps", "width", "height", "exposure_s")}
    return cam


def scene_to_dict(scene: Scene) -> dict:
    """The JSON object of a :class:`Scene` (inverse of :func:`parse_scene`).

    Only the keys the camera has are written: a size left to the video stays
    out, and a pose camera is written without a homography.
    """
    p = scene.physics
    cam = camera_to_dict(scene.camera)
    d = {
        "schema": SCHEMA,
        "physics": {"R": p.R, "mu_s": p.mu_s, "mu_r": p.mu_r, "g": p.g},
        "table": {"length": scene.table.length, "width": scene.table.width},
        "camera": cam,
    }
    if scene.render:
        d["render"] = dict(scene.render)
    if scene.calibration:
        d["calibration"] = {"perturbed": [camera_to_dict(c, geometry_only=True) for c in scene.calibration]}
    if scene.truth is not None:
        t = scene.truth
        d["truth"] = {"x0": list(t.x0), "v0": list(t.v0), "w0": list(t.w0), "t0": t.t0}
    return d

