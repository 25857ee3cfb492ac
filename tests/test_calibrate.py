"""``cuespin calibrate``: the camera from the table's corners, clicked or found, and its checks.

Frames are drawn with cv2 (``synthetic_table_frame``: a felt quadrilateral through a
tilted, distorting camera on wood, by 4x supersampling, with sensor noise and balls),
written as real FFV1 video and read back by the command itself.
"""

import io
import json
import math
import subprocess
import sys

import av
import cv2
import numpy as np
import pytest
from cuespin.physics.camera import pinhole_camera
from cuespin.physics.motion import BallParams
from cuespin.physics.scene import Scene, Table, parse_scene
from cuespin.pipeline.calibrate import (
    EDGE_PATTERN_PX,
    KAPPA_PATTERN_K1,
    CalibrationError,
    calibrate_corners,
    detect_corners,
    matched_corner_errors,
    synthetic_table_frame,
    table_corners,
)

R = 0.028575
TABLE = Table()
SIZE = (1280, 720)
# Automatic corners: the target on rendered scenes.
AUTO_CORNER_RMS_PX = 0.5


def true_corners(cam, table=TABLE):
    return cam.project(table_corners(table))


def scene_camera(cal):
    return Scene(physics=BallParams(R=R), camera=cal.camera).camera


def ball_grid():
    xs, ys = np.meshgrid(np.linspace(0.1, 2.44, 9), np.linspace(0.1, 1.17, 5))
    return np.column_stack([xs.ravel(), ys.ravel()])


def metre_error(cal, true):
    xy = ball_grid()
    return float(np.abs(scene_camera(cal).to_table(true.to_pixels(xy)) - xy).max())


@pytest.mark.parametrize("tilt,k1", [(0.0, 0.0), (8.0, -0.2), (15.0, 0.25)])
def test_exact_corners_with_intrinsics_give_the_camera(tilt, k1):
    true = pinhole_camera(height_m=2.0, tilt_deg=tilt, k1=k1, R=R, size=SIZE)
    cal = calibrate_corners(true_corners(true), SIZE, intrinsics=true.K, distortion=true.dist)
    assert cal.rms_px < 1e-6 and cal.focal_source == "intrinsics"
    assert metre_error(cal, true) < 1e-9
    assert cal.height_m == pytest.approx(2.0, abs=1e-9) and cal.tilt_deg == pytest.approx(tilt, abs=1e-6)


def test_focal_length_from_tilted_corners_and_from_camera_height():
    tilted = pinhole_camera(height_m=2.0, tilt_deg=12.0, R=R, size=SIZE)
    cal = calibrate_corners(true_corners(tilted), SIZE)
    assert cal.focal_source == "corners" and metre_error(cal, tilted) < 1e-9
    overhead = pinhole_camera(height_m=2.5, tilt_deg=0.0, R=R, size=SIZE)
    cal = calibrate_corners(true_corners(overhead), SIZE, camera_height_m=2.5)
    assert cal.focal_source == "camera-height" and metre_error(cal, overhead) < 1e-9


def test_overhead_without_focal_length_says_what_it_assumed():
    true = pinhole_camera(height_m=2.0, tilt_deg=0.0, R=R, size=SIZE)
    cal = calibrate_corners(true_corners(true), SIZE)
    assert cal.focal_source == "nominal" and "--camera-height" in cal.notes[0]
    # The cloth's homography alone (the ball plane taken as the cloth) is off by
    # R / D = 1.4% of every distance; the nominal focal length keeps that to the
    # few 0.1% the note states.
    xy = ball_grid()
    err = np.abs(scene_camera(cal).to_table(true.to_pixels(xy)) - xy)
    rel = err.max() / 1.27
    assert rel < 0.006


def test_ball_plane_is_not_the_cloth():
    # A camera calibrated on the cloth and used for the ball's centre unchanged
    # would be off by R / D: measure it, so the correction above is needed.
    true = pinhole_camera(height_m=2.0, tilt_deg=10.0, R=R, size=SIZE)
    cloth = Scene(physics=BallParams(R=1e-12), camera=true).camera   # centre plane = cloth
    xy = ball_grid()
    err = np.abs(cloth.to_table(true.to_pixels(xy)) - xy).max()
    assert err > 0.01                                     # ~ R / D x 1.3 m: 1.8 cm


def test_mirrored_and_implausible_corners_refused():
    true = pinhole_camera(height_m=2.0, tilt_deg=10.0, R=R, size=SIZE)
    c = true_corners(true)
    with pytest.raises(CalibrationError, match="mirrored"):
        calibrate_corners(c[::-1], SIZE, intrinsics=true.K)
    with pytest.raises(CalibrationError, match="mirrored"):
        calibrate_corners(c[[0, 3, 2, 1]], SIZE)
    with pytest.raises(CalibrationError, match="convex"):
        calibrate_corners(c[[0, 2, 1, 3]], SIZE)
    with pytest.raises(CalibrationError, match="outside"):
        calibrate_corners(c + [0, 700], SIZE)
    # starting along a short side: no 2.54 x 1.27 rectangle fits with this lens
    with pytest.raises(CalibrationError, match="no 2.54 x 1.27 m rectangle"):
        calibrate_corners(np.roll(c, 1, axis=0), SIZE, intrinsics=true.K)


@pytest.mark.parametrize("tilt,k1,height,cushion", [(10.0, 0.0, 2.0, 0.0), (15.0, -0.2, 1.8, 0.05)])
def test_automatic_corners_on_a_drawn_frame(tilt, k1, height, cushion):
    # rolled 1 deg: the drawing puts an edge on a multiple of 1/4 px, which
    # averages out only along edges off the pixel axes
    true = pinhole_camera(height_m=height, tilt_deg=tilt, k1=k1, R=R, size=SIZE, roll_deg=1.0)
    img = synthetic_table_frame(true, seed=int(tilt), cushion_m=cushion, pockets=cushion > 0)
    det = detect_corners(img)
    quad, edge_rms, kappa = det.corners, det.edge_rms, det.kappa
    # with darker cushions around it, the playing surface's edge is their noses
    assert det.edge == ("noses" if cushion else "felt")
    truth = true_corners(true)
    # the detected quad's first corner is wherever the outline starts: match by rotation
    d = matched_corner_errors(quad, truth)[0]
    rms = float(np.sqrt(np.mean(np.sum(d**2, axis=1))))
    assert rms < AUTO_CORNER_RMS_PX, (rms, d)
    assert edge_rms < 1.0
    # the lens estimated from the bowed edges: k1 = kappa f^2 within 10%
    assert kappa * true.K[0, 0] ** 2 == pytest.approx(k1, abs=0.02)


def write_video(frames, path, fps=30.0):
    """Colour FFV1 (lossless), through OpenCV's FFmpeg writer."""
    h, w = frames[0].shape[:2]
    wr = cv2.VideoWriter(str(path), cv2.CAP_FFMPEG, cv2.VideoWriter_fourcc(*"FFV1"), fps, (w, h), True)
    assert wr.isOpened()
    for f in frames:
        wr.write(f)
    wr.release()


def run_cli(*args):
    return subprocess.run([sys.executable, "-m", "cuespin.pipeline.cli", *map(str, args)],
                          capture_output=True, text=True, timeout=120)


def run_main(capsys, *args):
    """The command line in this process (argument parsing, files, exit status as a user gets them)."""
    from cuespin.pipeline.cli import main

    capsys.readouterr()
    code = main([str(a) for a in args])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_cli_calibrate_automatic_and_with_corners(tmp_path, capsys):
    true = pinhole_camera(height_m=2.0, tilt_deg=12.0, R=R, size=SIZE, fps=30.0, roll_deg=1.0)
    frames = [synthetic_table_frame(true, seed=1, cushion_m=0.05, pockets=True)]
    video = tmp_path / "table.avi"
    write_video(frames, video)
    out = tmp_path / "scene.json"
    p = run_cli("calibrate", video, "-o", out, "--R", R)      # the installed command, once
    assert p.returncode == 0, p.stderr
    scene = parse_scene(json.loads(out.read_text()))
    assert scene.camera.is_pinhole and (scene.camera.width, scene.camera.height) == SIZE
    assert scene.camera.fps == 30.0
    xy = ball_grid()
    err = np.abs(scene.camera.to_table(true.to_pixels(xy)) - xy).max()
    assert err < 1e-3, err
    assert "corner reprojection" in p.stdout and "noses" in p.stdout
    # the corners' error from the edges' jackknife (real: 0.02-0.04 px on drawn
    # tables), carried by 9 cameras moving the corners and the bow together
    # (and the corners' share of f); f from the corners and the drawn balls
    # (choose_focal), the balls' share in a tenth camera, said on stdout
    calib = json.loads(out.read_text())["calibration"]
    assert calib["focal_from"] == "corners+balls" and "% (from corners+balls)" in p.stdout, p.stdout
    assert 0.005 < calib["corner_sigma_px"] < 0.1 and len(calib["perturbed"]) == 10, calib["corner_sigma_px"]
    # clicked corners, rounded to whole pixels as a click is
    c = np.round(true_corners(true), 0).ravel()
    code, out_txt, err_txt = run_main(capsys, "calibrate", video, "-o", out, "--corners", ",".join(f"{v:g}" for v in c))
    assert code == 0, err_txt
    # the same rule for f as found corners, its error stated, 8 cameras and one for the balls' share
    calib = json.loads(out.read_text())["calibration"]
    assert calib["focal_from"] == "corners+balls" and "% (from corners+balls)" in out_txt, out_txt
    # (and one for the lens's bow, read from the table's edges in the video)
    assert calib["corner_sigma_px"] == 1.0 and len(calib["perturbed"]) == 10
    assert "bow from the table's edges" in err_txt
    # mirrored: refused, one line, exit 2
    cm = np.round(true_corners(true)[::-1], 0).ravel()
    code, _, err_txt = run_main(capsys, "calibrate", video, "-o", out, "--corners", ",".join(f"{v:g}" for v in cm))
    assert code == 2 and "mirrored" in err_txt and err_txt.strip().count("\n") == 0
    code, _, err_txt = run_main(capsys, "calibrate", video, "-o", out, "--corners", "1,2,3")
    assert code == 2 and "--corners: expected 8 numbers" in err_txt
    code, _, err_txt = run_main(capsys, "calibrate", tmp_path / "none.avi", "-o", out)
    assert code == 2 and "not found" in err_txt
    code, _, err_txt = run_main(capsys, "calibrate", video, "-o", out, "--camera-height", "2",
                                "--camera-height-error", "-1")
    assert code == 2 and "--camera-height-error" in err_txt and err_txt.strip().count("\n") == 0
    for bad in ("nan", "-0.5", "0"):
        code, _, err_txt = run_main(capsys, "calibrate", video, "-o", out, "--corner-error", bad)
        assert code == 2 and "--corner-error" in err_txt and err_txt.strip().count("\n") == 0, err_txt


def corner_errors(img, truth):
    """(stated, real) RMS error of a corner coordinate found automatically (px):
    the edges' jackknife and the distance from the true corners."""
    det = detect_corners(img)
    d = matched_corner_errors(det.corners, truth)[0]
    return float(np.sqrt(np.trace(det.corner_cov[:8, :8]) / 8.0)), float(np.sqrt(np.mean(d**2)))


def test_the_automatic_corners_stated_error_is_their_real_one():
    # The edge points along a side are correlated (smoothing, the drawing's
    # staircase), so their scatter over their number states the corners 2-4
    # times too sure; the edges' jackknife (with the bow re-estimated) gave
    # stated/real 0.6-1.8 per frame on 23 of 24 drawn frames (one, a side with
    # stray points, 5.1) and 1.04 pooled on these three (0.82, 1.04, 1.08;
    # docs/calibration.md, section 6).
    true = pinhole_camera(height_m=2.0, tilt_deg=10.0, k1=-0.25, R=R, size=SIZE, fps=240.0, roll_deg=1.0)
    truth = true_corners(true)
    pairs = np.array([corner_errors(synthetic_table_frame(true, seed=125 + 1000 * s, cushion_m=0.05, pockets=True),
                                    truth) for s in range(3)])
    ratio = np.sqrt(np.mean(pairs[:, 0] ** 2) / np.mean(pairs[:, 1] ** 2))
    assert 0.5 < ratio < 2.0, pairs
    # far below the 0.2 px floor stated before (3-7 times the real error)
    assert pairs[:, 0].max() < 0.1, pairs


# The stated covariance against the real errors of the corners and k1 on
# drawn frames of a distorted lens: the mean Mahalanobis distance per
# coordinate, e' C^-1 e / 9.  EDGE_PATTERN_PX was set on 8 cameras x noise
# seeds 0-39 (2 m, 10 deg, k1 -0.25 among them); this test uses a camera
# outside those (2.5 m, 7 deg, k1 -0.15) and fresh seeds (review 10a).
# Measured over 8-frame sets: with the pattern 0.70-0.96 on this camera
# (three sets), 0.72-1.00 on three cameras (eight sets); the jackknife alone
# 1.18-1.89, always 1.60-1.90 times the distance with the pattern.  The band
# is the sd over 8 frames (72 terms: 0.17) and the jackknife's own scatter;
# the ratio's floor is under its smallest measured value.
MAHALANOBIS_BAND = (0.6, 1.5)
ALONE_OVER_PATTERN_MIN = 1.4


def test_the_automatic_corners_covariance_is_honest_on_a_distorted_lens():
    true = pinhole_camera(height_m=2.5, tilt_deg=7.0, k1=-0.15, R=R, size=SIZE, fps=240.0, roll_deg=1.0)
    truth = true_corners(true)
    kappa = -0.15 / true.K[0, 0] ** 2
    with_pattern, alone = [], []
    for s in range(8):
        det = detect_corners(synthetic_table_frame(true, seed=7 + 1000 * s, cushion_m=0.05, pockets=True))
        d, idx = matched_corner_errors(det.corners, truth)
        idx, e = np.r_[idx, 8], np.r_[d.ravel(), det.kappa - kappa]
        C = det.corner_cov[np.ix_(idx, idx)]
        for out, cov in ((with_pattern, C), (alone, C - EDGE_PATTERN_PX**2 * np.diag(np.r_[np.ones(8), 0.0]))):
            d = np.sqrt(np.diag(cov))       # in correlation form: px and px^-2 differ by some 1e8
            out.append((e / d) @ np.linalg.solve(cov / np.outer(d, d), e / d) / 9.0)
    lo, hi = MAHALANOBIS_BAND
    assert lo < np.mean(with_pattern) < hi, with_pattern
    assert np.mean(alone) > ALONE_OVER_PATTERN_MIN * np.mean(with_pattern), (alone, with_pattern)


# k1's bias straight overhead (2 m, k1 -0.25: +2.3 of its scatter over 40
# noise seeds) is the drawn frame's supersampling pattern, not the lens
# model's or the edge locator's: on the noise-free frame k1 is +0.00026 off
# at the drawing's 4x and +0.00004 at 16x (measured), where the edges land
# on multiples of 1/16 px instead of 1/4 (the 4x error over 4, 0.000065, with
# a 1.5 margin: 0.0001).  With KAPPA_PATTERN_K1 the 4x frame's kappa is
# 1.49 of its stated error (2.6 with the jackknife alone; this camera's
# pattern is the largest of the 8 measured): within 1.96.
K1_AT_16X_MAX = 1e-4
K1_PATTERN_Z_MAX = 1.96


def test_k1s_bias_straight_overhead_is_the_drawings_pattern():
    true = pinhole_camera(height_m=2.0, tilt_deg=0.0, k1=-0.25, R=R, size=SIZE, fps=240.0, roll_deg=1.0)
    f2 = true.K[0, 0] ** 2
    err, z, alone = {}, {}, {}
    for ss in (4, 16):
        det = detect_corners(synthetic_table_frame(true, seed=0, noise=0.0, ss=ss, cushion_m=0.05, pockets=True))
        err[ss] = det.kappa - (-0.25 / f2)
        z[ss] = err[ss] / math.sqrt(det.corner_cov[8, 8])
        alone[ss] = err[ss] / math.sqrt(det.corner_cov[8, 8] - (KAPPA_PATTERN_K1 / (0.5 * max(SIZE)) ** 2) ** 2)
    assert abs(err[16] * f2) < K1_AT_16X_MAX < abs(err[4] * f2), err
    assert abs(z[4]) < K1_PATTERN_Z_MAX < abs(alone[4]), (z, alone)


@pytest.mark.slow
def test_the_automatic_corners_stated_error_on_the_renderers_realistic_table():
    # The realistic look's felt texture scatters the edge points by 0.6 px and
    # correlates them along a side; the jackknife's stated/real on the
    # renderer's tables, top-down and tilted 10 deg with k1 -0.25 (measured
    # 1.29, 1.49 and 1.38, 1.31 over two texture seeds; 0.72-1.73 over
    # 12 such frames, one 4.1).
    from dataclasses import replace

    from cuespin.data_gen.sampler import make_scene, sample_shot
    from cuespin.physics.camera import Camera
    from cuespin.physics.motion import Shot
    from cuespin.render.draw import FrameRenderer

    shot, params = sample_shot(100, "random")
    scene = make_scene(Shot(shot.x0, shot.v0, shot.w0, t0=0.1), params,
                       render={"look": "realistic", "noise_sigma": 2.0, "seed": 1})
    top = Camera(fps=240.0, width=1400, height=756, homography=((500.0, 0, 60.0), (0, -500.0, 695.0), (0, 0, 1.0)))
    tilted = pinhole_camera(height_m=2.0, tilt_deg=10.0, k1=-0.25, size=SIZE, fps=240.0, roll_deg=1.0,
                            margin_m=0.15, R=params.R)
    for cam, truth in ((top, top.to_pixels(table_corners(TABLE)[:, :2])), (tilted, true_corners(tilted))):
        img = next(iter(FrameRenderer(replace(scene, camera=cam), n_frames=1).frames()))
        stated, real = corner_errors(img, truth)
        assert 0.5 < stated / real < 2.5, (stated, real)


@pytest.mark.slow
def test_cli_calibrate_with_lens_file(tmp_path, capsys):
    true = pinhole_camera(height_m=1.6, tilt_deg=14.0, k1=-0.22, R=R, size=SIZE, fps=30.0)
    video = tmp_path / "table.avi"
    write_video([synthetic_table_frame(true, seed=5)], video)
    lens = tmp_path / "lens.json"
    lens.write_text(json.dumps({"intrinsics": true.K.tolist(), "distortion": [list(true.dist)]}))
    out = tmp_path / "scene.json"
    code, _, err_txt = run_main(capsys, "calibrate", video, "-o", out, "--intrinsics", lens)
    assert code == 0, err_txt
    cam = parse_scene(json.loads(out.read_text())).camera
    xy = ball_grid()
    assert np.abs(cam.to_table(true.to_pixels(xy)) - xy).max() < 1e-3
    lens.write_text(json.dumps({"distortion": [0.1, 0, 0, 0, 0]}))
    code, _, err_txt = run_main(capsys, "calibrate", video, "-o", out, "--intrinsics", lens)
    assert code == 2 and "intrinsics: required key is missing" in err_txt


def test_perturbed_cameras_move_one_corner_each():
    from cuespin.pipeline.calibrate import perturbed_cameras

    true = pinhole_camera(height_m=2.0, tilt_deg=10.0, R=R, size=SIZE)
    c = true_corners(true)
    cams = perturbed_cameras(c, 0.5, SIZE, intrinsics=true.K)
    assert len(cams) == 8
    xy = np.array([[1.27, 0.635]])
    moves = [np.abs(Scene(physics=BallParams(R=R), camera=cam).camera.to_table(true.to_pixels(xy)) - xy).max()
             for cam in cams]
    # half a pixel at one corner moves the table's middle by a fraction of a mm, never zero
    assert all(1e-6 < m < 2e-3 for m in moves), moves


def test_a_nominal_focal_length_carries_its_error_in_a_ninth_camera():
    # Overhead, a distorting lens, no focal length given: the corners (and
    # the edges' bow, k1 / f^2) cannot fix f, which sets the camera's height
    # and so the ball plane's scale (1 + R / D).  The ninth perturbed camera
    # has f NOMINAL_FOCAL_SIGMA longer, the same bow in pixels, the same
    # corners; it moves the table's middle by about R / D times that share of
    # the distance from the optical axis, and no corner.
    from cuespin.pipeline.calibrate import NOMINAL_FOCAL_SIGMA, perturbed_cameras

    true = pinhole_camera(height_m=2.0, tilt_deg=0.0, k1=-0.25, R=R, size=SIZE)
    c = true_corners(true)
    kappa = -0.25 / true.K[0, 0] ** 2
    cal = calibrate_corners(c, SIZE, kappa=kappa)
    assert cal.focal_source == "nominal"
    cams = perturbed_cameras(c, 0.2, SIZE, kappa=kappa)
    assert len(cams) == 9
    f0, f9 = cal.camera.K[0, 0], cams[8].K[0, 0]
    assert f9 / f0 == pytest.approx(1 + NOMINAL_FOCAL_SIGMA, rel=1e-9)
    assert cams[8].dist[0] / f9**2 == pytest.approx(kappa, rel=1e-9)        # the same bow in pixels
    on = Scene(physics=BallParams(R=R), camera=cams[8]).camera.with_centre_height(0.0)
    assert np.abs(on.project(table_corners(TABLE)) - cal.corners_px).max() < 0.01
    xy = np.array([[0.3, 0.2]])
    move = np.abs(scene_camera(cal).to_pixels(xy) - Scene(physics=BallParams(R=R),
                                                          camera=cams[8]).camera.to_pixels(xy)).max()
    # px: R / D ~ 1.4%, 13% of it (D grows about as f), over the ~530 px from
    # the optical axis: 0.97 px, less the lens's pull at the edge (measured 0.76)
    assert 0.4 < move < 1.2, move
    # a focal length that was given or solved keeps the 8 corner cameras only
    assert len(perturbed_cameras(c, 0.2, SIZE, kappa=kappa, camera_height_m=2.0)) == 8
    # a measured height with its error: the ninth camera that much higher
    cams = perturbed_cameras(c, 0.2, SIZE, kappa=kappa, camera_height_m=2.0, height_sigma_m=0.02)
    assert len(cams) == 9 and cams[8].centre[2] == pytest.approx(2.02, abs=1e-6)


@pytest.mark.slow
def test_automatic_on_the_renderers_realistic_table():
    """The renderer's realistic look (textured felt, darker cushions, pockets,
    sights, a lighting ramp, lens blur), top-down with the rails in view: the
    cushions' noses are found and the corners' homography is the camera's."""
    from dataclasses import replace

    from cuespin.data_gen.sampler import make_scene, sample_shot
    from cuespin.physics.camera import Camera
    from cuespin.physics.motion import Shot
    from cuespin.pipeline.calibrate import assign_corners
    from cuespin.render.draw import FrameRenderer

    shot, params = sample_shot(100, "random")
    scene = make_scene(Shot(shot.x0, shot.v0, shot.w0, t0=0.1), params,
                       render={"look": "realistic", "noise_sigma": 2.0, "seed": 1})
    cam = Camera(fps=240.0, width=1400, height=756, homography=((500.0, 0, 60.0), (0, -500.0, 695.0), (0, 0, 1.0)))
    scene = replace(scene, camera=cam)
    img = next(iter(FrameRenderer(scene, n_frames=1).frames()))
    det = detect_corners(img)
    assert det.edge == "noses"
    truth = scene.camera.to_pixels(table_corners(TABLE)[:, :2])
    d = matched_corner_errors(det.corners, truth)[0]
    assert np.sqrt(np.mean(np.sum(d**2, axis=1))) < AUTO_CORNER_RMS_PX        # measured 0.19
    cal = assign_corners(det.corners, (1400, 756), TABLE, kappa=det.kappa, homography=True)
    got = Scene(physics=params, camera=cal.camera).camera
    xy = ball_grid()
    assert np.abs(got.to_table(scene.camera.to_pixels(xy)) - xy).max() < 1e-3


@pytest.mark.parametrize("k1", [-0.25, 0.0])
def test_overhead_focal_length_from_the_balls_shapes(k1):
    # Straight overhead the corners cannot fix f (a near wide lens or a far
    # long one); a still ball's image is a sphere's silhouette, stretched away
    # from the optical axis by about 1 / cos of its angle from it, which f
    # sets.  The drawn frame's ball near the corner fixes f to about 1%
    # (measured: 0.2-1.2% off; stated about 10%, the floor the renderer's
    # shaded balls set), where the nominal one is 2-5% off (up to 15% on a phone).
    from cuespin.pipeline.calibrate import NOMINAL_FOCAL, calibrate_frame

    true = pinhole_camera(height_m=2.0, tilt_deg=0.0, k1=k1, R=R, size=SIZE, fps=240.0, roll_deg=1.0)
    img = synthetic_table_frame(true, seed=int(100 * abs(k1)), cushion_m=0.05, pockets=True)
    cal = calibrate_frame(img, TABLE, fps=240.0, R_nominal=R)
    assert cal.focal_source == "balls" and "still balls" in cal.notes[0]
    f_true, f = true.K[0, 0], cal.camera.K[0, 0]
    sigma = cal.perturbed[-1].K[0, 0] / f - 1.0           # the last camera: f one error longer
    assert 0.0 < sigma < 0.12                             # BALL_SHAPE_FLOOR's 0.03: about 10%
    assert abs(f / f_true - 1.0) < 2.0 * sigma, (f / f_true - 1.0, sigma)
    assert abs(f / f_true - 1.0) < 0.5 * abs(NOMINAL_FOCAL * SIZE[0] / f_true - 1.0)
    # k1 follows f (the bow fixes k1 / f^2), and the ball plane with it
    assert cal.camera.dist[0] == pytest.approx(k1, abs=0.01)
    assert metre_error(cal, true) < 3e-4
    without = calibrate_frame(img, TABLE, fps=240.0, R_nominal=R, use_balls=False)
    assert without.focal_source == "nominal" and len(without.perturbed) == len(cal.perturbed)


def test_the_lens_bows_error_is_in_the_perturbed_cameras_and_moves_the_stated_error():
    # k1 estimated from the edges' bow carries its standard error (the edges'
    # jackknife, jointly with the corners'; measured 1-4e-4 in k1, real errors
    # 1-4e-4) in the perturbed cameras: each moves the corners and k1 together
    # along one direction of their joint covariance.
    from cuespin.data_gen.sampler import sample_shot
    from cuespin.physics.motion import phases, positions
    from cuespin.pipeline.calibrate import calibrate_frame
    from cuespin.recover.api import recover_track

    true = pinhole_camera(height_m=2.0, tilt_deg=10.0, k1=-0.25, R=R, size=SIZE, fps=240.0, roll_deg=1.0)
    img = synthetic_table_frame(true, seed=102, cushion_m=0.05, pockets=True)
    cal = calibrate_frame(img, TABLE, fps=240.0, R_nominal=R)
    # f from the corners and the drawn balls (choose_focal): 9 joint moves, one for the balls' share of f
    assert cal.focal_source == "corners+balls" and len(cal.perturbed) == 10
    f = cal.camera.K[0, 0]
    steps = np.array([c.dist[0] / c.K[0, 0] ** 2 * f**2 - cal.camera.dist[0] for c in cal.perturbed])  # in k1 at f
    dk1 = float(np.sqrt(np.sum(steps**2)))                 # kappa's standard error, in k1
    assert 5e-5 < dk1 < 2e-3
    k = cal.perturbed[int(np.argmax(np.abs(steps)))]
    # the bow in pixels (k1 / f^2; k1 itself follows the focal length found)
    k1_at_true_f = cal.camera.dist[0] / f**2 * true.K[0, 0] ** 2
    assert abs(k1_at_true_f + 0.25) < 4 * dk1, (k1_at_true_f, dk1)
    # the same track through the camera found and through the one that moves k1 most
    shot, p = sample_shot(3, "random")
    t = np.arange(0.0, min(phases(shot, p).t2 + 0.3, 3.0), 1 / 240.0)
    xy = positions(shot, p, t, phases(shot, p))
    t = t[TABLE.contains(xy, p.R).cumprod().astype(bool)]
    uv = Scene(physics=p, camera=true).camera.to_pixels(xy[:len(t)])

    def v0(cam):
        c = Scene(physics=p, camera=cam).camera
        m = recover_track(t, c.to_table(uv), np.ones(len(t), bool), np.full((len(t), 2), 1e-5), p, 0.0, "mle",
                          False, lossless=True)["methods"]["mle"]
        assert m["status"] == "ok"
        return np.array(m["v0"])
    shift = np.abs(v0(k) - v0(cal.camera))
    # it moves v0 by a measurable share of the fit's own error at the tracker's
    # 0.03 px (about 1e-3 m/s RMS; docs/calibration.md, section 6)
    assert 1e-6 < shift.max() < 1e-3, shift


@pytest.mark.slow
@pytest.mark.parametrize("look", [{}, {"light_elevation": 1.55}], ids=["default-light", "lamp-overhead"])
@pytest.mark.parametrize("k1", [-0.25, 0.0])
def test_overhead_focal_length_from_a_rendered_shaded_ball(k1, look):
    # The renderer's realistic look: a shaded ball (a highlight, lens blur;
    # lit from one side, or by a lamp straight overhead, a billiard table's
    # usual light) at rest near a corner before the strike, straight overhead.
    # Its outline puts f low: 2.9-5.3% under the default light, 6.5-8.7%
    # under the lamp (measured); the stated error must cover it at one sigma
    # (BALL_SHAPE_FLOOR 0.03 states 9.6-10.6%, the worst at 0.9 of it; the
    # former 0.01 stated 3.2%, 2.0-2.7x too small under the lamp: fails here).
    from dataclasses import replace

    from cuespin.data_gen.sampler import make_scene, sample_shot
    from cuespin.physics.motion import Shot
    from cuespin.pipeline.calibrate import calibrate_frame
    from cuespin.render.draw import FrameRenderer

    shot, params = sample_shot(100, "random")
    scene = make_scene(Shot(np.array([2.40, 1.15]), shot.v0, shot.w0, t0=0.1), params,
                       render={"look": "realistic", "noise_sigma": 2.0, "seed": 1, **look})
    true = pinhole_camera(height_m=2.0, tilt_deg=0.0, k1=k1, size=SIZE, fps=240.0, roll_deg=1.0, margin_m=0.15,
                          R=params.R)
    img = next(iter(FrameRenderer(replace(scene, camera=true), n_frames=1).frames()))
    cal = calibrate_frame(img, TABLE, fps=240.0, R_nominal=params.R)
    assert cal.focal_source == "balls"
    f = cal.camera.K[0, 0]
    sigma = cal.perturbed[-1].K[0, 0] / f - 1.0
    assert abs(f / true.K[0, 0] - 1.0) < sigma, (f / true.K[0, 0] - 1.0, sigma)


def test_the_focal_length_rule_takes_the_surer_source_or_both():
    # One rule at every tilt (choose_focal): a source counts when its stated
    # error is under the nominal focal length's 15%; of two, both, weighted by
    # their stated errors (the table's edges and the balls' outlines are
    # independent measurements).
    from cuespin.pipeline.calibrate import NOMINAL_FOCAL_SIGMA, choose_focal

    assert choose_focal(None, None) is None
    assert choose_focal((1000.0, 200.0), (1000.0, 160.0)) is None            # both over 15%
    assert choose_focal((1000.0, 20.0), (900.0, 160.0))[:3] == ("corners", 1000.0, 20.0)
    assert choose_focal((1000.0, 400.0), (900.0, 90.0))[:3] == ("balls", 900.0, 90.0)
    source, f, sigma, w = choose_focal((1000.0, 30.0), (900.0, 90.0))
    assert source == "corners+balls" and w == pytest.approx(0.9)
    assert f == pytest.approx(990.0) and sigma == pytest.approx(1.0 / np.hypot(1 / 30.0, 1 / 90.0))
    assert sigma < 30.0 < NOMINAL_FOCAL_SIGMA * f


def test_a_slightly_tilted_camera_takes_f_from_the_corners_and_the_balls():
    # At 2-3 degrees the jackknife's corner error (0.02-0.03 px) fixes f from
    # the corners to 2-6% (measured on 18 drawn frames: error / stated RMS
    # 0.98, at most 1.72), the drawn balls to about 10% (stated; 0-1.4% off):
    # f is their weighted mean, its error stated by both, and each perturbed
    # camera moves the corners' share of f with the corners, one more the balls'.
    from cuespin.pipeline.calibrate import calibrate_frame

    true = pinhole_camera(height_m=2.0, tilt_deg=2.5, k1=-0.25, R=R, size=SIZE, fps=240.0, roll_deg=1.0)
    img = synthetic_table_frame(true, seed=50, cushion_m=0.05, pockets=True)
    cal = calibrate_frame(img, TABLE, fps=240.0, R_nominal=R)
    assert cal.focal_source == "corners+balls" and "still balls" in cal.notes[0]
    f = cal.camera.K[0, 0]
    assert 0.01 < cal.focal_sigma < 0.08
    assert abs(f / true.K[0, 0] - 1.0) < 2.0 * cal.focal_sigma, (f / true.K[0, 0] - 1.0, cal.focal_sigma)
    assert len(cal.perturbed) == 10                     # 9 joint moves of the corners and k1, one for the balls
    moved = np.array([c.K[0, 0] for c in cal.perturbed[:9]]) / f - 1.0
    # the perturbed cameras' f carries (nearly all of) the stated error: the
    # corners' weighted share in the nine, the balls' in the tenth
    spread = np.sqrt(np.sum(moved**2) + (cal.perturbed[9].K[0, 0] / f - 1.0) ** 2)
    assert spread == pytest.approx(cal.focal_sigma, rel=1e-3), (spread, cal.focal_sigma)


@pytest.mark.slow
@pytest.mark.parametrize("tilt,k1,look", [(2.0, -0.25, {"light_elevation": 1.55}), (3.0, 0.0, {})],
                         ids=["2deg-lamp", "3deg-default-light"])
def test_a_slightly_tilted_rendered_camera_states_its_focal_lengths_error(tilt, k1, look):
    # The renderer's realistic table tilted 2-3 degrees: its felt's texture
    # leaves the corners 0.12-0.18 px sure, mostly too little to fix f (over
    # 15%), so the rule takes the shaded ball's (at rest near a corner), or
    # both; on 8 such frames (tilts 2 and 3, k1 0 and -0.25, both lights) f
    # came -8.0% to +5.3% off, error / stated 0.24-0.80: within one stated
    # error (before, the corners' f alone at 2 degrees, k1 -0.25: +52%).
    from dataclasses import replace

    from cuespin.data_gen.sampler import make_scene, sample_shot
    from cuespin.physics.motion import Shot
    from cuespin.pipeline.calibrate import calibrate_frame
    from cuespin.render.draw import FrameRenderer

    shot, params = sample_shot(100, "random")
    scene = make_scene(Shot(np.array([2.40, 1.15]), shot.v0, shot.w0, t0=0.1), params,
                       render={"look": "realistic", "noise_sigma": 2.0, "seed": 1, **look})
    true = pinhole_camera(height_m=2.0, tilt_deg=tilt, k1=k1, size=SIZE, fps=240.0, roll_deg=1.0, margin_m=0.15,
                          R=params.R)
    img = next(iter(FrameRenderer(replace(scene, camera=true), n_frames=1).frames()))
    cal = calibrate_frame(img, TABLE, fps=240.0, R_nominal=params.R)
    assert cal.focal_source in ("balls", "corners+balls")
    err = cal.camera.K[0, 0] / true.K[0, 0] - 1.0
    assert abs(err) < cal.focal_sigma < 0.15, (err, cal.focal_sigma)


def test_stray_edge_points_do_not_inflate_the_corners_stated_error():
    # A side with stray edge points between _fit_line's cut (6 robust sigmas)
    # and the clean points' reach (2.4-3.8): a jackknife run that leaves them
    # out moves its line, and the corners were stated 5.1 times their real
    # error on this frame (measured); dropped beyond STRAY_EDGE_Z (4) first,
    # 0.66 (24 drawn frames: 0.61-2.58, median 1.02).
    true = pinhole_camera(height_m=1.5, tilt_deg=15.0, k1=-0.25, R=R, size=SIZE, fps=240.0, roll_deg=1.0)
    img = synthetic_table_frame(true, seed=1175, cushion_m=0.05, pockets=True)
    stated, real = corner_errors(img, true_corners(true))
    assert 0.5 < stated / real < 2.0, (stated, real)
    kept = detect_corners(img, robust=False)                  # as before: the strays kept
    assert math.sqrt(np.trace(kept.corner_cov[:8, :8]) / 8.0) > 3.0 * real


@pytest.fixture(scope="module")
def drawn_10deg():
    """A drawn table 2 m up, tilted 10 degrees, straight lens (1 s to draw;
    shared by the clicked and given corners' tests)."""
    true = pinhole_camera(height_m=2.0, tilt_deg=10.0, R=R, size=SIZE, fps=240.0, roll_deg=1.0)
    return true, synthetic_table_frame(true, seed=100, cushion_m=0.05, pockets=True)


def test_clicked_corners_state_the_focal_lengths_error(drawn_10deg):
    # Clicked corners (no lens given) take the automatic path's rule for f
    # (choose_focal: the corners' perspective and the frame's still balls)
    # and state its error the same way: each coordinate moved by the click's
    # error (1 px) moves the corners' share of f in its perturbed camera, one
    # more carries the balls'.  Measured on drawn frames tilted 10 degrees,
    # corners 1 px off (benchmarks/calibration.py --clicked, 35 independent
    # draws): f 4.0% RMS off (-9.9..+8.0%), stated 5.9%.
    from cuespin.pipeline.calibrate import calibrate_clicked

    true, img = drawn_10deg
    c = true_corners(true) + np.random.default_rng(7).normal(0.0, 1.0, (4, 2))
    cal = calibrate_clicked(c, SIZE, TABLE, frame=img, corner_sigma_px=1.0, fps=240.0, R_nominal=R)
    assert cal.focal_source == "corners+balls" and 0.02 < cal.focal_sigma < 0.1, (cal.focal_source, cal.focal_sigma)
    f = cal.camera.K[0, 0]
    assert abs(f / true.K[0, 0] - 1.0) < 2.0 * cal.focal_sigma, (f / true.K[0, 0] - 1.0, cal.focal_sigma)
    assert len(cal.perturbed) == 10        # 8 coordinates, the edges' bow, the balls' share of f
    spread = np.sqrt(np.sum([(p.K[0, 0] / f - 1.0) ** 2 for p in cal.perturbed]))
    assert spread == pytest.approx(cal.focal_sigma, rel=1e-3), (spread, cal.focal_sigma)
    # without the frame: the corners alone, no bow (stated over 5%: the balls' 10% weighed in above)
    alone = calibrate_clicked(c, SIZE, TABLE, corner_sigma_px=1.0, fps=240.0, R_nominal=R)
    assert alone.focal_source == "corners" and alone.focal_sigma > cal.focal_sigma and len(alone.perturbed) == 8
    assert abs(alone.camera.K[0, 0] / true.K[0, 0] - 1.0) < 2.0 * alone.focal_sigma
    # overhead, nothing fixes f: the nominal one with its 15%, carried by a ninth camera
    top = pinhole_camera(height_m=2.0, tilt_deg=0.0, R=R, size=SIZE, fps=240.0, roll_deg=1.0)
    nom = calibrate_clicked(true_corners(top), SIZE, TABLE, fps=240.0)
    assert nom.focal_source == "nominal" and nom.focal_sigma == pytest.approx(0.15) and len(nom.perturbed) == 9
    # the note says why in plain words (it read "(nothing (camera nearly overhead))", auto15)
    assert "focal length (the camera is nearly overhead) and no still ball does" in nom.notes[0], nom.notes


@pytest.mark.parametrize("use_balls", [False, pytest.param(True, marks=pytest.mark.slow)])
def test_found_and_given_corners_give_the_same_camera(drawn_10deg, use_balls):
    # One path after the corners (calibrate_frame with corners given, as
    # `calibrate --corners` runs it): the automatic corners given back with
    # the same error give the same camera, focal length, stated error and
    # perturbed cameras (the lens taken as undistorted in both).  The
    # balls' share too in the slow run (4 s more: the balls read twice).
    from cuespin.pipeline.calibrate import calibrate_frame

    true, img = drawn_10deg
    kw = dict(corner_sigma_px=1.0, fps=240.0, R_nominal=R, use_balls=use_balls)
    found = calibrate_frame(img, TABLE, estimate_lens=False, **kw)
    given = calibrate_frame(img, TABLE, corners=found.corners_px, estimate_lens=False, **kw)
    assert found.focal_source == given.focal_source == ("corners+balls" if use_balls else "corners")
    assert given.focal_sigma == pytest.approx(found.focal_sigma, rel=1e-9)
    assert len(found.perturbed) == len(given.perturbed) == 8 + use_balls
    for a, b in zip((found.camera,) + found.perturbed, (given.camera,) + given.perturbed):
        assert np.allclose(a.K, b.K, rtol=1e-9) and np.allclose(a.rvec, b.rvec, atol=1e-9)
        assert np.allclose(a.tvec, b.tvec, atol=1e-9)


def test_clicked_corners_on_a_distorting_lens_take_the_bow_from_the_edges():
    # Four clicked corners cannot show the lens's bow (8 numbers, 6 pose
    # parameters and f): without it, clicks 1 px off on a k1 -0.25 lens tilted
    # 10 degrees put f 37-40% off (stated 5.7%).  The bow is read from the
    # table's edges in the frame (edges_bow, the automatic path's fit) when the
    # outline found there is the clicked table: f 4.6% RMS off (-11.7..+9.3%),
    # stated 6.0-6.3% (28 independent draws, benchmarks/calibration.py --clicked).
    from cuespin.pipeline.calibrate import calibrate_clicked, edges_bow

    true = pinhole_camera(height_m=2.0, tilt_deg=10.0, k1=-0.25, R=R, size=SIZE, fps=240.0, roll_deg=1.0)
    img = synthetic_table_frame(true, seed=125, cushion_m=0.05, pockets=True)
    c = true_corners(true) + np.random.default_rng(7).normal(0.0, 1.0, (4, 2))
    cal = calibrate_clicked(c, SIZE, TABLE, frame=img, corner_sigma_px=1.0, fps=240.0, R_nominal=R)
    assert "bow from the table's edges" in cal.notes[0]
    f = cal.camera.K[0, 0]
    assert abs(f / true.K[0, 0] - 1.0) < 2.0 * cal.focal_sigma < 0.2, (f / true.K[0, 0] - 1.0, cal.focal_sigma)
    # k1 at the true f within 3 of its stated errors (the note's "+/- x")
    k1_sigma = float(cal.notes[0].split("+/- ")[1].split()[0])
    assert abs(cal.camera.dist[0] / f**2 * true.K[0, 0] ** 2 + 0.25) < 3.0 * k1_sigma, (cal.camera.dist, k1_sigma)
    # an outline that is not the clicked table's gives no bow, and says why
    bow, why = edges_bow(img, c + [0.0, 0.2 * (c[0, 1] - c[3, 1])])
    assert bow is None and "from the clicked corners" in why, why


def test_cli_clicked_corners_say_when_the_lens_is_taken_as_straight(tmp_path, capsys):
    # No table outline in the video (a plain frame): no bow for the clicked
    # corners, the lens taken as straight, said in one line on stderr (the
    # focal length given: the bow is read all the same, and the corners'
    # f not refitted, 1-2 s less).
    true = pinhole_camera(height_m=2.0, tilt_deg=10.0, R=R, size=SIZE, fps=30.0, roll_deg=1.0)
    video = tmp_path / "plain.avi"
    write_video([np.full((SIZE[1], SIZE[0], 3), 60, np.uint8)] * 3, video)
    c = np.round(true_corners(true), 0).ravel()
    code, _, err_txt = run_main(capsys, "calibrate", video, "-o", tmp_path / "scene.json", "--R", R,
                                "--focal-px", f"{true.K[0, 0]:.0f}", "--corners", ",".join(f"{v:g}" for v in c))
    assert code == 0, err_txt
    assert ("the lens taken as straight (no table outline found in the video): give --intrinsics for a wide lens"
            in err_txt), err_txt


# At 3 m and 10 degrees (k1 -0.25, bow known) the clicks' f is linear in the
# clicks (benchmarks' clicked draws, seed 3: the refit f against f at the
# exact corners plus the slope times the clicks, correlation 0.998 over 20
# draws, at most 0.14 stated errors apart but for the draw 3.8 stated errors
# out, 0.50) and the stated error read at the clicked corners is the exact
# corners' (f 7.15%) within 0.96-1.32x (docs/measurements.md, clicked14).
CLICKED_F_LINEAR_TOL = 0.6     # in stated errors at the exact corners
CLICKED_F_STATED_TOL = 0.4     # |stated at the clicks / stated at the exact corners - 1|


def test_clicked_corners_focal_error_at_3m_is_the_clicks_own():
    # clicked13's 3 m row (f 11.5% RMS against 7.4% stated, one draw 31%
    # short) was its draws, not the rule: its 20 clicks project onto f's
    # direction (the near and far edges' heights) with RMS 1.45 standard
    # errors, where 22 of 24 [seed, camera] pairs give 0.72-1.24; the f error they cause is
    # what the slope says, and the slope is the one stated.
    from cuespin.pipeline.calibrate import corner_focal

    true = pinhole_camera(height_m=3.0, tilt_deg=10.0, k1=-0.25, size=SIZE, fps=240.0, roll_deg=1.0)
    exact, ft = true_corners(true), true.K[0, 0]
    kappa, moves = -0.25 / ft**2, np.hstack([np.eye(8), np.zeros((8, 1))])
    f0, s0, fk = corner_focal(exact, SIZE, TABLE, moves, kappa=kappa)
    assert f0 == pytest.approx(ft, rel=1e-4) and 0.06 < s0 / ft < 0.085, (f0 / ft, s0 / ft)
    for i in (0, 16):                   # +12.6% (z +1.7) and -31.0% (z -3.8): the clicks', as stated
        d = np.random.default_rng([3, 0, i]).normal(0.0, 1.0, (4, 2))
        f, s, _ = corner_focal(exact + d, SIZE, TABLE, moves, kappa=kappa)
        assert abs(f - (f0 + (fk - f0) @ d.ravel())) < CLICKED_F_LINEAR_TOL * s0, (i, f / ft - 1)
        assert abs(s / s0 - 1.0) < CLICKED_F_STATED_TOL, (i, s / s0)


@pytest.mark.slow
@pytest.mark.parametrize("height,tilt,k1", [(1.5, 15.0, -0.25), (2.0, 10.0, 0.0)])
def test_cushion_lines_on_the_renderers_pocketed_table(height, tilt, k1):
    """The cushions' lines (the path a real pocketed table takes when its felt
    outline is broken) on the renderer's realistic table through a tilted,
    distorting pinhole camera: pockets, sights, darker cushions, textured
    felt, lens blur.  Measured (corners16): 0.118 and 0.208 px RMS from the
    truth, on the cloth (height 0); the issue's target is 0.5 px."""
    from dataclasses import replace

    from cuespin.data_gen.sampler import make_scene, sample_shot
    from cuespin.physics.motion import Shot
    from cuespin.render.draw import FrameRenderer

    shot, params = sample_shot(100, "random")
    cam = pinhole_camera(height_m=height, tilt_deg=tilt, k1=k1, R=params.R, size=SIZE, fps=240.0, roll_deg=1.0,
                         margin_m=0.2)
    scene = replace(make_scene(Shot(shot.x0, shot.v0, shot.w0, t0=0.1), params,
                               render={"look": "realistic", "noise_sigma": 2.0, "seed": 1}), camera=cam)
    img = next(iter(FrameRenderer(scene, n_frames=1).frames()))
    det = detect_corners(img, lines="always")
    assert det.edge == "noses"
    truth = cam.project(table_corners(TABLE))
    d = matched_corner_errors(det.corners, truth)[0]
    assert np.sqrt(np.mean(np.sum(d**2, axis=1))) < AUTO_CORNER_RMS_PX
    f = cam.K[0, 0]
    assert det.kappa * f * f == pytest.approx(k1, abs=0.01)     # measured within 0.001 (k1 -0.250 found)


def test_cushion_lines_refuse_a_table_the_frame_cuts():
    """No cushion line along a side (the frame cuts the table): refused with a
    reason, not a guessed corner."""
    from cuespin.pipeline.calibrate import CalibrationError, _felt_distance, _felt_quad, cushion_lines

    true = pinhole_camera(height_m=2.0, tilt_deg=10.0, R=R, size=SIZE, fps=240.0, roll_deg=1.0)
    img = synthetic_table_frame(true, seed=3, cushion_m=0.05, pockets=True)
    img[:, : SIZE[0] // 2] = img[SIZE[1] // 2, SIZE[0] // 2]       # the left half: felt to the frame's edge
    with pytest.raises(CalibrationError, match="give --corners"):
        D, thr = _felt_distance(img)
        cushion_lines(img, *_felt_quad(D, thr), D, thr)
    # the outline's own edge is lost there too: detect_corners then tries the lines, which refuse with the side
    with pytest.raises(CalibrationError, match="cushion's edge could not be located along the first side"):
        detect_corners(img)


def test_clicked_corners_at_the_noses_height():
    """Corners clicked where the cushions' noses meet lie h above the cloth;
    calibrated as such (``--nose-height``) the ball plane is exact, taken on
    the cloth it is off by h / (D - h) (measured 1.82% at 2 m for 36 mm)."""
    from cuespin.pipeline.calibrate import calibrate_clicked

    true = pinhole_camera(height_m=2.0, tilt_deg=10.0, R=R, size=SIZE, fps=240.0, roll_deg=1.0)
    h = 0.036
    clicks = true.project(table_corners(TABLE, height_m=h))
    at_noses = calibrate_clicked(clicks, SIZE, TABLE, intrinsics=np.array(true.K), corner_sigma_px=0.0,
                                 corner_height_m=h, R_nominal=R)
    on_cloth = calibrate_clicked(clicks, SIZE, TABLE, intrinsics=np.array(true.K), corner_sigma_px=0.0, R_nominal=R)
    assert metre_error(at_noses, true) < 1e-6
    assert metre_error(on_cloth, true) > 0.01     # a 1.8% scale: 10-24 mm at the table's ends


def test_cli_clicked_corners_at_the_noses_height(tmp_path, capsys):
    """``--nose-height`` reaches clicked corners through the command line: the
    clicks at the noses (36 mm up) give the true ball plane with it, one
    some 1.8% small without (test_clicked_corners_at_the_noses_height)."""
    true = pinhole_camera(height_m=2.0, tilt_deg=10.0, R=R, size=SIZE, fps=30.0, roll_deg=1.0)
    video = tmp_path / "table.avi"
    write_video([synthetic_table_frame(true, seed=2, cushion_m=0.05, pockets=True)], video)
    lens = tmp_path / "lens.json"
    lens.write_text(json.dumps({"intrinsics": np.array(true.K).tolist(), "distortion": [0, 0, 0, 0, 0]}))
    clicks = ",".join(f"{v:.3f}" for v in true.project(table_corners(TABLE, height_m=0.036)).ravel())
    out = tmp_path / "scene.json"
    errs = {}
    for extra in ((), ("--nose-height", "0.036")):
        code, _, err_txt = run_main(capsys, "calibrate", video, "-o", out, "--corners", clicks, "--intrinsics", lens,
                                    "--R", R, *extra)
        assert code == 0, err_txt
        cam = parse_scene(json.loads(out.read_text())).camera
        xy = ball_grid()
        errs[bool(extra)] = float(np.abs(cam.to_table(true.to_pixels(xy)) - xy).max())
    assert errs[True] < 1e-4 and errs[False] > 0.01, errs


def test_a_shadow_band_inside_the_noses_is_not_taken_for_them():
    """Cushions in the cloth's colour and a darker band 15 mm inside the noses
    (their shadows under lamps, as on the real clips): the outline's largest
    step is the band's inner edge (measured 2.16 px RMS off the noses' corners
    through a k1 -0.25 lens); the cushion lines take the outermost step, and
    the two disagree far beyond their errors (PATHS_DISAGREE_Z), so the
    lines' corners are kept (measured 0.098 px)."""
    true = pinhole_camera(height_m=2.0, tilt_deg=10.0, k1=-0.25, R=R, size=SIZE, roll_deg=1.0)
    img = synthetic_table_frame(true, seed=5, cushion_m=0.05, cushion_shade=1.05, pockets=True, band_m=0.015)
    truth = true.project(table_corners(TABLE))

    def rms(det):
        d = matched_corner_errors(det.corners, truth)[0]
        return float(np.sqrt(np.mean(np.sum(d**2, axis=1))))
    assert rms(detect_corners(img, lines="never")) > 1.0
    det = detect_corners(img)
    assert det.edge == "noses" and det.lines and rms(det) < AUTO_CORNER_RMS_PX
    assert not detect_corners(synthetic_table_frame(true, seed=5, cushion_m=0.05, pockets=True)).lines   # no band


# Review 12a's frame (1.5 m, 10 deg, k1 -0.25, roll 1 deg, seed 24): cushions
# in 1.05 x the felt's shade, whose noses show no step, so the lines answer
# the felt's outline (the cushions' outer edge).  With the felt edge's step
# taken of the wrong sign its corners were 1.99 px RMS off stating 0.38; with
# the right sign 0.044 px stating 0.057 (docs/measurements.md, cushion12).
# Bounds: 3x the real error measured; stated/real within a factor 2.5 of the
# measured 1.3 either way (the old 0.19 falls outside).
FELT_EDGE_RMS_PX = 3 * 0.044
FELT_EDGE_STATED_OVER_REAL = (0.5, 3.0)


def test_the_felt_edge_of_cloth_coloured_cushions_is_found_and_stated():
    true = pinhole_camera(height_m=1.5, tilt_deg=10.0, k1=-0.25, R=R, size=SIZE, roll_deg=1.0)
    img = synthetic_table_frame(true, seed=24, cushion_m=0.05, cushion_shade=1.05, pockets=True)
    det = detect_corners(img)
    assert det.edge == "felt" and det.lines
    stated, real = corner_errors(img, true.project(table_corners(TABLE, margin_m=0.05)))
    lo, hi = FELT_EDGE_STATED_OVER_REAL
    assert real < FELT_EDGE_RMS_PX and lo < stated / real < hi, (stated, real)


def test_a_band_crowding_the_lines_noses_widens_the_stated_error():
    """A shadow band 10 mm inside the noses (4-5 px in this frame, within
    LINES_CROWDED_PX): the outline's window straddles it (1.5 px off) and the
    lines' window reaches its inner edge (0.385 px off, stating 0.054); the
    lines are kept (PATHS_DISAGREE_Z) and state the two paths' difference too
    (measured 1.17 px RMS a coordinate), so that their real error is inside
    two stated standard errors on every coordinate."""
    true = pinhole_camera(height_m=2.0, tilt_deg=10.0, k1=-0.25, R=R, size=SIZE, roll_deg=1.0)
    img = synthetic_table_frame(true, seed=5, cushion_m=0.05, cushion_shade=1.05, pockets=True, band_m=0.010)
    truth = true_corners(true)
    det = detect_corners(img)
    assert det.edge == "noses" and det.lines
    e, idx = matched_corner_errors(det.corners, truth)
    e = e.ravel()
    assert np.all(np.abs(e) < 2.0 * np.sqrt(np.diag(det.corner_cov)[idx])), (e, np.diag(det.corner_cov)[idx])
    alone = detect_corners(img, lines="always")          # the lines' own error states too little here
    assert np.sqrt(np.mean(e**2)) > 2.0 * np.sqrt(np.trace(alone.corner_cov[:8, :8]) / 8.0)


def test_a_band_just_past_the_outlines_window_sends_the_noses_to_the_lines():
    """A 20 mm shadow band whose inner edge lies 8 px inside the noses, just
    past the outline's sub-pixel window (7 px): it still pulls the outline's
    noses (measured 0.164 px RMS a coordinate off, stating 0.038), so the
    straddle check reaches BAND_PULL_PX further, the lines are run and
    taken (z 5.5 > PATHS_DISAGREE_Z; measured 0.036 px)."""
    true = pinhole_camera(height_m=2.6, tilt_deg=11.0, k1=-0.12, R=R, size=SIZE, roll_deg=1.0)
    img = synthetic_table_frame(true, seed=66, cushion_m=0.05, cushion_shade=1.05, pockets=True, band_m=0.020)
    truth = true_corners(true)
    outline = detect_corners(img, lines="never")
    assert corner_errors(img, truth)[1] < 3 * 0.036
    assert detect_corners(img).lines
    d = matched_corner_errors(outline.corners, truth)[0]
    assert np.sqrt(np.mean(d**2)) > 0.1         # what the outline alone gives here


def _matched_errors(det, truth):
    """A detection's corner errors against ``truth`` (the nearest of its four
    starts) and their stated standard errors, per coordinate (px)."""
    e, idx = matched_corner_errors(det.corners, truth)
    return e.ravel(), np.sqrt(np.diag(det.corner_cov)[idx])


@pytest.mark.parametrize("seed", [12012, 12023])
def test_a_band_of_the_cushions_shade_is_refused(seed):
    """A shadow band inside the noses in nearly the cushions' shade (random
    drawn tables 12012: cushions 0.80, band 0.77 x the felt, 21 mm; 12023:
    0.88, 0.86, 9 mm): the noses do not show and both paths took the band's
    inner edge for them (measured 8.85 and 4.47 px RMS off, stating 0.028
    and 0.058; the paths agree at z 1.2 and 2.8).  The faint step between
    that edge and the felt's outline (21 and 6.0 x the cloth's step scatter,
    HIDDEN_NOSE_Z 4) refuses it, naming --corners."""
    from cuespin.pipeline.calibrate import random_table

    t = random_table(seed)
    with pytest.raises(CalibrationError, match="faint step.*give --corners"):
        detect_corners(t["frame"])
    det = detect_corners(t["frame"], lines="never", refuse=False)     # what was answered: the band's inner edge
    e, sd = _matched_errors(det, t["noses"])
    assert np.sqrt(np.mean(e**2)) > 1.0 and np.sqrt(np.mean(e**2)) > 5.0 * np.sqrt(np.mean(sd**2))


def _jpeg(img: np.ndarray, quality: int) -> np.ndarray:
    """``img`` through OpenCV's JPEG codec at ``quality`` (what a phone or a
    webcam's MJPG stream does to a frame)."""
    ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, quality])
    return cv2.imdecode(buf, cv2.IMREAD_COLOR)


def test_a_jpeg_compressed_table_whose_noses_show_is_answered():
    """Random drawn table 16005 (noses show, no band) through JPEG at
    quality 70: the codec's 8x8 blocks ring beside the nose edge and flatten
    the felt, so the faint step between the noses and the outline read 6.2 x
    the felt's scatter and the table was refused (rev13v).  The same ringing
    shows on the felt's side of the nose (the step is 1.19 x it there, under
    HIDDEN_MIRROR_Z 1.3): answered, measured 0.048 px off stating 0.063."""
    from cuespin.pipeline.calibrate import random_table

    t = random_table(16005)
    det = detect_corners(_jpeg(t["frame"], 70))
    assert det.edge == "noses"
    e, sd = _matched_errors(det, t["noses"])
    assert np.sqrt(np.mean(e**2)) < 3 * 0.048 and np.all(np.abs(e) <= 3.0 * sd), (e, sd)


def test_a_jpeg_compressed_band_of_the_cushions_shade_is_still_refused():
    """Random drawn table 12023 (a 9 mm band at 0.86 x the felt inside
    cushions of 0.88, answered 4.5 px off before cushion13) drawn at frame
    noise 0.5 and through JPEG at quality 70: the band's faint step is 1.43
    x the ringing on the felt's side of the nose, the least of the hidden
    tables' but one (HIDDEN_MIRROR_Z 1.3).  With the gate at 2.6 (rev13v's
    first try) it was answered 4.5 px off stating 0.06; still refused."""
    from cuespin.pipeline.calibrate import random_table

    t = random_table(12023)
    look = dict(t["look"], noise=0.5)
    frame = synthetic_table_frame(t["camera"], seed=12023, **look)
    with pytest.raises(CalibrationError, match="faint step.*give --corners"):
        detect_corners(_jpeg(frame, 70))


def test_a_band_the_codec_erased_is_refused():
    """Random drawn table 14014 (a band at 0.800 x the felt inside cushions
    of 0.792: a 0.5-level step) drawn at frame noise 0.5 and through JPEG
    at quality 70: the codec quantises the step away (the strip between the
    band's inner edge and the outline reads 50.7 levels flat on every side),
    so no faint-step rule can see it, and it was answered 9.8 px off stating
    0.053 (rev13v).  The felt's pixels equal their neighbours on 0.999 of
    the samples and the nose rings (0.18 levels): a codec's flat cloth
    (CODEC_FLAT_SHARE, CODEC_RING_LEVELS) is refused, naming --corners."""
    from cuespin.pipeline.calibrate import random_table

    t = random_table(14014)
    frame = synthetic_table_frame(t["camera"], seed=14014, **dict(t["look"], noise=0.5))
    with pytest.raises(CalibrationError, match="compression flattened.*give --corners"):
        detect_corners(_jpeg(frame, 70))


@pytest.mark.parametrize("lines", ["always", "never"])
def test_a_band_the_codec_erased_is_refused_on_either_path(lines):
    """The same frame (14014, noise 0.5, JPEG 70) with the path forced: the
    cushions' lines take the band's inner edge too (answered 11.57 px off
    stating 0.047 under ``always``, the outline 11.54 px off under
    ``never``; review of jpeg12), so the refusals hold on every path."""
    from cuespin.pipeline.calibrate import random_table

    t = random_table(14014)
    frame = _jpeg(synthetic_table_frame(t["camera"], seed=14014, **dict(t["look"], noise=0.5)), 70)
    with pytest.raises(CalibrationError, match="compression flattened.*give --corners"):
        detect_corners(frame, lines=lines)
    e, sd = _matched_errors(detect_corners(frame, lines=lines, refuse=False), t["noses"])
    assert np.sqrt(np.mean(e**2)) > 5.0 and np.sqrt(np.mean(e**2)) > 20.0 * np.sqrt(np.mean(sd**2))


@pytest.mark.xfail(strict=True, reason="H.264 keeps the cloth's noise (flat share 0.12-0.25) but smooths the "
                   "band's faint step under HIDDEN_NOSE_Z (4.11 raw -> 2.74 at CRF 18, 2.72 at 20, 0 at 23): "
                   "answered 9.8 px off stating 0.04-0.06; no rule found that spares the visible tables (fixcal); "
                   "the command's mean of 32 still frames refuses it at CRF 18, not at 20-23 (mean12)")
@pytest.mark.parametrize("crf", [18, 20, 23])
def test_a_band_of_the_cushions_shade_through_h264_is_refused(crf):
    """Random drawn table 14014 (a 0.5-level band step inside the noses) at its
    drawn noise (3.77 levels) through H.264 (libx264, preset medium, the key
    frame): answered 9.74-9.79 px RMS off stating 0.039-0.057 at CRF 18-23
    (review of jpeg12: 11.5 px the largest corner).  It should be refused."""
    from benchmarks.calibration import through_codec
    from cuespin.pipeline.calibrate import random_table

    t = random_table(14014)
    with pytest.raises(CalibrationError, match="give --corners"):
        detect_corners(through_codec(t["frame"], "h264", crf=crf))


def test_the_still_frames_are_the_first_run_where_nothing_moves():
    """``still_mean`` on drawn grey frames (noise 3 levels, seed 5): a bright
    disc moving 2 px a frame for the first 6 frames, then at rest 40 frames:
    the run starts where it rests and its 32 frames' mean keeps the still
    image to its noise over sqrt(32) (0.53 levels; 4 x that asserted).  A
    disc moving 0.5 px a frame is never still (a 16 px block's mean moves
    over STILL_FLOOR_LEVELS 3): the longest run is a frame or two.

    A phone's auto-exposure settling at the clip's start (every level +8 %
    from frame 1 on) changes nothing: a disc moving 0.3 px a frame runs
    3 frames, as without the step (the block test before fixvis took it as
    still for 23: the step raised the blocks' scatter and the threshold),
    and a disc at rest runs from the step on (its bright blocks move by more
    than the felt's: the run restarts at the step)."""
    from cuespin.pipeline.calibrate import still_mean

    rng = np.random.default_rng(5)
    yy, xx = np.mgrid[0:128, 0:128]

    def frame(cx, gain=1.0):
        clean = 60.0 + 170.0 * (np.hypot(xx - cx, yy - 64.0) < 10.0)
        return clean, np.clip(np.round(gain * clean + rng.normal(0.0, 3.0, clean.shape)), 0, 255).astype(np.uint8)

    xs = [30.0 + 2.0 * min(k, 5) for k in range(46)]
    frames = [frame(x)[1] for x in xs]
    mean, count, start = still_mean(frames)
    assert (count, start) == (32, 5)
    assert np.sqrt(np.mean((mean[..., 0] - frame(40.0)[0]) ** 2)) < 4 * 3.0 / np.sqrt(32)
    _, count, _ = still_mean([frame(30.0 + 0.5 * k)[1] for k in range(20)])
    assert count <= 2
    _, count, _ = still_mean([frame(30.0 + 0.3 * k, 1.0 + 0.08 * (k > 0))[1] for k in range(40)])
    assert count <= 3   # 3 without the step too (0.6 px over the run: the test's third of a pixel)
    _, count, start = still_mean([frame(40.0, 1.0 + 0.08 * (k > 0))[1] for k in range(40)])
    assert (count, start) == (32, 1)


@pytest.mark.slow
def test_a_band_of_the_cushions_shade_through_h264_is_refused_from_the_still_frames(tmp_path):
    """Random drawn table 14014 (a 0.5-level band step inside the noses) as a
    phone films a still table: 32 frames, each with its own noise (3.77
    levels), in ONE H.264 stream at CRF 18 (libx264, preset medium), read by
    the command's own path (``calibrate_video``: the mean of the still frames,
    ``still_mean``).  The first frame alone is answered 9.80 px off stating
    0.066; the mean of 32 is refused (faint step 11.9 x the scatter; the
    median of 9 frames the command took before: 7.4 x).  At CRF 20-28 the
    encoder codes a still table's later frames as copies of the key frame,
    so their mean is the key frame's (mean12, docs/measurements.md)."""
    from benchmarks.calibration import h264_encode
    from cuespin.pipeline.calibrate import calibrate_video, random_table

    t = random_table(14014)
    video = tmp_path / "table.mp4"
    h264_encode(synthetic_table_frame(t["camera"], seed=14014, frames=32, **t["look"]), str(video), crf=18)
    with pytest.raises(CalibrationError, match="faint step.*give --corners"):
        calibrate_video(video)


@pytest.mark.slow
def test_a_table_whose_noses_show_through_h264_is_answered_from_the_still_frames(tmp_path):
    """Random drawn table 18009 (cushions, no band) filmed still as 32 frames in
    one H.264 stream at CRF 18: the first frame is answered (0.04 px RMS off),
    but the mean of 32 has no equal neighbours left (no flat cloth to say a
    codec touched it) while the codec's ringing beside the noses, the same in
    every frame, adds up on all four sides: the raw frames' coherent-band
    rule refused it.  The command knows the codec (``_lossy``): answered,
    measured 0.15 px RMS off stating 0.066 (mean12)."""
    from benchmarks.calibration import h264_encode
    from cuespin.pipeline.calibrate import calibrate_video, random_table

    t = random_table(18009)
    video = tmp_path / "table.mp4"
    h264_encode(synthetic_table_frame(t["camera"], seed=18009, frames=32, **t["look"]), str(video), crf=18)
    cal = calibrate_video(video)
    e, _ = matched_corner_errors(cal.corners_px, t["noses"])
    assert cal.edge == "noses" and np.sqrt(np.mean(e**2)) < 3 * 0.15, e


@pytest.mark.slow
def test_a_phone_h264_file_resaved_losslessly_is_still_read_as_lossy(tmp_path):
    """Random drawn table 18058 filmed still as 32 frames in one H.264 stream
    at CRF 18, decoded and re-saved as FFV1 (a lossless container of codec
    frames): the container says lossless, so before fixvis the raw frames'
    coherent-band rule ran on the mean of codec frames and refused it (faint
    steps on all four sides 6.5 x the scatter).  The still run's first frame
    says what the codec did (its felt's flat share 0.45-0.47 a side, raw
    frames 0.000-0.001, over RAW_FLAT_SHARE 0.05): answered, measured 0.05 px
    RMS off, as from the .mp4 (fixvis, docs/measurements.md)."""
    from benchmarks.calibration import h264_encode
    from cuespin.pipeline.calibrate import calibrate_video, random_table

    t = random_table(18058)
    mp4, mkv = tmp_path / "table.mp4", tmp_path / "table.mkv"
    h264_encode(synthetic_table_frame(t["camera"], seed=18058, frames=32, **t["look"]), str(mp4), crf=18)
    cap, out = cv2.VideoCapture(str(mp4)), None
    while True:
        ok, img = cap.read()
        if not ok:
            break
        if out is None:
            out = cv2.VideoWriter(str(mkv), cv2.VideoWriter_fourcc(*"FFV1"), 30, (img.shape[1], img.shape[0]))
        out.write(img)
    cap.release()
    out.release()
    cal = calibrate_video(mkv)
    e, _ = matched_corner_errors(cal.corners_px, t["noses"])
    assert cal.edge == "noses" and np.sqrt(np.mean(e**2)) < 3 * 0.05, e


def test_a_clean_lossless_video_is_not_read_as_lossy():
    """Random drawn table 18000 filmed still by a clean lossless camera
    (noise 0.3 levels): its felt's flat share (0.55 a side) is over
    RAW_FLAT_SHARE, as a codec's, so one frame alone reads lossy (the
    misread, review SHOULD 4); the next still frame equals it as often
    (0.55), so the video is read lossless (``_video_lossy``:
    flat share minus that at most NOISE_FLAT_EXCESS 0.02; measured -0.007
    to +0.007 on lossless tables, lossy12).  The same frames through JPEG 95
    (excess 0.05-0.18 on 18000-18059) and one H.264 stream at CRF 23 (its
    frames copies of the first: equal 0.96-1.0, FROZEN_SHARE 0.95, then the
    flat share decides) still read lossy."""
    from benchmarks.calibration import h264_encode
    from cuespin.pipeline.calibrate import (
        _felt_distance,
        _felt_flat_shares,
        _felt_quad,
        _frame_lossy,
        _video_lossy,
        edge_points,
        random_table,
    )

    t = random_table(18000)
    frames = synthetic_table_frame(t["camera"], seed=18000, frames=2, **dict(t["look"], noise=0.3))
    mean = frames.astype(np.float32).mean(axis=0)
    sides = edge_points(mean, *_felt_quad(*_felt_distance(mean)))
    assert _frame_lossy([(0, 0, 0, f) for f in _felt_flat_shares(frames[0], sides)])     # one frame: misread
    assert not _video_lossy(frames[0], frames[1], sides)
    jpeg = [_jpeg(f, 95) for f in frames[:2]]
    assert _video_lossy(jpeg[0], jpeg[1], sides)
    drawn = synthetic_table_frame(t["camera"], seed=18000, frames=4, **t["look"])
    buf = io.BytesIO()
    h264_encode(list(drawn), buf, crf=23)
    buf.seek(0)
    with av.open(buf) as d:
        h264 = [f.to_ndarray(format="bgr24") for f in d.decode(video=0)]
    assert _video_lossy(h264[0], h264[1], sides)


def test_an_h264_stream_between_keeping_noise_and_copying_is_read_lossy():
    """Fresh random drawn table 18121 (not among 18000-18059, which set the
    constants) as one 4-frame H.264 stream at CRF 21: x264 keeps part of the
    noise, so the felt is no flatter in space than from frame to frame
    (flat minus equal share about -0.01, under NOISE_FLAT_EXCESS: the flat
    share alone reads it lossless, the review's misread), but what it keeps
    it codes in steps a sensor's quantised noise does not take: the share of
    differences of 2 levels or more among the nonzero ones exceeds the
    quantised Gaussian's at the same zero share by about 0.4
    (``_noise_tail_excess``; lossless frames at most 0.018, fixcrf).  The
    same table filmed losslessly at noise 0.2 and 0.3 stays lossless."""
    from benchmarks.calibration import h264_encode
    from cuespin.pipeline.calibrate import (
        NOISE_TAIL_EXCESS,
        _felt_distance,
        _felt_quad,
        _noise_tail_excess,
        _video_lossy,
        edge_points,
        random_table,
    )

    t = random_table(18121)
    drawn = synthetic_table_frame(t["camera"], seed=18121, frames=4, **t["look"])
    mean = drawn.astype(np.float32).mean(axis=0)
    sides = edge_points(mean, *_felt_quad(*_felt_distance(mean)))
    buf = io.BytesIO()
    h264_encode(list(drawn), buf, crf=21)
    buf.seek(0)
    with av.open(buf) as d:
        h264 = [f.to_ndarray(format="bgr24") for f in d.decode(video=0)]
    assert _noise_tail_excess(h264[0], h264[1], sides) > NOISE_TAIL_EXCESS
    assert _video_lossy(h264[0], h264[1], sides)
    for noise in (0.2, 0.3):
        clean = synthetic_table_frame(t["camera"], seed=18121, frames=2, **dict(t["look"], noise=noise))
        assert _noise_tail_excess(clean[0], clean[1], sides) < NOISE_TAIL_EXCESS
        assert not _video_lossy(clean[0], clean[1], sides)


@pytest.mark.slow
def test_the_codec_flat_rule_spares_noisy_jpeg_and_raw_frames():
    """The codec's flat-cloth rule (``_codec_flattened``) on the random drawn
    tables 16000-16019 whose outline takes noses: off on every one at the
    drawn noise (2-4 levels) raw and through JPEG 70 (flat shares 0.51-0.91
    on 18000-18059, under CODEC_FLAT_SHARE 0.99: measured 0 of 6 and 0 of 7
    here), on for most at noise 0.5 through JPEG 70 (0.964-1.0 on
    18000-18059; measured 6 of 7 here), where a band's faint step under the
    codec's quantum is erased (14014)."""
    from cuespin.pipeline.calibrate import (
        _codec_flattened,
        _felt_distance,
        _felt_quad,
        cushion_noses,
        edge_points,
        random_table,
    )

    seen = {"raw": [], "jpeg70": [], "n05 jpeg70": []}
    for seed in range(16000, 16020):
        t = random_table(seed)
        if "cushion_m" not in t["look"]:
            continue
        quiet = synthetic_table_frame(t["camera"], seed=seed, **dict(t["look"], noise=0.5))
        for name, img in (("raw", t["frame"]), ("jpeg70", _jpeg(t["frame"], 70)), ("n05 jpeg70", _jpeg(quiet, 70))):
            D, thr = _felt_distance(img)
            quad, contour = _felt_quad(D, thr)
            hidden = []
            if cushion_noses(img, edge_points(img, quad, contour), hidden=hidden) is not None:
                seen[name].append(_codec_flattened(hidden))
    assert len(seen["raw"]) >= 5 and not any(seen["raw"]) and not any(seen["jpeg70"]), seen
    assert len(seen["n05 jpeg70"]) >= 5 and np.mean(seen["n05 jpeg70"]) >= 0.5, seen


def test_a_band_faint_on_every_side_at_one_place_is_refused():
    """Random drawn table 16030 (cushions 0.765 x the felt's shade, a band at
    0.749 inside them: a 1-level step), raw: its faint step is 3.10 x the
    scatter (under HIDDEN_NOSE_Z 4), and the outline took the band's inner
    edge for the noses, answered 3.98 px off stating 0.024 (jpeg12).  The
    four sides' steps at the same share of the way to the outline (0.23)
    add up to 5.8 x (BAND_COHERENT_Z 4.2): refused, naming --corners."""
    from cuespin.pipeline.calibrate import random_table

    with pytest.raises(CalibrationError, match="same place on all four sides.*give --corners"):
        detect_corners(random_table(16030)["frame"])


@pytest.mark.slow
def test_the_coherent_band_rule_spares_tables_whose_noses_show():
    """The coherent faint-step rule (``_band_z``) on the raw frames of the
    random drawn tables 16000-16059 whose outline takes noses: off on every
    one whose noses show (measured on 12000-17059: 92 showing, 0-3.07
    against BAND_COHERENT_Z 4.2; here 0 refused), and on for the hidden
    ones that the faint step alone let through or refuses (16024, 16030,
    16043: 5.8 and over).  Through JPEG 95 the rule is off (the felt's flat
    share over RAW_FLAT_SHARE)."""
    from cuespin.pipeline.calibrate import (
        BAND_COHERENT_Z,
        _band_z,
        _felt_distance,
        _felt_quad,
        cushion_noses,
        edge_points,
        random_table,
    )

    showing, hidden_z, jpeg = [], {}, []
    for seed in range(16000, 16060):
        t = random_table(seed)
        look = t["look"]
        if "cushion_m" not in look:
            continue
        hides = abs(look["cushion_shade"] - look.get("band_shade", 9.0)) < 0.1
        for name, img in (("raw", t["frame"]), ("jpeg95", _jpeg(t["frame"], 95))):
            if name == "jpeg95" and seed % 4:
                continue                                    # a quarter of them: the gate, not the statistic
            D, thr = _felt_distance(img)
            quad, contour = _felt_quad(D, thr)
            hidden, coherent = [], []
            if cushion_noses(img, edge_points(img, quad, contour), hidden=hidden, coherent=coherent) is None:
                continue
            z = _band_z(hidden, coherent)
            if name == "jpeg95":
                jpeg.append(z)
            elif hides:
                hidden_z[seed] = z
            else:
                showing.append((seed, z))
    assert len(showing) >= 15 and all(z < BAND_COHERENT_Z for _, z in showing), showing
    assert hidden_z.get(16030, 0.0) >= BAND_COHERENT_Z, hidden_z
    assert jpeg and not any(jpeg), jpeg


def test_noses_straddled_all_round_with_the_lines_refusing_are_refused():
    """Random drawn table 19001 (cushions 0.984 x the felt's shade, a band
    at 0.875 inside them), raw: the outline took the band's inner edge for
    the noses, 10.9 px off stating 0.055 (nose16), the band's outer edge in
    sight beside it on all four sides, while the cushions' lines refuse.
    With nothing to check the outline against, a band's other edge on every
    side (STRADDLED_SIDES_REFUSE) refuses it, naming --corners."""
    from cuespin.pipeline.calibrate import random_table

    with pytest.raises(CalibrationError, match="all 4 sides.*lines.*refuse.*give --corners"):
        detect_corners(random_table(19001)["frame"])


@pytest.mark.slow
def test_the_straddled_rule_refuses_no_right_answer():
    """The straddled-on-every-side rule (``STRADDLED_SIDES_REFUSE``) on the
    raw frames of the random drawn tables 19000-19059 with cushions: every
    frame it refuses is one whose outline (what ``auto`` answered before,
    the lines refusing) is more than 1 px off; 19001 among them, and the
    rest of the block's answers unchanged (strad12: 4 frames straddled
    all round, the lines answering right on the other 3)."""
    from cuespin.pipeline.calibrate import random_table

    refused = {}
    for seed in range(19000, 19060):
        t = random_table(seed)
        if "cushion_m" not in t["look"]:
            continue
        try:
            detect_corners(t["frame"])
        except CalibrationError as err:
            if "lines, which would take the outermost" in str(err):
                outline = detect_corners(t["frame"], lines="never", refuse=False)
                e, _ = _matched_errors(outline, t["noses"])
                refused[seed] = float(np.sqrt(np.mean(e**2)))
    assert 19001 in refused and all(rms > 1.0 for rms in refused.values()), refused


def test_a_narrow_band_seen_on_two_sides_is_refused():
    """Random drawn table 19053 (cushions 0.879 x the felt's shade, a 10 mm
    band at 0.869 inside them), raw: the outline took the band's inner edge
    for the noses, 3.83 px off stating 0.065 (nose16).  Its faint step per
    side 8.2, 2.0, 4.9, 1.4 x the scatter (median under HIDDEN_NOSE_Z, the
    coherent sum 1.8: the band's outer edge on the far sides lies at the
    faint-step zone's inner end); the second-largest side 4.94 reaches
    SECOND_SIDE_Z 4.1: refused, naming --corners."""
    from cuespin.pipeline.calibrate import random_table

    with pytest.raises(CalibrationError, match="two sides or more.*give --corners"):
        detect_corners(random_table(19053)["frame"])


@pytest.mark.slow
def test_the_second_side_rule_spares_tables_whose_noses_show():
    """The second-largest side's faint step (``_second_side_z``) on the raw
    frames of the random drawn tables 13000-13039 whose outline takes noses:
    under SECOND_SIDE_Z on every one whose noses show (13007, the largest
    measured on 12000-17059 and 19000-19059, reads 3.34; strad12), and 0
    through JPEG 95 (the felt's flat share over RAW_FLAT_SHARE)."""
    from cuespin.pipeline.calibrate import (
        SECOND_SIDE_Z,
        _felt_distance,
        _felt_quad,
        _second_side_z,
        cushion_noses,
        edge_points,
        random_table,
    )

    showing, jpeg = {}, []
    for seed in range(13000, 13040):
        t = random_table(seed)
        look = t["look"]
        if "cushion_m" not in look or abs(look["cushion_shade"] - look.get("band_shade", 9.0)) < 0.1:
            continue
        for name, img in (("raw", t["frame"]), ("jpeg95", _jpeg(t["frame"], 95))):
            D, thr = _felt_distance(img)
            quad, contour = _felt_quad(D, thr)
            hidden = []
            if cushion_noses(img, edge_points(img, quad, contour), hidden=hidden) is None:
                continue
            if name == "raw":
                showing[seed] = _second_side_z(hidden)
            else:
                jpeg.append(_second_side_z(hidden))
    assert len(showing) >= 10 and showing.get(13007, 0.0) > 3.0, showing
    assert all(z < SECOND_SIDE_Z for z in showing.values()), showing
    assert jpeg and not any(jpeg), jpeg


def test_paths_disagreeing_with_nothing_to_say_which_refuse():
    """The two paths' noses 9.2 combined errors apart on random table 12006
    (a band of the cushions' shade: both wrong, 6.1 and 5.8 px) with no band
    in the outline's window: the rule refuses rather than pick one, even
    without the faint-step check (``hidden_z`` 0)."""
    from cuespin.pipeline.calibrate import (
        _felt_distance,
        _felt_quad,
        _outline_or_lines,
        cushion_lines,
        random_table,
    )

    img = random_table(12006)["frame"]
    outline = detect_corners(img, lines="never", refuse=False)      # (refused by its faint step on its own)
    D, thr = _felt_distance(img)
    quad, contour = _felt_quad(D, thr)

    def cushions(inside=None):
        from cuespin.pipeline.calibrate import _detection
        return _detection(*cushion_lines(img, quad, contour, D, thr, inside=inside), D.shape, lines=True)

    with pytest.raises(CalibrationError, match="disagree.*give --corners"):
        _outline_or_lines(outline, False, cushions, hidden_z=0.0)


def test_an_outline_stopped_at_a_dark_band_goes_to_the_lines():
    """Random drawn table 13036 (cushions 0.965 x the felt, a 22 mm band at
    0.726): the felt region stops at the band, so the outline answers
    ``felt`` 30.4 px inside the felt's true outline, while the lines find
    the noses (0.021 px).  The lines' noses lie outside the outline's felt,
    which a felt outline cannot be: the lines are taken, within 2 stated sd."""
    from cuespin.pipeline.calibrate import random_table

    t = random_table(13036)
    det = detect_corners(t["frame"])
    assert det.edge == "noses" and det.lines
    e, sd = _matched_errors(det, t["noses"])
    assert np.sqrt(np.mean(e**2)) < 3 * 0.021
    assert np.all(np.abs(e) <= 2.0 * sd), (e, sd)


def test_a_step_outside_the_outlines_noses_sends_them_to_the_lines():
    """Random drawn table 14018 (cushions 0.90 x the felt, a 21 mm band at
    0.77, far from the outline's window): the band's inner edge is the
    largest step, so the outline took it for the noses (9.4 px off stating
    0.035) while the lines, reading from the outside in, found the noses
    (0.057 px, stating 0.057; z 147).  The cushion-to-band step outside the
    outline's noses says which is wrong: the lines are taken (found on the
    held-out set 14000-14039, where the first rule refused it)."""
    from cuespin.pipeline.calibrate import random_table

    t = random_table(14018)
    det = detect_corners(t["frame"])
    assert det.edge == "noses" and det.lines
    e, sd = _matched_errors(det, t["noses"])
    rms = np.sqrt(np.mean(e**2))
    assert rms < 3 * 0.057 and 0.5 < rms / np.sqrt(np.mean(sd**2)) < 2.0, (e, sd)     # measured 1.00 (6 of 8 in 2 sd)


# The stated corner errors on random drawn tables (calibrate.random_table)
# whose noses show: 0.963 and 0.961 of the coordinates within 2 stated sd on
# seeds 12000-12039 and 13000-13039 (docs/measurements.md, cushion12); on
# 12010-12021 (11 such tables, a crowded band among them) 0.955, and 0.898
# without LINES_CROWDED_PX's widening.  The floor: 0.96 less 2 binomial sd
# over 88 coordinates (0.021).
RANDOM_TABLES_COVER_MIN = 0.92


def test_random_tables_corners_within_their_stated_errors():
    from cuespin.pipeline.calibrate import random_table

    inside, confident_wrong, refused = [], [], []
    for seed in range(12010, 12022):
        t = random_table(seed)
        look = t["look"]
        hides = abs(look.get("cushion_shade", 0.0) - look.get("band_shade", 9.0)) < 0.1
        try:
            det = detect_corners(t["frame"])
        except CalibrationError:
            refused.append(seed)
            continue
        e, sd = _matched_errors(det, t[det.edge])
        rms, stated = np.sqrt(np.mean(e**2)), np.sqrt(np.mean(sd**2))
        if rms > 1.0 and rms > 5.0 * stated:
            confident_wrong.append(seed)
        if not hides:               # a band of the cushions' shade hides the noses (refused: cushion13)
            inside.append(np.abs(e) <= 2.0 * sd)
    # no confident wrong answer (12012, a band of the cushions' shade, answered 8.8 px off stating 0.028 before
    # HIDDEN_NOSE_Z) and no table whose noses show refused
    assert confident_wrong == [] and refused == [12012], (confident_wrong, refused)
    assert len(inside) == 11 and np.mean(inside) >= RANDOM_TABLES_COVER_MIN, np.sum(inside, axis=1)
