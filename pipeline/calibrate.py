"""``cuespin calibrate``: the camera of a scene file, found from the table itself.

The playing surface's four corners (clicked by the user, ``--corners``, or
found in the video: the felt's quadrilateral) fix the camera's pose.  The
corners lie on the cloth (z = 0) and the ball's centre moves at z = R, so the
camera written is always a full pinhole camera (``intrinsics``, ``rvec``,
``tvec``; CONVENTIONS.md), which converts in the ball-centre plane exactly:

* with ``--intrinsics`` (a lens calibration: camera matrix and distortion),
  the pose is solved from the corners (``cv2.solvePnP``), exact;
* without, the camera matrix is square-pixel with its principal point at the
  image centre, and its focal length comes from ``--focal-px``, or from
  ``--camera-height`` (the lens's height above the cloth, measured), or from
  the corners themselves when the view is tilted enough to fix it, else a
  phone's nominal focal length, said on stderr with what it may cost.

A homography fitted to the cloth's corners and used for the ball's centre would
make every distance too small by ``R / D`` (D the camera's height: 1.4% at 2 m),
which is why the pose is needed at all.

Checks (a refused camera is one line and exit status 2): corners that do not
form a convex quadrilateral in the frame, a mirrored order (the table seen
from below: every spin sign would flip), a camera below the cloth or behind
the table, corners that no rectangle of the table's size fits through the
camera (wrong order, wrong table size or wrong lens) and implausible focal
lengths or tilts.
"""

from __future__ import annotations

import json
import math
import sys
from dataclasses import dataclass, field, replace
from pathlib import Path

import cv2
import numpy as np

from cuespin.physics.camera import Camera, as_tuple, distort, pinhole_camera, undistort
from cuespin.physics.scene import SCHEMA, Table, camera_to_dict
from cuespin.pipeline.io import InputError

# A pose whose corners reproject worse than this (px RMS) is not the table's
# rectangle seen through the camera: clicked corners are good to 1-2 px, the
# automatic ones to 0.1 px; wrong order or table size gives tens of px.
MAX_CORNER_RMS_PX = 4.0
# Focal lengths outside this range of the image's larger side are not a camera
# anyone films with (a 26 mm-equivalent phone lens is 0.75; 0.2 is a 150-degree
# fisheye, 5 a long telephoto).
FOCAL_RANGE = (0.2, 5.0)
# A phone's main camera: 26 mm equivalent, 69 degrees across the larger side.
NOMINAL_FOCAL = 0.73
# Relative 1-sigma error stated for that nominal focal length (assumed, not
# measured on phones): main cameras span 23-28 mm equivalent (+/- 10%) and
# video modes crop by up to 10-20% more.  The overhead camera that needs it
# cannot fix f from its corners, and f sets the camera's height D, hence the
# ball plane's scale (1 + R / D): its share of v0's error is R / D times this
# (docs/calibration.md, section 6), carried by one more perturbed camera.
NOMINAL_FOCAL_SIGMA = 0.15
# Default error of a measured --camera-height (m): a tape from the cloth to
# a phone's lens, whose entrance pupil sits a few mm inside it (assumed).
# 2% (4 cm) at 2 m moved the ball-centre conversion by up to 3.9e-4 m
# (docs/calibration.md, section 6).
CAMERA_HEIGHT_SIGMA_M = 0.02
# Tilt of the optical axis from straight down beyond which the table is too
# foreshortened to track a ball on (deg).
MAX_TILT_DEG = 70.0
# The focal length counts as fixed by the corners when its 1-sigma interval
# (at the stated corner error) is within this factor.
FOCAL_DETERMINED = 1.10


class CalibrationError(InputError):
    """A camera the corners cannot give, or one refused as implausible."""


@dataclass(frozen=True)
class Calibration:
    """A camera found from the table's corners, and how sure it is.

    Attributes
    ----------
    camera : Camera
        Pinhole camera (intrinsics, distortion, rvec, tvec) of the video.
    corners_px : ndarray, shape (4, 2)
        The measured corners (px), in table order: (0, 0), (L, 0), (L, W), (0, W).
    residual_px : ndarray, shape (4, 2)
        Measured minus reprojected corners (px).
    focal_source : str
        Where the focal length came from: ``intrinsics``, ``focal``,
        ``camera-height``, ``corners``, ``balls`` (the still balls' shapes,
        :func:`focal_from_balls`) or ``nominal``.
    notes : list of str
        Assumptions worth telling the user.
    edge_rms_px : float or None
        Automatic detection only: RMS distance of the felt's edge points from
        the four fitted lines (px).
    edge : str or None
        Automatic detection only: ``noses`` or ``felt`` (:class:`Detection`).
    corner_sigma_px : float or None
        Error of each corner coordinate (px) assumed (clicked: ``--corner-error``,
        default 1; automatic: the RMS over the 8 coordinates of the edges'
        jackknife error, :func:`corner_covariance`, with ``EDGE_PATTERN_PX``).
    perturbed : tuple of Camera
        The cameras of the calibration's sensitivity set (:func:`perturbed_cameras`):
        with a corner error given (clicked corners, or ``corner_sigma_px``),
        each of the 8 corner coordinates moved by ``corner_sigma_px`` in turn
        (and, with the lens's bow estimated, one for k1's error with the
        corners it gives); for automatic corners, the 9 joint moves of the
        corners and k1 whose outer products sum to their jackknife covariance
        (:func:`covariance_moves`); each with the corners' share of the focal
        length moved with them; then one for the rest of the focal length's
        error (the balls', the nominal one's, the measured height's).
        Written to the scene file's ``calibration.perturbed`` for the
        recovery's errors.
    focal_sigma : float or None
        Without a lens, focal length or height given (corners found or
        clicked): the focal length's stated relative error (the corners', the
        balls', their combination's, :func:`choose_focal`, or
        ``NOMINAL_FOCAL_SIGMA``).
    """

    camera: Camera
    corners_px: np.ndarray
    residual_px: np.ndarray
    focal_source: str
    notes: list = field(default_factory=list)
    edge_rms_px: float | None = None
    edge: str | None = None
    corner_sigma_px: float | None = None
    perturbed: tuple = ()
    focal_sigma: float | None = None

    @property
    def rms_px(self) -> float:
        """Corner reprojection error, RMS over the 4 corners' distances (px)."""
        return float(np.sqrt(np.mean(np.sum(self.residual_px**2, axis=1))))

    @property
    def height_m(self) -> float:
        """Camera centre above the cloth (m)."""
        return float(self.camera.centre[2])

    @property
    def tilt_deg(self) -> float:
        """Optical axis from straight down (deg)."""
        axis = self.camera.rotation[2]
        return float(np.degrees(np.arccos(np.clip(-axis[2], -1.0, 1.0))))


def table_corners(table: Table, margin_m: float = 0.0, height_m: float = 0.0) -> np.ndarray:
    """The playing surface's corners (m, z up) in the order ``--corners`` takes them:
    (0, 0), (L, 0), (L, W), (0, W), grown by ``margin_m`` on every side, at ``height_m``."""
    m = margin_m
    return np.array([[-m, -m, height_m], [table.length + m, -m, height_m],
                     [table.length + m, table.width + m, height_m], [-m, table.width + m, height_m]])


def signed_area(poly) -> float:
    """Shoelace area of an image polygon in (u, v); negative when it runs counter-clockwise
    on the screen (v down), as a true view of the table's corners in order does."""
    p = np.asarray(poly, dtype=float)
    q = np.roll(p, -1, axis=0)
    return float(np.sum(p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]) / 2.0)


def _check_quad(corners: np.ndarray, size: tuple) -> None:
    w, h = size
    for i, (u, v) in enumerate(corners):
        if not (-0.5 <= u <= w - 0.5 and -0.5 <= v <= h - 0.5):
            raise CalibrationError(f"--corners: corner {i + 1} ({u:g}, {v:g}) is outside the "
                                   f"{w}x{h} frame")
    # Convex and simple: every turn the same way.
    turns = []
    for i in range(4):
        a, b, c = corners[i], corners[(i + 1) % 4], corners[(i + 2) % 4]
        turns.append((b[0] - a[0]) * (c[1] - b[1]) - (b[1] - a[1]) * (c[0] - b[0]))
    if not (all(t > 0 for t in turns) or all(t < 0 for t in turns)):
        raise CalibrationError("--corners: the four points do not form a convex quadrilateral; "
                               "give them in order around the table")
    if signed_area(corners) > 0:
        raise CalibrationError("--corners: mirrored order (clockwise on the screen): the table would "
                               "be seen from below and every spin sign would flip; give (0,0), "
                               "(length,0), (length,width), (0,width) counter-clockwise as seen")


def _homography_dlt(src, dst):
    """Exact homography of 4 point pairs (direct linear transform, normalised)."""
    def norm(p):
        c = p.mean(axis=0)
        s = math.sqrt(2.0) / np.mean(np.linalg.norm(p - c, axis=1))
        return np.array([[s, 0.0, -s * c[0]], [0.0, s, -s * c[1]], [0.0, 0.0, 1.0]])
    Ts, Td = norm(src), norm(dst)
    a = np.column_stack([src, np.ones(len(src))]) @ Ts.T
    b = np.column_stack([dst, np.ones(len(dst))]) @ Td.T
    rows = []
    for (x, y, w), (u, v, z) in zip(a, b):
        rows.append([0, 0, 0, -z * x, -z * y, -z * w, v * x, v * y, v * w])
        rows.append([z * x, z * y, z * w, 0, 0, 0, -u * x, -u * y, -u * w])
    _, _, vt = np.linalg.svd(np.array(rows))
    H = vt[-1].reshape(3, 3)
    return np.linalg.solve(Td, H @ Ts)


def _pose(obj, img, K, dist):
    """Pose of the 4 coplanar points (all at one height): the plane's homography in
    normalised coordinates decomposed (Zhang), the table in front of the camera,
    then refined by Levenberg-Marquardt; one solution branch for every K, so the
    fit's error is a smooth function of the focal length.

    Returns ``(rvec, tvec, residual (4, 2) = measured - reprojected px)``.
    """
    h = float(obj[0, 2])
    und = img if dist is None or not np.any(dist) else _undistort_px(img, K, dist)
    n = np.column_stack([(und[:, 0] - K[0, 2]) / K[0, 0], (und[:, 1] - K[1, 2]) / K[1, 1]])
    M = _homography_dlt(obj[:, :2], n)
    lam = 2.0 / (np.linalg.norm(M[:, 0]) + np.linalg.norm(M[:, 1]))
    if M[2, 2] < 0:  # the plane's origin in front of the camera (t_z > 0)
        lam = -lam
    r1, r2, t = lam * M[:, 0], lam * M[:, 1], lam * M[:, 2]
    U, _, Vt = np.linalg.svd(np.column_stack([r1, r2, np.cross(r1, r2)]))
    Rm = U @ Vt
    if np.linalg.det(Rm) < 0:
        Rm = U @ np.diag([1.0, 1.0, -1.0]) @ Vt
    t = t - Rm[:, 2] * h
    rvec, _ = cv2.Rodrigues(Rm)
    o = np.ascontiguousarray(obj, dtype=np.float64).reshape(-1, 1, 3)
    u = np.ascontiguousarray(und, dtype=np.float64).reshape(-1, 1, 2)
    rvec, tvec = cv2.solvePnPRefineLM(o, u, K, np.zeros(5), rvec, t.reshape(3, 1).copy())
    proj, _ = cv2.projectPoints(o, rvec, tvec, K, np.zeros(5) if dist is None else _lens(dist))
    return rvec.ravel(), tvec.ravel(), img - proj[:, 0]


def _K(f, size):
    w, h = size
    return np.array([[f, 0.0, (w - 1) / 2.0], [0.0, f, (h - 1) / 2.0], [0.0, 0.0, 1.0]])


def _camera_height(obj, img, f, size) -> float:
    r, t, _ = _pose(obj, img, _K(f, size), None)
    Rm, _ = cv2.Rodrigues(r)
    return float((-Rm.T @ t)[2])


def _chi2(obj, img, f, size) -> float:
    return float(np.sum(_pose(obj, img, _K(f, size), None)[2] ** 2))


def focal_from_corners(obj, img, size, sigma_px: float):
    """Focal length (px) that best fits 4 corners with square pixels and a centred
    principal point, and its 1-sigma interval at corner error ``sigma_px``.

    Four corners give 8 numbers for 6 pose parameters and f: a tilted view
    fixes f, a view from straight above does not (the interval is then wide).
    """
    big = max(size)
    grid = big * np.exp(np.linspace(np.log(FOCAL_RANGE[0]), np.log(FOCAL_RANGE[1]), 65))
    chi = np.array([_chi2(obj, img, f, size) for f in grid]) / sigma_px**2
    i = int(np.argmin(chi))
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    f = math.exp(_golden(lambda lf: _chi2(obj, img, math.exp(lf), size), math.log(lo), math.log(hi), 1e-7))
    c0 = _chi2(obj, img, f, size) / sigma_px**2
    inside = grid[chi <= c0 + 1.0]
    return f, (float(min(inside.min(), f)), float(max(inside.max(), f))) if inside.size else (f, f)


def corner_focal(corners_px, size, table: Table, moves, *, kappa: float = 0.0, margin_m: float = 0.0,
                 corner_height_m: float = 0.0):
    """The focal length the corners give (:func:`focal_from_corners`, through the
    lens's bow ``kappa``) and its standard error under the corners' errors.

    The corners are moved by each row of ``moves`` in turn (shape (m, 9): the
    8 corner coordinates in table order and kappa; :func:`covariance_moves` of
    the edges' jackknife, or one coordinate at a time) and f refitted:
    ``sigma^2 = sum_k (f_k - f)^2``, the first-order variance the perturbed
    cameras would carry.  (The chi^2 interval of :func:`focal_from_corners`
    assumes independent corners and is read off a grid 5% apart: at 2-3
    degrees of tilt it cannot tell 2% from 5%.)

    Returns
    -------
    (f, sigma, f_k) : float, float, ndarray of shape (m,)
        Focal length (px), its standard error (px; infinite when f or a
        refit lies at ``FOCAL_RANGE``'s edge), and f under each move.
    """
    obj = table_corners(table, margin_m, corner_height_m)
    centre = np.array([(size[0] - 1) / 2.0, (size[1] - 1) / 2.0])
    base = np.asarray(corners_px, dtype=float).reshape(4, 2)

    def fit(c, k):
        return focal_from_corners(obj, _undistort_radial(c, centre, k) if k else c, size, 1.0)[0]
    f = fit(base, kappa)
    fk = np.array([fit(base + row[:8].reshape(4, 2), kappa + row[8]) for row in np.asarray(moves, dtype=float)])
    lo, hi = FOCAL_RANGE[0] * max(size) * 1.01, FOCAL_RANGE[1] * max(size) / 1.01
    if not lo < min(f, fk.min()) <= max(f, fk.max()) < hi:
        # a minimum on FOCAL_RANGE's edge is no minimum (straight overhead chi^2
        # falls towards one end): the corners do not fix f
        return f, math.inf, fk
    return f, float(np.sqrt(np.sum((fk - f) ** 2))), fk


def choose_focal(corners=None, balls=None):
    """Where the focal length comes from, one rule for every view: of the
    sources whose stated error is under the nominal focal length's
    (``NOMINAL_FOCAL_SIGMA``), the one with the smaller stated error, or, when
    both the corners' perspective and the still balls' shapes qualify, their
    inverse-variance combination (independent measurements: the table's edges
    and the balls' outlines; both stated honestly, docs/calibration.md,
    section 3).

    Parameters
    ----------
    corners, balls : (f, sigma) or None
        Focal length and its standard error (px) from :func:`corner_focal` and
        :func:`focal_from_balls`.

    Returns
    -------
    (source, f, sigma, w) or None
        ``corners``, ``balls`` or ``corners+balls``; f and its standard error
        (px); ``w`` the corners' weight (1 - w the balls').  None: neither
        qualifies (the nominal focal length then).
    """
    use = {k: v for k, v in (("corners", corners), ("balls", balls))
           if v is not None and np.isfinite(v[1]) and 0 < v[1] < NOMINAL_FOCAL_SIGMA * v[0]}
    if not use:
        return None
    if len(use) == 1:
        (k, (f, s)), = use.items()
        return k, float(f), float(s), 1.0 if k == "corners" else 0.0
    (fc, sc), (fb, sb) = use["corners"], use["balls"]
    w = sb**2 / (sc**2 + sb**2)
    return "corners+balls", float(w * fc + (1.0 - w) * fb), float(sc * sb / math.hypot(sc, sb)), float(w)


def calibrate_corners(corners_px, size, table: Table = Table(), *, intrinsics=None, distortion=None,
                      focal_px: float | None = None, camera_height_m: float | None = None,
                      corner_sigma_px: float = 1.0, margin_m: float = 0.0,
                      corner_height_m: float = 0.0, fps: float = 30.0,
                      R_nominal: float = 0.028575, kappa: float = 0.0,
                      homography: bool = False) -> Calibration:
    """The camera from the playing surface's four corners in pixels.

    Parameters
    ----------
    corners_px : array_like, shape (4, 2)
        Pixels of the table points (0, 0), (L, 0), (L, W), (0, W) (m), i.e.
        counter-clockwise as seen on the screen, starting at the origin corner.
    size : (int, int)
        Frame ``(width, height)`` (px).
    table : Table
    intrinsics, distortion : array_like, optional
        A lens calibration (OpenCV's camera matrix and ``[k1, k2, p1, p2, k3]``).
    focal_px, camera_height_m : float, optional
        Without intrinsics: the focal length (px), or the lens's height above
        the cloth (m), to fix the focal length where the corners cannot.
    corner_sigma_px : float
        Error of each corner coordinate (px), for the focal length's interval.
    margin_m, corner_height_m : float
        Where the measured quadrilateral lies: the surface grown by
        ``margin_m`` (m) at ``corner_height_m`` (m) above the cloth (0, 0: the
        playing surface itself).
    fps : float
        The video's nominal rate, for the camera written.
    R_nominal : float
        Ball radius (m) used only to state what an assumed focal length costs.
    kappa : float
        Without intrinsics: radial distortion about the frame's centre in
        pixels (``k1 / f^2``, e.g. from the felt's bowed edges); the camera
        written has ``k1 = kappa f^2``.
    homography : bool
        Write the corners' plane homography instead of a pose: the ball's
        centre plane taken as the corners' plane.  Exact for an orthographic
        view (the renderer's top-down camera, a camera far above); for a real
        camera D above the cloth every distance comes out short by R / D.

    Returns
    -------
    Calibration

    Raises
    ------
    CalibrationError
        One line: the corners or the camera they give fail a check.
    """
    img = np.asarray(corners_px, dtype=float).reshape(4, 2)
    if not np.all(np.isfinite(img)):
        raise CalibrationError("--corners: must be finite numbers")
    size = (int(size[0]), int(size[1]))
    _check_quad(img, size)
    obj = table_corners(table, margin_m, corner_height_m)
    if homography:
        return _homography_calibration(obj, img, size, intrinsics, distortion, kappa, fps,
                                       corner_sigma_px)
    notes = []
    dist = None
    if intrinsics is not None:
        K = np.asarray(intrinsics, dtype=float)
        dist = None if distortion is None else np.asarray(distortion, dtype=float).ravel()
        source = "intrinsics"
    else:
        big = max(size)
        img_meas = img
        if kappa:
            img = _undistort_radial(img, np.array([(size[0] - 1) / 2.0, (size[1] - 1) / 2.0]), kappa)
        if focal_px is not None:
            f, source = float(focal_px), "focal"
        elif camera_height_m is not None:
            if not camera_height_m > corner_height_m:
                raise CalibrationError("--camera-height: must be above the cloth (m)")
            # height(f) grows with f (a longer lens sees the same table from further away)
            lo, hi = FOCAL_RANGE[0] * big, FOCAL_RANGE[1] * big
            if not (_camera_height(obj, img, lo, size) < camera_height_m < _camera_height(obj, img, hi, size)):
                raise CalibrationError(f"--camera-height: no focal length in {FOCAL_RANGE[0]}-"
                                       f"{FOCAL_RANGE[1]} x {big} px puts the camera {camera_height_m:g} m "
                                       f"above these corners")
            for _ in range(60):
                mid = math.sqrt(lo * hi)
                if _camera_height(obj, img, mid, size) < camera_height_m:
                    lo = mid
                else:
                    hi = mid
            f, source = math.sqrt(lo * hi), "camera-height"
        else:
            f, (f_lo, f_hi) = focal_from_corners(obj, img, size, corner_sigma_px)
            source = "corners"
            if f_hi / f_lo > FOCAL_DETERMINED ** 2:
                f_nom = NOMINAL_FOCAL * big
                f = min(max(f_nom, f_lo), f_hi)
                source = "nominal"
                d_nom = _camera_height(obj, img, f, size)
                spread = [_camera_height(obj, img, g, size) for g in (max(f_lo, 0.5 * big),
                                                                      min(f_hi, 1.2 * big))]
                scale = R_nominal * abs(1.0 / min(spread) - 1.0 / max(spread)) / 2.0
                notes.append(f"the corners do not fix the focal length (camera nearly overhead); "
                             f"assumed f = {f:.0f} px (a phone's main camera), camera {d_nom:.2f} m "
                             f"above the cloth; the ball-plane scale may be off by up to "
                             f"{100 * scale:.2g}%: give --camera-height or --intrinsics")
        if not (FOCAL_RANGE[0] * big <= f <= FOCAL_RANGE[1] * big):
            raise CalibrationError(f"implausible camera: focal length {f:.0f} px is outside "
                                   f"{FOCAL_RANGE[0]}-{FOCAL_RANGE[1]} x the frame's {big} px")
        K = _K(f, size)
        if kappa:
            dist = np.array([kappa * f * f, 0.0, 0.0, 0.0, 0.0])
        img = img_meas
    rvec, tvec, res = _pose(obj, img, K, dist)
    Rm, _ = cv2.Rodrigues(rvec)
    centre = -Rm.T @ tvec
    if centre[2] <= corner_height_m:
        raise CalibrationError("--corners: mirrored order or a camera below the table; give "
                               "(0,0), (length,0), (length,width), (0,width) counter-clockwise as seen")
    rms = float(np.sqrt(np.mean(np.sum(res**2, axis=1))))
    if rms > MAX_CORNER_RMS_PX:
        raise CalibrationError(f"--corners: no {table.length:g} x {table.width:g} m rectangle fits them "
                               f"through this camera (corner RMS {rms:.1f} px): check the order "
                               f"(start at a corner, go along a long side), the table size and the lens")
    tilt = float(np.degrees(np.arccos(np.clip(-Rm[2, 2], -1.0, 1.0))))
    if tilt > MAX_TILT_DEG:
        raise CalibrationError(f"implausible camera: it looks {tilt:.0f} deg from straight down "
                               f"(more than {MAX_TILT_DEG:g})")
    cam = Camera(fps=float(fps), width=size[0], height=size[1], homography=None, exposure_s=0.0,
                 intrinsics=as_tuple(K),
                 distortion=None if dist is None or not np.any(dist) else as_tuple(np.resize(dist, 5)),
                 rvec=as_tuple(rvec), tvec=as_tuple(tvec))
    return Calibration(camera=cam, corners_px=img, residual_px=res, focal_source=source, notes=notes,
                       corner_sigma_px=float(corner_sigma_px))


def _homography_calibration(obj, img, size, intrinsics, distortion, kappa, fps, sigma):
    """The corners' plane homography as the camera (see ``homography`` above),
    through the lens when one is known or estimated (a homography in
    undistorted pixels, with intrinsics and distortion)."""
    K = dist = None
    und = img
    if intrinsics is not None:
        K = np.asarray(intrinsics, dtype=float)
        dist = None if distortion is None else np.asarray(distortion, dtype=float).ravel()
        und = img if dist is None else _undistort_px(img, K, dist)
    elif kappa:
        f = NOMINAL_FOCAL * max(size)
        K = _K(f, size)
        dist = np.array([kappa * f * f, 0.0, 0.0, 0.0, 0.0])
        und = _undistort_radial(img, K[:2, 2], kappa)
    H = _homography_dlt(obj[:, :2], und)
    H = H / H[2, 2]
    cam = Camera(fps=float(fps), width=int(size[0]), height=int(size[1]), homography=as_tuple(H),
                 intrinsics=None if K is None else as_tuple(K),
                 distortion=None if dist is None or not np.any(dist) else as_tuple(_lens(dist)))
    proj = cam.with_centre_height(0.0).to_pixels(obj[:, :2])
    notes = ["homography: the ball's centre plane is taken as the corners' plane (exact for a "
             "top-down render or a far camera; a real camera D m above the cloth reads every "
             "distance short by R / D)"]
    return Calibration(camera=cam, corners_px=img, residual_px=img - proj, focal_source="homography",
                       notes=notes, corner_sigma_px=float(sigma))


def perturbed_cameras(corners_px, sigma_px: float, size, table: Table = Table(), *,
                      height_sigma_m: float = 0.0, focal_sigma: float = 0.0, kappa_sigma: float = 0.0,
                      kappa_corners=None, moves=None, focal_moves=None, **kw) -> list:
    """The cameras of the 8 corner coordinates each moved by ``sigma_px``, one at a
    time, and, when the focal length is the nominal one (an overhead camera
    without a lens calibration or height), a ninth with it
    ``1 + NOMINAL_FOCAL_SIGMA`` times longer; when it comes from
    ``camera_height_m`` and ``height_sigma_m`` > 0, a ninth with the camera
    that much higher (the tape's error); when ``focal_px`` is given with a
    relative error ``focal_sigma`` > 0 (the balls' f), a ninth with it that
    much longer.  With the lens's bow estimated (``kappa``, no intrinsics)
    and its standard error ``kappa_sigma`` > 0, one more: ``kappa`` that much
    larger, with the corners the edges give then (``kappa_corners``; default
    the same corners).

    For propagating a calibration's error to anything computed through the
    camera (v0, w0): with ``q`` the quantity through the calibrated camera and
    ``q_k`` through camera k, its calibration variance is ``sum_k (q_k - q)^2``
    (first order; the corners' errors independent, ``sigma_px`` per
    coordinate).  ``kw`` as for :func:`calibrate_corners` (the same lens or
    focal length source); a corner moved into an implausible camera is skipped.

    ``moves`` (shape (m, 9), automatic corners: :func:`covariance_moves` of the
    edges' jackknife) replaces the 8 single moves: camera k has the corners
    moved by ``moves[k, :8]`` together and ``kappa`` by ``moves[k, 8]``, so
    that ``sum_k (q_k - q)^2`` is the first-order variance under the corners'
    and the bow's joint covariance (adjacent corners share a side's line).

    ``focal_moves`` (one focal length (px) per corner move, in the order of
    ``moves`` or of the 8 single moves): with the focal length fixed
    (``focal_px``) but taken partly from the corners (:func:`choose_focal`),
    camera k has it at ``focal_moves[k]``, what the corners so moved give it.
    """
    base = np.asarray(corners_px, dtype=float).reshape(4, 2)
    cams = []
    def at(k, trial):
        return trial if focal_moves is None else dict(trial, focal_px=float(focal_moves[k]))
    if moves is not None:
        for k, row in enumerate(np.asarray(moves, dtype=float)):
            trial = dict(kw, kappa=kw["kappa"] + row[8]) if row[8] and "kappa" in kw else kw
            try:
                cams.append(calibrate_corners(base + row[:8].reshape(4, 2), size, table, **at(k, trial)).camera)
            except CalibrationError:
                continue
    for k in range(8 if moves is None else 0):
        c = base.copy()
        c.flat[k] += sigma_px
        try:
            cams.append(calibrate_corners(c, size, table, **at(k, kw)).camera)
        except CalibrationError:
            continue
    if focal_sigma > 0 and kw.get("focal_px") and kw.get("intrinsics") is None and not kw.get("homography"):
        try:
            cams.append(calibrate_corners(base, size, table,
                                          **dict(kw, focal_px=kw["focal_px"] * (1.0 + focal_sigma))).camera)
        except CalibrationError:
            pass
    if kappa_sigma > 0 and kw.get("kappa") and kw.get("intrinsics") is None and not kw.get("homography"):
        # The bow's own error: the edges straightened by a kappa one standard
        # error larger meet at slightly different corners (mostly at the frame's edge).
        kc = base if kappa_corners is None else np.asarray(kappa_corners, dtype=float).reshape(4, 2)
        try:
            cams.append(calibrate_corners(kc, size, table, **dict(kw, kappa=kw["kappa"] + kappa_sigma)).camera)
        except CalibrationError:
            pass
    if kw.get("camera_height_m") and height_sigma_m > 0 and not (
            kw.get("homography") or kw.get("intrinsics") is not None or kw.get("focal_px")):
        # The measured height's own error: f re-solved for a camera that much higher.
        try:
            cams.append(calibrate_corners(base, size, table,
                                          **dict(kw, camera_height_m=kw["camera_height_m"] + height_sigma_m)).camera)
        except CalibrationError:
            pass
    if not (kw.get("homography") or kw.get("intrinsics") is not None or kw.get("focal_px")
            or kw.get("camera_height_m")):
        try:
            cal = calibrate_corners(base, size, table, **kw)
        except CalibrationError:
            return cams
        if cal.focal_source == "nominal":
            # The assumed focal length's own error (NOMINAL_FOCAL_SIGMA): the
            # same corners through a lens that much longer (the same bow in
            # pixels: kappa is k1 / f^2), its pose re-solved.
            f = float(cal.camera.K[0, 0]) * (1.0 + NOMINAL_FOCAL_SIGMA)
            try:
                cams.append(calibrate_corners(base, size, table, **dict(kw, focal_px=f)).camera)
            except CalibrationError:
                pass
    return cams


# --------------------------------------------------------------------------- automatic
# The table is found in the mean of the video's still frames (mean12): where
# each frame carries its own sensor and codec noise, the mean's noise falls as
# 1 / sqrt(frames) while a band's faint step inside the noses stays (random
# table 14014 in one H.264 stream at CRF 18: the first frame answered 9.80 px
# off stating 0.066, the mean of 32 refused at 11.9 x the scatter).  At CRF
# 20 and over x264 codes a still table's later frames as copies of the key
# frame, and the mean is the key frame's (docs/measurements.md, ## mean12).
# A run is still while no STILL_BLOCK_PX-square block's grey mean moves from
# the run's first frame (less the blocks' median move: an exposure step) by more than STILL_FLOOR_LEVELS, or STILL_Z of the
# blocks' robust scatter where that is larger (a noisier camera).  Measured
# on 32 still frames in one H.264 stream (random tables 14014 and the 33 of
# 18000-18059 with cushions, CRF 18 and 28): the largest block move 0.91-2.58
# levels; the scatter 0.06-0.35 levels at CRF 18 (the move at most 5.9 x it
# where it is over 0.2) and 0.00-0.15 at 20 and over (blocks repeated), so
# the floor decided on every one; a drawn ball (table 18000) moved 0.2 px
# moves a block by 2.2-3.1 levels raw and at CRF 23/28, 0.5 px by 5.0-5.6:
# a run is still to about a third of a pixel.
STILL_FRAMES = 32           # frames averaged (the brief's 16-32: 32 refused 14014 at 11.9 x, 16 at 9.9 x)
STILL_MIN_FRAMES = 16       # fewer still frames in a row: the median of frames spread over the video
STILL_BLOCK_PX = 16
STILL_Z = 8.0               # 1.35 x the largest measured (5.9, CRF 18)
STILL_FLOOR_LEVELS = 3.0    # 1.16 x the largest measured move of a still frame (2.58)
STILL_SCAN_FRAMES = 600     # frames read looking for a still run (2.5 s at 240 fps, 20 s at 30 fps)


def _blocks(img: np.ndarray) -> np.ndarray:
    """Grey means of ``STILL_BLOCK_PX``-square blocks (levels)."""
    g = img.astype(np.float32).mean(axis=2) if img.ndim == 3 else img.astype(np.float32)
    h, w = g.shape[:2]
    return cv2.resize(g, (max(w // STILL_BLOCK_PX, 1), max(h // STILL_BLOCK_PX, 1)), interpolation=cv2.INTER_AREA)


def still_moved(b: np.ndarray, b0: np.ndarray) -> float:
    """How far a frame's block means ``b`` moved from the run's first ``b0``,
    after the change common to the whole image (the blocks' median
    difference: an exposure step moves the felt, most of the image, by one
    offset): the largest block residual over the threshold (above 1: not
    still).

    Without the common change taken out, a phone's auto-exposure settling at
    the clip's start (+8 % at frame 1) raised every block's difference, so
    the scatter's threshold let a disc moving 0.3 px a frame pass as still
    for 32 frames; with it, runs of 1-5 frames as without the step (the
    reviewer's ``flick3.py``; fixvis, docs/measurements.md).  A gain and
    offset fitted by least squares was tried and not kept: where few blocks
    are bright (a ball on the felt) the gain follows the ball's own blocks
    and absorbs its motion (a disc moving 0.3 px a frame still 3 frames).
    Bright blocks under an exposure step (the rails, a ball at rest) end
    the run at the step; it starts again after it."""
    d = b - b0
    d = np.abs(d - np.median(d))
    return float(d.max() / max(STILL_Z * 1.4826 * float(np.median(d)), STILL_FLOOR_LEVELS))


def still_mean(frames, n: int = STILL_FRAMES, first: list | None = None):
    """The mean of the first ``n`` still frames in a row of ``frames`` (an
    iterable of images), else of the longest still run in it.  ``first``,
    when given, gets the run's first frame (as decoded) and, when the run
    has two or more, its second (the same table again: what the sensor's
    noise alone changes, :func:`_video_lossy`).

    Returns
    -------
    mean : ndarray, float32
        The run's mean image (levels).
    count : int
        Frames averaged.
    start : int
        The run's first frame (index in ``frames``).
    """
    best = (None, 0, 0, None, None)
    total = b0 = img0 = img1 = None
    count = start = 0
    for k, img in enumerate(frames):
        img = img if img.ndim == 3 else img[:, :, None]
        b = _blocks(img)
        if total is not None and still_moved(b, b0) <= 1.0:
            total += img
            count += 1
            img1 = img if count == 2 else img1
        else:
            if count > best[1]:
                best = (total, count, start, img0, img1)
            total, b0, count, start, img0, img1 = img.astype(np.float32), b, 1, k, img, None
        if count >= n:
            break
    if count > best[1]:
        best = (total, count, start, img0, img1)
    if best[0] is None:
        return None, 0, 0
    if first is not None:
        first.extend(f for f in best[3:] if f is not None)
    return (best[0] / best[1]).astype(np.float32), best[1], best[2]


def reference_frame(path, n: int = 9) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """The table's image: the mean of the video's first ``STILL_FRAMES``
    still frames in a row (:func:`still_mean`, read from the start, at most
    ``STILL_SCAN_FRAMES``); with fewer than ``STILL_MIN_FRAMES`` of them, the
    median of ``n`` frames spread over the video (the table without the
    moving ball, and without a cue that crosses the view for a moment).

    Returns
    -------
    image : ndarray, float32
        The mean (or median) image (levels).
    single : ndarray
        One decoded frame of those: the still run's first, else the first of
        the spread frames (what the codec left: :func:`detect_corners`'
        ``single``).
    single_next : ndarray or None
        The still run's second frame (the sensor's noise alone changed it:
        :func:`detect_corners`' ``single_next``); None without a still run
        of 16 or more."""
    from cuespin.videoio import quiet_native_stderr

    def opened():
        with quiet_native_stderr():
            cap = cv2.VideoCapture(str(path), cv2.CAP_FFMPEG)
        if not cap.isOpened():
            raise InputError(f"{path}: not a video OpenCV can read")
        return cap

    def read(cap, limit):
        for _ in range(limit):
            ok, img = cap.read()
            if not ok or img is None:
                return
            yield img

    cap = opened()
    try:
        first = []
        with quiet_native_stderr():
            mean, count, _ = still_mean(read(cap, STILL_SCAN_FRAMES), first=first)
    finally:
        cap.release()
    if count >= STILL_MIN_FRAMES:
        return mean, first[0], first[1]
    cap = opened()      # read again from the start (a finished capture does not always rewind)
    try:
        count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
        idx = set(np.unique(np.linspace(0, max(count - 1, 0), n).round().astype(int)).tolist())
        frames = []
        with quiet_native_stderr():
            if count <= 4 * n:  # short: decoding straight through beats seeking
                for i in range(max(count, 1)):
                    ok, img = cap.read()
                    if not ok or img is None:
                        break
                    if i in idx:
                        frames.append(img if img.ndim == 3 else img[:, :, None])
            else:
                for i in sorted(idx):
                    cap.set(cv2.CAP_PROP_POS_FRAMES, float(i))
                    ok, img = cap.read()
                    if ok and img is not None:
                        frames.append(img if img.ndim == 3 else img[:, :, None])
    finally:
        cap.release()
    if not frames:
        raise InputError(f"{path}: no frame could be decoded")
    return np.median(np.stack(frames), axis=0).astype(np.float32), frames[0], None


def _felt_distance(img: np.ndarray) -> tuple[np.ndarray, float]:
    """Per-pixel colour distance from the felt (the central region's median
    colour, in Lab) and the threshold between felt and surround (Otsu)."""
    img = np.clip(np.asarray(img, dtype=np.float32), 0, 255).astype(np.uint8)
    if img.ndim == 2 or img.shape[2] == 1:
        img = np.repeat(img.reshape(img.shape[0], img.shape[1], 1), 3, axis=2)
    lab = cv2.cvtColor(img, cv2.COLOR_BGR2Lab).astype(np.float32)
    h, w = lab.shape[:2]
    centre = lab[int(0.35 * h):int(0.65 * h), int(0.35 * w):int(0.65 * w)].reshape(-1, 3)
    felt = np.median(centre, axis=0)
    D = np.linalg.norm(lab - felt, axis=2)
    top = float(np.percentile(D, 99.5)) or 1.0
    D8 = np.clip(D / top * 255.0, 0, 255).astype(np.uint8)
    thr, _ = cv2.threshold(D8, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    return D, float(thr) * top / 255.0


def _felt_quad(D: np.ndarray, thr: float):
    """The felt region's outline as 4 corners (px), counter-clockwise on screen,
    and the region's contour (px, shape (m, 2))."""
    mask = (D < thr).astype(np.uint8)
    k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))
    mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, k)
    n, lab, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=4)
    if n < 2:
        raise CalibrationError("no felt found in the frame; give --corners")
    h, w = mask.shape
    c = lab[h // 2, w // 2]
    best = c if c > 0 else 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    region = (lab == best).astype(np.uint8)
    contours, _ = cv2.findContours(region, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    cnt = max(contours, key=cv2.contourArea)
    hull = cv2.convexHull(cnt)  # balls and a cue on the felt are holes or bites: the hull closes them
    peri = cv2.arcLength(hull, True)
    for eps in np.linspace(0.005, 0.08, 40):
        quad = cv2.approxPolyDP(hull, eps * peri, True)
        if len(quad) == 4:
            break
    else:
        raise CalibrationError("the felt's outline is not a quadrilateral (the table is cut by the "
                               "frame's edge or hidden); give --corners")
    quad = quad[:, 0, :].astype(float)
    if signed_area(quad) > 0:
        quad = quad[::-1]
    return quad, cnt[:, 0, :].astype(float)


def _lens(dist):
    d = np.zeros(5)
    if dist is not None:
        v = np.asarray(dist, dtype=float).ravel()
        d[: v.size] = v
    return d


def _undistort_px(uv, K, dist):
    """Image pixels to the pixels of the same camera without its distortion."""
    n = undistort(np.column_stack([(uv[:, 0] - K[0, 2]) / K[0, 0], (uv[:, 1] - K[1, 2]) / K[1, 1]]),
                  _lens(dist))
    return n * np.diag(K)[:2] + K[:2, 2]


def _distort_px(uv, K, dist):
    """Undistorted pixels back to the image's (inverse of :func:`_undistort_px`)."""
    nd, _ = distort(np.column_stack([(uv[:, 0] - K[0, 2]) / K[0, 0], (uv[:, 1] - K[1, 2]) / K[1, 1]]),
                    _lens(dist))
    return nd * np.diag(K)[:2] + K[:2, 2]


def _line_intersection(l1, l2):
    """Lines as (point, unit direction)."""
    (p, d), (q, e) = l1, l2
    A = np.column_stack([d, -e])
    s = np.linalg.solve(A, q - p)
    return p + s[0] * d


def _smoothed(img):
    im = np.asarray(img, dtype=np.float32)
    if im.ndim == 2:
        im = im[:, :, None]
    return cv2.GaussianBlur(im, (0, 0), 1.0).reshape(im.shape)


def _subpixel_edge(Ds, base, nrm, offs):
    """Where, along ``nrm`` from each base point, the colour crosses halfway from
    the inside's (the profile's first 2 px) to the outside's (its last 2 px);
    points without one clean crossing, or with under 5 levels of contrast, dropped."""
    pts = base[:, None, :] + offs[None, :, None] * nrm           # (m, k, 2)
    col = cv2.remap(Ds, pts[..., 0].astype(np.float32), pts[..., 1].astype(np.float32),
                    cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).reshape(pts.shape[:2] + (-1,))
    q = 8
    c_in = np.median(col[:, :q], axis=1)
    c_out = np.median(col[:, -q:], axis=1)
    span = c_out - c_in
    n2 = np.sum(span * span, axis=1)
    # fraction of the way from inside to outside colour (linear in coverage)
    prof = np.einsum("mkc,mc->mk", col - c_in[:, None, :], span) / np.where(n2 > 0, n2, 1.0)[:, None]
    above = prof >= 0.5
    cross = (~above[:, :-1]) & above[:, 1:]
    good = (n2 > 25.0) & (cross.sum(axis=1) == 1)
    k = np.argmax(cross, axis=1)
    r = np.arange(len(base))
    p0, p1 = prof[r, k], prof[r, k + 1]
    x = offs[k] + (0.5 - p0) / np.where(p1 != p0, p1 - p0, 1.0) * (offs[1] - offs[0])
    return (base + x[:, None] * nrm)[good]


# How far past the noses' sub-pixel window (px) a band's inner edge still
# pulls the halfway crossing: the window's inside colour is read over its
# first 2 px, and the frame's smoothing (1 px) and the step's own blur reach
# further.  Measured (cushion12, 15-25 mm bands through 7 cameras): the
# outline's noses 0.08-0.18 px off stating 0.03-0.05 with the band's edge 7-8
# px in (the lines' profile), where the window reaches 7; 0.01-0.03 off at
# 8.5 px and beyond.  Checked on 7 other cameras (18-22 mm bands): 2 of 21
# answers change, 0.218 and 0.164 -> 0.036 px, none worse; 80 random drawn
# tables unchanged.  The outline kept at z 2.4-3.1 is still 0.05-0.11 px off
# stating 0.02-0.05 on 5 of those frames.
BAND_PULL_PX = 2.0

# The outline's noses are refused when the median over the four sides of
# the largest step between them and the outline's edge, too small for the
# step rule, reaches this many times the flat felt's step scatter
# (cushion_noses' ``hidden``): a band inside the noses in nearly the
# cushions' shade shows only there, and its inner edge is taken for the
# noses.  Set (cushion13, docs/measurements.md) on the random drawn tables
# 12000-12039 and 13000-13039: those whose noses show (35 taking noses)
# 0-2.5, the 5 whose band has the cushions' shade (4.2-8.8 px off stating
# 0.02-0.06) 6.0-34.8; 4 is about the geometric middle of 2.5 and 6.0.  The
# renderer's realistic table (textured felt, rails; 7 cameras x seeds 1-3)
# 0.32-1.87.  Held out, 14000-14039 and 15000-15039: 23 showing 0-2.5, the 5
# hidden 4.1-56.9 (all refused, 6.1-10.6 px off; 14014's band 0.008 of the
# felt's shade from its cushions', 0.5 levels, is the closest).  A band
# narrower than 6 px in the image is not seen (its step lies in the nose's
# own window), nor one of exactly the cushions' shade (nothing shows).
HIDDEN_NOSE_Z = 4.0

# The least step scatter (grey levels) that ratio is taken over: a frame's
# integer levels.  A noise-free drawn frame's median profile scatters 0.001
# (the estimate's own floor) and the drawing's pattern puts 0.009-0.014
# levels of step outside its noses (2 m overhead, k1 -0.25, 4x and 16x
# supersampled), 10x the rule on a correct answer; the noisy drawn tables'
# sides scatter 0.02-0.14.
HIDDEN_NOISE_FLOOR = 0.02

# ...and the faint step must also be this many times the largest step at the
# same offsets on the felt's side of the nose taken (median over the sides):
# a JPEG's 8x8 blocks ring beside the strong nose edge, and the codec
# flattens the felt so the scatter above shrinks, which sent drawn tables
# whose noses show to 6-38 x the scatter (rev13v, docs/measurements.md).
# The ringing shows on both sides of the edge; a band's faint step only on
# the cushions' side.  But a faint step of a few tenths of a level is itself
# the size of that ringing, so the two overlap and this is a trade (rev13v,
# random drawn tables 12000-16059 taking noses, JPEG 95/85/70/50, frame noise
# 3 and 0.5): hidden tables 0.90 (14014, noise 0.5, quality 85), then 1.43
# and 1.49 (12023, noise 0.5, quality 70 and 95; answered 4.5 px off stating
# 0.06 when let through), the rest 1.95 and over; 1.3 keeps every hidden
# frame but that one refused.  Visible tables at quality 70 refused 66/82 ->
# 18/82, at noise 0.5 19/21 -> 7/21; quality 95 none either way; quality 50
# 71/82 -> 50/82.  Raw frames: no decision changes.
HIDDEN_MIRROR_Z = 1.3

# A lossy codec's flat cloth is refused (``_codec_flattened``, jpeg12 in
# docs/measurements.md): where the frame's noise is too small to dither the
# codec's quantisation, a band's faint step under the quantum is erased
# (random table 14014 at noise 0.5 + JPEG 70: a 0.5-level step read 50.7
# flat on every side, answered 9.8 px off stating 0.053; no step statistic
# can refuse it).  Flat: the felt's pixels (inside the noses) equal their
# right-hand neighbours in every channel on at least CODEC_FLAT_SHARE of
# the samples (median over the sides).  Measured on random tables 14014,
# 16005 and (fresh) 18000-18059: noise 0.5 + JPEG 70 0.964-1.0 (the erased
# case 0.999); noise 2-4 (as drawn) + JPEG 50 0.85-0.996, JPEG 70 0.51-0.91,
# JPEG 95 0.09-0.23; noise 1 + JPEG 85 0.91-0.945; noise 0.5 + JPEG 95
# 0.84-0.88, raw 0.14; a noise-free raw frame 1.00.  Cost on 18000-18059
# (tables taking noses): noise 0.5 + JPEG 70 refusals 4 -> 17 of 21 whose
# noses show, noise 2-4 + JPEG 50 10 -> 11 of 21, JPEG 70 and 95 none.  Ringing: the largest
# step on the felt's side of the nose (grey levels, median over the sides)
# at least CODEC_RING_LEVELS: a noise-free raw frame 0.007-0.010 (it keeps
# a faint step: 14014 drawn noise-free is refused by HIDDEN_NOSE_Z, 13.2),
# noise 0.5 raw 0.016-0.022, JPEG-flat frames 0.17-0.38.
CODEC_FLAT_SHARE = 0.99
CODEC_RING_LEVELS = 0.1

# The outline's noses are refused on a frame no lossy codec touched when the
# four sides' faint steps, added where a band's outer edge would lie (the
# same share of the way to the outline on every side, the same sign:
# ``_coherent_z``), reach BAND_COHERENT_Z, and their sum there is at least
# HIDDEN_MIRROR_Z times the same sum mirrored to the felt's side of the nose.
# Random table 16030 (cushions 0.765 of the felt's shade, a band at 0.749)
# was answered 3.98 px off stating 0.024 on raw frames, its faint step 3.10
# x the scatter, under HIDDEN_NOSE_Z, while visible tables reach 2.52 there
# (nose16, docs/measurements.md).  Measured on raw frames of the random drawn
# tables 12000-17059 taking noses (jpeg12's saved profiles): the 92 whose
# noses show 0-3.07 (16025; 13007 2.73), the 16 hidden 5.80 (16030, at 0.23
# of the way, mirror 1.99) and 8.75-above; 4.2 is about the geometric middle
# of 3.07 and 5.80.  Noise 0.5 raw: showing up to 2.07, hidden 21.7 and
# above.  Not on JPEG: a codec's ringing adds up coherently too (visible
# tables at JPEG 95 up to 6.18, 14015; 16030 3.72), so the rule is kept to
# frames whose felt is nowhere flat (``_flat_share`` at most RAW_FLAT_SHARE:
# noise 2-4 raw 0.000-0.002, JPEG 95 0.076-0.23, noise 0.5 raw 0.14).  Held
# out, 19000-19059 raw: the 13 frames whose noses show and are answered
# 0-2.73, the 3 hidden ones refused already 20.7-114.5; no answer changed.
# The renderer's realistic table (textured felt, rails; 6 cameras x seeds
# 1-3, raw): 0.13-2.03.
BAND_COHERENT_Z = 4.2
RAW_FLAT_SHARE = 0.05

# A video whose container says lossless is read lossy when its still run's
# first frame is flatter in space than its noise leaves it in time
# (``_video_lossy``): the felt's flat share (``_flat_share``, median over the
# sides) over the share of the same pixels equal in the run's second frame by
# more than NOISE_FLAT_EXCESS.  Where that share is FROZEN_SHARE or more the
# noise says nothing and RAW_FLAT_SHARE decides as for one frame.  Measured
# (lossy12, docs/measurements.md) on the random tables 18000-18059 with
# cushions (33), the still table's first two frames: lossless at noise 0.2,
# 0.3, 0.5 and as drawn (2-4) flat minus equal -0.007..+0.007 (flat shares
# 0.92, 0.55, 0.14, 0.00; the renderer's realistic table, noise 0.2-2,
# -0.79..0.00: its felt's texture parts neighbours);
# decoded codec frames, 8-frame streams: JPEG 95 0.051-0.18, MJPG (OpenCV's
# writer) 0.081-0.61, H.264 CRF 18 0.20-0.51, CRF 20 0.12-0.27; 0.02 is about
# the geometric middle of 0.007 and 0.051.  H.264 CRF 23 and 28 code the
# later frames as copies: equal 0.961-1.000 (flat -0.07..0.00 beyond it),
# where lossless noise 0.2 reads 0.92-0.93 and 0.15 0.99: FROZEN_SHARE
# between 0.93 and 0.961, so noise under about 0.18 levels reads lossy as
# before (flat shares 0.92-1.00 there).
NOISE_FLAT_EXCESS = 0.02
FROZEN_SHARE = 0.95

# Where the noise speaks (equal share under FROZEN_SHARE) a video is read lossy
# also when its temporal differences are not a sensor's (``_noise_tail_excess``):
# a lossless camera's two still frames differ by its noise, N(0, 2 sigma^2)
# quantised (each frame's noise rounded to whole levels), whose share of
# |d| >= 2 among the nonzero differences follows from its zero share alone;
# x264 between keeping the noise and copying frames (CRF 21-22) flattens the
# felt no more than the noise does, but codes what it keeps in larger steps.
# The observed share over the law's by more than NOISE_TAIL_EXCESS in any
# channel (with at least NOISE_TAIL_MIN_NONZERO nonzero differences there)
# reads lossy.  Measured (fixcrf, docs/measurements.md) on the fresh random
# tables 18111-18160 (50), the still table's first two frames (32-frame
# streams): lossless at noise 0.2, 0.3, 0.5 and as drawn (2-4) excess
# 0.000-0.018 (the renderer's realistic table, noise 0.2-2: 0.000-0.013);
# H.264 CRF 21-22 wherever the noise speaks 0.077-0.86, the 13 streams the
# flat share read lossless 0.077-0.69; 0.04 is about the geometric middle of
# 0.018 and 0.077 (no decision differs anywhere from 0.03 to 0.05).
# NOISE_TAIL_MIN_NONZERO: with 50 nonzero differences where the law's tail
# share is 0.002 (noise about 0.17 levels) a share over 0.04 needs 2-3
# counts where 0.1 are expected.  The law is the project's renderer's (a
# felt pixel's mean on a whole level); a camera whose means fall between
# levels shows more +-1 differences for the same zero share, so it errs
# towards lossless.  JPEG 95-98 keeps the noise's shape (excess up to
# 0.021) and is read by the flat share alone (JPEG 98 on 18150 read
# lossless: flat minus equal 0.019).
NOISE_TAIL_EXCESS = 0.04
NOISE_TAIL_MIN_NONZERO = 50

# The outline's noses are refused on a frame no lossy codec touched (the
# felt's flat share at most RAW_FLAT_SHARE) when the second-largest side's
# faint step (``cushion_noses``' ``hidden``, sides whose step is at least
# HIDDEN_MIRROR_Z x the felt side's ringing) reaches SECOND_SIDE_Z x the
# scatter: a narrow band (10 mm) whose outer edge lies at the faint-step
# zone's inner end on the far sides shows strongly on two sides only, so
# neither the median (HIDDEN_NOSE_Z) nor the coherent sum sees it.  Random
# table 19053 (cushions 0.879 of the felt's shade, a 10 mm band at 0.869)
# was answered 3.83 px off stating 0.065 raw, sides 8.2, 2.0, 4.9, 1.4
# (nose16, docs/measurements.md).  Measured (strad12): raw frames taking
# the outline's noses and answered right, random tables 12000-17059
# (jpeg12's profiles, 92 whose noses show) up to 3.34 (13007), 12000-12039,
# 13000-13039 and 19000-19059 (49) up to 3.34 (13007; 19014 2.86); 19053
# 4.94; 4.1 is about the geometric middle.  Held out, 20000-20059 raw: the
# 25 answered right up to 2.46, the 4 hidden refused already; no answer
# changed.  The renderer's realistic table (6 cameras x seeds 1-3, raw)
# 0-1.59.  Not on lossy frames: through JPEG 95 right answers reach 2.75
# and 19053 4.27, through H.264 CRF 20 right answers 4.47 (13013) against
# 19053's 3.35.  The margin is thin: a factor 1.2 either side, set on the
# one case it must catch (19053); the held-out right answers stay 1.7 x
# under it.  It matters for single raw frames given to calibrate_frame or
# detect_corners: on the command's mean of 32 raw frames (reference_frame)
# the largest right answers read 0 (13007 3.34 -> 0.00, 19014 2.86 ->
# 0.00; the renderer's realistic table, 3 cameras, 0.00 either way) while
# 19053 reads 11.6 and is refused by HIDDEN_NOSE_Z already (9.7 x; the
# reviewer's rawmean2.py/realmean.py, fixvis).
SECOND_SIDE_Z = 4.1


def cushion_noses(img: np.ndarray, sides: list, search_frac: float = 0.08, reach_px: float = 4.0,
                  outer: list | None = None, hidden: list | None = None, coherent: list | None = None):
    """The cushions' noses inside the felt-coloured outline, when they show.

    A table's cushions are often cloth of the felt's colour, so the outline
    found first can be the cushions' outer edge, a cushion's width beyond the
    playing surface.  Each side is searched inward (up to ``search_frac`` of
    the outline's smaller size) for a step in brightness parallel to it, the
    nose's line (a darker cushion face or top); found on all four sides, at a
    consistent distance, it is located sub-pixel like the outline.

    Returns
    -------
    list of 4 ndarrays or None
        Edge points of the noses, or None when no such line shows.

    ``outer``, when given, gets one bool a side: whether another step of
    the same size rule lies within the sub-pixel window of the one taken
    (``reach_px`` + 3 px) or ``BAND_PULL_PX`` beyond it: a band narrower
    than that (a shadow inside the nose), whose two edges the halfway
    crossing cannot tell apart; or anywhere outside it (the step taken,
    the largest, is then a band's inner edge, not the nose).

    ``hidden``, when given, gets four floats a side: the largest step
    between the nose taken and the outline's own edge (from 6 px out, past
    the nose step's own window, to 7 px inside the outline, where the
    outline edge's blur ends) too small for the step rule, in units of the
    flat felt's step scatter (the rule's ``noise``), and in units of the
    largest step at the same offsets on the felt's side of the nose (a
    codec's ringing beside the nose edge shows on both sides): a band
    inside the noses in nearly the cushions' shade, whose inner edge was
    taken for them (``_hidden_z``); these two 0 with no room between or a
    step the rule sees there (a band's edge in sight: the paths'
    cross-check's).  Then that largest step on the felt's side (grey
    levels) and the felt's flat share (:func:`_flat_share`;
    ``_codec_flattened``).

    ``coherent``, when given, gets one tuple a side for :func:`_coherent_z`:
    the signed step profile in units of the flat felt's step scatter (the
    nose's step positive), the nose's index, the outline's end of the
    profile and the faint-step zone's inner end; None for a side whose
    zone holds a step the rule sees.
    """
    Ds = _smoothed(img)
    grey = Ds.mean(axis=2) if Ds.ndim == 3 else Ds
    out = []
    for base, nrm, offs, P in _inward_samples(sides, search_frac):
        prof = cv2.remap(grey.astype(np.float32), P[..., 0].astype(np.float32),
                         P[..., 1].astype(np.float32), cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        # The side's median profile (felt texture and noise averaged away along
        # the side); the step: the largest difference of the means over 3 px
        # either side, away from the outline's own edge (its last 5 px).
        med_prof = np.median(prof, axis=0)
        w = 6
        cs = np.concatenate([[0.0], np.cumsum(med_prof)])
        g = np.zeros_like(med_prof)
        g[w:-w] = np.abs((cs[2 * w + 1:] - cs[w + 1:-w]) - (cs[w:-w - 1] - cs[:-2 * w - 1])) / w
        g[-10:] = 0.0
        k = int(np.argmax(g))
        inner = g[w: max(len(offs) // 3, w + 4)]
        noise = np.median(inner) + 1.4826 * np.median(np.abs(inner - np.median(inner))) + 1e-3
        # a cushion's face or top: a step of at least 3 grey levels, 8x the flat felt's
        step_min = max(STEP_MIN_LEVELS, STEP_MIN_NOISE * noise)
        # the faint-step zone's inner end: 7 px inside the outline, where its edge's blur ends
        end = len(g) - 14
        if not (g[k] > step_min):
            return None
        if outer is not None:
            peak = (g >= np.roll(g, 1)) & (g >= np.roll(g, -1)) & (g > step_min)
            near = np.abs(np.arange(len(g)) - k)
            # or anywhere out to the outline's edge: the outermost step is the nose (the lines' rule), and
            # one outside this says a band's inner edge was taken (random table 14018: 9.4 px off)
            out_ = (np.arange(len(g)) >= k + 2 * w) & (np.arange(len(g)) < end)   # as ``hidden``'s zone
            outer.append(bool((peak & (near > w) & ((near <= 2 * (reach_px + 3.0 + BAND_PULL_PX)) | out_)).any()))
        if hidden is not None:
            zone = g[k + 2 * w: end]
            top = float(zone.max()) if len(zone) else 0.0
            # the same offsets mirrored to the felt's side of the nose, where g is defined
            mirror = 2 * k - np.arange(k + 2 * w, end)
            mirror = g[mirror[mirror >= w]]
            ring = float(mirror.max()) if len(mirror) else 0.0
            scale = max(noise, HIDDEN_NOISE_FLOOR)
            # the felt's own pixels beside their neighbours (unsmoothed), inside the nose: a codec's flat blocks
            flat = _flat_share(img, _felt_part(offs, P))
            # a step the rule sees there is a band's edge in sight (the paths' cross-check), not a hidden one
            hidden.append((top / scale, top / max(ring, scale), ring, flat) if top <= step_min
                          else (0.0, 0.0, ring, flat))
        if coherent is not None:
            zone = g[k + 2 * w: end]
            signed = np.zeros_like(med_prof)
            signed[w:-w] = ((cs[2 * w + 1:] - cs[w + 1:-w]) - (cs[w:-w - 1] - cs[:-2 * w - 1])) / w
            ok = len(zone) and zone.max() <= step_min
            coherent.append((signed * np.sign(signed[k]) / max(noise, HIDDEN_NOISE_FLOOR), k, len(g) - 5, end)
                            if ok else None)
        med = float(offs[k])
        nose = _subpixel_edge(Ds, base + med * nrm, nrm, np.arange(-reach_px - 3.0, reach_px + 3.0 + 1e-9, 0.25))
        if len(nose) < max(10, 0.3 * len(base)):
            return None
        out.append(nose)
    return out


def _inward_samples(sides: list, search_frac: float = 0.08):
    """The sample points :func:`cushion_noses` reads inside each side of an
    outline (edge points ``sides``): per side, the points it starts from
    (every second), the outward normal, the offsets along it (px, up to
    ``search_frac`` of the outline's smaller size inward, every 0.5 px) and
    the points (base x offsets x 2)."""
    lines = [_fit_line(p)[:2] for p in sides]
    corners = np.array([_line_intersection(lines[i - 1], lines[i]) for i in range(4)])
    size = min(np.linalg.norm(corners[2] - corners[0]), np.linalg.norm(corners[3] - corners[1])) / math.sqrt(2)
    depth = max(search_frac * size, 12.0)
    for i, pts in enumerate(sides):
        a, b = corners[i], corners[(i + 1) % 4]
        d = (b - a) / np.linalg.norm(b - a)
        nrm = np.array([-d[1], d[0]])                       # outward
        base = pts[::2]
        offs = np.arange(-depth, 0.0, 0.5)                  # inside the outline
        yield base, nrm, offs, base[:, None, :] + offs[None, :, None] * nrm


def _felt_part(offs, P) -> np.ndarray:
    """Of one side's inward sample points ``P`` at offsets ``offs``
    (:func:`_inward_samples`), those on the felt: the deepest third of the
    search (at least two offsets), where :func:`cushion_noses` reads the
    felt's flat share."""
    return P[:, : max(len(offs) // 3, 2)]


def _felt_flat_shares(img: np.ndarray, sides: list, other: np.ndarray | None = None) -> list:
    """The felt's flat share (:func:`_flat_share`; with ``other``, its share
    equal to the same pixel there) on each side of an outline, where
    :func:`cushion_noses` reads it (:func:`_felt_part`): for a frame whose
    own noses need not show (a single codec frame), and for
    :func:`_video_lossy`'s two still frames."""
    return [_flat_share(img, _felt_part(offs, P), other) for _, _, offs, P in _inward_samples(sides)]


def _flat_share(img: np.ndarray, P: np.ndarray, other: np.ndarray | None = None) -> float:
    """The share of the pixels at sample points ``P`` (px, any shape x 2) equal
    in every channel to their right-hand neighbour: near 1 where a lossy codec
    flattened the cloth into constant blocks, low on noisy raw frames.  With
    ``other`` (an image of the same size): equal to the same pixel there
    instead."""
    im = np.asarray(img)
    if im.ndim == 2:
        im = im[:, :, None]
    h, w = im.shape[:2]
    q = np.rint(P.reshape(-1, 2)).astype(int)
    q = q[(q[:, 0] >= 0) & (q[:, 0] < w - 1) & (q[:, 1] >= 0) & (q[:, 1] < h)]
    if len(q) == 0:
        return 0.0
    if other is None:
        return float(np.all(im[q[:, 1], q[:, 0]] == im[q[:, 1], q[:, 0] + 1], axis=-1).mean())
    ot = np.asarray(other).reshape(im.shape)
    return float(np.all(im[q[:, 1], q[:, 0]] == ot[q[:, 1], q[:, 0]], axis=-1).mean())


def edge_points(img: np.ndarray, quad: np.ndarray, contour: np.ndarray,
                reach_px: float = 4.0, step_px: float = 2.0) -> list:
    """Sub-pixel points of the felt's edge along each side of a rough quadrilateral.

    The felt region's contour (whole pixels) is followed, so a side bowed by
    the lens is followed too; at every ``step_px`` along it the edge is
    located along the side's normal, where the (lightly smoothed) colour
    crosses halfway from the felt's to the surround's, measured along the
    line between the two colours in the frame's own (linear) values: a pixel
    half covered by felt sits exactly there, which a perceptual distance
    (Lab) would not give.

    Returns
    -------
    list of 4 ndarrays, shape (m_i, 2)
        Edge points (px, the image's own distorted pixels), side i running from
        ``quad[i]`` to ``quad[i+1]``.
    """
    Ds = _smoothed(img)
    offs = np.arange(-reach_px - 3.0, reach_px + 3.0 + 1e-9, 0.25)
    sides = []
    for i, pts in enumerate(_side_points(quad, contour)):
        a, b = quad[i], quad[(i + 1) % 4]
        d = (b - a) / np.linalg.norm(b - a)
        nrm = np.array([-d[1], d[0]])       # outward for a counter-clockwise (on screen) quad
        base = pts[:: max(int(step_px), 1)]
        edge = _subpixel_edge(Ds, base, nrm, offs)
        if len(edge) < 10:
            raise CalibrationError("the felt's edge could not be located along a side; give --corners")
        sides.append(edge)
    return sides


def _robust_keep(r: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """The points whose residuals ``r`` lie within 6 robust standard deviations
    (1.4826 MAD of the ``keep`` ones; 0.05 px at least): the trimming rule of
    :func:`_fit_line` and :func:`_curve_rms`."""
    mad = np.median(np.abs(r[keep])) + 1e-3
    return np.abs(r) < max(6.0 * 1.4826 * mad, 0.05)


def _fit_line(pts):
    """Total-least-squares line, far points (a pocket, a ball on the edge) dropped:
    ``(centre, unit direction, residuals of the kept points)``."""
    keep = np.ones(len(pts), bool)
    for _ in range(3):
        c = pts[keep].mean(axis=0)
        evals, evecs = np.linalg.eigh((pts[keep] - c).T @ (pts[keep] - c))
        dirn = evecs[:, 1]
        dist = (pts - c) @ np.array([-dirn[1], dirn[0]])
        keep = _robust_keep(dist, keep)
    return c, dirn, dist[keep]


def _undistort_radial(uv, centre, kappa):
    """Undo a radial distortion given in pixels: ``u_d = c + (u - c)(1 + kappa |u - c|^2)``
    (OpenCV's k1 = kappa f^2 for a focal length f), by Newton's method."""
    if kappa == 0.0:
        return uv
    d = uv - centre
    rd = np.linalg.norm(d, axis=1)
    r = rd.copy()
    for _ in range(30):
        step = (r * (1.0 + kappa * r * r) - rd) / (1.0 + 3.0 * kappa * r * r)
        r -= step
        if np.all(np.abs(step) < 1e-12):
            break
    scale = np.where(rd > 0, r / np.where(rd > 0, rd, 1.0), 1.0)
    return centre + d * scale[:, None]


def fit_sides(sides, K=None, dist=None, kappa: float = 0.0, centre=None):
    """Corners from four sides' edge points: the points undistorted (by the
    known lens, or by ``kappa`` about ``centre``), a line per side, adjacent
    lines intersected, the corners distorted back.

    Returns
    -------
    corners : ndarray, shape (4, 2)
        Image (distorted) pixels; corner i is where side i-1 meets side i.
    edge_rms : float
        RMS distance of the kept edge points from their lines (px).
    """
    return _corners_of([_fit_line(p) for p in _straightened(sides, K, dist, kappa, centre)], K, dist, kappa, centre)


def _straightened(sides, K, dist, kappa, centre) -> list:
    """Each side's edge points undistorted (the known lens, or ``kappa`` about ``centre``)."""
    if K is not None:
        return [_undistort_px(p, K, dist) for p in sides]
    return [_undistort_radial(p, centre, kappa) for p in sides] if kappa else list(sides)


def _corners_of(fits, K, dist, kappa, centre):
    """:func:`fit_sides`' corners and edge RMS from the four sides' :func:`_fit_line` fits."""
    lines = [(c, d) for c, d, _ in fits]
    corners = np.array([_line_intersection(lines[i - 1], lines[i]) for i in range(4)])
    if K is not None:
        corners = _distort_px(corners, K, dist)
    elif kappa:
        dd = corners - centre
        corners = centre + dd * (1.0 + kappa * np.sum(dd * dd, axis=1))[:, None]
    allres = np.concatenate([r for _, _, r in fits])
    return corners, float(np.sqrt(np.mean(allres**2)))


def radial_sigma(sides, centre, kappa: float, size) -> float:
    """Standard error of ``kappa`` (px^-2) from the edges' own fit: the curvature
    of the edge points' sum of squared distances from their lines about the
    best ``kappa``, each point's error taken as their RMS there
    (``se = sqrt(2 / chi2'')``, chi2 = SSR / rms^2)."""
    n = sum(len(s) for s in sides)
    h = 0.002 / (0.5 * float(max(size))) ** 2      # 0.002 in k1 for f of half the frame

    def ssr(k):
        return n * fit_sides(sides, kappa=k, centre=centre)[1] ** 2
    s0 = ssr(kappa)
    curv = (ssr(kappa + h) - 2.0 * s0 + ssr(kappa - h)) / (h * h) / (s0 / n)
    return float(math.sqrt(2.0 / curv)) if curv > 0 else 0.0


# Edge points further than this many robust standard deviations (1.4826 x the
# median absolute residual) from their side's line are strays (a ball or the
# cue near the cushion, a pocket's jaw): measured on the drawn tables' 24
# frames, the clean sides' points reach 2.4-3.8 (as many Gaussian draws
# would), the strays 4-200.  _fit_line's own cut (6) keeps those between 4 and
# 6, and a jackknife run that leaves a group of them out moves a line by
# several times its error (the corners' stated error up to 5x the real one).
STRAY_EDGE_Z = 4.0


def drop_strays(sides, K=None, dist=None, kappa: float = 0.0, centre=None, z: float = STRAY_EDGE_Z) -> list:
    """Each side's edge points without those further than ``z`` robust standard
    deviations from its line (``STRAY_EDGE_Z``), so that every fit after (the
    bow, the corners, their jackknife) sees the same points."""
    out = []
    for p, q in zip(sides, _straightened(sides, K, dist, kappa, centre)):
        c, d, _ = _fit_line(q)
        r = (q - c) @ np.array([-d[1], d[0]])
        scale = max(1.4826 * float(np.median(np.abs(r))), 0.01)
        keep = np.abs(r) <= z * scale
        out.append(p[keep] if keep.sum() >= 2 * JACKKNIFE_GROUPS else p)
    return out


# The groups of consecutive edge points per side the corners' jackknife leaves
# out in turn: long enough (about 1/16 of a side, 30-60 points) that the
# texture's and the drawing's correlation along a side (a few px) stays
# inside a group; enough of them that the variance has some 60 degrees of
# freedom over the four sides.
JACKKNIFE_GROUPS = 16


def corner_covariance(sides, K=None, dist=None, kappa: float = 0.0, centre=None, size=None,
                      groups: int = JACKKNIFE_GROUPS) -> np.ndarray:
    """Covariance of the corners :func:`fit_sides` gives and of the lens's bow,
    by a delete-a-group jackknife along each side.

    Neighbouring edge points are not independent (the felt's texture, the
    frame's smoothing, a drawing's sub-pixel staircase), so the scatter about
    the lines over the number of points understates how well a line is placed
    (2-3 times on drawn tables, measured).  Each side's points, in order along
    it, are cut into ``groups`` runs; everything is refitted without each run
    in turn, and ``(g - 1) / g`` times the sum of the squared changes is that
    side's share (the sides' errors are independent).  With ``size`` (the lens's
    bow estimated from these edges, :func:`radial_from_edges`), ``kappa`` is
    re-estimated too (one Newton step on the edges' sum of squares), and the
    corners with it, so the bow's error and its pull on the corners are in the
    covariance; otherwise the lens is held fixed.

    Returns
    -------
    ndarray, shape (9, 9)
        Covariance of ``(corners.ravel(), kappa)`` (px^2; px^-2 for kappa; its
        row and column 0 when the lens is not estimated).
    """
    h = 0.0 if size is None else 0.002 / (0.5 * float(max(size))) ** 2    # as radial_sigma's step
    kappas = (kappa - h, kappa, kappa + h) if h else (kappa,)
    # the points straightened once per kappa; a trial refits only the side it thins
    straight = [_straightened(sides, K, dist, k, centre) for k in kappas]
    fits = [[_fit_line(p) for p in st] for st in straight]

    def fit(i, keep):
        out = []
        for k, st, ft in zip(kappas, straight, fits):
            trial = list(ft)
            trial[i] = _fit_line(st[i][keep])
            out.append(_corners_of(trial, K, dist, k, centre))
        if not h:
            return np.append(out[0][0].ravel(), kappa)
        (cm, em), (c0, e0), (cp, ep) = out
        sm, s0, sp = em**2, e0**2, ep**2
        curv = sp - 2.0 * s0 + sm
        # the edges' mean square's minimum without this run (one Newton step), kept within the steps taken
        x = float(np.clip(-0.5 * (sp - sm) / curv, -1.0, 1.0)) if curv > 0 else 0.0
        c = c0 + 0.5 * x * (cp - cm) + 0.5 * x * x * (cp - 2.0 * c0 + cm)    # corners there (quadratic)
        return np.append(c.ravel(), kappa + x * h)

    cov = np.zeros((9, 9))
    for i, pts in enumerate(sides):
        cut = np.array_split(np.arange(len(pts)), groups)
        d = []
        for run in cut:
            keep = np.ones(len(pts), bool)
            keep[run] = False
            d.append(fit(i, keep))
        d = np.array(d) - np.mean(d, axis=0)
        cov += (len(cut) - 1) / len(cut) * d.T @ d
    return cov


def covariance_moves(cov: np.ndarray) -> np.ndarray:
    """Moves whose outer products sum to ``cov``: rows ``l_k`` with
    ``sum_k l_k l_k^T = cov``, from the eigenvectors of the correlation matrix
    (the corners in px and kappa in px^-2 differ by some 1e8 in scale);
    directions with no variance dropped.  Moving a calibration along each
    in turn carries ``cov`` into anything computed through the camera."""
    cov = np.asarray(cov, dtype=float)
    d = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    on = d > 0
    out = np.zeros((0, len(d)))
    if not on.any():
        return out
    corr = cov[np.ix_(on, on)] / np.outer(d[on], d[on])
    evals, evecs = np.linalg.eigh(corr)
    keep = evals > 1e-9 * evals.max()
    rows = (d[on][:, None] * evecs[:, keep] * np.sqrt(evals[keep])).T
    out = np.zeros((len(rows), len(d)))
    out[:, on] = rows
    return out


def radial_from_edges(sides, centre, size) -> float:
    """The radial distortion (``kappa``, px^-2) that makes the felt's four sides
    straightest: a phone's wide lens bows them by several pixels; one
    coefficient about the frame's centre (OpenCV's k1, without k2) is what
    four lines can fix."""
    big = float(max(size))
    scale = (0.5 * big) ** 2   # kappa in units of k1 for a focal length of half the frame

    def cost(k):
        return fit_sides(sides, kappa=k / scale, centre=centre)[1]
    return _golden(cost, -0.6, 0.6, 1e-6) / scale


def _golden(fun, lo: float, hi: float, tol: float) -> float:
    """Minimum of a unimodal function on [lo, hi] by golden-section search."""
    g = (math.sqrt(5.0) - 1.0) / 2.0
    a, b = hi - g * (hi - lo), lo + g * (hi - lo)
    fa, fb = fun(a), fun(b)
    while hi - lo > tol:
        if fa < fb:
            hi, b, fb = b, a, fa
            a = hi - g * (hi - lo)
            fa = fun(a)
        else:
            lo, a, fa = a, b, fb
            b = lo + g * (hi - lo)
            fb = fun(b)
    return (lo + hi) / 2.0


# --------------------------------------------------------------------------- cushion lines (a pocketed table)
# When the felt-coloured outline's sides are not smooth curves (the pockets
# cut the cushions, markers or the rail's diamonds bite into the outline, a
# shadow band along the noses splits the felt's region: a real table,
# auto15's clips), the cushions' lines are found instead
# (:func:`cushion_lines`).  Threshold: the largest side's RMS about its
# robust quadratic (:func:`_curve_rms`), measured (corners16): 0.07-1.01 px
# on the drawn tables (8 cameras, 1.5-3 m, tilt 0-15 deg, k1 -0.25..+0.25,
# with and without cushions and pockets), 0.57-1.12 px on the renderer's
# realistic table through the same cameras, 13.9 and 26.7 px on the real
# clips; 4 px is about their geometric middle (3.6x the renders' largest,
# 3.5x under the real ones).  Both paths find the renders' corners (the
# lines 0.12-0.67 px RMS, the outline 0.14-0.69), so a render past it
# loses little; the real clips' outline is no table at all.
OUTLINE_STRAIGHT_PX = 4.0

# The reference line along a side from the felt region's contour: a
# quadratic (a lens's bow) fitted by RANSAC, inliers within this distance
# (px: the contour is whole pixels, so +-1 px, and a bow's cubic remainder).
CONTOUR_INLIER_PX = 1.5

# The least share of a side's contour points that must lie on one curve for
# it to be a side at all (the real clips' sides keep 29-87%: the felt's
# region there is split by a shadow band along two of the cushions; a
# frame's edge cutting the table leaves less); the step's own points
# (the same share, along the nose) are the stricter check.
CONTOUR_MIN_SHARE = 0.2

# A corner pocket's jaws reach this share of the table's shorter side along
# each side from the corner (the renderer's corner pocket, radius 0.062 m
# centred 0.031 m out on the diagonal: 0.07 m of 1.27 m, 5.5%; the real
# clips' about 30 of 560 px, 5.4%).
CORNER_GAP_FRAC = 0.1

# How far either side of the reference curve the cushion's profile is read,
# as a share of the table's shorter side in the image (a cushion is about 4%
# of a table's width: the renderer's 0.05 of 1.27 m, the real clips' 22 of
# 560 px; the reference may be the cushion's outer edge or a shadow's inner
# edge, a cushion's width apart).
CUSHION_SEARCH_FRAC = 0.1

# A step in the side's median profile counts when it is at least this many
# grey levels and this many times the flat cloth's robust scatter
# (cushion_noses' rule: 3 levels, 8x).
STEP_MIN_LEVELS = 3.0
STEP_MIN_NOISE = 8.0


# The felt's hue tells the cushion's top from the rail when the two differ
# by at least this much in Lab's (a, b) across a side (the real clips' red
# rail: 60-90; a grey felt by a black rail: a few), else the whole colour's
# distance is used.
CHROMA_MIN_CONTRAST = 20.0


def _felt_chroma(img: np.ndarray) -> np.ndarray:
    """Per-pixel distance in Lab's (a, b) from the felt's (the frame's middle)."""
    im = np.clip(np.asarray(img, dtype=np.float32), 0, 255).astype(np.uint8)
    if im.ndim == 2 or im.shape[2] == 1:
        return np.zeros(im.shape[:2], np.float32)
    ab = cv2.cvtColor(im, cv2.COLOR_BGR2Lab).astype(np.float32)[..., 1:]
    h, w = ab.shape[:2]
    felt = np.median(ab[int(0.35 * h):int(0.65 * h), int(0.35 * w):int(0.65 * w)].reshape(-1, 2), axis=0)
    return np.linalg.norm(ab - felt, axis=2).astype(np.float32)


def _curve_rms(pts: np.ndarray) -> float:
    """RMS (px) of a side's edge points about a quadratic along it (a lens's bow
    is a smooth curve: a k1 -0.25 lens bows a drawn table's sides by 4-8 px RMS
    about a line, under 0.1 px about a quadratic), the points over 6 robust
    standard deviations off dropped as :func:`_fit_line` drops them."""
    c = pts.mean(axis=0)
    _, evecs = np.linalg.eigh((pts - c).T @ (pts - c))
    d = evecs[:, 1]
    t_, o = (pts - c) @ d, (pts - c) @ np.array([-d[1], d[0]])
    keep = np.ones(len(pts), bool)
    for _ in range(3):
        r = o - np.polyval(np.polyfit(t_[keep], o[keep], 2), t_)
        keep = _robust_keep(r, keep)
    return float(np.sqrt(np.mean(r[keep] ** 2)))


def _side_points(quad: np.ndarray, contour: np.ndarray, lo: float = 0.06, hi: float = 0.94) -> list:
    """The contour's points nearest each side of ``quad`` (and within ``lo``-``hi``
    of its length): a list of 4 arrays of points in order along the side."""
    dists, along = [], []
    for i in range(4):
        a, b = quad[i], quad[(i + 1) % 4]
        L = float(np.linalg.norm(b - a))
        d = (b - a) / L
        rel = contour - a
        t = rel @ d
        dists.append(np.abs(rel @ np.array([-d[1], d[0]])) + np.where((t < 0) | (t > L), 1e9, 0.0))
        along.append(t / L)
    side_of = np.argmin(np.array(dists), axis=0)
    out = []
    for i in range(4):
        sel = (side_of == i) & (along[i] > lo) & (along[i] < hi)
        out.append(contour[sel][np.argsort(along[i][sel])])
    return out


def _ransac_curve(t: np.ndarray, o: np.ndarray, tol: float, rng, trials: int = 300):
    """A quadratic ``o(t)`` through most of the points (RANSAC, then least
    squares on the inliers twice): ``(coefficients, inlier share)``."""
    n = len(t)
    if n < 10:
        return None, 0.0
    idx = np.sort(np.array([rng.choice(n, 3, replace=False) for _ in range(trials)]), axis=1)
    ts, os_ = t[idx], o[idx]
    ok = np.ptp(ts, axis=1) >= 0.2
    ok &= np.min(np.diff(ts, axis=1), axis=1) > 1e-9
    if not ok.any():
        return None, 0.0
    ts, os_ = ts[ok], os_[ok]
    V = np.stack([ts * ts, ts, np.ones_like(ts)], axis=-1)                 # (m, 3, 3) Vandermonde
    coef = np.linalg.solve(V, os_[..., None])[..., 0]                    # (m, 3): a t^2 + b t + c
    res = np.abs(coef[:, :1] * t * t + coef[:, 1:2] * t + coef[:, 2:] - o)
    best = coef[int(np.argmax(np.sum(res < tol, axis=1)))]
    for _ in range(2):
        inl = np.abs(np.polyval(best, t) - o) < tol
        best = np.polyfit(t[inl], o[inl], 2)
    return best, float(np.mean(np.abs(np.polyval(best, t) - o) < tol))


def cushion_lines(img: np.ndarray, quad: np.ndarray, contour: np.ndarray, D: np.ndarray, thr: float,
                  noses: bool = True, reach_px: float = 1.0, inside: list | None = None):
    """Edge points of the cushions' noses on a pocketed table, where the felt's
    outline is broken (``OUTLINE_STRAIGHT_PX``).

    Along each side of the rough quadrilateral the felt region's contour gives
    a reference curve (:func:`_ransac_curve`: the points in the pockets' gaps
    and on markers left out).  The side's median profile across it (grey, and
    the colour's distance from the felt), over ``CUSHION_SEARCH_FRAC`` of the
    table's shorter side either way, is read in order from the outside in:
    the felt-coloured band's outer edge (the cushion's, where the rail
    begins), then the first step in brightness inside it (``STEP_MIN_LEVELS``,
    ``STEP_MIN_NOISE``) is the nose: the cushion's top ends there, whatever
    lies inside it (the renderer's cloth; on a lit table the nose's face and
    its shadow on the cloth, a darker band 6-11 px wide on the real clips,
    whose inner edge moves with the lamps).  No such step: the felt band's
    outer edge itself (``edge`` ``"felt"``).  Each point of the side is then
    located sub-pixel there (:func:`_subpixel_edge`, within ``reach_px`` +
    3 px, narrower than a shadow band), the points more than 2 px off the
    side's nose line dropped (the pockets' jaws, the balls).  ``noses``
    False: the felt band's outer edge on every side.

    ``inside``, when given, gets one float a side: how far (px) inside the
    nose the next step of the same size rule lies (a shadow band's inner
    edge; ``inf`` with none, or on the felt band's outer edge): one nearer
    than the sub-pixel window's reach pulls the nose's crossing too
    (``LINES_CROWDED_PX``).

    Returns
    -------
    sides : list of 4 ndarrays
        Edge points (px), as :func:`edge_points`.
    edge : str
        ``noses`` or ``felt``.

    Raises
    ------
    CalibrationError
        A side with no line along its contour or no edge across it (the
        reason says which).
    """
    Ds = _smoothed(img)
    grey = (Ds.mean(axis=2) if Ds.ndim == 3 else Ds).astype(np.float32)
    Dm = cv2.GaussianBlur(D.astype(np.float32), (0, 0), 1.0)
    Dc = _felt_chroma(Ds)
    names = ("first", "second", "third", "fourth")
    shorter = min(np.linalg.norm(quad[1] - quad[0]), np.linalg.norm(quad[2] - quad[1]),
                  np.linalg.norm(quad[3] - quad[2]), np.linalg.norm(quad[0] - quad[3]))
    reach = max(CUSHION_SEARCH_FRAC * shorter, 15.0)
    offs = np.arange(-reach, reach + 1e-9, 0.5)
    w = 6                               # 3 px a side of a step, as cushion_noses
    rng = np.random.default_rng(0)
    sides, kinds = [], []
    for i, pts in enumerate(_side_points(quad, contour)):
        a, b = quad[i], quad[(i + 1) % 4]
        L = float(np.linalg.norm(b - a))
        d = (b - a) / L
        nrm = np.array([-d[1], d[0]])                        # outward
        coef, share = _ransac_curve((pts - a) @ d / L, (pts - a) @ nrm, CONTOUR_INLIER_PX, rng)
        if coef is None or share < CONTOUR_MIN_SHARE:
            raise CalibrationError(f"the {names[i]} side of the felt is not a line ({100 * share:.0f}% of its "
                                   f"edge on one, under {100 * CONTOUR_MIN_SHARE:.0f}%): the table is cut by the "
                                   "frame or hidden; give --corners")
        ts = np.arange(0.1, 0.9, 1.0 / L)
        base = a + (ts * L)[:, None] * d + np.polyval(coef, ts)[:, None] * nrm
        # the curve's own normal (a bowed side turns by a few tenths of a degree)
        slope = np.polyval(np.polyder(coef), ts) / L
        tang = d[None, :] + slope[:, None] * nrm[None, :]
        tang /= np.linalg.norm(tang, axis=1, keepdims=True)
        nrms = np.column_stack([-tang[:, 1], tang[:, 0]])
        P = base[:, None, :] + offs[None, :, None] * nrms[:, None, :]
        px, py = P[..., 0].astype(np.float32), P[..., 1].astype(np.float32)
        g_prof = np.median(cv2.remap(grey, px, py, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE), axis=0)
        d_prof = np.median(cv2.remap(Dm, px, py, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE), axis=0)
        c_prof = np.median(cv2.remap(Dc, px, py, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE), axis=0)
        # the cushion's outer edge: where the colour's hue leaves the felt's (the cushion's top and a
        # shadow on it are the cloth's hue, a rail is not), else its distance from the felt
        prof = c_prof if np.ptp(c_prof) >= CHROMA_MIN_CONTRAST else d_prof
        inner = float(np.median(prof[: len(offs) // 4]))
        out = np.nonzero(prof >= 0.5 * (inner + prof.max()))[0]
        out = out[out > len(offs) // 4]
        if len(out) == 0 or out[0] < 2 * w:
            raise CalibrationError(f"no felt's edge across the {names[i]} side; give --corners")
        k_out = int(out[0]) - 1                                # the first step out of the felt's hue
        cs = np.concatenate([[0.0], np.cumsum(g_prof)])
        g = np.zeros_like(g_prof)
        g[w:-w] = ((cs[2 * w + 1:] - cs[w + 1:-w]) - (cs[w:-w - 1] - cs[:-2 * w - 1])) / w
        flat = np.abs(g[w: max(len(offs) // 4, w + 4)])       # the cloth, well inside
        noise = float(np.median(flat) + 1.4826 * np.median(np.abs(flat - np.median(flat)))) + 1e-3
        ag = np.abs(g)
        peak = (ag >= np.roll(ag, 1)) & (ag >= np.roll(ag, -1)) & (ag > max(STEP_MIN_LEVELS, STEP_MIN_NOISE * noise))
        peak[max(k_out - 2 * w, 0):] = False                   # the felt band's own outer edge
        cand = np.nonzero(peak)[0]
        if len(cand) and noses:
            k, kind = int(cand[-1]), "noses"
            sgn = np.sign(g[k])
            if inside is not None:      # the next step in, beyond the nose's own (g's window, 3 px)
                others = cand[cand < k - w]
                inside.append(float(offs[k] - offs[others[-1]]) if len(others) else math.inf)
        else:
            if inside is not None:
                inside.append(math.inf)
            k, kind = k_out, "felt"
            # the step's sign as g's (outward minus inward, the profile runs from the felt out): the step
            # below takes the largest change of that sign (the reverse took a noise dip or the window's end:
            # review 12a's frame, 1.99 px off the felt's outline stating 0.38)
            sgn = np.sign(np.mean(g_prof[k + 1:k + 2 * w + 1]) - np.mean(g_prof[max(k - 2 * w, 0):k]))
        # each point's own step near the side's (a bowed nose, a reference curve a few px off), smoothed
        # along the side over 9 points; a quadratic through most of them (the pockets' gaps left out)
        win = np.arange(offs[k] - 6.0, offs[k] + 6.0 + 1e-9, 0.5)
        Q = base[:, None, :] + win[None, :, None] * nrms[:, None, :]
        G = cv2.remap(grey, Q[..., 0].astype(np.float32), Q[..., 1].astype(np.float32), cv2.INTER_LINEAR,
                      borderMode=cv2.BORDER_REPLICATE)
        G = cv2.blur(G, (1, 9))
        step = np.zeros_like(G)
        step[:, 2:-2] = sgn * ((G[:, 3:-1] + G[:, 4:]) - (G[:, :-4] + G[:, 1:-3]))
        o_pt = win[np.argmax(step, axis=1)]
        c2, share2 = _ransac_curve(ts, o_pt, CONTOUR_INLIER_PX, rng)
        if c2 is None or share2 < CONTOUR_MIN_SHARE:
            raise CalibrationError(f"the cushion's edge is not a line along the {names[i]} side "
                                   f"({100 * share2:.0f}% of it on one); give --corners")
        at = base + np.polyval(c2, ts)[:, None] * nrms
        edge = _subpixel_edge(Ds, at, nrms.mean(axis=0) / np.linalg.norm(nrms.mean(axis=0)),
                              np.arange(-reach_px - 3.0, reach_px + 3.0 + 1e-9, 0.25))
        if len(edge) >= 10:         # off the side's (bowed) line: a pocket's jaw, a ball
            te, oe = (edge - a) @ d / L, (edge - a) @ nrm
            ce, _ = _ransac_curve(te, oe, 1.0, rng)
            if ce is not None:
                edge = edge[np.abs(np.polyval(ce, te) - oe) < 2.0]
        if len(edge) < max(10, 0.3 * len(base)):
            raise CalibrationError(f"the cushion's edge could not be located along the {names[i]} side "
                                   f"({len(edge)} of {len(base)} points); give --corners")
        sides.append(edge)
        kinds.append(kind)
    # the pockets' jaws bend the noses' ends: points nearer a corner than CORNER_GAP_FRAC of the shorter
    # side left out (the rough quadrilateral's corners, where the cut above began, can be tens of px off)
    lines_ = [_fit_line(p)[:2] for p in sides]
    corners = np.array([_line_intersection(lines_[i - 1], lines_[i]) for i in range(4)])
    gap = CORNER_GAP_FRAC * min(np.linalg.norm(np.roll(corners, -1, axis=0) - corners, axis=1))
    for i in range(4):
        a, b = corners[i], corners[(i + 1) % 4]
        d = (b - a) / np.linalg.norm(b - a)
        t_ = (sides[i] - a) @ d
        keep = (t_ > gap) & (t_ < np.linalg.norm(b - a) - gap)
        if keep.sum() < 10:
            raise CalibrationError(f"the cushion's edge could not be located along the {names[i]} side "
                                   "between its pockets; give --corners")
        sides[i] = sides[i][keep]
    if len(set(kinds)) > 1:
        raise CalibrationError("the cushions' noses show on " + ", ".join(n for n, k in zip(names, kinds) if k == "noses")
                               + " side(s) only: no one outline all round; give --corners")
    return sides, kinds[0]


@dataclass(frozen=True)
class Detection:
    """The table's outline found in a frame.

    Attributes
    ----------
    corners : ndarray, shape (4, 2)
        Sub-pixel corners (px), counter-clockwise on screen, not yet assigned
        to table corners.
    edge_rms : float
        RMS distance of the edge points from the fitted sides (px): how sharp
        and how straight the edge is.
    kappa : float
        Radial distortion about the frame's centre in pixels (``k1 / f^2``)
        estimated from the sides' bow; 0 with a known lens.
    edge : str
        ``noses`` (the cushions' noses: the playing surface itself) or
        ``felt`` (the felt-coloured outline: the playing surface unless the
        cushions are cloth-coloured, see ``--felt-margin``).
    kappa_sigma : float
        Standard error of ``kappa`` from the edges' fit (:func:`radial_sigma`)
        with the drawing's pattern (``KAPPA_PATTERN_K1``); 0 with a known lens.
    corners_kappa : ndarray, shape (4, 2), or None
        The corners fitted with ``kappa + kappa_sigma`` (same order as
        ``corners``): the lens's error carried into the perturbed cameras.
    corner_cov : ndarray, shape (9, 9), or None
        Covariance of ``(corners.ravel(), kappa)`` from the edge points'
        jackknife (:func:`corner_covariance`; kappa's row 0 with a known lens)
        and the edge locator's fixed pattern (``EDGE_PATTERN_PX``,
        ``KAPPA_PATTERN_K1``).
    lines : bool
        The sides are the cushions' lines (:func:`cushion_lines`), not the
        felt outline's.
    """

    corners: np.ndarray
    edge_rms: float
    kappa: float
    edge: str
    kappa_sigma: float = 0.0
    corners_kappa: np.ndarray | None = None
    corner_cov: np.ndarray | None = None
    lines: bool = False


# The edge locator's fixed-pattern error on a corner coordinate (px): what a
# frame's pixel grid puts on the sub-pixel edges the same way in every noise
# draw, which a jackknife along the sides cannot see (it sees the points'
# scatter about a line, not where the line sits).  Measured on the drawn
# tables (synthetic_table_frame, 4x supersampled: edges land on multiples of
# 1/4 px): the corners of noise-free frames 0.007-0.012 px RMS off (0.002-0.004
# at 16x), the mean error over 40 noise seeds 0.007-0.015 px RMS per camera
# against 0.02 px of scatter; with the jackknife alone the errors' Mahalanobis
# distance per coordinate was 1.68 pooled over 8 cameras x noise seeds 0-39
# (the stated covariance too sure along its narrow directions), 0.98 with
# this added (set there); on seeds 100-139 1.52 and 0.89 (the same 8 cameras,
# so the same pattern: not an independent check; on three other cameras
# 0.70-1.00, review 10a).  About 85% of this variance is the drawn frames' 4x
# supersampling (noise-free corners 0.0099 -> 0.0038 px at 16x): a real
# camera's own pattern is unmeasured, and this stays as a floor of the
# corners' error (docs/measurements.md, auto13).
EDGE_PATTERN_PX = 0.012

# The same pattern's error on the lens's bow, as k1 at a focal length of half
# the frame's larger side (kappa = KAPPA_PATTERN_K1 / (max(size) / 2)^2):
# the drawn tables' noise-free frames (4x supersampling, roll 1 deg) put k1
# off by -0.00012 to +0.00026 over the 8 cameras of EDGE_PATTERN_PX (RMS
# 0.00006 in these units; under 0.00006 in k1 on every camera at 16x), and
# each camera's mean error over 40 noise seeds repeats its noise-free
# frame's (2 m overhead, k1 -0.25: +0.00026 noise-free, +0.00030 and
# +0.00026 on seeds 0-39 and 100-139, 2.3-2.4 of its scatter; noise 8
# instead of 3 at 16x: +0.00005 +- 0.00008, so not the noise's).  The value
# comes from the noise-free frames alone; the seeds check it.  It is a
# draw of the geometry: straight overhead it is -0.00007 to +0.00026 at
# rolls of 0.3-3.5 deg (a bowed side's apex runs along a pixel row, where
# the supersampled edge keeps one sub-pixel level for tens of pixels and
# does not average out; the likely reason, not measured apart).  Added
# to the covariance as a joint move of kappa and the corners the edges give
# with it (independent of the jackknife's): k1's z RMS over the
# 8 cameras x 40 seeds 1.17 -> 0.96 (seeds 0-39) and 1.09 -> 0.90 (100-139)
# pooled; straight overhead, k1 -0.25, 1.88 -> 1.44 (its pattern is the
# largest of the 8) (docs/measurements.md, auto14).  It is the drawn
# frames' pattern: a real camera's own (its sensor, demosaicing, lens) is
# unmeasured, and this floor stands in for it; it widens the calibration's
# share of v0 and R w0 by 1.05-1.13 on tilted views (auto14, 12
# calibrations a row), and the 95.5% coverage over 209 calibrations was
# measured without it (review 11b).
KAPPA_PATTERN_K1 = 6e-5


def detect_corners(img: np.ndarray, K=None, dist=None, estimate_lens: bool = True,
                   noses: bool = True, robust: bool = True, pattern_px: float = EDGE_PATTERN_PX,
                   lines: str = "auto",
                   kappa_pattern_k1: float = KAPPA_PATTERN_K1, refuse: bool = True,
                   lossy: bool = False, single: np.ndarray | None = None,
                   single_next: np.ndarray | None = None) -> Detection:
    """The playing surface's four corners in a frame (:class:`Detection`).

    Parameters
    ----------
    img : ndarray
        The frame (BGR or grey).
    K, dist : optional
        A known lens: the edges are straightened with it.
    estimate_lens : bool
        Without ``K``: estimate one radial coefficient from the edges' bow.
    noses : bool
        Look for the cushions' noses inside the felt-coloured outline.
    lines : str
        ``auto``: the cushions' lines (:func:`cushion_lines`) when a side of
        the felt's outline is not a smooth curve (``OUTLINE_STRAIGHT_PX``: a
        pocketed real table) or its edge is not found along a side; else
        both paths, compared: the lines' when the two disagree beyond their
        errors (``PATHS_DISAGREE_Z``) and a second step in or outside the
        outline's noses says the outline took a band's edge, or when the
        outline's felt lies inside the lines' noses; refused when they
        disagree with nothing to say which is wrong, or when a faint step
        outside the outline's noses says a band in the cushions' shade
        hides them (``HIDDEN_NOSE_Z``); a band crowding the lines' noses
        stated as the two's difference (``LINES_CROWDED_PX``); decided in
        :func:`_outline_or_lines`.  ``always`` or ``never``.
    robust : bool
        Drop the edge points ``STRAY_EDGE_Z`` robust standard deviations or
        more from their side's line (:func:`drop_strays`) before the bow,
        the corners and their jackknife.
    pattern_px : float
        The edge locator's fixed-pattern error (px a corner coordinate,
        ``EDGE_PATTERN_PX``), added to the jackknife's covariance on the 8
        corner coordinates as independent errors (0: the jackknife alone).
    kappa_pattern_k1 : float
        The same pattern's error on the bow (``KAPPA_PATTERN_K1``: k1 at a
        focal length of half the frame's larger side), added when the lens
        is estimated to ``kappa_sigma`` and to the covariance, as kappa's
        move with the corners the edges give with it.
    refuse : bool
        Refuse, on whichever path answers, when the outline's noses show a
        faint step outside them, a coherent band or a codec's flat cloth
        (:func:`_outline_or_lines`); False answers what those refusals
        withhold (to measure what they guard against).
    lossy : bool
        The frame came through a lossy codec, whatever its pixels show: the
        raw frames' rules (the coherent band, :func:`_band_z`, and the
        second side's faint step, :func:`_second_side_z`) are off, as on a
        single codec frame, whose flat cloth says so.  A mean of codec frames
        (:func:`reference_frame`) has no equal neighbours left, and the
        codec's ringing, the same in every frame, adds up coherently there
        (random table 18009 through H.264 CRF 18: the first frame answered,
        the mean of 32 refused; mean12).
    single : ndarray, optional
        One frame of the video ``img`` is a mean of (:func:`reference_frame`:
        the still run's first): where a mean hides what the codec did, that
        frame's felt says it.  Its flat share beyond its noise's
        (:func:`_video_lossy`, with ``single_next``; without it, over
        ``RAW_FLAT_SHARE``) makes the frame lossy as ``lossy`` does (a
        phone's H.264 file transcoded to FFV1 or PNG: a lossless container
        of codec frames), and the codec's flat cloth
        (:func:`_codec_flattened`) is read from it (with the mean's ringing
        beside the noses), not from the mean, whose averaged frames have no
        equal neighbours left.
    single_next : ndarray, optional
        The still frame after ``single`` (:func:`reference_frame`): the same
        table again, changed by the sensor's noise alone, which says how
        flat that noise leaves the felt (:func:`_video_lossy`).
    """
    D, thr = _felt_distance(img)
    quad, contour = _felt_quad(D, thr)
    kw = dict(K=K, dist=dist, estimate_lens=estimate_lens, robust=robust, pattern_px=pattern_px,
              kappa_pattern_k1=kappa_pattern_k1)
    outline, straddled, n_straddled, hidden, coherent = None, False, 0, [], []
    on_noses, felt_sides = False, None
    # the outline's noses are looked for on every path: their faint-step and flat-cloth statistics refuse
    # the lines' answer too, which takes the same band's inner edge (random table 14014 at noise 0.5 + JPEG
    # 70: lines="always" 11.6 px off stating 0.047; fixcal, docs/measurements.md)
    try:
        sides = felt_sides = edge_points(img, quad, contour)
        edge = "felt"
        outer = []
        if noses:
            inner = cushion_noses(img, sides, outer=outer, hidden=hidden, coherent=coherent)
            if inner is not None:
                sides, edge, on_noses = inner, "noses", True
        straddled, n_straddled = any(outer), sum(outer)
        if lines == "never" or (lines == "auto" and max(_curve_rms(p) for p in sides) <= OUTLINE_STRAIGHT_PX):
            outline = _detection(sides, edge, D.shape, **kw)
    except CalibrationError:
        if lines == "never":
            raise

    def cushions(inside=None):
        return _detection(*cushion_lines(img, quad, contour, D, thr, noses=noses, inside=inside), D.shape,
                          lines=True, **kw)

    flat_hidden = hidden
    if on_noses and single is not None:
        # the single frame's felt where the mean's was read; the ringing the mean's (the codec's, the same in
        # every frame of a still run: mean12)
        felt_flat = _felt_flat_shares(single, felt_sides)
        flat_hidden = [(z, zr, ring, f) for (z, zr, ring, _), f in zip(hidden, felt_flat)]
        if single_next is not None:     # the video's own noise says how flat a lossless frame's felt is
            lossy = lossy or _video_lossy(single, single_next, felt_sides, flat=felt_flat)
        else:
            lossy = lossy or _frame_lossy(flat_hidden) or _frame_lossy(hidden)
    elif on_noses:
        lossy = lossy or _frame_lossy(hidden)
    return _outline_or_lines(outline, straddled, cushions, lines, hidden_z=_hidden_z(hidden) if on_noses else 0.0,
                             flattened=on_noses and _codec_flattened(flat_hidden),
                             band_z=_band_z(hidden, coherent, lossy) if on_noses else 0.0, refuse=refuse,
                             n_straddled=n_straddled if on_noses else 0,
                             second_z=_second_side_z(hidden, lossy) if on_noses else 0.0)


def _frame_lossy(hidden: list) -> bool:
    """Whether one frame, alone, says a lossy codec touched it: its felt's
    flat share (``cushion_noses``' ``hidden``, median over the sides) over
    ``RAW_FLAT_SHARE``.  Without a second still frame the sensor's noise
    cannot be told from the felt's texture, so a clean lossless frame (noise
    under about 0.5 levels) reads lossy here too (lossy12,
    docs/measurements.md); :func:`_video_lossy` tells them apart."""
    return bool(hidden) and bool(np.median(np.asarray(hidden, dtype=float)[:, 3]) > RAW_FLAT_SHARE)


def _video_lossy(single: np.ndarray, single_next: np.ndarray, sides: list, flat: list | None = None) -> bool:
    """Whether a lossy codec touched a video's frames, from two still frames.

    A lossless camera's quantised noise leaves a felt pixel equal to its
    right-hand neighbour (:func:`_flat_share`) at most about as often as to
    itself in the next still frame (the same table again: only the noise
    changed; texture and shading make neighbours differ more, never less),
    whatever the noise's level.  A codec flattens the cloth in space beyond
    that (``NOISE_FLAT_EXCESS``).  Where the frames are equal nearly
    everywhere (``FROZEN_SHARE``: noise under about 0.18 levels, or a
    codec's frames coded as copies of the first) the noise says nothing, and
    the one frame's flat share decides (:func:`_frame_lossy`).  Otherwise a
    codec that keeps as much of the noise as it flattens (H.264 CRF 21-22)
    is told by its differences' shape (:func:`_noise_tail_excess` over
    ``NOISE_TAIL_EXCESS``).

    Parameters
    ----------
    single, single_next : ndarray
        The still run's first two frames (BGR or grey, as decoded).
    sides : list
        The felt outline's edge points (:func:`_felt_flat_shares`' ``sides``).
    flat : list, optional
        ``_felt_flat_shares(single, sides)`` when the caller has it already;
        None: computed here.

    Returns
    -------
    bool
    """
    flat = float(np.median(_felt_flat_shares(single, sides) if flat is None else flat))
    same = float(np.median(_felt_flat_shares(single, sides, single_next)))
    if same >= FROZEN_SHARE:
        return flat > RAW_FLAT_SHARE
    return flat - same > NOISE_FLAT_EXCESS or _noise_tail_excess(single, single_next, sides) > NOISE_TAIL_EXCESS


def _quantised_noise_law(sigma: np.ndarray) -> np.ndarray:
    """The difference of two frames' quantised noise: for per-frame noise
    ``sigma`` (levels; each frame's N(0, sigma^2) rounded to whole levels
    about a whole-level mean), the probabilities of a difference 0, +-1 and
    of magnitude 2 or more, shape (len(sigma), 3)."""
    from scipy.special import ndtr

    k = np.arange(-60, 61)
    out = []
    for s in np.atleast_1d(sigma):
        p = ndtr((k + 0.5) / s) - ndtr((k - 0.5) / s)
        d = np.convolve(p, p[::-1])
        j = np.abs(np.arange(-120, 121))
        out.append([d[j == 0].sum(), d[j == 1].sum(), d[j >= 2].sum()])
    return np.array(out)


_NOISE_SIGMA = np.geomspace(0.05, 20.0, 400)
_NOISE_LAW: np.ndarray | None = None


def _noise_tail_excess(single: np.ndarray, single_next: np.ndarray, sides: list) -> float:
    """How far two still frames' differences on the felt are from a sensor's
    quantised noise: per channel, the share of differences of magnitude 2 or
    more among the nonzero ones, minus the share :func:`_quantised_noise_law`
    gives at the channel's observed zero share; the largest over the channels
    with at least ``NOISE_TAIL_MIN_NONZERO`` nonzero differences (0.0 if
    none).  Read on the felt pixels :func:`_video_lossy` reads (each once).

    Returns
    -------
    float
        The excess (a share, 0-1); about 0 for a lossless camera's frames.
    """
    global _NOISE_LAW
    if _NOISE_LAW is None:
        _NOISE_LAW = _quantised_noise_law(_NOISE_SIGMA)
    a, b = np.asarray(single), np.asarray(single_next)
    if a.ndim == 2:
        a, b = a[:, :, None], b[:, :, None]
    h, w = a.shape[:2]
    q = np.concatenate([np.rint(_felt_part(offs, P).reshape(-1, 2)).astype(int)
                        for _, _, offs, P in _inward_samples(sides)])
    q = np.unique(q[(q[:, 0] >= 0) & (q[:, 0] < w) & (q[:, 1] >= 0) & (q[:, 1] < h)], axis=0)
    d = np.abs(a[q[:, 1], q[:, 0]].astype(int) - b.reshape(a.shape)[q[:, 1], q[:, 0]].astype(int))
    excess = 0.0
    for c in range(d.shape[1]):
        n0, n2 = int((d[:, c] == 0).sum()), int((d[:, c] >= 2).sum())
        nonzero = len(d) - n0
        if nonzero < NOISE_TAIL_MIN_NONZERO:
            continue
        sigma = np.interp(-n0 / len(d), -_NOISE_LAW[:, 0], _NOISE_SIGMA)      # zero share falls with sigma
        p1, p2 = (np.interp(sigma, _NOISE_SIGMA, _NOISE_LAW[:, i]) for i in (1, 2))
        excess = max(excess, n2 / nonzero - p2 / (p1 + p2))
    return float(excess)


def _band_z(hidden: list, coherent: list, lossy: bool | None = None) -> float:
    """The four sides' faint steps added where a band's outer edge would lie
    (:func:`_coherent_z`), on a frame no lossy codec touched (``lossy``
    False; None: the frame's own flat share says, :func:`_frame_lossy`) and
    at least ``HIDDEN_MIRROR_Z`` times the same sum on the felt's side of
    the nose; else 0.  Compared with ``BAND_COHERENT_Z``."""
    if not hidden or (_frame_lossy(hidden) if lossy is None else lossy):
        return 0.0
    z = _coherent_z(coherent)
    return z if z >= HIDDEN_MIRROR_Z * max(_coherent_z(coherent, mirror=True), 1.0) else 0.0


def _second_side_z(hidden: list, lossy: bool | None = None) -> float:
    """The second-largest side's faint step over the scatter (sides whose step
    is at least ``HIDDEN_MIRROR_Z`` x the felt side's ringing; the others 0),
    on a frame no lossy codec touched (``lossy`` False; None: the frame's own
    flat share says, :func:`_frame_lossy`); else 0.  Compared with
    ``SECOND_SIDE_Z``."""
    if len(hidden) < 2 or (_frame_lossy(hidden) if lossy is None else lossy):
        return 0.0
    h = np.asarray(hidden, dtype=float)
    return float(np.sort(np.where(h[:, 1] >= HIDDEN_MIRROR_Z, h[:, 0], 0.0))[-2])


def _hidden_z(hidden: list) -> float:
    """The faint step's size over the flat felt's scatter, 0 when it is ringing.

    Parameters
    ----------
    hidden : list of tuples
        ``cushion_noses``' ``hidden``, one a side: the faint step over the
        felt's step scatter, over the largest step at the same offsets on
        the felt's side of the nose, that largest step (grey levels) and
        the felt's flat share (:func:`_flat_share`).

    Returns
    -------
    float
        The median over the sides of the first (compared with
        ``HIDDEN_NOSE_Z``), or 0 when the median of the second is under
        ``HIDDEN_MIRROR_Z``: the felt's side of the nose shows steps nearly as
        large, a codec's ringing beside the nose edge rather than a band's.
    """
    if not hidden:
        return 0.0
    over_scatter, over_ringing = np.median(np.asarray(hidden, dtype=float)[:, :2], axis=0)
    return float(over_scatter) if over_ringing >= HIDDEN_MIRROR_Z else 0.0


def _coherent_z(coherent: list, mirror: bool = False) -> float:
    """The four sides' faint steps added at one common place between the noses and the outline.

    A band inside the noses in nearly the cushions' shade has its outer edge
    at the same share of the way from the noses taken (its inner edge) to
    the felt's outline (the cushions' outer edge) on every side, band and
    cushion widths being the same all round, and its step has the same sign
    there; the flat felt's noise does neither.  So the sides' signed steps
    (``cushion_noses``' ``coherent``, in units of each side's scatter) are
    summed at each share r of that way (0-1, steps of 0.005), over the sides
    whose faint-step zone holds it (at least 3), and divided by the root of
    their number: about 1 on noise, about twice a side's own step on a band.

    Parameters
    ----------
    coherent : list
        ``cushion_noses``' ``coherent``.
    mirror : bool
        The same offsets mirrored to the felt's side of the nose (a codec's
        ringing beside the nose edge shows on both sides).

    Returns
    -------
    float
        The largest such sum over r (0 when a side's zone holds a step the
        rule sees, or fewer than 3 sides hold r).
    """
    if len(coherent) != 4 or any(c is None for c in coherent):
        return 0.0
    r = np.linspace(0.0, 1.0, 201)
    tot, cnt = np.zeros_like(r), np.zeros_like(r)
    for prof, k, n, end in coherent:
        span = n - k
        idx = k + r * span
        if mirror:
            idx = 2 * k - idx
            ok = (idx >= 6) & (r * span >= 12)
        else:
            ok = (idx >= k + 12) & (idx <= end)
        tot += np.where(ok, np.interp(idx, np.arange(len(prof)), prof), 0.0)
        cnt += ok
    v = np.abs(tot) / np.sqrt(np.maximum(cnt, 1.0))
    v[cnt < 3] = 0.0
    return float(v.max())


def _codec_flattened(hidden: list) -> bool:
    """Whether a lossy codec flattened the cloth past seeing a band in the
    cushions' shade: the felt's pixels equal to their neighbours on at least
    ``CODEC_FLAT_SHARE`` (median over the sides) while the felt's side of
    the nose rings by ``CODEC_RING_LEVELS`` or more (a noise-free raw frame
    is flat too, but does not ring, and keeps a faint step)."""
    if not hidden:
        return False
    h = np.asarray(hidden, dtype=float)
    return bool(np.median(h[:, 3]) >= CODEC_FLAT_SHARE and np.median(h[:, 2]) >= CODEC_RING_LEVELS)


def _outline_or_lines(outline, straddled: bool, cushions, lines: str = "auto", hidden_z: float = 0.0,
                      flattened: bool = False, band_z: float = 0.0, refuse: bool = True,
                      n_straddled: int = 0, second_z: float = 0.0) -> Detection:
    """Which path's corners :func:`detect_corners` answers: the felt's outline's
    or the cushions' lines' (the one place this is decided).

    Parameters
    ----------
    outline : Detection or None
        The outline's (its noses' when they show); None when its edge is not
        found along a side or a side is not a smooth curve
        (``OUTLINE_STRAIGHT_PX``: a pocketed real table's outline is bitten
        by pockets, markers and shadows).
    straddled : bool
        Another step lies within the outline's noses' sub-pixel window on a
        side, or anywhere outside them (``cushion_noses``' ``outer``: a
        shadow band's other edge, so the step taken may be its inner edge
        or its crossing fall between the two).
    cushions : callable
        ``cushions(inside=None)``: the cushions' lines' :class:`Detection`
        (:func:`cushion_lines`, ``inside`` filled a side), or raises
        :class:`CalibrationError`.
    lines : str
        ``auto``; ``always`` or ``never`` the one path.
    hidden_z : float
        ``_hidden_z`` of ``cushion_noses``' ``hidden`` when the outline's
        noses were found (0 otherwise): a faint step between them and the
        outline's edge.
    flattened : bool
        ``_codec_flattened`` of the same when the outline's noses were
        found: a lossy codec flattened the cloth, so a band in nearly the
        cushions' shade would leave no faint step to see.
    band_z : float
        ``_band_z`` of the same: the four sides' faint steps added where a
        band's outer edge would lie, on an uncompressed frame.
    refuse : bool
        Apply the refusals below (``hidden_z``, ``band_z``, ``second_z``,
        ``flattened``) before any path is answered, on every ``lines``
        mode: the lines take the same band's inner edge.  False: answer
        what they withhold (measurements).
    n_straddled : int
        On how many sides the outline's noses are straddled (``straddled``
        counted a side; 0 when the outline's noses were not found): on
        ``STRADDLED_SIDES_REFUSE`` or more, ``auto`` refuses instead of
        answering the outline when the lines refuse (``refuse``).
    second_z : float
        ``_second_side_z`` of ``hidden``: the second-largest side's faint
        step, on an uncompressed frame (a narrow band seen on two sides).

    Returns
    -------
    Detection
        ``auto``: the lines' when the outline is None.  Else both paths are
        run and compared (the lines refused: the outline's, unless its
        noses are straddled on ``STRADDLED_SIDES_REFUSE`` sides):
        the same edge within ``PATHS_DISAGREE_Z`` combined errors: the
        outline's; beyond it, the lines' when the outline's noses are
        straddled (a band's other edge in sight says which is wrong), else
        refused.  The outline's ``felt`` and the lines' ``noses`` lying
        outside it (the felt region stopped at a dark band inside the
        noses): the lines'; other differing edges: the outline's.  When a
        band lies within ``LINES_CROWDED_PX`` inside the lines' noses, the
        one kept states the two's difference as a further error (the
        corners' covariance plus its outer product).

    Raises
    ------
    CalibrationError
        Any mode (``refuse``), the outline's noses with a faint step outside them
        (``hidden_z`` at least ``HIDDEN_NOSE_Z``, ``band_z`` at least
        ``BAND_COHERENT_Z``, or ``second_z`` at least ``SECOND_SIDE_Z``) or a codec's flat cloth
        that could not show one (``flattened``); ``auto``, the two paths'
        corners disagreeing on the same edge with nothing to say which is
        wrong, or the lines refusing while the outline's noses are
        straddled on every side (``n_straddled``, ``refuse``): the reason
        says so and asks for ``--corners``.
    """
    if refuse and hidden_z >= HIDDEN_NOSE_Z:
        raise CalibrationError(f"a faint step ({hidden_z:.1f} x the cloth's scatter) lies between the noses found "
                               "and the felt's outline: a band inside the cushions in nearly their shade may hide "
                               "the noses, whose inner edge would be taken for them; give --corners")
    if refuse and band_z >= BAND_COHERENT_Z:
        raise CalibrationError(f"faint steps at the same place on all four sides ({band_z:.1f} x the cloth's "
                               "scatter) lie between the noses found and the felt's outline: a band inside the "
                               "cushions in nearly their shade may hide the noses, whose inner edge would be taken "
                               "for them; give --corners")
    if refuse and second_z >= SECOND_SIDE_Z:
        raise CalibrationError(f"a faint step ({second_z:.1f} x the cloth's scatter) lies between the noses found "
                               "and the felt's outline on two sides or more: a narrow band inside the cushions in "
                               "nearly their shade may hide the noses, whose inner edge would be taken for them; "
                               "give --corners")
    if refuse and flattened:
        raise CalibrationError("the video's compression flattened the cloth into constant blocks: a band inside the "
                               "cushions in nearly their shade, whose inner edge would be taken for the noses, could "
                               "not be seen; give --corners (or a less compressed frame)")
    if lines == "never":
        return outline
    if lines == "always" or outline is None:
        return cushions()
    inside = []
    try:
        other = cushions(inside)
    except CalibrationError as err:
        if refuse and n_straddled >= STRADDLED_SIDES_REFUSE:
            raise CalibrationError(f"another step lies beside the noses found on all {n_straddled} sides (a band's "
                                   "other edge: the step taken may be its inner edge) and the cushions' lines, which "
                                   f"would take the outermost, refuse ({err}); give --corners") from err
        return outline
    sig = math.sqrt((np.trace(outline.corner_cov[:8, :8]) + np.trace(other.corner_cov[:8, :8])) / 8.0)
    diff = other.corners - outline.corners
    z = float(np.abs(diff).max() / sig)
    if other.edge != outline.edge:
        # the noses lie inside the felt's outline: the lines' noses outside it say the felt region stopped short
        outside = outline.edge == "felt" and abs(signed_area(other.corners)) > abs(signed_area(outline.corners))
        if not (outside and z > PATHS_DISAGREE_Z):
            return outline
        kept = other
    elif z <= PATHS_DISAGREE_Z:
        kept = outline
    elif outline.edge == "noses" and straddled:
        kept = other
    else:
        raise CalibrationError(f"the felt outline's and the cushions' lines' {outline.edge} disagree by "
                               f"{np.abs(diff).max():.1f} px ({z:.0f} x their stated errors) with nothing to say "
                               "which is wrong (a band inside the cushions in nearly their shade?); give --corners")
    if other.edge == outline.edge and min(inside) <= LINES_CROWDED_PX:     # (a felt's and noses' differ by a cushion)
        g = np.append(diff.ravel(), 0.0)
        kept = replace(kept, corner_cov=kept.corner_cov + np.outer(g, g))
    return kept


# ``auto`` refuses when the cushions' lines refuse and the outline's noses
# are straddled (cushion_noses' ``outer``: another step beside them or
# outside them, a band's other edge in sight) on at least this many sides,
# instead of answering the outline.  Random table 19001 (cushions 0.984 of
# the felt's shade, a band at 0.875 whose inner edge the outline took) was
# answered 10.9 px off stating 0.055 on raw frames (nose16,
# docs/measurements.md).  Measured (strad12) on random drawn tables
# 12000-12039, 13000-13039 and 19000-19059, raw, JPEG 95 and H.264 CRF 20:
# the outline's noses straddled on all four sides on 7, 7 and 9 frames
# (raw, JPEG, H.264), the lines refusing on one (19001 raw, now refused); no
# right answer refused, no other answer changed.  Held out, 20000-20059 raw and JPEG 95: straddled
# all round on 8 frames each, the lines answering right on all; no answer
# changed.  Fewer sides would be a threshold set on nothing: no wrong
# answer in these blocks was straddled on 1-3 sides.
STRADDLED_SIDES_REFUSE = 4

# The outline's noses and the cushions' lines disagree when their largest
# corner difference (px) exceeds this many times the two detections'
# combined stated error (RMS of a coordinate).  Set at 6 (corners16) on 16
# frames: 0.5-2.9 where both are right, 10.8-36.7 with a 15 mm shadow band;
# review 12a found wrong noses kept at z 4.6 on 2 of 7 new cameras.
# Measured since (cushion12, docs/measurements.md) on frames not used to set
# it: 80 random drawn tables (benchmarks/calibration.py --tables, seeds
# 12000-12039 and 13000-13039) both paths right at z 0.29-3.73 (3.73: both
# 0.07-0.09 px off, a 20 mm band), the outline wrong (1.5-9.3 px) at
# 28-225; a 15 mm band through 7 other cameras: the outline wrong (0.16-0.77
# px, the lines 0.02-0.03) at z 4.82-28.4.  4 lies between 3.73 and 4.82;
# an agreeing pair past it swaps one right answer for another.
PATHS_DISAGREE_Z = 4.0

# A band's inner edge this near inside the lines' noses (px) lies within
# reach of their sub-pixel window too (reach_px 1 + 3 px, and the frame's
# 1 px smoothing): neither path's crossing is then the nose's alone, and the
# one kept states the two's difference as well.  Measured (cushion12): bands
# 4.0-5.0 px in, the lines 0.06-0.74 px off stating 0.03-0.24 alone, 0.6-6.2
# widened (2-43x too wide); at 5.5-6.5 px in, 0.02-0.07 off stating 0.03.
LINES_CROWDED_PX = 5.0


def _detection(sides, edge: str, shape, *, K=None, dist=None, estimate_lens: bool = True, robust: bool = True,
               pattern_px: float = EDGE_PATTERN_PX, kappa_pattern_k1: float = KAPPA_PATTERN_K1,
               lines: bool = False) -> Detection:
    """:func:`detect_corners`' corners, lens and errors from four sides' edge points in a frame of ``shape``."""
    h, w = shape[:2]
    centre = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
    kappa = kappa_sigma = 0.0
    corners_kappa = None
    kappa_floor = kappa_pattern_k1 / (0.5 * max(w, h)) ** 2
    if K is None and estimate_lens:
        kappa = radial_from_edges(sides, centre, (w, h))
    if robust:
        sides = drop_strays(sides, K, dist, kappa, centre)
    if K is None and estimate_lens:
        kappa = radial_from_edges(sides, centre, (w, h)) if robust else kappa     # without the strays
        kappa_sigma = math.hypot(radial_sigma(sides, centre, kappa, (w, h)), kappa_floor)
        corners_kappa = fit_sides(sides, kappa=kappa + kappa_sigma, centre=centre)[0]
    corners, edge_rms = fit_sides(sides, K, dist, kappa, centre)
    cov = corner_covariance(sides, K, dist, kappa, centre, size=(w, h) if corners_kappa is not None else None)
    cov[:8, :8] += pattern_px**2 * np.eye(8)
    if corners_kappa is not None and kappa_floor > 0:
        # the pattern's bow error as a joint move: kappa and the corners the edges then give (kappa alone,
        # the corners held, widened the ball-centre map's share 1.2-1.4x at 2 m, 10 deg, k1 -0.25)
        g = kappa_floor * np.append((corners_kappa - corners).ravel() / kappa_sigma, 1.0)
        cov += np.outer(g, g)
    return Detection(corners=corners, edge_rms=edge_rms, kappa=kappa, edge=edge, kappa_sigma=kappa_sigma,
                     corners_kappa=corners_kappa, corner_cov=cov, lines=lines)


def assign_corners(quad: np.ndarray, size, table: Table, **kw) -> Calibration:
    """Which detected corner is the table's origin: every counter-clockwise
    start is tried and the best-fitting camera kept; of the two that fit
    equally (the table turned half round) the one with the origin nearest the
    frame's bottom-left, as in the default camera."""
    tries = []
    for s in range(4):
        order = np.roll(quad, -s, axis=0)
        try:
            cal = calibrate_corners(order, size, table, **kw)
        except CalibrationError:
            continue
        u, v = order[0]
        if kw.get("homography"):
            # every order fits 4 points exactly: the one whose view is closest to
            # square pixels (the long side along x) wins
            sv = np.linalg.svd(cal.camera.with_centre_height(0.0).jacobian(
                [table.length / 2, table.width / 2]), compute_uv=False)
            tries.append((round(float(sv[0] / sv[1]), 3), u - v, cal))
        else:
            tries.append((round(cal.rms_px, 1), u - v, cal))
    if not tries:
        raise CalibrationError("no camera fits the felt's outline as a "
                               f"{table.length:g} x {table.width:g} m table; give --corners")
    tries.sort(key=lambda x: (x[0], x[1]))
    return tries[0][2]


# --------------------------------------------------------------------------- f from the balls
# The ring between BALL_RING[0] and [1] of a ball's radii about it gives the
# felt's colour and the noise (and must be all felt).
BALL_RING = (1.2, 1.6)
# A ball's outline is where its colour distance from the felt falls halfway
# from its level this far (px) inside the steepest fall: close enough to the
# edge that a shaded ball's limb is still the level (2.5 px put the renderer's
# shaded balls' f 5-7% low, 1.5 px 2-5%; drawn flat balls alike, 0.2-1.2%).
LIMB_INNER_PX = 1.5
# A still ball's blob on the felt: its area within this range of the disc
# the table's scale predicts (rough: the scale varies over a tilted view).
BALL_AREA_RANGE = (0.4, 2.5)
# Least ball-minus-felt colour difference (grey levels) to measure a shape on.
BALL_MIN_CONTRAST = 20.0
# Error of a ball's measured shape beyond the edge points' scatter
# (dimensionless, per component), added in quadrature.  On drawn flat balls the
# shapes come within 0.001-0.004 of the exact outline's, but a shaded ball's
# limb darkens towards its edge, unevenly round an off-axis ball, and the
# outline's halfway point moves in on the darker side: on the renderer's
# realistic balls straight overhead (balls at (2.40, 1.15) and (2.30, 0.20) m)
# f came 2.0-5.3% low under its default light and 6.5-9.1% low under a lamp
# overhead (a billiard table's usual light).  The stated f error is about 3-4
# times this floor (0.01: 3.2-5.0%, up to 2.7x too small under the lamp);
# 0.03 states 9.6-12.7%, covering the worst measured look at 0.9 of its stated
# error at most (docs/calibration.md, section 6).
BALL_SHAPE_FLOOR = 0.03


@dataclass(frozen=True)
class BallImage:
    """A still ball's image on the felt, by the ellipse fitted to its outline.

    Attributes
    ----------
    centre : ndarray, shape (2,)
        Centre of the ellipse fitted to the outline (px).
    shape : ndarray, shape (2,)
        That ellipse's second moments' traceless part over half their trace,
        ``((Mxx - Myy) / 2, Mxy) / ((Mxx + Myy) / 2)``: 0 for a circle; a
        sphere's silhouette off the optical axis is elongated along the line to it by
        about ``1 / cos`` of the angle from the axis, which the focal length
        sets (:func:`focal_from_balls`).
    sigma : float
        1-sigma error of each ``shape`` component: the outline points' scatter
        and ``BALL_SHAPE_FLOOR``.
    """

    centre: np.ndarray
    shape: np.ndarray
    sigma: float


def _shape(M) -> np.ndarray:
    return np.array([(M[0, 0] - M[1, 1]) / 2.0, M[0, 1]]) / ((M[0, 0] + M[1, 1]) / 2.0)


def ball_images(img: np.ndarray, quad: np.ndarray, r_px: float) -> list:
    """The still balls' images inside the playing surface (:class:`BallImage`).

    A blob of non-felt colour of about a ball's area (radius ``r_px``) whose
    surroundings out to ``BALL_RING[1]`` radii are felt (not a pocket, a
    cushion or another ball); its outline is found along 90 rays from it
    (:func:`_limb_points`: the colour distance from the felt, linear in the
    pixel's coverage for a locally even ball colour, halfway down at the
    edge) and an ellipse fitted to it (:func:`_fit_ellipse`); the shape is
    that ellipse's.  The frame's values are taken as linear in coverage (the
    renderer's and the drawn frames are; a camera's gamma moves the halfway
    point by the limb's brightness).
    """
    D, thr = _felt_distance(img)
    h, w = D.shape
    surface = np.zeros((h, w), np.uint8)
    cv2.fillConvexPoly(surface, np.round(quad).astype(np.int32), 1)
    surface = cv2.erode(surface, np.ones((5, 5), np.uint8))
    blob = ((D >= thr) & (surface > 0)).astype(np.uint8)
    n, lab, stats, cent = cv2.connectedComponentsWithStats(blob, connectivity=8)
    col = np.asarray(img, dtype=np.float64)
    if col.ndim == 2:
        col = col[..., None]
    area0 = math.pi * r_px**2
    out = []
    for i in range(1, n):
        if not (BALL_AREA_RANGE[0] * area0 <= stats[i, cv2.CC_STAT_AREA] <= BALL_AREA_RANGE[1] * area0):
            continue
        rc = math.sqrt(stats[i, cv2.CC_STAT_AREA] / math.pi)
        cu, cv_ = cent[i]
        reach = BALL_RING[1] * rc + 2.0
        u0, u1 = int(cu - reach), int(cu + reach) + 2
        v0, v1 = int(cv_ - reach), int(cv_ + reach) + 2
        if u0 < 0 or v0 < 0 or u1 > w or v1 > h:
            continue
        sl = np.s_[v0:v1, u0:u1]
        vv, uu = np.mgrid[v0:v1, u0:u1]
        du, dv = uu - cu, vv - cv_
        rr = np.hypot(du, dv)
        own = cv2.dilate((lab[sl] == i).astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
        if np.mean((D[sl] >= thr)[(rr <= BALL_RING[1] * rc) & ~own]) > 0.01:
            continue                        # something else within the ring: a cushion, pocket, ball
        ring = (rr >= BALL_RING[0] * rc) & (rr <= BALL_RING[1] * rc)
        felt = np.median(col[sl][ring], axis=0)
        # |colour - felt| is linear in the pixel's coverage for a locally even
        # ball colour, whatever the shading elsewhere on the ball
        dmap = np.linalg.norm(col[sl] - felt, axis=2).astype(np.float32)
        noise = 1.4826 * float(np.median(np.abs(dmap[ring] - np.median(dmap[ring]))))
        pts = _limb_points(dmap, cu - u0, cv_ - v0, rc, noise)
        if pts is None:
            continue
        ell = _fit_ellipse(pts)
        if ell is None:
            continue
        centre, M, resid = ell
        sigma = math.hypot(2.0 * math.sqrt(2.0 / len(pts)) * resid / math.sqrt(2.0 * np.trace(M)),
                           BALL_SHAPE_FLOOR)
        out.append(BallImage(centre=centre + [u0, v0], shape=_shape(M), sigma=float(sigma)))
    return out


def _limb_points(dmap, cu, cv_, rc, noise, n_rays: int = 90):
    """Sub-pixel points of a ball's outline along rays from ``(cu, cv_)``: where
    the colour distance from the felt falls halfway from its level just inside
    the edge (``LIMB_INNER_PX`` in from the steepest fall) to the felt's (0), by linear
    interpolation along the ray (bilinear samples every 0.1 px).  A ray whose
    edge is weaker than ``BALL_MIN_CONTRAST`` or 5 noise levels is skipped."""
    step = 0.1
    s = np.arange(0.5 * rc, BALL_RING[1] * rc, step)
    th = 2.0 * np.pi * np.arange(n_rays) / n_rays
    mx = (cu + np.cos(th)[:, None] * s[None, :]).astype(np.float32)
    my = (cv_ + np.sin(th)[:, None] * s[None, :]).astype(np.float32)
    prof = cv2.remap(dmap, mx, my, cv2.INTER_LINEAR)
    pts = []
    inner = int(round(LIMB_INNER_PX / step))
    for k in range(n_rays):
        p = prof[k]
        j = int(np.argmin(np.diff(p)))              # steepest fall
        if j - inner < 0:
            continue
        level = float(p[j - inner])
        if level < max(BALL_MIN_CONTRAST, 5.0 * noise):
            continue
        half = level / 2.0
        below = np.nonzero(p[j - inner:] < half)[0]
        if not below.size:
            continue
        m = j - inner + int(below[0])
        sm = s[m - 1] + step * (p[m - 1] - half) / (p[m - 1] - p[m])
        pts.append((cu + np.cos(th[k]) * sm, cv_ + np.sin(th[k]) * sm))
    return np.array(pts) if len(pts) >= n_rays // 2 else None


def _fit_ellipse(pts):
    """Centre, second moments (``Q^-1 / 4`` of the ellipse ``d^T Q d <= 1``) and
    RMS radial residual (px) of the ellipse through outline points
    (``cv2.fitEllipseDirect``), refitted without points more than 3 robust
    sigmas off (a marking or a highlight at the edge)."""
    keep = np.ones(len(pts), bool)
    for _ in range(3):
        if keep.sum() < 6:
            return None
        (cx, cy), (w_, h_), ang = cv2.fitEllipseDirect(pts[keep].astype(np.float32))
        a, b = w_ / 2.0, h_ / 2.0
        c, s_ = math.cos(math.radians(ang)), math.sin(math.radians(ang))
        Rm = np.array([[c, -s_], [s_, c]])
        d = (pts - [cx, cy]) @ Rm                    # in the ellipse's axes
        rho = np.hypot(d[:, 0] / a, d[:, 1] / b)     # 1 on the ellipse
        res = (rho - 1.0) * np.hypot(d[:, 0], d[:, 1]) / np.maximum(rho, 1e-9)
        scale = 1.4826 * float(np.median(np.abs(res[keep]))) + 1e-3
        new = np.abs(res) < 3.0 * scale
        if np.array_equal(new, keep):
            break
        keep = new
    M = Rm @ np.diag([a * a, b * b]) @ Rm.T / 4.0
    return np.array([cx, cy]), M, float(np.sqrt(np.mean(res[keep] ** 2)))


def focal_from_balls(balls, corners_px, size, table: Table = Table(), *, R: float = 0.028575, **kw):
    """Focal length (px) from the still balls' shapes, and its standard error.

    A sphere's silhouette is elongated towards the optical axis by about
    ``1 / cos`` of its angle from it, and that angle for a given pixel is set
    by the focal length: for each trial f the camera is re-solved from the
    same corners (``kw`` as for :func:`calibrate_corners`), each ball's
    outline predicted at the table point its centre images to
    (:meth:`Camera.ball_outline`, the same ellipse fitted to it) and compared with the
    measured ``shape`` (chi^2 over the balls); the error is where chi^2 rises
    by 1, widened by ``sqrt(chi2 / dof)`` when the fit is worse than the
    pixels' noise.  A ball near the axis shows nothing; one near the table's
    corner straight overhead fixes f to a few percent (measured,
    docs/calibration.md, section 6).

    Returns
    -------
    (f, sigma) : tuple of float, or None
        None when no ball was measured or chi^2 has no minimum inside
        ``FOCAL_RANGE``.
    """
    if not balls:
        return None
    big = max(size)
    kw = {k: v for k, v in kw.items() if k not in ("focal_px", "camera_height_m", "intrinsics", "distortion")}

    def chi2(f):
        try:
            cam = calibrate_corners(corners_px, size, table, focal_px=f, **kw).camera.with_centre_height(R)
        except CalibrationError:
            return math.inf
        total = 0.0
        for b in balls:
            xy = cam.to_table(b.centre[None])[0]
            try:
                fit = _fit_ellipse(cam.ball_outline(xy, R, n=90))  # as the measured outline is fitted
            except cv2.error:
                fit = None
            if fit is None:  # no ellipse through the predicted outline: this f explains nothing
                return math.inf
            total += float(np.sum((b.shape - _shape(fit[1])) ** 2)) / b.sigma**2
        return total

    grid = big * np.exp(np.linspace(np.log(0.3), np.log(3.0), 41))
    chi = np.array([chi2(f) for f in grid])
    i = int(np.argmin(chi))
    if not np.isfinite(chi[i]) or i in (0, len(grid) - 1):
        return None
    f = math.exp(_golden(lambda lf: chi2(math.exp(lf)), math.log(grid[i - 1]), math.log(grid[i + 1]), 1e-5))
    c0 = chi2(f)
    dof = 2 * len(balls) - 1
    rise = max(1.0, c0 / dof) if dof > 0 else 1.0

    def edge(step):
        # where chi^2 first rises by ``rise`` going from f by factors of ``step``
        g, prev = f, f
        for _ in range(400):
            g *= step
            if not (FOCAL_RANGE[0] * big <= g <= FOCAL_RANGE[1] * big):
                return None
            if chi2(g) > c0 + rise:
                return math.sqrt(g * prev)
            prev = g
        return None
    lo, hi = edge(1.0 / 1.005), edge(1.005)
    if lo is None or hi is None:
        return None
    return f, (hi - lo) / 2.0


def calibrate_video(path, table: Table = Table(), corners=None, *, intrinsics=None, distortion=None,
                    felt_margin_m: float = 0.0, felt_height_m: float = 0.0, nose_height_m: float = 0.0,
                    camera_height_sigma_m: float = 0.0, use_balls: bool = True, **kw) -> Calibration:
    """A video's camera: from given corners, or from the table found in its median frame.

    Automatic: the cushions' noses when they show (the playing surface's edge,
    at ``nose_height_m`` above the cloth), else the felt-coloured outline (the
    surface grown by ``felt_margin_m`` at ``felt_height_m``).  Given corners
    take the same focal-length rule (:func:`calibrate_clicked`), the still
    balls read from the same median frame; with ``nose_height_m`` they are
    taken as clicked where the noses meet, that high above the cloth (the
    table's frame is the cloth's: x, y of the playing surface's edge, z 0).
    """
    from cuespin.videoio import quiet_native_stderr

    with quiet_native_stderr():
        cap = cv2.VideoCapture(str(path), cv2.CAP_FFMPEG)
    if not cap.isOpened():
        raise InputError(f"{path}: not a video OpenCV can read")
    size = (int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)))
    fps = float(cap.get(cv2.CAP_PROP_FPS)) or 30.0
    cap.release()
    if size[0] <= 0 or size[1] <= 0:
        raise InputError(f"{path}: the video has no frames")
    K = None if intrinsics is None else np.asarray(intrinsics, dtype=float)
    dist = None if distortion is None else np.asarray(distortion, dtype=float).ravel()
    if corners is not None:
        # the median frame where the edges' bow or the still balls are read
        frame = reference_frame(path)[0] if K is None and not kw.get("homography") else None
        if nose_height_m:           # clicked where the cushions' noses meet, above the cloth
            kw["corner_height_m"] = nose_height_m
        return calibrate_clicked(corners, size, table, frame=frame, intrinsics=K, distortion=dist, fps=fps,
                                 camera_height_sigma_m=camera_height_sigma_m, use_balls=use_balls, **kw)
    image, single, single_next = reference_frame(path)
    return calibrate_frame(image, table, intrinsics=K, distortion=dist, fps=fps, lossy=_lossy(path), single=single,
                           single_next=single_next,
                           felt_margin_m=felt_margin_m, felt_height_m=felt_height_m,
                           nose_height_m=nose_height_m, camera_height_sigma_m=camera_height_sigma_m,
                           use_balls=use_balls, **kw)


def _lossy(path) -> bool:
    """Whether the video's codec is lossy (:func:`cuespin.track.reader.probe`);
    False when it cannot say.  The container only: a lossy codec's frames
    re-saved losslessly say lossless here, and the still run's first frame
    (:func:`detect_corners`' ``single``) decides then."""
    from cuespin.track.reader import TrackError, probe

    try:
        return not probe(path).lossless
    except TrackError:
        return False


def _focal_by_rule(same: dict) -> bool:
    """Whether the focal length is left to :func:`choose_focal`: no lens, focal
    length or height given, and a pose (not ``homography``)."""
    return (same.get("intrinsics") is None and same.get("focal_px") is None
            and same.get("camera_height_m") is None and not same.get("homography"))


# Clicked corners take the lens's bow from the table's edges in the frame
# (:func:`detect_corners`) when the outline found there is the table they
# were clicked on: every found corner within this share of the clicked
# quadrilateral's shorter side of a clicked one.  Measured on the drawn and
# the renderer's realistic tables (2 m at 0, 3, 10 degrees, 1.5 m at 15,
# k1 -0.25..+0.25; benchmarks/bowmatch.py): the noses' outline 0.0-0.1% off
# the playing surface, the felt's outline beyond the cushions (noses=False)
# 3.3-5.6%; 0.15 is 2.7 times the felt's worst, clicks 1 px off move it
# 0.2%, and an outline 20% off is another table's.
CLICKED_BOW_MATCH = 0.15


def edges_bow(frame: np.ndarray, corners_px):
    """The lens's bow from the table's edges in ``frame`` (no lens known):
    ``((kappa, its standard error), "")`` (px^-2, :class:`Detection`), or
    ``(None, why)`` when no outline is found there or it is not the table
    of ``corners_px`` (``CLICKED_BOW_MATCH``; ``why`` a phrase for the user)."""
    c = np.asarray(corners_px, dtype=float).reshape(4, 2)
    try:
        det = detect_corners(frame)
    except (CalibrationError, cv2.error, np.linalg.LinAlgError):
        return None, "no table outline found in the video"
    side = float(np.linalg.norm(np.roll(c, -1, axis=0) - c, axis=1).min())
    off = min(float(np.abs(np.roll(det.corners, -s, axis=0) - c).max()) for s in range(4))
    if off > CLICKED_BOW_MATCH * side:
        return None, (f"the table outline found in the video lies {off:.0f} px from the clicked corners, over "
                      f"{CLICKED_BOW_MATCH:.0%} of the table's shorter side")
    return (float(det.kappa), float(det.kappa_sigma)), ""


def calibrate_clicked(corners_px, size, table: Table = Table(), *, frame=None, use_balls: bool = True,
                      estimate_lens: bool = True, camera_height_sigma_m: float = 0.0, **kw) -> Calibration:
    """The camera from given (clicked) corners, by the automatic path's rules.

    The corners are taken in the order given (:func:`calibrate_corners`'
    checks), each coordinate with the error ``corner_sigma_px`` (default 1 px,
    independent).  With no lens given, the lens's bow comes from the table's
    edges in ``frame`` (:func:`edges_bow`), its error one more move; the
    focal length from the one rule (:func:`choose_focal`: the corners'
    perspective, the still balls' shapes in ``frame``, or the nominal focal
    length); the perturbed cameras move each coordinate in turn, with the
    corners' share of f.  The same as :func:`calibrate_frame` writes for
    corners found with that error, but for the corners' move with the bow
    (clicked corners do not follow the edges).

    Parameters
    ----------
    corners_px : array_like, shape (4, 2)
        As for :func:`calibrate_corners`.
    size : (int, int)
        Frame ``(width, height)`` (px).
    frame : ndarray, optional
        A frame of the table without the moving ball: the edges' bow and the
        still balls' f.
    use_balls, estimate_lens : bool
        Read the still balls' shapes, the edges' bow, in ``frame``.
    camera_height_sigma_m : float
        Error of ``camera_height_m`` (m), carried by one more camera.
    **kw
        As for :func:`calibrate_corners`.
    """
    size = (int(size[0]), int(size[1]))
    kw.setdefault("corner_sigma_px", 1.0)
    kw.setdefault("fps", 30.0)
    cal = calibrate_corners(corners_px, size, table, **kw)      # the checks, the order as given
    moves = np.hstack([kw["corner_sigma_px"] * np.eye(8), np.zeros((8, 1))])
    bow, straight = None, ""
    if frame is not None and estimate_lens and kw.get("intrinsics") is None and not kw.get("homography") \
            and not kw.get("kappa"):
        bow, straight = edges_bow(frame, cal.corners_px)
    if bow is not None:
        try:
            cal = calibrate_corners(corners_px, size, table, **dict(kw, kappa=bow[0]))
        except CalibrationError:            # no plausible camera through that bow: the clicks as they are
            f = float(cal.camera.K[0, 0])
            straight = (f"the bow from the table's edges in the video, k1 = {bow[0] * f * f:+.3f}, leaves no "
                        "plausible camera through the clicked corners")
            bow = None
    if bow is not None:
        kw["kappa"] = bow[0]
        if bow[1] > 0:
            moves = np.vstack([moves, np.append(np.zeros(8), bow[1])])
    cal = _focal_and_errors(cal, size, table, kw, moves, frame=frame if use_balls else None,
                            camera_height_sigma_m=camera_height_sigma_m)
    if straight:        # said, not silent: a wide lens taken as straight bends every line (v0 16x off at k1 -0.25)
        cal = replace(cal, notes=[f"the lens taken as straight ({straight}): give --intrinsics for a wide lens"]
                      + list(cal.notes))
    if bow is not None:
        f = float(cal.camera.K[0, 0])
        cal = replace(cal, notes=[f"the lens's bow from the table's edges in the video: k1 = {bow[0] * f * f:+.3f} "
                                  f"+/- {bow[1] * f * f:.2g} at f = {f:.0f} px"] + list(cal.notes))
    return cal


def _focal_and_errors(cal: Calibration, size, table: Table, same: dict, moves: np.ndarray, *, frame=None,
                      camera_height_sigma_m: float = 0.0) -> Calibration:
    """The focal length by the one rule and the perturbed cameras, for corners
    found or given alike (:func:`calibrate_frame`, :func:`calibrate_clicked`).

    ``cal``: the corners' camera in table order, solved with ``same`` (the
    keywords of :func:`calibrate_corners`); ``moves`` (m, 9): the corners' and
    the bow's error as joint moves (the jackknife's :func:`covariance_moves`,
    or one coordinate at a time by a given error, with the bow's own row);
    ``frame``: where the still balls are read (None: not read).

    With no lens, focal length or height given (:func:`_focal_by_rule`), f
    is the corners' (:func:`corner_focal`, refitted along each move), the
    balls' (:func:`focal_from_balls`) or both weighted by their errors when
    under ``NOMINAL_FOCAL_SIGMA`` (:func:`choose_focal`), else the nominal
    one; it is then held as ``focal_px`` in every perturbed camera, each
    corner move moving the corners' share of it, one more camera carrying the
    rest (the balls' or the nominal one's error).
    """
    same = dict(same)
    notes = list(cal.notes)
    focal_sigma = 0.0
    focal_moves = None
    if _focal_by_rule(same):
        margin, height = same.get("margin_m", 0.0), same.get("corner_height_m", 0.0)
        fc = corner_focal(cal.corners_px, size, table, moves, kappa=same.get("kappa", 0.0), margin_m=margin,
                          corner_height_m=height)
        fb = None
        if frame is not None:
            R = float(same.get("R_nominal", 0.028575))
            scale = math.sqrt(abs(signed_area(cal.corners_px)) / (table.length * table.width))   # px per m, roughly
            fb = focal_from_balls(ball_images(frame, cal.corners_px, R * scale), cal.corners_px, size, table, R=R,
                                  **same)
        pick = choose_focal(fc[:2], fb)
        if pick is None:
            # neither the corners nor a ball under the nominal error: a phone's main camera, with its error
            f = NOMINAL_FOCAL * max(size)
            source, sigma, w = "nominal", NOMINAL_FOCAL_SIGMA * f, 0.0
            focal_sigma = NOMINAL_FOCAL_SIGMA
        else:
            source, f, sigma, w = pick
            if w < 1:                       # the balls' share: one camera with it one (weighted) error longer
                focal_sigma = (1.0 - w) * fb[1] / f
        same["focal_px"] = f
        if w > 0:                           # the corners' share of f moves with them in each perturbed camera
            focal_moves = f + w * (fc[2] - fc[0])
        cal = replace(calibrate_corners(cal.corners_px, size, table, **same), focal_source=source,
                      focal_sigma=sigma / f, edge_rms_px=cal.edge_rms_px, edge=cal.edge)
        corners_say = (f"{fc[0]:.0f} px +/- {100 * fc[1] / fc[0]:.1f}%" if math.isfinite(fc[1])
                       else "the camera is nearly overhead")
        if source == "corners+balls":
            notes = [f"f = {f:.0f} px +/- {100 * sigma / f:.1f}% from the corners' perspective ({corners_say}) "
                     f"and the still balls' shapes ({fb[0]:.0f} px +/- {100 * fb[1] / fb[0]:.1f}%), weighted by "
                     f"their stated errors; camera {cal.height_m:.2f} m above the cloth"]
        elif source == "balls":
            notes = [f"the corners do not fix the focal length ({corners_say}); f = {f:.0f} px "
                     f"+/- {100 * sigma / f:.1f}% from the still balls' shapes (a sphere's image stretches "
                     f"away from the optical axis), camera {cal.height_m:.2f} m above the cloth"]
        elif source == "nominal":
            notes = [f"the corners do not fix the focal length ({corners_say}) and no still ball does; assumed "
                     f"f = {f:.0f} px +/- {100 * NOMINAL_FOCAL_SIGMA:.0f}% (a phone's main camera), camera "
                     f"{cal.height_m:.2f} m above the cloth: give --camera-height or --intrinsics"]
        else:
            notes = []
    cal = replace(cal, notes=notes)
    return _with_perturbed(cal, size, table, height_sigma_m=camera_height_sigma_m, focal_sigma=focal_sigma,
                           moves=moves, focal_moves=focal_moves, **same)


def calibrate_frame(frame: np.ndarray, table: Table = Table(), *, corners=None, intrinsics=None,
                    distortion=None, felt_margin_m: float = 0.0, felt_height_m: float = 0.0,
                    nose_height_m: float = 0.0, camera_height_sigma_m: float = 0.0, use_balls: bool = True,
                    estimate_lens: bool = True, lossy: bool = False, single: np.ndarray | None = None,
                    single_next: np.ndarray | None = None, **kw) -> Calibration:
    """The camera found in one frame of the table (``calibrate_video``'s automatic
    path): the corners and the lens's bow from :func:`detect_corners`, the
    corners' order from :func:`assign_corners`, their error (the edges'
    jackknife, or ``corner_sigma_px`` a coordinate with the bow's own), then
    the focal length by one rule and the perturbed cameras
    (:func:`_focal_and_errors`, as for clicked corners).  With ``corners``
    given: :func:`calibrate_clicked` on them (the bow and the balls read in
    ``frame``).  ``estimate_lens=False``: the lens taken as undistorted (no
    bow fitted).  ``lossy``: the frame came through a lossy codec;
    ``single``: one frame of the video ``frame`` is a mean of, and
    ``single_next`` the still frame after it (:func:`detect_corners`).
    ``kw`` as for :func:`calibrate_corners`."""
    h, w = frame.shape[:2]
    size = (int(w), int(h))
    K = None if intrinsics is None else np.asarray(intrinsics, dtype=float)
    dist = None if distortion is None else np.asarray(distortion, dtype=float).ravel()
    if corners is not None:
        kw.setdefault("corner_height_m", nose_height_m)  # clicks at the noses (review 12a: was ignored here)
        return calibrate_clicked(corners, size, table, frame=frame, use_balls=use_balls, estimate_lens=estimate_lens,
                                 intrinsics=K, distortion=dist, camera_height_sigma_m=camera_height_sigma_m, **kw)
    det = detect_corners(frame, K, dist, estimate_lens=estimate_lens, lossy=lossy, single=single,
                         single_next=single_next)
    quad, edge_rms, kappa = det.corners, det.edge_rms, det.kappa
    if det.edge == "noses":
        felt_margin_m, felt_height_m = 0.0, nose_height_m
    # The corners' error from the edges' jackknife (the lens's bow re-estimated
    # with them): stated/real 0.6-1.8 on drawn and rendered tables, where the
    # points' scatter over their number gave 0.2-0.8 (docs/calibration.md,
    # section 6), with the edge locator's fixed pattern added (EDGE_PATTERN_PX:
    # without it the covariance was too sure along its narrow directions).  A
    # corner error given (``corner_sigma_px``) is taken instead, one
    # coordinate at a time, and the bow's error as one more joint move.
    given = "corner_sigma_px" in kw
    if not given:
        kw["corner_sigma_px"] = float(math.sqrt(np.trace(det.corner_cov[:8, :8]) / 8.0))
    same = dict(intrinsics=K, distortion=dist, fps=kw.pop("fps", 30.0), kappa=kappa, margin_m=felt_margin_m,
                corner_height_m=felt_height_m, **kw)
    cal = assign_corners(quad, size, table, **same)
    # corner j of the assigned order is the detection's (j + s) % 4
    s = int(np.argmin([np.abs(np.roll(quad, -k, axis=0) - cal.corners_px).max() for k in range(4)]))
    if given:
        moves = np.hstack([kw["corner_sigma_px"] * np.eye(8), np.zeros((8, 1))])
        if det.corners_kappa is not None and det.kappa_sigma > 0:
            # the bow's own error: kappa one standard error larger and the corners
            # the edges then give, as one more joint move (its share of f with it)
            kc = np.roll(det.corners_kappa, -s, axis=0)
            moves = np.vstack([moves, np.append((kc - cal.corners_px).ravel(), det.kappa_sigma)])
    else:
        idx = [2 * ((j + s) % 4) + c for j in range(4) for c in (0, 1)] + [8]
        moves = covariance_moves(det.corner_cov[np.ix_(idx, idx)])
    cal = replace(cal, edge_rms_px=edge_rms, edge=det.edge)
    cal = _focal_and_errors(cal, size, table, same, moves, frame=frame if use_balls else None,
                            camera_height_sigma_m=camera_height_sigma_m)
    if det.lines:       # said: the path a real pocketed table takes, measured on two real clips only
        cal = replace(cal, notes=["the felt's outline is broken (pockets, markers, shadows along the cushions): "
                                  "the cushions' lines were fitted instead (docs/calibration.md); check the "
                                  "corners, and give --nose-height for a real table's noses"] + list(cal.notes))
    return cal


def _with_perturbed(cal: Calibration, size, table: Table, **kw) -> Calibration:
    """The calibration with its :func:`perturbed_cameras` (solved as ``cal`` was),
    which the recovery uses to carry the corners' error into v0 and w0."""
    if not cal.corner_sigma_px:
        return cal
    kw.pop("corner_sigma_px", None)
    cams = perturbed_cameras(cal.corners_px, cal.corner_sigma_px, size, table,
                             corner_sigma_px=cal.corner_sigma_px, **kw)
    notes = list(cal.notes)
    moves = kw.get("moves")
    want = (8 if moves is None else len(moves)) + (cal.focal_source == "nominal" and not kw.get("focal_px")) + (
        cal.focal_source == "camera-height" and kw.get("height_sigma_m", 0.0) > 0)
    want += (kw.get("focal_sigma", 0.0) > 0 and bool(kw.get("focal_px"))) + (
        kw.get("kappa_sigma", 0.0) > 0 and bool(kw.get("kappa")) and not kw.get("homography")
        and kw.get("intrinsics") is None)
    if len(cams) < want:
        # A corner whose move leaves no plausible camera drops its term: the
        # calibration's share of the errors is then understated.
        notes.append(f"only {len(cams)} of the {want} perturbed cameras could be solved; the calibration's "
                     f"share of the recovery's errors is understated (click the corners again)")
    return replace(cal, perturbed=tuple(cams), notes=notes)


# --------------------------------------------------------------------------- synthetic frames
def _inset(p, delta):
    """A polygon's edges moved ``delta`` inward (vertices along the bisectors)."""
    d = np.roll(p, -1, axis=0) - p
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    area = np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])
    n = np.column_stack([-d[:, 1], d[:, 0]]) * (1.0 if area > 0 else -1.0)   # inward normals
    n_prev = np.roll(n, 1, axis=0)
    return p + delta * (n + n_prev) / (1.0 + np.sum(n * n_prev, axis=1))[:, None]


def _coverage(polys, w, h, ss):
    """Fraction of each pixel inside the polygons (px), by ``ss`` x supersampling.
    cv2.fillPoly also fills the pixels its outline touches (measured: half a
    subpixel beyond every edge), so the outline is first moved in by that much."""
    big = np.zeros((h * ss, w * ss), np.uint8)
    shift = 4
    pts = [np.round(_inset((p + 0.5) * ss - 0.5, 0.5) * (1 << shift)).astype(np.int32) for p in polys]
    cv2.fillPoly(big, pts, 255, lineType=cv2.LINE_8, shift=shift)
    return cv2.resize(big, (w, h), interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0


def synthetic_table_frame(cam, table=Table(), seed=0, noise=3.0, ss=4, felt=(40, 120, 30), wood=(40, 75, 125),
                          balls=((0.6, 0.4), (2.45, 1.2)), cushion_m: float = 0.0,
                          cushion_shade: float = 0.8, pockets: bool = False, band_m: float = 0.0,
                          band_shade: float = 0.8, frames: int = 0):
    """A frame of the table through ``cam`` to check the detector on: the playing
    surface's felt (its edge bowed by the lens, sampled every few mm) on wood,
    optionally cushions ``cushion_m`` wide in ``cushion_shade`` x the felt's
    colour and black pockets (the renderer's realistic look has both), white
    balls (radius: the camera's centre height), Gaussian noise; ``band_m`` > 0:
    a band that wide inside the noses in ``band_shade`` x the felt's colour
    (the noses' shadows on a lit table's cloth).  Everything
    lies in the cloth's plane.  Coverage by ``ss`` x supersampling,
    area-averaged (pixel integration); an edge lands on a multiple of
    ``1/ss`` px (averaged out along edges off the pixel axes).  The renderer
    draws the realistic table; this is the bare geometry.  ``frames`` > 0:
    that many frames of the still table, shape (frames, h, w, 3), each with
    its own noise (the first is the single frame's)."""
    rng = np.random.default_rng(seed)
    w, h = cam.width, cam.height
    s = np.linspace(0.0, 1.0, 400)[:-1]

    def outline(m):
        x0, y0, x1, y1 = -m, -m, table.length + m, table.width + m
        e = np.concatenate([np.column_stack([x0 + (x1 - x0) * s, y0 + 0 * s]),
                            np.column_stack([x1 + 0 * s, y0 + (y1 - y0) * s]),
                            np.column_stack([x1 - (x1 - x0) * s, y1 + 0 * s]),
                            np.column_stack([x0 + 0 * s, y1 - (y1 - y0) * s])])
        return cam.project(np.column_stack([e, np.zeros(len(e))]))

    felt = np.asarray(felt, np.float32)
    img = np.empty((h, w, 3), np.float32)
    img[:] = wood
    layers = []
    if cushion_m > 0:
        layers.append(([outline(cushion_m)], cushion_shade * felt))
    if band_m > 0:
        layers.append(([outline(0.0)], band_shade * felt))
        layers.append(([outline(-band_m)], felt))
    else:
        layers.append(([outline(0.0)], felt))
    if pockets:
        th = np.linspace(0.0, 2.0 * np.pi, 120, endpoint=False)
        polys = []
        for px, py, r in [(-0.031, -0.031, 0.062), (table.length + 0.031, -0.031, 0.062),
                          (-0.031, table.width + 0.031, 0.062),
                          (table.length + 0.031, table.width + 0.031, 0.062),
                          (table.length / 2, -0.035, 0.058), (table.length / 2, table.width + 0.035, 0.058)]:
            c = np.column_stack([px + r * np.cos(th), py + r * np.sin(th), np.zeros(len(th))])
            polys.append(cam.project(c))
        layers.append((polys, np.array([16.0, 16.0, 18.0], np.float32)))
    if balls:
        layers.append(([cam.ball_outline(np.array(xy), cam.centre_height, n=90) for xy in balls],
                       np.array([235.0, 235.0, 235.0], np.float32)))
    for polys, colour in layers:
        c = _coverage(polys, w, h, ss)[..., None]
        img = img * (1 - c) + colour * c
    out = [np.clip(np.round(img + rng.normal(0.0, noise, img.shape)), 0, 255).astype(np.uint8)
           for _ in range(max(frames, 1))]
    return np.stack(out) if frames > 0 else out[0]


def matched_corner_errors(corners: np.ndarray, truth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Detected corners' errors against the true ones, whatever corner they start at.

    A detection's first corner is wherever the felt's outline starts, so the
    corners are matched by the rotation (of the four) that puts them nearest
    ``truth`` (the largest coordinate difference least).

    Parameters
    ----------
    corners, truth : ndarray, shape (4, 2)
        Detected and true corners (px), in the same sense of rotation.

    Returns
    -------
    errors : ndarray, shape (4, 2)
        The matched corners less ``truth`` (px).
    idx : ndarray, shape (8,)
        Where each matched coordinate lies in ``corners.ravel()`` (and so in
        a detection's ``corner_cov``): ``corner_cov[np.ix_(idx, idx)]`` is
        the errors' covariance (px^2).
    """
    k = min(range(4), key=lambda k: np.abs(np.roll(corners, -k, axis=0) - truth).max())
    return np.roll(corners, -k, axis=0) - truth, np.roll(np.arange(8).reshape(4, 2), -k, axis=0).ravel()


def random_table(seed: int):
    """A drawn table (``synthetic_table_frame``) with its camera and look drawn
    from ``seed`` (a local Generator): camera 1.5-3 m up, tilt 0-15 deg, k1
    -0.25..+0.25, roll -3..+3 deg; half the tables with cushions 30-60 mm wide
    (and pockets) in 0.75-1.10 x the felt's shade (from plain dark noses to
    cloth-coloured cushions barely brighter than the felt), a third of those
    with a shadow band 8-25 mm inside the noses (0.7-0.9 x the felt's shade);
    frame noise 2-4 grey levels.  Every draw is made whatever is used, so a
    seed's table stays the same when the distribution of one part changes.

    Returns
    -------
    dict
        ``camera``, ``frame`` (BGR uint8), ``noses`` (the playing surface's
        corners, px) and ``felt`` (the felt-coloured outline's: the cushions'
        outer edge when there are cushions), ``look`` (the drawing's keywords).
    """
    rng = np.random.default_rng([seed, 12])
    height, tilt, k1, roll = rng.uniform(1.5, 3.0), rng.uniform(0.0, 15.0), rng.uniform(-0.25, 0.25), rng.uniform(-3, 3)
    cushioned, cushion_m, shade = rng.uniform() < 0.5, rng.uniform(0.03, 0.06), rng.uniform(0.75, 1.10)
    banded, band_m, band_shade = rng.uniform() < 1 / 3, rng.uniform(0.008, 0.025), rng.uniform(0.7, 0.9)
    noise = rng.uniform(2.0, 4.0)
    cam = pinhole_camera(height_m=height, tilt_deg=tilt, k1=k1, size=(1280, 720), fps=240.0, roll_deg=roll,
                         R=0.028575)
    look = dict(noise=noise)
    if cushioned:
        look.update(cushion_m=cushion_m, cushion_shade=shade, pockets=True)
        if banded:
            look.update(band_m=band_m, band_shade=band_shade)
    frame = synthetic_table_frame(cam, seed=seed, **look)
    return {"camera": cam, "frame": frame, "noses": cam.project(table_corners(Table())),
            "felt": cam.project(table_corners(Table(), margin_m=look.get("cushion_m", 0.0))), "look": look,
            "drawn": (height, tilt, k1, roll)}


# --------------------------------------------------------------------------- command line
def _floats(text: str, n: int | None, what: str) -> list:
    try:
        vals = [float(v) for v in text.replace(";", ",").split(",") if v.strip()]
    except ValueError:
        raise InputError(f"{what}: expected comma-separated numbers, got {text!r}")
    if n is not None and len(vals) != n:
        raise InputError(f"{what}: expected {n} numbers, got {len(vals)}")
    if not all(math.isfinite(v) for v in vals):
        raise InputError(f"{what}: must be finite numbers")
    return vals


def read_intrinsics(path):
    """A lens calibration file: JSON with ``intrinsics`` (3x3) and optional
    ``distortion`` (the keys of a scene file's camera block, so a scene file
    itself works too)."""
    path = Path(path)
    try:
        d = json.loads(path.read_text())
    except FileNotFoundError:
        raise InputError(f"intrinsics file not found: {path}")
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{path}: not a readable JSON file ({exc.__class__.__name__})")
    if isinstance(d, dict) and isinstance(d.get("camera"), dict):
        d = d["camera"]
    from cuespin.physics.scene import SceneError, _parse_camera

    if not isinstance(d, dict) or "intrinsics" not in d:
        raise InputError(f"{path}: intrinsics: required key is missing")
    probe = {"fps": 1.0, "intrinsics": d["intrinsics"], "homography": [[1, 0, 0], [0, -1, 0], [0, 0, 1]]}
    if "distortion" in d:
        probe["distortion"] = d["distortion"]
    try:
        cam = _parse_camera(probe, Table(), 0.028575)
    except SceneError as exc:
        raise InputError(f"{path}: {str(exc).replace('camera.', '')}")
    return cam.K, cam.dist


def cmd_calibrate(args) -> int:
    table = Table(*_floats(args.table, 2, "--table")) if args.table else Table()
    if min(table.length, table.width) <= 0:
        raise InputError("--table: length and width must be > 0")
    corners = None if args.corners is None else np.array(_floats(args.corners, 8, "--corners")).reshape(4, 2)
    K = dist = None
    if args.intrinsics:
        K, dist = read_intrinsics(args.intrinsics)
    for name in ("focal_px", "camera_height", "R", "mu_s", "mu_r", "corner_error"):
        v = getattr(args, name)
        if v is not None and not (math.isfinite(v) and v > 0 or (name == "mu_r" and v == 0)):
            raise InputError(f"--{name.replace('_', '-')}: must be a positive number")
    out = Path(args.output)
    if not out.parent.exists():
        raise InputError(f"output folder does not exist: {out.parent}")
    video = Path(args.video)
    if not video.is_file():
        raise InputError(f"video not found: {video}")
    kw = {}
    if args.corner_error is not None:
        kw["corner_sigma_px"] = args.corner_error
    if args.R is not None:
        kw["R_nominal"] = args.R
    if args.homography:
        kw["homography"] = True
    if args.camera_height_error is not None and not (math.isfinite(args.camera_height_error)
                                                     and args.camera_height_error >= 0):
        raise InputError("--camera-height-error: must be a number >= 0")
    cal = calibrate_video(video, table, corners, intrinsics=K, distortion=dist, focal_px=args.focal_px,
                          camera_height_m=args.camera_height, felt_margin_m=args.felt_margin,
                          camera_height_sigma_m=(CAMERA_HEIGHT_SIGMA_M if args.camera_height_error is None
                                                 else args.camera_height_error),
                          felt_height_m=args.felt_height, nose_height_m=args.nose_height, **kw)
    cam = cal.camera
    physics = {k: v for k, v in (("R", args.R), ("mu_s", args.mu_s), ("mu_r", args.mu_r)) if v is not None}
    camd = {"fps": cam.fps, "width": cam.width, "height": cam.height}
    if cam.homography is not None:
        camd["homography"] = [list(r) for r in cam.homography]
    if cam.intrinsics is not None:
        camd["intrinsics"] = [list(r) for r in cam.intrinsics]
    if cam.distortion is not None:
        camd["distortion"] = list(cam.distortion)
    if cam.is_pinhole:
        camd["rvec"], camd["tvec"] = list(cam.rvec), list(cam.tvec)
    camd["exposure_s"] = 0.0
    scene = {"schema": SCHEMA, "physics": physics,
             "table": {"length": table.length, "width": table.width}, "camera": camd,
             "calibration": {"corners_px": cal.corners_px.tolist(), "corner_rms_px": cal.rms_px,
                             "corner_sigma_px": cal.corner_sigma_px,
                             "focal_from": cal.focal_source, "edge_rms_px": cal.edge_rms_px,
                             # The corners' error carried into v0 and w0 by the recovery.
                             "perturbed": [camera_to_dict(c, geometry_only=True) for c in cal.perturbed]}}
    tmp = out.with_name(out.name + ".part")
    tmp.write_text(json.dumps(scene, indent=2) + "\n")
    tmp.replace(out)
    for note in cal.notes:
        print(f"calibrate: {note}", file=sys.stderr)
    what = {"noses": "the cushions' noses", "felt": "the felt's outline"}.get(cal.edge, "")
    found = ("given" if corners is not None else
             f"found in the video ({what}, edges straight to {cal.edge_rms_px:.2f} px RMS)")
    where = (f"camera {cal.height_m:.2f} m above the cloth, tilted {cal.tilt_deg:.1f} deg, "
             f"f = {cam.K[0, 0]:.0f} px" + (f" +/- {100 * cal.focal_sigma:.1f}%" if cal.focal_sigma else "")
             + f" (from {cal.focal_source})" if cam.is_pinhole else
             "camera: the corners' homography")
    print(f"wrote {out}: corners {found}; corner reprojection {cal.rms_px:.2f} px RMS "
          f"(max {np.linalg.norm(cal.residual_px, axis=1).max():.2f} px); {where}")
    if not physics.get("R"):
        print("calibrate: physics.R not given (--R): the scene assumes a pool ball's 0.028575 m",
              file=sys.stderr)
    return 0


def add_parser(sub) -> None:
    """Register ``cuespin calibrate`` on the CLI's subparsers."""
    c = sub.add_parser("calibrate", help="find the camera from the table: write a scene file's camera",
                       description="Find VIDEO's camera from the playing surface's four corners and write "
                                   "SCENE.json (physics, table and a pinhole camera in OpenCV's "
                                   "conventions). Corners: --corners in pixels, or found automatically "
                                   "from the felt in the video's median frame. The ball's centre is "
                                   "R above the cloth the corners lie on: the camera written accounts "
                                   "for it. See docs/calibration.md.")
    c.add_argument("video", help="the shot's video (or any video from the same fixed camera)")
    c.add_argument("-o", "--output", required=True, help="scene file to write (JSON)")
    c.add_argument("--corners", metavar="U1,V1,...,U4,V4",
                   help="pixels of the corners (0,0), (length,0), (length,width), (0,width): start at "
                        "any corner, go along a long side, counter-clockwise as seen on the screen")
    c.add_argument("--intrinsics", metavar="FILE",
                   help="lens calibration: JSON with intrinsics (3x3) and distortion [k1,k2,p1,p2,k3]")
    c.add_argument("--focal-px", type=float, default=None, help="focal length (px), without --intrinsics")
    c.add_argument("--camera-height", type=float, default=None, metavar="M",
                   help="the lens's height above the cloth (m), to fix the focal length without --intrinsics")
    c.add_argument("--camera-height-error", type=float, default=None, metavar="M",
                   help=f"error of --camera-height (m; default {CAMERA_HEIGHT_SIGMA_M:g}), carried into "
                        "v0's and w0's errors")
    c.add_argument("--corner-error", type=float, default=None, metavar="PX",
                   help="error of each corner coordinate (px; default 1 for clicked corners, "
                        "the edges' jackknife for automatic ones)")
    c.add_argument("--table", default=None, metavar="LENGTH,WIDTH",
                   help="playing surface (m; default 2.54,1.27)")
    c.add_argument("--felt-margin", type=float, default=0.0, metavar="M",
                   help="automatic, when no cushion nose shows: the felt-coloured outline lies this far "
                        "beyond the playing surface (m; cloth-covered cushions: their width)")
    c.add_argument("--felt-height", type=float, default=0.0, metavar="M",
                   help="automatic, when no cushion nose shows: that outline's height above the cloth (m)")
    c.add_argument("--nose-height", type=float, default=0.0, metavar="M",
                   help="height of the cushions' noses above the cloth (m; 0 for the renderer's flat "
                        "table, about 0.036 on a real pool table): the noses' line found automatically, "
                        "or --corners clicked where the noses meet, lies that high")
    c.add_argument("--homography", action="store_true",
                   help="write the corners' homography, not a pose: for top-down renders (an "
                        "orthographic view); a real camera D above the cloth reads distances short by R/D")
    c.add_argument("--R", type=float, default=None, help="ball radius (m), written to physics")
    c.add_argument("--mu-s", type=float, default=None, help="sliding friction, written to physics")
    c.add_argument("--mu-r", type=float, default=None, help="rolling friction, written to physics")
    c.set_defaults(func=cmd_calibrate)
