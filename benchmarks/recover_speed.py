"""Fit plus both recoveries against decoding the same video, timed in the same run.

For N generated shots (the sampler's mix of presets, frame rates and
noise; videos capped at ``--max-seconds``, default 2 s: the ratio, not the
shot, is measured) per codec: render once, track once, then in
R alternating rounds time decoding every frame of the file (OpenCV, as the
tracker reads it, nothing else) and the recovery of the tracked centres
(``recover.api.recover_track``, method ``all``: segmentation, decisions,
both maximum-likelihood passes, the paper's method and its errors).  Each
shot's ratio is the median of its rounds' recovery time over the median of
its decode times, in wall-clock time and in CPU time (the process's, the
decoder's threads included: on a loaded machine the wall clock is mostly
waiting); prints per shot and the median and 95th percentile per codec
(target: median <= 0.1).

Usage: python benchmarks/recover_speed.py [--n 8] [--seed 0] [--rounds 3] [--codec MJPG FFV1] [--max-seconds 2]
                                         [--look plain|realistic]
"""

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from cuespin.track.video import decode_seconds


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=8)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--codec", nargs="+", default=["MJPG", "FFV1"])
    ap.add_argument("--max-seconds", type=float, default=2.0)
    ap.add_argument("--look", choices=["plain", "realistic"], default="plain",
                    help="the sampler's look (realistic: the shaded ball and felt, as accuracy.py --look)")
    args = ap.parse_args()
    from cuespin.data_gen.sampler import sample_scenes
    from cuespin.recover.api import recover_track
    from cuespin.recover.measurements import pixel_to_table, table_covariance
    from cuespin.render import render_settings, render_video
    from cuespin.render.video import video_suffix
    from cuespin.track.tracker import TrackerConfig
    from cuespin.track.video import track_video

    scenes = sample_scenes(args.n, args.seed, look=args.look)
    with tempfile.TemporaryDirectory() as tmp:
        for codec in args.codec:
            print(f"\n{codec}: {'shot':>4} {'frames':>6} {'decode s':>9} {'recover s':>9} {'ratio':>6} "
                  f"{'CPU ratio':>9}")
            ratios, cpu_ratios = [], []
            for i, scene in enumerate(scenes):
                scene.render["max_duration"] = args.max_seconds
                scene.render["codec"] = codec
                # .mp4 for H264 (libx264 writes no .avi), else .avi
                video = Path(tmp) / f"shot_{i}{video_suffix(str(render_settings(scene)['codec']))}"
                render_video(scene, video)
                tr = track_video(video, scene, TrackerConfig())
                cam = scene.camera
                cov = table_covariance(cam, tr.xy, tr.cov_px)
                px_to_m = pixel_to_table(cam, tr.xy)
                dec, rec, dec_cpu, rec_cpu = [], [], [], []
                for _ in range(args.rounds):  # alternating: the machine's load falls on both alike
                    cpu = time.process_time()
                    d, n = decode_seconds(video)
                    dec_cpu.append(time.process_time() - cpu)
                    dec.append(d)
                    clock, cpu = time.perf_counter(), time.process_time()
                    recover_track(tr.t, tr.xy, tr.ok, cov, scene.physics, cam.exposure_s, "all", False,
                                  lossless=tr.lossless, inter_frame=tr.inter_frame, px_to_m=px_to_m)
                    rec.append(time.perf_counter() - clock)
                    rec_cpu.append(time.process_time() - cpu)
                video.unlink()
                r = statistics.median(rec) / statistics.median(dec)
                ratios.append(r)
                cpu_ratios.append(statistics.median(rec_cpu) / statistics.median(dec_cpu))
                print(f"{'':6}{i:4d} {n:6d} {statistics.median(dec):9.3f} {statistics.median(rec):9.3f} {r:6.3f} "
                      f"{cpu_ratios[-1]:9.3f}", flush=True)
            for name, rs in (("wall", ratios), ("CPU", cpu_ratios)):
                print(f"{codec}: (fit + both recoveries) / decode over {len(rs)} shots, {name}: median "
                      f"{np.median(rs):.3f}, p95 {np.percentile(rs, 95):.3f} (target <= 0.1)", flush=True)


if __name__ == "__main__":
    main()
