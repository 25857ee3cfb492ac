"""The camera: table metres of the ball's centre <-> pixels, through a homography or a real lens.

One object converts for every stage (CONVENTIONS.md, "Images and time").  It
is built from either

* a **homography** only: a 3x3 matrix mapping ``[x, y, 1]`` of the plane of
  the ball's centre (height R above the cloth) to homogeneous pixels, seen
  through a distortion-free camera (the conventions' top-down default); or
* a **real camera** in OpenCV's conventions: ``intrinsics`` (camera matrix
  ``K``), ``distortion`` ``[k1, k2, p1, p2, k3]`` and the pose ``rvec``,
  ``tvec`` (a table point ``X`` (m, z up) has camera coordinates
  ``Rodrigues(rvec) X + tvec``; pixels as ``cv2.projectPoints`` gives them).
  The ball is a sphere of radius R centred at ``(x, y, R)``; the camera needs
  that height, ``centre_height``, which :class:`cuespin.physics.scene.Scene`
  fills from ``physics.R`` (so a scene's camera and its ball always agree).
* ``intrinsics`` (+ ``distortion``) with a homography but no pose is also
  accepted: the homography then maps the centre plane to *undistorted*
  pixels, and the lens bends them.

Both reduce to one pipeline: a plane homography ``G`` from the centre plane
to normalised image coordinates (``G = [r1, r2, r3 R + t]`` for a pose,
``K^-1 H`` for a lens with a homography, ``H`` itself with no lens), then
OpenCV's distortion, then ``K``.  Every method is vectorised over points.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

# Newton's iteration that inverts the lens distortion stops once a step is
# below this (normalised image units, about 1e-12 px at f = 1000 px): the
# round trip pixels -> metres -> pixels is then exact to float rounding.
UNDISTORT_TOL = 1e-15
UNDISTORT_MAX_ITER = 30


def apply_homography(H, pts):
    """Map points, shape (n, 2) or (2,), through a 3x3 homography (vectorised)."""
    H = np.asarray(H, dtype=float)
    pts = np.asarray(pts, dtype=float)
    p = pts @ H[:, :2].T + H[:, 2]
    return p[..., :2] / p[..., 2:3]


def homography_jacobian(H, xy):
    """Jacobian d(image)/d(plane) of a homography at plane points.

    Parameters
    ----------
    H : array_like, shape (3, 3)
    xy : array_like, shape (n, 2) or (2,)

    Returns
    -------
    ndarray, shape (n, 2, 2) or (2, 2)
        ``J[k, i, j] = d out_i / d xy_j``.
    """
    H = np.asarray(H, dtype=float)
    xy = np.asarray(xy, dtype=float)
    one = xy.ndim == 1
    pts = np.atleast_2d(xy)
    num = pts @ H[:2, :2].T + H[:2, 2]                       # (n, 2)
    den = pts @ H[2, :2] + H[2, 2]                           # (n,)
    J = (H[None, :2, :2] * den[:, None, None] - num[:, :, None] * H[None, 2, None, :2]) \
        / (den**2)[:, None, None]
    return J[0] if one else J


def is_mirrored(H, xy) -> bool:
    """Whether a table-to-pixel homography reverses orientation at a table point.

    A camera above the table sees the table frame (x, y, z up) with the image's
    v axis pointing down, so a true view has ``det J < 0`` (the default
    top-down camera's ``J = diag(s, -s)``).  ``det J > 0`` is the table seen
    in a mirror (or its corners given in mirrored order): every cross product,
    and so the sign of the recovered spin, would flip.
    """
    return bool(np.linalg.det(homography_jacobian(H, np.asarray(xy, dtype=float))) > 0)


def _distort(n, dist):
    """OpenCV's distortion of normalised points and its Jacobian.

    Parameters
    ----------
    n : ndarray, shape (m, 2)
        Undistorted normalised image coordinates.
    dist : ndarray, shape (5,)
        ``[k1, k2, p1, p2, k3]``.

    Returns
    -------
    nd : ndarray, shape (m, 2)
    D : ndarray, shape (m, 2, 2)
        ``d nd / d n``.
    """
    k1, k2, p1, p2, k3 = dist
    x, y = n[:, 0], n[:, 1]
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    dr = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)                # d radial / d r2
    xy2 = 2.0 * x * y
    nd = np.empty_like(n)
    nd[:, 0] = x * radial + p1 * xy2 + p2 * (r2 + 2.0 * x * x)
    nd[:, 1] = y * radial + p1 * (r2 + 2.0 * y * y) + p2 * xy2
    D = np.empty(n.shape[:1] + (2, 2))
    cross = xy2 * dr + 2.0 * p1 * x + 2.0 * p2 * y
    D[:, 0, 0] = radial + 2.0 * x * x * dr + 2.0 * p1 * y + 6.0 * p2 * x
    D[:, 0, 1] = cross
    D[:, 1, 0] = cross
    D[:, 1, 1] = radial + 2.0 * y * y * dr + 6.0 * p1 * y + 2.0 * p2 * x
    return nd, D


def _solve2(A, b):
    """Solve many 2x2 systems ``A x = b`` (A (m, 2, 2), b (m, 2)) in closed form."""
    det = A[:, 0, 0] * A[:, 1, 1] - A[:, 0, 1] * A[:, 1, 0]
    x0 = (A[:, 1, 1] * b[:, 0] - A[:, 0, 1] * b[:, 1]) / det
    x1 = (A[:, 0, 0] * b[:, 1] - A[:, 1, 0] * b[:, 0]) / det
    return np.stack([x0, x1], axis=-1)


def _undistort(nd, dist):
    """Invert :func:`_distort` by Newton's method (converges monotonically where the
    radial profile is monotone, i.e. everywhere a real lens images; points past
    the fold of the profile come back NaN)."""
    n = nd.copy()
    for _ in range(UNDISTORT_MAX_ITER):
        f, D = _distort(n, dist)
        step = _solve2(D, f - nd)
        n -= step
        if not np.any(np.abs(step) > UNDISTORT_TOL):
            break
    f, _ = _distort(n, dist)
    bad = ~(np.abs(f - nd).max(axis=-1) < 1e-9)
    if bad.any():
        n[bad] = np.nan
    return n


# Public names for the lens model (calibration works with it directly).
distort = _distort
undistort = _undistort


def rodrigues(rvec) -> np.ndarray:
    """Rotation matrix of a rotation vector (axis times angle, rad), as ``cv2.Rodrigues``."""
    r = np.asarray(rvec, dtype=float).reshape(3)
    th = float(np.linalg.norm(r))
    if th < 1e-300:
        return np.eye(3)
    k = r / th
    Kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(th) * Kx + (1.0 - math.cos(th)) * (Kx @ Kx)


def rotation_to_rvec(Rm) -> np.ndarray:
    """Rotation vector of a rotation matrix (inverse of :func:`rodrigues`)."""
    Rm = np.asarray(Rm, dtype=float)
    c = np.clip((np.trace(Rm) - 1.0) / 2.0, -1.0, 1.0)
    th = math.acos(c)
    if th < 1e-12:
        return np.zeros(3)
    if th > math.pi - 1e-6:
        # Near 180 deg the antisymmetric part vanishes: axis from R + I.
        B = (Rm + np.eye(3)) / 2.0
        k = np.sqrt(np.clip(np.diag(B), 0.0, None))
        i = int(np.argmax(k))
        k = B[i] / k[i]
        return th * k / np.linalg.norm(k)
    w = np.array([Rm[2, 1] - Rm[1, 2], Rm[0, 2] - Rm[2, 0], Rm[1, 0] - Rm[0, 1]])
    return th * w / (2.0 * math.sin(th))


def as_tuple(a):
    """Nested tuples of floats of an array (the dataclasses' hashable storage); None stays None."""
    if a is None:
        return None
    a = np.asarray(a, dtype=float)
    if a.ndim == 1:
        return tuple(float(v) for v in a)
    return tuple(as_tuple(r) for r in a)


@dataclass(frozen=True)
class Camera:
    """A video's timing and its camera: ball-centre metres <-> pixels.

    Attributes
    ----------
    fps : float
        Nominal frames per second; frame ``k`` is stamped ``k / fps`` (s).
    width, height : int or None
        Image size (px); None when a scene file leaves it to the video
        (filled by :meth:`with_size`).
    homography : tuple of tuple or None
        3x3 matrix mapping ``[x, y, 1]`` of the ball-centre plane (m) to
        homogeneous pixels (undistorted pixels when ``intrinsics`` is given).
        Ignored when a pose is given.
    exposure_s : float
        Exposure time (s), centred on the frame's timestamp.
    intrinsics : tuple of tuple or None
        Camera matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` (px).
    distortion : tuple or None
        ``(k1, k2, p1, p2, k3)``, OpenCV's order; None means none.
    rvec, tvec : tuple or None
        Pose: table point ``X`` (m) has camera coordinates
        ``Rodrigues(rvec) X + tvec`` (tvec in m).
    centre_height : float or None
        Height of the ball-centre plane above the cloth (m), i.e. ``physics.R``;
        a :class:`~cuespin.physics.scene.Scene` sets it.  Only a pose camera
        needs it (a homography already describes that plane).
    """

    fps: float
    width: int | None
    height: int | None
    homography: tuple | None = None
    exposure_s: float = 0.0
    intrinsics: tuple | None = None
    distortion: tuple | None = None
    rvec: tuple | None = None
    tvec: tuple | None = None
    centre_height: float | None = None

    def __post_init__(self):
        if self.homography is None and not self.is_pinhole:
            raise ValueError("camera: needs a homography or intrinsics with a pose (rvec, tvec)")
        if (self.distortion is not None or self.rvec is not None) and self.intrinsics is None:
            raise ValueError("camera: distortion and a pose need intrinsics")

    # ----------------------------------------------------------- structure
    @property
    def is_pinhole(self) -> bool:
        """True for a real camera with a pose (intrinsics, rvec, tvec)."""
        return self.intrinsics is not None and self.rvec is not None and self.tvec is not None

    @property
    def has_lens(self) -> bool:
        """True when pixels go through a camera matrix (and possibly distortion)."""
        return self.intrinsics is not None

    @cached_property
    def K(self) -> np.ndarray:
        """Camera matrix (3x3, px); identity for a homography-only camera."""
        return np.eye(3) if self.intrinsics is None else np.array(self.intrinsics, dtype=float)

    @cached_property
    def dist(self) -> np.ndarray:
        """Distortion ``[k1, k2, p1, p2, k3]`` (zeros when absent)."""
        d = np.zeros(5)
        if self.distortion is not None:
            v = np.asarray(self.distortion, dtype=float).ravel()
            d[: v.size] = v
        return d

    @cached_property
    def rotation(self) -> np.ndarray | None:
        """``Rodrigues(rvec)`` (3x3), or None without a pose."""
        return rodrigues(self.rvec) if self.is_pinhole else None

    @cached_property
    def centre(self) -> np.ndarray | None:
        """The camera's centre in the table frame (m), ``-R^T t``; None without a pose."""
        if not self.is_pinhole:
            return None
        return -self.rotation.T @ np.asarray(self.tvec, dtype=float)

    @cached_property
    def _has_dist(self) -> bool:
        return bool(np.any(self.dist != 0.0))

    @cached_property
    def _G(self) -> np.ndarray:
        """Plane homography: ball-centre plane ``[x, y, 1]`` -> normalised image
        coordinates (or pixels for a homography-only camera)."""
        if self.is_pinhole:
            if self.centre_height is None:
                raise ValueError("camera.centre_height is not set: a pose camera needs the "
                                 "ball-centre height (physics.R); build it inside a Scene")
            Rm, t = self.rotation, np.asarray(self.tvec, dtype=float)
            return np.column_stack([Rm[:, 0], Rm[:, 1], Rm[:, 2] * self.centre_height + t])
        H = np.array(self.homography, dtype=float)
        return np.linalg.solve(self.K, H) if self.has_lens else H

    @cached_property
    def _Ginv(self) -> np.ndarray:
        return np.linalg.inv(self._G)

    @property
    def H(self) -> np.ndarray:
        """Homography of the ball-centre plane to (undistorted) pixels, 3x3.

        Exact for a homography camera; for a lens it leaves the distortion out
        (use the methods below to convert).
        """
        return self.K @ self._G if self.has_lens else self._G.copy()

    # ----------------------------------------------------------- image side
    def _to_px(self, n):
        """Normalised (m, 2) -> pixels, with the pixel-from-normalised Jacobian."""
        if not self.has_lens:
            return n, None
        K = self.K
        if self._has_dist:
            nd, D = _distort(n, self.dist)
        else:
            nd, D = n, None
        uv = nd @ K[:2, :2].T + K[:2, 2]
        J = K[None, :2, :2] if D is None else K[:2, :2] @ D
        return uv, J

    def _from_px(self, uv):
        if not self.has_lens:
            return uv
        K = self.K
        nd = np.column_stack([(uv[:, 0] - K[0, 2] - K[0, 1] * (uv[:, 1] - K[1, 2]) / K[1, 1]) / K[0, 0],
                              (uv[:, 1] - K[1, 2]) / K[1, 1]])
        return _undistort(nd, self.dist) if self._has_dist else nd

    # ----------------------------------------------------------- conversions
    def to_pixels(self, xy):
        """Ball centres ``(x, y)`` (m) at height ``centre_height`` to pixels ``(u, v)``.

        Parameters
        ----------
        xy : array_like, shape (n, 2) or (2,)

        Returns
        -------
        ndarray, shape (n, 2) or (2,)
            Where the ball's centre images, through the lens.
        """
        xy = np.asarray(xy, dtype=float)
        pts = np.atleast_2d(xy)
        uv, _ = self._to_px(apply_homography(self._G, pts))
        return uv[0] if xy.ndim == 1 else uv

    def to_table(self, uv):
        """Pixels ``(u, v)`` to ball centres (m): the inverse of :meth:`to_pixels`.

        The lens distortion is inverted by Newton's method and the ray is cut
        with the ball-centre plane ``z = centre_height`` (for a pose camera
        that is the inverse plane homography).

        Parameters
        ----------
        uv : array_like, shape (n, 2) or (2,)

        Returns
        -------
        ndarray, shape (n, 2) or (2,)
        """
        uv = np.asarray(uv, dtype=float)
        pts = np.atleast_2d(uv)
        xy = apply_homography(self._Ginv, self._from_px(pts))
        return xy[0] if uv.ndim == 1 else xy

    def to_plane(self, uv, z: float = 0.0):
        """Pixels ``(u, v)`` to the points ``(x, y)`` (m) of the horizontal plane ``z``
        (m above the cloth) they see: the cloth at 0, a cushion's nose at its height.

        For a pose camera, the ray through each pixel (lens undone) cut with
        that plane.  A camera without a pose knows only the ball-centre plane,
        so ``z`` is ignored (as in :meth:`project`): the result is
        :meth:`to_table`'s.

        Parameters
        ----------
        uv : array_like, shape (n, 2) or (2,)
        z : float

        Returns
        -------
        ndarray, shape (n, 2) or (2,)
        """
        if not self.is_pinhole:
            return self.to_table(uv)
        uv = np.asarray(uv, dtype=float)
        pts = np.atleast_2d(uv)
        Rm, t = self.rotation, np.asarray(self.tvec, dtype=float)
        G = np.column_stack([Rm[:, 0], Rm[:, 1], Rm[:, 2] * float(z) + t])
        xy = apply_homography(np.linalg.inv(G), self._from_px(pts))
        return xy[0] if uv.ndim == 1 else xy

    def jacobian(self, xy) -> np.ndarray:
        """d(pixels)/d(metres) of :meth:`to_pixels` at ball-centre positions (analytic).

        Parameters
        ----------
        xy : array_like, shape (n, 2) or (2,)

        Returns
        -------
        ndarray, shape (n, 2, 2) or (2, 2)
            ``J[k, i, j] = d uv_i / d xy_j`` (px per m).
        """
        xy = np.asarray(xy, dtype=float)
        pts = np.atleast_2d(xy)
        Jg = homography_jacobian(self._G, pts)
        _, Jk = self._to_px(apply_homography(self._G, pts))
        J = Jg if Jk is None else Jk @ Jg
        return J[0] if xy.ndim == 1 else J

    def px_per_m(self, xy) -> float:
        """Local scale (px per m) at one table point: sqrt of the Jacobian's |det|."""
        return float(np.sqrt(abs(np.linalg.det(self.jacobian(np.asarray(xy, dtype=float).reshape(2))))))

    def cov_to_table(self, xy, cov_px) -> np.ndarray:
        """Pixel covariances (px^2) at table points to table covariances (m^2).

        ``C_m = J^-1 C_px J^-T`` with the camera's Jacobian at each point, so a
        tilted camera's varying scale and shear, and the lens, reach the weights.

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

    def project(self, X):
        """Arbitrary table points ``(x, y, z)`` (m, z up from the cloth) to pixels.

        For a pose camera this is ``cv2.projectPoints``; points at or behind
        the camera's plane come back NaN.  A camera without a pose knows only
        the ball-centre plane, so ``z`` is ignored: every point is drawn as if
        at the centre's height (for the top-down default camera that is an
        orthographic view, which is what it stands for).

        Parameters
        ----------
        X : array_like, shape (n, 3) or (3,)

        Returns
        -------
        ndarray, shape (n, 2) or (2,)
        """
        X = np.asarray(X, dtype=float)
        pts = np.atleast_2d(X)
        if self.is_pinhole:
            Xc = pts @ self.rotation.T + np.asarray(self.tvec, dtype=float)
            z = np.where(Xc[:, 2] > 0, Xc[:, 2], np.nan)
            uv, _ = self._to_px(Xc[:, :2] / z[:, None])
        else:
            uv, _ = self._to_px(apply_homography(self._G, pts[:, :2]))
        return uv[0] if X.ndim == 1 else uv

    def ball_outline(self, xy, R: float | None = None, n: int = 64):
        """Pixel polygon of the ball's silhouette through the lens.

        For a pose camera: the sphere of radius ``R`` centred at
        ``(x, y, centre_height)`` is seen along the cone of rays tangent to it
        from the camera's centre (half-angle ``asin(R / distance)``); each ray
        is imaged through the lens.  Under perspective that outline is not a
        circle (an ellipse before distortion) and its centroid is not the
        projected centre (:meth:`silhouette_centroid_offset`).  Without a pose:
        the image of the circle of radius ``R`` about the centre in the
        centre plane (CONVENTIONS.md), through the lens if there is one.

        Parameters
        ----------
        xy : array_like, shape (m, 2) or (2,)
            Ball centres (m).
        R : float, optional
            Ball radius (m); default ``centre_height``.
        n : int
            Vertices per outline, evenly spaced in angle about the cone (or circle).

        Returns
        -------
        ndarray, shape (m, n, 2) or (n, 2)
            Vertices in order around the outline.
        """
        if R is None:
            R = self.centre_height
            if R is None:
                raise ValueError("ball_outline: give R (the camera's centre_height is not set)")
        xy = np.asarray(xy, dtype=float)
        pts = np.atleast_2d(xy)
        m = pts.shape[0]
        th = 2.0 * np.pi * np.arange(n) / n
        cs = np.stack([np.cos(th), np.sin(th)], axis=-1)                 # (n, 2)
        if self.is_pinhole:
            c = pts @ self.rotation[:, :2].T + (self.rotation[:, 2] * self.centre_height
                                                 + np.asarray(self.tvec, dtype=float))
            dist = np.linalg.norm(c, axis=-1)
            a = c / dist[:, None]                                         # (m, 3)
            s = np.clip(R / dist, 0.0, 1.0)
            co = np.sqrt(1.0 - s * s)
            # e1 = (a_z, 0, -a_x)/norm is perpendicular to a and never zero for a
            # point in front of the camera (a_z > 0).
            e1 = np.stack([a[:, 2], np.zeros(m), -a[:, 0]], axis=-1)
            e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
            e2 = np.cross(a, e1)
            d = (co[:, None, None] * a[:, None, :]
                 + s[:, None, None] * (cs[None, :, 0, None] * e1[:, None, :]
                                       + cs[None, :, 1, None] * e2[:, None, :]))   # (m, n, 3)
            nrm = d[..., :2] / d[..., 2:3]
            uv, _ = self._to_px(nrm.reshape(-1, 2))
        else:
            circ = pts[:, None, :] + R * cs[None, :, :]
            uv, _ = self._to_px(apply_homography(self._G, circ.reshape(-1, 2)))
        uv = uv.reshape(m, n, 2)
        return uv[0] if xy.ndim == 1 else uv

    def silhouette_centroid_offset(self, xy, R: float | None = None, n: int = 720):
        """Area centroid of the ball's silhouette minus its projected centre (px).

        The polygon of :meth:`ball_outline` with ``n`` vertices; its centroid
        converges as ``1/n^2`` (720 vertices: under 1e-4 px on a 20-px ball).

        Parameters
        ----------
        xy : array_like, shape (m, 2) or (2,)
        R : float, optional
            Ball radius (m); default ``centre_height``.

        Returns
        -------
        ndarray, shape (m, 2) or (2,)
        """
        xy = np.asarray(xy, dtype=float)
        poly = self.ball_outline(np.atleast_2d(xy), R, n)                # (m, n, 2)
        c = polygon_centroid(poly) - self.to_pixels(np.atleast_2d(xy))
        return c[0] if xy.ndim == 1 else c

    # ----------------------------------------------------------- time, size
    def frame_times(self, n: int) -> np.ndarray:
        """Timestamps ``k / fps`` (s) of frames ``0 .. n-1``."""
        return np.arange(n) / self.fps

    def with_size(self, width: int, height: int) -> Camera:
        """This camera with the video's frame size where the scene left it out.

        A size the scene does give is kept (the reader then checks it against
        the video's and refuses a mismatch).
        """
        return replace(self, width=int(width) if self.width is None else self.width,
                       height=int(height) if self.height is None else self.height)

    def with_centre_height(self, h: float) -> Camera:
        """This camera for a ball centred ``h`` m above the cloth."""
        return self if self.centre_height == h else replace(self, centre_height=float(h))


def polygon_centroid(poly) -> np.ndarray:
    """Area centroid of simple polygons (shoelace), shape (..., n, 2) -> (..., 2)."""
    p = np.asarray(poly, dtype=float)
    q = np.roll(p, -1, axis=-2)
    cr = p[..., 0] * q[..., 1] - q[..., 0] * p[..., 1]
    A = cr.sum(axis=-1) / 2.0
    cx = ((p[..., 0] + q[..., 0]) * cr).sum(axis=-1) / (6.0 * A)
    cy = ((p[..., 1] + q[..., 1]) * cr).sum(axis=-1) / (6.0 * A)
    return np.stack([cx, cy], axis=-1)


def default_camera(fps: float = 240.0, px_per_m: float = 500.0, margin_px: float = 5.0,
                   table=None, exposure_s: float = 0.0) -> Camera:
    """The top-down camera of CONVENTIONS.md, y flipped.

    ``[[s, 0, m], [0, -s, s W], [0, 0, 1]]`` with ``s`` px per metre and
    margin ``m``: the table's far side (y = W) lies on row 0 and a margin of
    ``m`` px is left on the three other sides, sizes rounded up to even (video
    codecs need even sizes).  With the defaults this is exactly the
    conventions' 1280 x 640 view, ``[[500, 0, 5], [0, -500, 635], [0, 0, 1]]``.
    """
    length, width_m = (2.54, 1.27) if table is None else (table.length, table.width)
    s = float(px_per_m)
    width = 2 * int(math.ceil((length * s + 2 * margin_px) / 2 - 1e-9))
    height = 2 * int(math.ceil((width_m * s + margin_px) / 2 - 1e-9))
    H = ((s, 0.0, float(margin_px)), (0.0, -s, s * width_m), (0.0, 0.0, 1.0))
    return Camera(fps=float(fps), width=width, height=height, homography=H,
                  exposure_s=float(exposure_s))


def look_at_rotation(tilt_deg: float, roll_deg: float = 0.0) -> np.ndarray:
    """Rotation table -> camera for a camera tilted ``tilt_deg`` from straight down.

    At tilt 0 the image's u runs along +x and v along -y (the far side y = W
    at the top, as the default camera); a tilt moves the camera towards the
    near side (y = 0) looking towards +y; ``roll_deg`` then turns the image
    about the optical axis.
    """
    t = math.radians(tilt_deg)
    Rm = np.array([[1.0, 0.0, 0.0],
                   [0.0, -math.cos(t), -math.sin(t)],
                   [0.0, math.sin(t), -math.cos(t)]])
    r = math.radians(roll_deg)
    Rz = np.array([[math.cos(r), -math.sin(r), 0.0], [math.sin(r), math.cos(r), 0.0], [0.0, 0.0, 1.0]])
    return Rz @ Rm


def pinhole_camera(table=None, height_m: float = 2.0, tilt_deg: float = 0.0,
                   f_px: float | None = None, size: tuple = (1280, 720), k1: float = 0.0,
                   k2: float = 0.0, fps: float = 240.0, exposure_s: float = 0.0,
                   R: float | None = None, roll_deg: float = 0.0, margin_m: float = 0.1,
                   pad_px: float = 8.0) -> Camera:
    """A tilted pinhole camera with radial distortion looking at the table's centre.

    Parameters
    ----------
    table : Table, optional
        Playing surface (default 2.54 m x 1.27 m).
    height_m : float
        Height of the camera's centre above the cloth (m).
    tilt_deg : float
        Angle of the optical axis from straight down (deg); the axis passes
        through the table's centre (see :func:`look_at_rotation`).
    f_px : float, optional
        Focal length (px); default: the largest that keeps the table and
        ``margin_m`` around it (the rails) ``pad_px`` inside the frame.
    size : (int, int)
        Image ``(width, height)`` (px); the principal point is its centre.
    k1, k2 : float
        Radial distortion (OpenCV's; a phone's wide lens: k1 about -0.1 to -0.25).
    R : float, optional
        Ball-centre height (m); a Scene fills it from ``physics.R``.

    Returns
    -------
    Camera
    """
    length, width_m = (2.54, 1.27) if table is None else (table.length, table.width)
    w, h = int(size[0]), int(size[1])
    Rm = look_at_rotation(tilt_deg, roll_deg)
    target = np.array([length / 2, width_m / 2, 0.0])
    C = target + np.array([0.0, -height_m * math.tan(math.radians(tilt_deg)), height_m])
    C[2] = height_m
    t = -Rm @ C
    dist = (float(k1), float(k2), 0.0, 0.0, 0.0)
    cx, cy = (w - 1) / 2.0, (h - 1) / 2.0
    if f_px is None:
        # Normalised coordinates do not depend on f: distort the outline of the
        # table plus margin once and scale it into the frame.
        s = np.linspace(0.0, 1.0, 64)
        x0, x1, y0, y1 = -margin_m, length + margin_m, -margin_m, width_m + margin_m
        edge = np.concatenate([
            np.column_stack([x0 + (x1 - x0) * s, np.full_like(s, y0)]),
            np.column_stack([x0 + (x1 - x0) * s, np.full_like(s, y1)]),
            np.column_stack([np.full_like(s, x0), y0 + (y1 - y0) * s]),
            np.column_stack([np.full_like(s, x1), y0 + (y1 - y0) * s])])
        Xc = np.column_stack([edge, np.zeros(len(edge))]) @ Rm.T + t
        nd, _ = _distort(Xc[:, :2] / Xc[:, 2:3], np.array(dist))
        f_px = float(min(np.min((cx - pad_px) / np.abs(nd[:, 0])),
                         np.min((cy - pad_px) / np.abs(nd[:, 1]))))
    K = ((float(f_px), 0.0, cx), (0.0, float(f_px), cy), (0.0, 0.0, 1.0))
    return Camera(fps=float(fps), width=w, height=h, homography=None, exposure_s=float(exposure_s),
                  intrinsics=K, distortion=dist if (k1 or k2) else None,
                  rvec=as_tuple(rotation_to_rvec(Rm)), tvec=as_tuple(t),
                  centre_height=None if R is None else float(R))
