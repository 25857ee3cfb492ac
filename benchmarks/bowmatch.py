"""The found outline's offset from the playing surface's corners, as a share
of the quadrilateral's shorter side (``CLICKED_BOW_MATCH``'s measure), on
drawn and the renderer's realistic tables.

Usage: python benchmarks/bowmatch.py [felt]   (felt: the felt's outline, ``noses=False``)
"""
import sys
from pathlib import Path
from dataclasses import replace
import numpy as np
sys.path.insert(0, str(Path(__file__).parent))
from calibration import SIZE, FPS, ROLL_DEG, table_corners
from cuespin.physics.camera import pinhole_camera
from cuespin.physics.scene import Table
from cuespin.physics.motion import Shot
from cuespin.data_gen.sampler import make_scene, sample_shot
from cuespin.pipeline.calibrate import detect_corners, synthetic_table_frame
from cuespin.render.draw import FrameRenderer

NOSES = sys.argv[1:] != ["felt"]
shot, params = sample_shot(100, "random")
for h, t, k in [(2.0, 10.0, 0.0), (2.0, 10.0, -0.25), (2.0, 3.0, -0.25), (1.5, 15.0, 0.0), (2.0, 0.0, 0.25)]:
    for kind in ("drawn", "realistic"):
        cam = pinhole_camera(height_m=h, tilt_deg=t, k1=k, size=SIZE, fps=FPS, roll_deg=ROLL_DEG,
                             margin_m=0.15 if kind == "realistic" else 0.1, R=params.R)
        c = cam.project(table_corners(Table()))
        if kind == "drawn":
            img = synthetic_table_frame(cam, seed=int(10 * t + 100 * abs(k)), cushion_m=0.05, pockets=True)
        else:
            scene = make_scene(Shot(shot.x0, shot.v0, shot.w0, t0=0.1), params,
                               render={"look": "realistic", "noise_sigma": 2.0, "seed": 1})
            img = next(iter(FrameRenderer(replace(scene, camera=cam), n_frames=1).frames()))
        det = detect_corners(img, noses=NOSES)
        side = float(np.linalg.norm(np.roll(c, -1, axis=0) - c, axis=1).min())
        off = min(float(np.abs(np.roll(det.corners, -s, axis=0) - c).max()) for s in range(4))
        print(f"{kind:9s} {h} m {t:g} deg k1 {k:+.2f}: edge {det.edge} "
              f"offset {off:.1f} px, side {side:.0f} px: {off / side:.1%}", flush=True)
