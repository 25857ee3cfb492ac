"""The camera model: homography and real (pinhole + distortion) cameras, round trips,
Jacobians, agreement with OpenCV, the ball's silhouette."""

import json

import cv2
import numpy as np
import pytest

from cuespin.physics.camera import (
    Camera,
    default_camera,
    is_mirrored,
    pinhole_camera,
    polygon_centroid,
    rodrigues,
    rotation_to_rvec,
)
from cuespin.physics.motion import BallParams
from cuespin.physics.scene import Scene, SceneError, Table, parse_scene, scene_to_dict

R = 0.028575
TABLE = Table()


def table_points(n, seed, margin=0.0):
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(margin, TABLE.length - margin, n),
                            rng.uniform(margin, TABLE.width - margin, n)])


def cameras():
    """The cameras the contract allows: top-down, a general homography, tilted
    pinholes with a phone's wide-lens distortion (both signs), a lens with a homography."""
    H = np.array([[480.0, 35.0, 40.0], [-20.0, -470.0, 660.0], [0.00002, 0.00004, 1.0]])
    cams = {
        "top-down": default_camera(),
        "homography": Camera(fps=240.0, width=1280, height=720, homography=tuple(map(tuple, H))),
        "pinhole": pinhole_camera(height_m=2.0, tilt_deg=12.0, R=R),
        "barrel": pinhole_camera(height_m=1.5, tilt_deg=15.0, k1=-0.25, k2=0.05, R=R, roll_deg=3.0),
        "pincushion": pinhole_camera(height_m=3.0, tilt_deg=5.0, k1=0.25, R=R),
    }
    K = ((900.0, 0.0, 640.0), (0.0, 900.0, 360.0), (0.0, 0.0, 1.0))
    cams["lens+homography"] = Camera(fps=240.0, width=1280, height=720,
                                     homography=tuple(map(tuple, H)), intrinsics=K,
                                     distortion=(-0.2, 0.03, 0.001, -0.0005, 0.0))
    return cams


@pytest.mark.parametrize("name", list(cameras()))
def test_round_trip_metres_pixels_metres(name):
    cam = cameras()[name]
    xy = table_points(500, 1)
    uv = cam.to_pixels(xy)
    assert np.all(np.isfinite(uv))
    np.testing.assert_allclose(cam.to_table(uv), xy, rtol=0, atol=1e-9)
    # single points keep their shape
    assert cam.to_pixels(xy[0]).shape == (2,) and cam.to_table(uv[0]).shape == (2,)
    np.testing.assert_allclose(cam.to_table(uv[0]), xy[0], atol=1e-9)


@pytest.mark.parametrize("name", ["pinhole", "barrel", "pincushion"])
def test_pinhole_sees_whole_table_inside_frame(name):
    cam = cameras()[name]
    uv = cam.to_pixels(table_points(2000, 2))
    assert uv[:, 0].min() > 0 and uv[:, 0].max() < cam.width - 1
    assert uv[:, 1].min() > 0 and uv[:, 1].max() < cam.height - 1


@pytest.mark.parametrize("name", list(cameras()))
def test_jacobian_matches_finite_differences(name):
    cam = cameras()[name]
    xy = table_points(50, 3)
    J = cam.jacobian(xy)
    assert J.shape == (50, 2, 2) and cam.jacobian(xy[0]).shape == (2, 2)
    h = 1e-6
    for j in range(2):
        d = np.zeros(2)
        d[j] = h
        fd = (cam.to_pixels(xy + d) - cam.to_pixels(xy - d)) / (2 * h)
        # central differences of ~1000 px/m maps: truncation ~1e-9, rounding ~1e-7
        np.testing.assert_allclose(J[:, :, j], fd, rtol=1e-7, atol=1e-5)


def test_top_down_jacobian_and_scale():
    cam = default_camera()
    np.testing.assert_allclose(cam.jacobian([1.0, 0.5]), [[500.0, 0.0], [0.0, -500.0]])
    assert cam.px_per_m([1.0, 0.5]) == pytest.approx(500.0)
    cov = cam.cov_to_table([[1.0, 0.5]], np.eye(2)[None] * 0.25)
    np.testing.assert_allclose(cov[0], np.eye(2) * 0.25 / 500.0**2)


@pytest.mark.parametrize("name", ["pinhole", "barrel", "pincushion"])
def test_agrees_with_cv2_project_points(name):
    cam = cameras()[name]
    xy = table_points(300, 4)
    X = np.column_stack([xy, np.full(len(xy), R)])
    ref, _ = cv2.projectPoints(X, np.array(cam.rvec), np.array(cam.tvec), cam.K, cam.dist)
    np.testing.assert_allclose(cam.to_pixels(xy), ref[:, 0, :], atol=1e-9)
    # arbitrary heights: the cloth (z = 0) and a rail top (z = 0.04)
    for z in (0.0, 0.04):
        X[:, 2] = z
        ref, _ = cv2.projectPoints(X, np.array(cam.rvec), np.array(cam.tvec), cam.K, cam.dist)
        np.testing.assert_allclose(cam.project(X), ref[:, 0, :], atol=1e-9)


def test_agrees_with_cv2_undistort_and_tangential_terms():
    cam = Camera(fps=60.0, width=1920, height=1080, intrinsics=((1400.0, 0.0, 955.0), (0.0, 1390.0, 545.0),
                                                                 (0.0, 0.0, 1.0)),
                 distortion=(-0.18, 0.06, 0.0015, -0.0008, -0.01),
                 rvec=tuple(rotation_to_rvec(rodrigues([np.pi * 0.93, 0.1, 0.05]))),
                 tvec=(-1.2, 0.7, 2.3), centre_height=R)
    xy = table_points(200, 5)
    X = np.column_stack([xy, np.full(len(xy), R)])
    ref, _ = cv2.projectPoints(X, np.array(cam.rvec), np.array(cam.tvec), cam.K, cam.dist)
    uv = cam.to_pixels(xy)
    np.testing.assert_allclose(uv, ref[:, 0, :], atol=1e-9)
    np.testing.assert_allclose(cam.to_table(uv), xy, atol=1e-9)


def test_rodrigues_matches_opencv():
    rng = np.random.default_rng(6)
    for _ in range(20):
        r = rng.normal(size=3) * rng.uniform(0.0, 3.1)
        np.testing.assert_allclose(rodrigues(r), cv2.Rodrigues(r)[0], atol=1e-12)
        np.testing.assert_allclose(rodrigues(rotation_to_rvec(rodrigues(r))), rodrigues(r), atol=1e-9)


def brute_force_silhouette(cam, xy, R, n_px=601, half=None):
    """Centroid of a sphere's image by dense ray casting: every pixel-grid ray
    (through the lens, undistorted) that meets the sphere."""
    c_px = cam.to_pixels(xy)
    r_px = R * cam.px_per_m(xy)
    half = half or 1.6 * r_px
    g = np.linspace(-half, half, n_px)
    uu, vv = np.meshgrid(c_px[0] + g, c_px[1] + g)
    uv = np.column_stack([uu.ravel(), vv.ravel()])
    K = cam.K
    nd = np.column_stack([(uv[:, 0] - K[0, 2]) / K[0, 0], (uv[:, 1] - K[1, 2]) / K[1, 1]])
    from cuespin.physics.camera import _undistort
    n = _undistort(nd, cam.dist)
    d = np.column_stack([n, np.ones(len(n))])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    C = cam.rotation @ np.array([xy[0], xy[1], R]) + np.array(cam.tvec)
    # ray meets sphere when its distance from the centre is below R
    proj = d @ C
    hit = (C @ C - proj**2) < R * R
    return uv[hit].mean(axis=0) - c_px


@pytest.mark.parametrize("name", ["pinhole", "barrel"])
def test_silhouette_against_brute_force(name):
    cam = cameras()[name]
    xy = np.array([0.15, 0.12])                   # a corner: the largest offset
    off = cam.silhouette_centroid_offset(xy)
    brute = brute_force_silhouette(cam, xy, R)
    # grid pitch ~0.07 px: the hit mask's centroid came within 2e-4 px (601-2001 rays a side)
    np.testing.assert_allclose(off, brute, atol=1e-3)
    assert np.linalg.norm(off) > 0.01           # and the offset is real, not zero


def test_top_down_silhouette_is_the_circle():
    cam = default_camera()
    poly = cam.ball_outline([[1.0, 0.5]], R, n=360)[0]
    c = cam.to_pixels([1.0, 0.5])
    np.testing.assert_allclose(np.linalg.norm(poly - c, axis=1), R * 500.0, rtol=1e-12)
    np.testing.assert_allclose(cam.silhouette_centroid_offset([1.0, 0.5], R), [0.0, 0.0], atol=1e-9)


def test_pinhole_outline_is_ellipse_tangent_cone():
    # Without distortion, every outline point's ray is tangent to the sphere.
    cam = cameras()["pinhole"]
    xy = np.array([2.2, 1.0])
    poly = cam.ball_outline(xy, n=90)
    n = np.column_stack([(poly - cam.K[:2, 2]) / np.diag(cam.K)[:2], np.ones(len(poly))])
    d = n / np.linalg.norm(n, axis=1, keepdims=True)
    C = cam.rotation @ np.array([*xy, R]) + np.array(cam.tvec)
    dist_ray = np.sqrt(C @ C - (d @ C) ** 2)
    np.testing.assert_allclose(dist_ray, R, rtol=1e-9)


def test_polygon_centroid():
    sq = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]])
    np.testing.assert_allclose(polygon_centroid(sq), [1.0, 0.5])
    np.testing.assert_allclose(polygon_centroid(sq[::-1]), [1.0, 0.5])


def test_mirrored_homography_detected():
    cam = default_camera()
    assert not is_mirrored(cam.H, [1.0, 0.5])
    flip = cam.H @ np.diag([1.0, -1.0, 1.0]) + np.array([[0, 0, 0], [0, 0, -635.0 + 635.0], [0, 0, 0]])
    assert is_mirrored(flip, [1.0, -0.5])
    for name, c in cameras().items():
        assert not is_mirrored(c.H, [1.27, 0.6]), name


def test_pinhole_camera_geometry():
    cam = pinhole_camera(height_m=2.5, tilt_deg=10.0, R=R)
    assert cam.is_pinhole and not default_camera().is_pinhole
    assert cam.centre[2] == pytest.approx(2.5)
    # the optical axis meets the cloth at the table's centre: it images at the principal point
    np.testing.assert_allclose(cam.project([1.27, 0.635, 0.0]), cam.K[:2, 2], atol=1e-9)
    # far side (y = W) above the near side, +x to the right: not mirrored
    a, b = cam.to_pixels([[1.27, 1.2], [1.27, 0.1]])
    assert a[1] < b[1]
    assert cam.to_pixels([2.4, 0.6])[0] > cam.to_pixels([0.1, 0.6])[0]


def test_scene_sets_centre_height_and_round_trips():
    cam = pinhole_camera(height_m=1.8, tilt_deg=14.0, k1=-0.2)     # no R yet
    scene = Scene(physics=BallParams(R=0.03075), camera=cam)
    assert scene.camera.centre_height == 0.03075
    d = json.loads(json.dumps(scene_to_dict(scene)))
    assert "homography" not in d["camera"] and len(d["camera"]["distortion"]) == 5
    again = parse_scene(d)
    assert again == scene
    xy = table_points(20, 7)
    np.testing.assert_allclose(again.camera.to_pixels(xy), scene.camera.to_pixels(xy), atol=1e-12)
    # a different R is a different centre plane: the pixels move
    other = Scene(physics=BallParams(R=0.0286), camera=cam)
    assert np.abs(other.camera.to_pixels(xy) - scene.camera.to_pixels(xy)).max() > 0.05


def test_pose_from_opencv_shapes_accepted():
    cam = pinhole_camera(height_m=2.0, tilt_deg=8.0, k1=-0.1, R=R)
    d = {"physics": {"R": R}, "camera": {
        "fps": 30, "intrinsics": [list(r) for r in cam.intrinsics],
        "distortion": [list(cam.dist)],                          # calibrateCamera's (1, 5)
        "rvec": [[v] for v in cam.rvec], "tvec": [[v] for v in cam.tvec],   # solvePnP's (3, 1)
        "homography": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}}        # ignored with a pose
    s = parse_scene(d)
    assert s.camera.is_pinhole and s.camera.width is None
    np.testing.assert_allclose(s.camera.to_pixels([1.0, 0.5]), cam.to_pixels([1.0, 0.5]), atol=1e-9)
    assert s.camera.with_size(1280, 720).width == 1280
    assert s.camera.with_size(1280, 720).with_size(640, 480).height == 720


def _cam_dict(**kw):
    cam = pinhole_camera(height_m=2.0, tilt_deg=8.0, R=R)
    d = {"fps": 30, "intrinsics": [list(r) for r in cam.intrinsics],
         "rvec": list(cam.rvec), "tvec": list(cam.tvec)}
    for k, v in kw.items():
        if v is KeyError:
            d.pop(k, None)
        else:
            d[k] = v
    return {"physics": {"R": R}, "camera": d}


@pytest.mark.parametrize("kw,expect", [
    ({"intrinsics": KeyError, "distortion": [0.1, 0, 0, 0, 0]}, "camera.distortion: needs camera.intrinsics"),
    ({"intrinsics": KeyError}, "camera.rvec: a pose needs camera.intrinsics"),
    ({"tvec": KeyError}, "camera.tvec: required with camera.rvec"),
    ({"rvec": KeyError}, "camera.rvec: required with camera.tvec"),
    ({"intrinsics": [[1000, 0, 640], [0, 1000, 360]]}, "camera.intrinsics: expected shape [3, 3]"),
    ({"intrinsics": [[1000, 5, 640], [0, 1000, 360], [0, 0, 1]]}, "camera.intrinsics: expected [[fx, 0, cx]"),
    ({"intrinsics": [[-1000, 0, 640], [0, 1000, 360], [0, 0, 1]]}, "camera.intrinsics: expected [[fx, 0, cx]"),
    ({"distortion": [0.1, 0.0, 0.0]}, "camera.distortion: expected shape [5]"),
    ({"distortion": [0.1, 0.0, 0.0, float("nan"), 0.0]}, "camera.distortion: must be finite"),
    ({"rvec": [0.1, 0.2]}, "camera.rvec: expected shape [3]"),
    ({"tvec": [0.0, float("inf"), 2.0]}, "camera.tvec: must be finite"),
    ({"tvec": [0.0, 0.0, -2.0]}, "camera.tvec: the camera's centre is"),
    ({"rvec": KeyError, "tvec": KeyError}, "camera.homography: required key is missing"),
    ({"rvec": KeyError, "tvec": KeyError, "intrinsics": KeyError,
      "homography": [[500, 0, 5], [0, 500, 5], [0, 0, 1]]}, "camera.homography: mirrored"),
    ({"rvec": KeyError, "tvec": KeyError, "intrinsics": KeyError,
      "homography": [[500, 0, 5], [0, -500, 635], [0.0, -1.0, 1]]}, "camera.homography: the table's corners"),
])
def test_invalid_camera_keys_name_the_key(kw, expect):
    with pytest.raises(SceneError) as err:
        parse_scene(_cam_dict(**kw))
    assert str(err.value).startswith(expect), str(err.value)
    assert "\n" not in str(err.value)


def test_parse_records_defaults():
    s = parse_scene({"physics": {"mu_s": 0.3}, "camera": {"fps": 30, "homography": [[500, 0, 5], [0, -500, 635],
                                                                                     [0, 0, 1]]}})
    assert dict(s.defaulted) == {"physics.R": 0.028575, "physics.mu_r": 0.01}
    assert s.camera.width is None and s.camera.height is None


def test_vectorised_speed():
    # The tracker converts per frame and the renderer per blur node: 10^4 points
    # through the distorting camera must be far faster than a frame's decode (~ms).
    import time
    cam = cameras()["barrel"]
    xy = table_points(10000, 8)
    uv = cam.to_pixels(xy)
    t = time.perf_counter()
    cam.to_table(uv)
    cam.jacobian(xy)
    assert time.perf_counter() - t < 0.5


@pytest.mark.parametrize("name", ["barrel", "pincushion", "top-down"])
def test_to_plane_inverts_project_at_any_height(name):
    cam = cameras()[name]
    xy = table_points(200, 9, margin=-0.1)          # the rails too
    for z in (0.0, 0.037):
        X = np.column_stack([xy, np.full(len(xy), z)])
        np.testing.assert_allclose(cam.to_plane(cam.project(X), z), xy, atol=1e-9)
