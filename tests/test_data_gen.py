"""The seeded sampler and datasets."""

import numpy as np
import pytest

from cuespin.data_gen import PRESETS, sample_scene, sample_scenes, sample_shot
from cuespin.data_gen.dataset import generate_dataset
from cuespin.physics import contact_velocity, phases, sliding_parabola, straight_motion
from cuespin.physics.scene import motion_end
from cuespin.render.video import truth_path


def test_same_seed_same_scene_and_no_global_state():
    np.random.seed(1)
    a = sample_scenes(6, seed=42)
    np.random.seed(2)
    b = sample_scenes(6, seed=42)
    assert a == b
    assert sample_scenes(6, seed=43) != a


def test_one_scene_of_a_seed_is_the_scene_the_whole_list_holds():
    # scene_at(i) samples shot i alone (the benchmarks' shot i of a seed):
    # the same scene as sample_scenes(n)[i], whatever n, preset mix and look.
    from cuespin.data_gen.sampler import scene_at

    for kw in ({}, {"look": "realistic"}, {"preset": "case4", "camera": "topdown"}):
        scenes = sample_scenes(12, seed=37, **kw)
        assert all(scene_at(i, 37, **kw) == scenes[i] for i in (0, 5, 11))
        assert scene_at(5, 37, **kw) == sample_scenes(6, seed=37, **kw)[5]


@pytest.mark.parametrize("case", range(1, 6))
def test_case_presets(case):
    for seed in range(5):
        shot, params = sample_shot(seed, f"case{case}")
        assert straight_motion(shot.v0, shot.w0, params).case == case


def test_random_preset_ranges():
    speeds, ratios, angles = [], [], []
    for seed in range(300):
        shot, p = sample_shot(seed, "random")
        v = np.hypot(*shot.v0)
        speeds.append(v)
        ratios.append(p.R * np.hypot(*shot.w0) / v)
        angles.append(np.arctan2(shot.w0[1], shot.w0[0]))
        assert 0.1 <= p.mu_s <= 0.3 and 0.005 <= p.mu_r <= 0.02
        assert 0.1 <= shot.t0 <= 0.5
    assert 0.2 <= min(speeds) and max(speeds) <= 5.0
    assert max(ratios) <= 2.5 and max(ratios) > 2.2
    # spin in every planar direction: all four quadrants used
    assert len(set(np.floor(np.array(angles) / (np.pi / 2)).astype(int))) == 4


def test_masse_curves_and_slides_long():
    for seed in range(5):
        shot, p = sample_shot(seed, "masse")
        ph = phases(shot, p)
        assert ph.t1 - shot.t0 > 0.5
        par = sliding_parabola(shot.x0, shot.v0, shot.w0, p)
        assert np.isfinite(par.a)


def test_leaves_table_preset_leaves():
    for seed in range(5):
        scene = sample_scene(seed, "leaves_table", fps=120.0)
        _, left = motion_end(scene.truth, scene.physics, scene.table, 120.0, 20.0)
        assert left


def test_generate_same_seed_same_files_and_resume(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    ra = generate_dataset(a, n=2, seed=5, preset="leaves_table", fps=60.0)
    rb = generate_dataset(b, n=2, seed=5, preset="leaves_table", fps=60.0)
    assert ra["written"] == rb["written"] == 2
    for pa, pb in zip(ra["paths"], rb["paths"]):
        for f in (pa, pa.with_suffix(".json"), truth_path(pa)):
            g = pb.parent / f.name
            assert f.read_bytes() == g.read_bytes()
    # A shot whose scene file is missing is unfinished: a rerun redoes it only.
    (a / "shot_0001.json").unlink()
    again = generate_dataset(a, n=2, seed=5, preset="leaves_table", fps=60.0)
    assert again["written"] == 1 and again["skipped"] == 1
    assert not list(a.glob("*.part*"))


def test_presets_listed():
    assert set(PRESETS) >= {"random", "case1", "case2", "case3", "case4", "case5", "masse",
                            "leaves_table"}
    with pytest.raises(ValueError):
        sample_shot(0, "nope")
    # contact velocity of a case4 shot is zero: rolls from the strike
    shot, p = sample_shot(0, "case4")
    np.testing.assert_allclose(contact_velocity(shot.v0, shot.w0, p.R), 0.0, atol=1e-12)


def test_realistic_look_sampled_reproducibly_and_covers_the_colours():
    from cuespin.render.look import BALL_COLOURS, FELT_COLOURS, grey_level

    a = sample_scenes(40, seed=7, look="realistic")
    assert a == sample_scenes(40, seed=7, look="realistic")
    assert a != sample_scenes(40, seed=8, look="realistic")
    # The plain look's draws are untouched by the option.
    assert sample_scenes(3, seed=7) == sample_scenes(3, seed=7, look="plain")
    looks = [s.render for s in a]
    assert all(r["look"] == "realistic" for r in looks)
    assert {r["ball_name"] for r in looks} == set(BALL_COLOURS)
    assert {r["felt_name"] for r in looks} == set(FELT_COLOURS)
    contrast = [abs(grey_level(r["ball_colour"]) - grey_level(r["felt_colour"])) for r in looks]
    assert min(contrast) < 25
    assert {r["markings"] for r in looks} == {"none", "dots", "logo"}
    assert any(r["cue"] for r in looks) and not all(r["cue"] for r in looks)
    assert all(1.0 <= r["noise_sigma"] <= 8.0 for r in looks)
    # The camera shows the rails: the playing surface's corners lie inside
    # the frame, at least the rail's width from its edges.
    for s in a:
        from cuespin.render.look import CUSHION_WIDTH_M, RAIL_WIDTH_M
        b = CUSHION_WIDTH_M + RAIL_WIDTH_M
        corners = np.array([[-b, -b], [s.table.length + b, s.table.width + b]])
        uv = s.camera.to_pixels(corners)
        assert (uv >= -0.5).all() and (uv[:, 0] <= s.camera.width - 0.5).all()
        assert (uv[:, 1] <= s.camera.height - 0.5).all()


def test_resting_balls_are_off_the_path_and_on_the_cloth():
    from cuespin.physics import positions

    n_balls = 0
    for s in sample_scenes(30, seed=3, look="realistic"):
        end, _ = motion_end(s.truth, s.physics, s.table, 240.0, 20.0)
        path = positions(s.truth, s.physics, np.linspace(s.truth.t0, end, 2000))
        R = s.physics.R
        for b in s.render["balls"]:
            p = np.array([b["x"], b["y"]])
            assert np.hypot(*(path - p).T).min() >= 2 * R + 0.03 - 1e-3
            assert s.table.contains(p[None], margin=R)[0]
            n_balls += 1
        xy = [(b["x"], b["y"]) for b in s.render["balls"]]
        for i in range(len(xy)):
            for j in range(i):
                assert np.hypot(xy[i][0] - xy[j][0], xy[i][1] - xy[j][1]) >= 2 * R
    assert n_balls >= 20


def test_generate_realistic_dataset(tmp_path):
    import cv2

    r = generate_dataset(tmp_path, n=1, seed=2, preset="leaves_table", fps=60.0, look="realistic")
    cap = cv2.VideoCapture(str(r["paths"][0]))
    ok, im = cap.read()
    cap.release()
    assert ok and im.ndim == 3
    # Colour: the channels differ (the grey look's are equal).
    assert np.abs(im[..., 0].astype(int) - im[..., 2]).mean() > 5


def test_tilted_cameras_sampled_in_range_and_round_trip():
    import json

    from cuespin.physics.scene import parse_scene, scene_to_dict

    scenes = sample_scenes(12, seed=4, look="realistic", camera="tilted")
    assert scenes == sample_scenes(12, seed=4, look="realistic", camera="tilted")
    tilts = []
    for s in scenes:
        cam = s.camera
        assert cam.is_pinhole
        assert 1.5 <= cam.centre[2] <= 3.0
        assert -0.25 <= cam.dist[0] <= 0.0
        axis = cam.rotation.T @ np.array([0.0, 0.0, 1.0])         # optical axis, table frame
        tilts.append(np.degrees(np.arccos(-axis[2])))
        # The table with its rails is in view.
        corners = np.array([[-0.16, -0.16, 0], [s.table.length + 0.16, -0.16, 0],
                            [-0.16, s.table.width + 0.16, 0], [s.table.length + 0.16, s.table.width + 0.16, 0]])
        uv = cam.project(corners)
        assert (uv >= 0).all() and (uv[:, 0] < cam.width).all() and (uv[:, 1] < cam.height).all()
        assert parse_scene(json.loads(json.dumps(scene_to_dict(s)))) == s
    assert max(tilts) <= 15.0 + 1e-9 and max(tilts) > 8.0
    with pytest.raises(ValueError):
        sample_scene(0, camera="fisheye")
