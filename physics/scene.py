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


@dataclass(frozen=True)
class Camera:
    """A video's timing and its table-to-image homography.

    Attributes
    ----------
    fps : float
        Frames per second; frame ``k`` is stamped ``k / fps`` (s).
    width, height : int
        Image size (px).
    homography : tuple of tuple
        3x3 matrix mapping table ``[x, y, 1]`` (m) to homogeneous pixels.
    exposure_s : float
        Exposure time (s), centred on the frame's timestamp.
    """

    fps: float
    width: int
    height: int
    homography: tuple
    exposure_s: float = 0.0

    @property
    def H(self) -> np.ndarray:
        """The homography as a 3x3 array."""
        return np.array(self.homography, dtype=float)

    def to_pixels(self, xy):
        """Table points (m), shape (n, 2), to pixels ``(u, v)``, shape (n, 2)."""
        return apply_homography(self.H, xy)

    def to_table(self, uv):
        """Pixels ``(u, v)``, shape (n, 2), to table points (m), shape (n, 2)."""
        return apply_homography(np.linalg.inv(self.H), uv)

    def px_per_m(self, xy) -> float:
        """Local scale (px per m) at a table point: sqrt of the Jacobian's |det|."""
        return float(np.sqrt(abs(np.linalg.det(homography_jacobian(self.H, xy)))))

    def jacobian(self, xy) -> np.ndarray:
        """d(pixels)/d(metres) at table points.

        Parameters
        ----------
        xy : array_like, shape (n, 2) or (2,)
            Ball-centre positions (m).

        Returns
        -------
        ndarray, shape (n, 2, 2) or (2, 2)
            ``J[k, i, j] = d uv_i / d xy_j`` (px per m) at each point.
        """
        xy = np.asarray(xy, dtype=float)
        one = xy.ndim == 1
        pts = np.atleast_2d(xy)
        H = self.H
        num = pts @ H[:2, :2].T + H[:2, 2]                       # (n, 2)
        den = pts @ H[2, :2] + H[2, 2]                           # (n,)
        J = (H[None, :2, :2] * den[:, None, None] - num[:, :, None] * H[None, 2, :2][:, None, :]) \
            / (den**2)[:, None, None]
        return J[0] if one else J

    def cov_to_table(self, xy, cov_px) -> np.ndarray:
        """Pixel covariances (px^2) at table points to table covariances (m^2).

        ``C_m = J^-1 C_px J^-T`` with the camera's Jacobian at each point, so a
        tilted camera's varying scale and shear reach the weights.

        Parameters
        ----------
        xy : array_like, shape (n, 2)
            Ball-centre positions (m).
        cov_px : array_like, shape (n, 2, 2)
            Covariance of each pixel centre (px^2).

        Returns
        -------
        ndarray, shape (n, 2, 2)
        """
        Jinv = np.linalg.inv(self.jacobian(np.atleast_2d(xy)))
        return Jinv @ np.asarray(cov_px, dtype=float) @ np.swapaxes(Jinv, -1, -2)

    def frame_times(self, n: int) -> np.ndarray:
        """Timestamps ``k / fps`` (s) of frames ``0 .. n-1``."""
        return np.arange(n) / self.fps


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



def default_camera(fps: float = 240.0, px_per_m: float = 500.0, margin_px: float = 5.0,
                   table: Table = Table(), exposure_s: float = 0.0) -> Camera:
    """The top-down camera of CONVENTIONS.md, y flipped.

    ``[[s, 0, m], [0, -s, s W], [0, 0, 1]]`` with ``s`` px per metre and
    margin ``m``: the table's far side (y = W) lies on row 0 and a margin of
    ``m`` px is left on the three other sides, sizes rounded up to even (video
    codecs need even sizes).  With the defaults this is exactly the
    conventions' 1280 x 640 view, ``[[500, 0, 5], [0, -500, 635], [0, 0, 1]]``.
    """
    s = float(px_per_m)
    width = 2 * int(math.ceil((table.length * s + 2 * margin_px) / 2 - 1e-9))
    height = 2 * int(math.ceil((table.width * s + margin_px) / 2 - 1e-9))
    H = ((s, 0.0, float(margin_px)), (0.0, -s, s * table.width), (0.0, 0.0, 1.0))
    return Camera(fps=float(fps), width=width, height=height, homography=H,
                  exposure_s=float(exposure_s))


def apply_homography(H, pts):
    """Map points, shape (n, 2), through a 3x3 homography (vectorised)."""
    pts = np.asarray(pts, dtype=float)
    p = pts @ H[:, :2].T + H[:, 2]
    return p[..., :2] / p[..., 2:3]


def homography_jacobian(H, xy):
    """2x2 Jacobian d(pixels)/d(metres) of a homography at one table point."""
    x, y = float(xy[0]), float(xy[1])
    num = H[:2, 0] * x + H[:2, 1] * y + H[:2, 2]
    den = H[2, 0] * x + H[2, 1] * y + H[2, 2]
    return (H[:2, :2] * den - np.outer(num, H[2, :2])) / den**2


@dataclass(frozen=True)
class Scene:
    """One shot: physics, table, camera, renderer settings and (optionally) truth."""

    physics: BallParams
    camera: Camera
    table: Table = Table()
    render: dict = field(default_factory=dict)
    truth: Shot | None = None


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


def _vector(d: dict, key: str, path: str, shape: tuple) -> np.ndarray:
    if key not in d:
        raise SceneError(f"{path}.{key}: required key is missing")
    try:
        arr = np.array(d[key], dtype=float)
    except (TypeError, ValueError):
        raise SceneError(f"{path}.{key}: expected numbers of shape {shape}, got {json_repr(d[key])}")
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
        ``fps <= 0`` or a singular homography.
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
    cam = _block(d, "camera", required=True)
    H = _vector(cam, "homography", "camera", (3, 3))
    if abs(np.linalg.det(H)) < 1e-12 * max(1.0, np.abs(H).max()) ** 3:
        raise SceneError("camera.homography: matrix is singular")
    camera = Camera(fps=_number(cam, "fps", "camera", positive=True),
                    width=_number(cam, "width", "camera", positive=True, integer=True),
                    height=_number(cam, "height", "camera", positive=True, integer=True),
                    homography=tuple(tuple(float(c) for c in row) for row in H),
                    exposure_s=_number(cam, "exposure_s", "camera", 0.0, nonneg=True))
    tb = _block(d, "table", required=False) or {}
    table = Table(length=_number(tb, "length", "table", Table.length, positive=True),
                  width=_number(tb, "width", "table", Table.width, positive=True))
    render = _block(d, "render", required=False) or {}
    tr = _block(d, "truth", required=False)
    truth = None
    if tr is not None:
        truth = Shot(x0=_vector(tr, "x0", "truth", (2,)), v0=_vector(tr, "v0", "truth", (2,)),
                     w0=_vector(tr, "w0", "truth", (2,)), t0=_number(tr, "t0", "truth", nonneg=True))
    return Scene(physics=params, camera=camera, table=table, render=dict(render), truth=truth)


def scene_to_dict(scene: Scene) -> dict:
    """The JSON object of a :class:`Scene` (inverse of :func:`parse_scene`)."""
    p, c = scene.physics, scene.camera
    d = {
        "schema": SCHEMA,
        "physics": {"R": p.R, "mu_s": p.mu_s, "mu_r": p.mu_r, "g": p.g},
        "table": {"length": scene.table.length, "width": scene.table.width},
        "camera": {"fps": c.fps, "width": c.width, "height": c.height,
                   "homography": [list(r) for r in c.homography], "exposure_s": c.exposure_s},
    }
    if scene.render:
        d["render"] = dict(scene.render)
    if scene.truth is not None:
        t = scene.truth
        d["truth"] = {"x0": list(t.x0), "v0": list(t.v0), "w0": list(t.w0), "t0": t.t0}
    return d
