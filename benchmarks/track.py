"""Tracker speed against decode-only, memory against length, accuracy against the bound.

speed:    per codec (MJPG, FFV1, mp4v, H.264 written with PyAV's libx264) a
          1280 x 640, 240 fps colour shot (a yellow ball on green felt, noise
          3 per channel) of 1000 and of 10000 frames; in one run on the same
          file, alternating, decoding every frame to BGR with cv2 and
          nothing else, and the full tracker; prints both throughputs and the
          median of the ratios (target >= 0.8), and the median ratio of
          their CPU times (process-wide, both threads: less noisy than wall
          time on a shared machine, and what a fully loaded one gives).
          With --rest, the slower shot that stops in view at frame 787 (the
          default one leaves the view at ~460 and rests off the table), and
          how the resting ball is followed: frames found, error against the
          truth's centre, status codes.  --fresh-noise: new noise in every
          frame (a camera's sensor) instead of the rolled bank of 16, which
          x264 codes in ~450 bytes a frame.  --codecs picks codecs, --video-dir
          keeps the files (a 10,000-frame render takes ~17 min on a loaded
          2-core machine).
          With --threads, each run's CPU split by thread (Linux: sampled
          from /proc/self/task): the main thread, the decoder thread, FFmpeg's
          and other libraries' worker threads, with the minor page faults of each
          (the sampler's own CPU, its row, 0.05-0.15 s a run, is in the
          process times then: take the ratios from a run without it).
memory:   peak RSS of the tracker (in a fresh process) on a 1000-frame video
          and on a 10000-frame one (target: within 20 MB); MJPG, or each of
          --codecs.
accuracy: centroid RMSE against the truth sidecar and the Cramer-Rao bound
          (from the rendered image's derivatives) per noise level, ball
          radius, blur, lighting gradient and codec, for the disc fit and for
          moments; and the RMS of the errors in the tracker's stated
          per-frame errors (target ~1 on lossless video).

colour:   per ball/felt colour pair, noise and codec: the colour tracker's
          RMSE against the colour Cramer-Rao bound (every channel), err/se, and
          the same frames' luma tracked grey-only, side by side.

realistic: per look of the realistic renderer (uniform, shaded, highlight,
          markings, lens blur; colours, noise 1-8 per channel and 60-480 fps
          as data_gen samples them, no cue and no other balls), each shot
          rendered once to FFV1, transcoded to MJPG and to grey (luma) FFV1,
          and tracked three times: found %, false positives (> R/4 off),
          RMSE on moving frames against the truth sidecar's projected centre,
          the colour Cramer-Rao bound of that look (every channel, the look's
          nuisance parameters, the markings' pattern unknown:
          track.bound.centroid_crb_realistic), the ratio,
          err/se (the tracker's stated errors; raw: before track.misfit's
          factor; dm: about the shot's mean error, the constant bias x0
          absorbs), the same for MJPG, and grey-only against the luma bound.

Usage: python benchmarks/track.py [speed] [memory] [colour] [accuracy] [realistic] [--quick] [--frames 1000 10000]
                                  [--repeat 3] [--threads] [--codecs mjpg h264] [--rest] [--fresh-noise]
                                  [--video-dir DIR]
                                  [--n 60] [--seed 0] [--workers 2] [--seconds 0.6] [--csv out.csv]
                                  [--shots I ...] [--frames-out DIR] [--codecs ffv1 mjpg grey] [--mix]
       python benchmarks/track.py realistic --summarize out.csv
"""

import argparse
import collections
import json
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import cv2
import numpy as np

from cuespin.data_gen.sampler import make_scene, sample_shot
from cuespin.physics import Shot
from cuespin.render import FrameRenderer
from cuespin.pipeline.measure import tracker_accuracy
from cuespin.track.colour import LUMA  # OpenCV's BGR-to-grey weights (BT.601)
from cuespin.track.synthetic import colour_frames, write_av
from cuespin.track.video import decode_seconds, track_video

# PyAV encoder, pixel format, options and file type per codec: what cameras
# and common tools write.
CODECS = {
    "MJPG": ("mjpeg", "yuvj420p", None, "avi", 8e5),  # bits per frame: 0.1 MB, as OpenCV writes
    "FFV1": ("ffv1", "bgr0", None, "avi", None),
    "mp4v": ("mpeg4", "yuv420p", None, "avi", 2e5),
    "H264": ("libx264", "yuv420p", {"crf": "18"}, "mp4", None),  # x264's default keyframe interval, 250
}


# The --rest shot's v0 and w0 against the sampled one's: the ball stops in
# view at frame 787 (uv 426, 350; 240 fps, 500 px/m), where the sampled
# shot's leaves the view at frame ~460 and rests off the table.
REST_SCALE = 0.45


def scene_for(codec, seconds, fps=240.0, noise=5.0, px_per_m=500.0, blur=False, gradient=0.0,
              seed=1, t0=0.3, v_scale=1.0):
    shot, params = sample_shot(seed, "case3")
    shot = Shot(shot.x0, np.asarray(shot.v0) * v_scale, np.asarray(shot.w0) * v_scale, t0=t0)
    return make_scene(shot, params, fps=fps, px_per_m=px_per_m,
                      exposure_s=(1.0 / fps if blur else 0.0),
                      render={"noise_sigma": noise, "codec": codec, "duration": seconds,
                              "gradient": gradient, "gradient_angle": 0.6, "seed": seed,
                              "felt_grey": 90.0, "ball_grey": 210.0})


def colour_video(tmp, codec, n_frames, fps=240.0, rest=False, fresh=False):
    """A colour shot of ``n_frames`` written with PyAV (every frame rendered,
    the felt's noise from a bank of 16); (path, scene).  ``rest``: the
    slower shot that comes to rest in view (:data:`REST_SCALE`).  ``fresh``:
    new noise in every frame, as a camera's sensor gives (the bank's rolled
    noise lets x264 code a frame in ~450 bytes, so its decode is cheap)."""
    scene = scene_for(codec, n_frames / fps, fps=fps, v_scale=REST_SCALE if rest else 1.0)
    enc, pix, opts, ext, rate = CODECS[codec]
    path = Path(tmp) / f"speed_{codec}_{n_frames}{'_rest' if rest else ''}{'_fresh' if fresh else ''}.{ext}"
    if not path.exists():
        write_av(colour_frames(scene, (40, 200, 220), (40, 110, 30), noise=3.0, seed=1,
                               noise_bank=0 if fresh else 16),
                 path, enc, pix, fps, options=opts, bit_rate=rate and rate * fps)
    return path, scene


def decode_only(path) -> float:
    """Decode-only throughput (frames/s): every frame to BGR with cv2, as any
    OpenCV user decodes (:func:`cuespin.track.video.decode_seconds`)."""
    seconds, n = decode_seconds(path)
    return n / seconds


def _task_cpu() -> dict:
    """{native thread id: (name, CPU s, of it in the kernel s, minor faults)} of this process."""
    tick = os.sysconf("SC_CLK_TCK")
    out = {}
    for tid in os.listdir("/proc/self/task"):
        try:
            with open(f"/proc/self/task/{tid}/stat") as f:
                stat = f.read()
            with open(f"/proc/self/task/{tid}/comm") as f:
                name = f.read().strip()
        except OSError:  # the thread ended
            continue
        rest = stat[stat.rindex(")") + 2:].split()  # proc(5): minflt, utime, stime are fields 10, 14, 15
        out[int(tid)] = (name, (int(rest[11]) + int(rest[12])) / tick, int(rest[12]) / tick, int(rest[7]))
    return out


class ThreadCPU:
    """Each thread's CPU between construction and :meth:`done`, sampled every
    20 ms (a thread that ends loses at most its last 20 ms).  Python threads
    are named by their thread name, FFmpeg's decoder threads "av:...";
    threads a library starts unnamed show the process's name, "python"
    (OpenCV's pool, and one started at the first frame decoded that keeps
    its ~0.2 s a 1000-frame run, in decoding alone too, at cv2.setNumThreads(1)).
    """

    def __init__(self):
        self.first = _task_cpu()
        self.last = dict(self.first)
        self.names = {threading.main_thread().native_id: "main"}
        self._stop = threading.Event()
        self._t = threading.Thread(target=self._run, name="sampler", daemon=True)
        self._t.start()

    def _run(self):
        while not self._stop.wait(0.02):
            self.last.update(_task_cpu())
            for t in threading.enumerate():
                if t.native_id is not None and t.native_id not in self.names:
                    self.names[t.native_id] = "py:" + t.name.split(" ")[0]

    def done(self) -> dict:
        """{thread name: [CPU s, kernel s, minor faults]}, threads of one name summed."""
        self._stop.set()
        self._t.join()
        self.last.update(_task_cpu())
        out = collections.defaultdict(lambda: [0.0, 0.0, 0])
        for tid, (name, cpu, sys_, flt) in self.last.items():
            _, cpu0, sys0, flt0 = self.first.get(tid, (name, 0.0, 0.0, 0))
            row = out[self.names.get(tid, name)]
            row[0] += cpu - cpu0
            row[1] += sys_ - sys0
            row[2] += flt - flt0
        return dict(out)


def _thread_line(label, split):
    parts = [f"{k} {v[0]:.2f}" + (f" (sys {v[1]:.2f}, {v[2] // 1000}k faults)" if v[2] >= 1000 else "")
             for k, v in sorted(split.items(), key=lambda kv: -kv[1][0]) if v[0] >= 0.005]
    print(f"    {label:8} " + ", ".join(parts))


def _rest_line(res, scene):
    """How the tracker follows the ball once it has stopped: frames found at
    rest, the found ones' median and largest distance from the truth's
    centre (px), and the first frame of the rest."""
    uv = FrameRenderer(scene, n_frames=res.n_frames).truth.uv
    first = np.flatnonzero(np.any(uv != uv[-1], axis=1))[-1] + 1
    at = np.arange(first, res.n_frames)
    err = np.hypot(*(res.uv[at] - uv[at]).T)[res.ok[at]]
    print(f"    at rest from frame {first}: {res.ok[at].sum()}/{len(at)} found, error median "
          f"{np.median(err):.3f} px, max {err.max():.3f} px; status codes at rest "
          f"{dict(collections.Counter(res.status[at].tolist()))}")


def speed(tmp, repeat, lengths, threads=False, codecs=tuple(CODECS), rest=False, keep=False, fresh=False):
    print(f"\nspeed: 1280x640 colour, 240 fps (median of alternating runs){', ball at rest in view' if rest else ''}"
          f"{', new noise every frame' if fresh else ''}")
    print(f"{'codec':6} {'frames':>6} {'decode fps':>11} {'track fps':>10} {'ratio':>6} {'cpu':>5}  ok")
    for n in lengths:
        for codec in codecs:
            video, scene = colour_video(tmp, codec, n, rest=rest, fresh=fresh)
            decs, trks, ratios, cpus = [], [], [], []
            splits = []
            for _ in range(repeat):  # interleaved: the machine is shared
                per = ThreadCPU() if threads else None
                c = time.process_time()
                d = decode_only(video)
                c_dec = time.process_time() - c
                splits.append(per.done() if per else None)
                per = ThreadCPU() if threads else None
                t, c = time.perf_counter(), time.process_time()
                res = track_video(video, scene)
                k = res.n_frames / (time.perf_counter() - t)
                splits.append(per.done() if per else None)
                cpus.append(c_dec / (time.process_time() - c))
                decs.append(d)
                trks.append(k)
                ratios.append(k / d)
            print(f"{codec:6} {res.n_frames:6d} {statistics.median(decs):11.1f} "
                  f"{statistics.median(trks):10.1f} {statistics.median(ratios):6.2f} {statistics.median(cpus):5.2f}  "
                  f"{res.ok.sum()}/{res.n_frames}", flush=True)
            if threads:  # the last run's split, by thread (CPU s)
                _thread_line("decode", splits[-2])
                _thread_line("track", splits[-1])
            if rest:
                _rest_line(res, scene)
            if n >= 5000 and not keep:
                video.unlink()


_CHILD = """
import json, resource, sys
from cuespin.pipeline.io import read_scene
from cuespin.track.video import decode_seconds, track_video
scene = read_scene(sys.argv[2])
res = track_video(sys.argv[1], scene)
print(json.dumps({"frames": res.n_frames, "maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def memory(tmp, lengths, codec="MJPG", rest=False, fresh=False):
    from cuespin.pipeline.io import write_scene
    print(f"\nmemory: peak RSS of a fresh tracking process ({codec}, colour"
          f"{', ball at rest in view' if rest else ''})")
    out = {}
    for n in lengths:
        video, scene = colour_video(tmp, codec, n, rest=rest, fresh=fresh)
        sf = Path(tmp) / f"mem_{codec}_{n}.json"
        write_scene(sf, scene)
        r = subprocess.run([sys.executable, "-c", _CHILD, str(video), str(sf)], capture_output=True,
                           text=True, check=True)
        out[n] = json.loads(r.stdout.strip().splitlines()[-1])
        print(f"{n:6d} frames: {out[n]['frames']:5d} tracked, peak RSS {out[n]['maxrss_mb']:.1f} MB")
    a, b = min(lengths), max(lengths)
    print(f"{b} frames add {out[b]['maxrss_mb'] - out[a]['maxrss_mb']:.1f} MB to {a} (target <= 20)")


def accuracy_row(tmp, label, scene, refine):
    acc = tracker_accuracy(scene, Path(tmp) / "acc.avi", refine, n_eval=10)
    res = acc.result
    print(f"{label:44} {refine:8} {acc.rmse:9.4f} {acc.crb:9.4f} {acc.ratio:6.2f} {acc.stated_z:7.2f}  "
          f"ok {res.ok.sum()}/{res.n_frames}")
    return acc.rmse, acc.crb


def accuracy(tmp, quick):
    print("\naccuracy: per-axis centroid RMSE (px) over moving frames vs Cramer-Rao bound")
    print("(err/se: RMS of the errors in the tracker's own stated errors; 1 when they are honest)")
    print(f"{'condition':44} {'refine':8} {'rmse':>9} {'bound':>9} {'ratio':>6} {'err/se':>7}")
    noises = (0.1, 0.3, 1.0, 5.0, 10.0)  # below ~0.5, 8-bit rounding is most of the noise
    radii = (8.0, 14.3, 20.0) if not quick else (14.3,)
    for codec in ("FFV1", "MJPG"):
        for noise in noises:
            for radius in radii:
                for blur, grad in ((False, 0.0), (True, 15.0)):
                    scene = scene_for(codec, 0.6, noise=noise, px_per_m=radius / 0.028575,
                                      blur=blur, gradient=grad)
                    label = f"{codec} sigma {noise:4.1f} r {radius:4.1f}px {'blur+grad' if blur else 'sharp'}"
                    for refine in (("fit", "moments") if codec == "FFV1" else ("fit",)):
                        accuracy_row(tmp, label, scene, refine)


# Ball and felt colours (BGR): the pairs, two under 25 grey levels apart.
PAIRS = {"yellow/grey": ((40, 200, 220), (170, 170, 170)),
         "red/blue": ((40, 40, 200), (150, 80, 40)),
         "red/green": ((40, 40, 200), (40, 110, 30)),
         "white/grey": ((230, 230, 230), (120, 120, 120)),
         "orange/red": ((30, 120, 240), (40, 40, 150))}


def colour_accuracy(tmp, pair, noise, codec="FFV1", fps=240.0, seed=1, grey=False, ramp=0.0):
    """RMSE, the colour Cramer-Rao bound and err/se on moving frames of one colour shot.

    With ``grey`` the same frames' luma is tracked instead (the grey-only
    tracker's view), against the same colour bound.
    """
    import numpy as np

    from cuespin.render import FrameRenderer
    from cuespin.track.bound import centroid_crb_colour

    ball, felt = PAIRS[pair]
    scene = scene_for(codec, 0.6, fps=fps, seed=seed)
    enc, pix, opts, ext, rate = CODECS[codec]
    path = Path(tmp) / f"acc.{ext}"
    frames = colour_frames(scene, ball, felt, noise=noise, seed=seed, ramp=ramp)
    if grey:
        frames = (np.clip(np.rint(f @ LUMA), 0, 255).astype(np.uint8) for f in frames)
        pix = "gray" if codec == "FFV1" else pix
    write_av(frames, path, enc, pix, fps, options=opts, bit_rate=rate and rate * fps)
    res = track_video(path, scene)
    r = FrameRenderer(scene)
    truth = r.truth
    moving = np.flatnonzero(res.ok & (truth.t > scene.truth.t0 + 0.02))
    err = res.uv[moving] - truth.uv[moving]
    h, wd = scene.camera.height, scene.camera.width
    light = 1.0 + ramp * (np.arange(wd) / wd - 0.5)
    felt_img = np.asarray(felt, float)[None, None, :] * light[None, :, None] * np.ones((h, 1, 1))
    bounds = [centroid_crb_colour(r._uv_nodes[k], r.radius_px, ball, felt_img, noise**2 * np.eye(3), False)
              for k in moving[np.linspace(0, len(moving) - 1, 8).astype(int)]]
    z = err / res.stderr_px[moving]
    found = res.ok[truth.t > scene.truth.t0 + 0.02].mean()
    return (float(np.sqrt(np.mean(err**2))), float(np.sqrt(np.mean(np.square(bounds)))),
            float(np.sqrt(np.mean(z**2))), float(found))


def colour(tmp, quick):
    print("\ncolour: per-axis RMSE (px) on moving frames vs the colour Cramer-Rao bound (every channel)")
    print("grey: the same frames' luma tracked (grey-only), against the same colour bound")
    print(f"{'pair':12} {'codec':5} {'noise':>5} {'found':>6} {'rmse':>8} {'bound':>8} {'ratio':>6} "
          f"{'err/se':>6} | {'grey rmse':>9} {'ratio':>6} {'err/se':>6}")
    noises = (2.0, 8.0) if quick else (1.0, 2.0, 4.0, 8.0)
    for codec in ("FFV1", "MJPG"):
        for pair in PAIRS:
            for noise in noises:
                rm, b, z, f = colour_accuracy(tmp, pair, noise, codec)
                rg, _, zg, fg = colour_accuracy(tmp, pair, noise, codec, grey=True)
                print(f"{pair:12} {codec:5} {noise:5.1f} {f:6.3f} {rm:8.4f} {b:8.4f} {rm / b:6.2f} {z:6.2f} | "
                      f"{rg:9.4f} {rg / b:6.2f} {zg:6.2f}", flush=True)


# The realistic looks: render keys set over data_gen's sample of each shot
# (which keeps its colours, light, noise, frame rate and motion blur).
REALISTIC_LOOKS = {
    "uniform": {"ambient": 1.0, "specular": 0.0, "markings": "none", "psf_sigma": 0.0},
    "shaded": {"specular": 0.0, "markings": "none", "psf_sigma": 0.0},
    "highlight": {"markings": "none", "psf_sigma": 0.0},
    "markings": {"specular": 0.0, "psf_sigma": 0.0},
    "blur": {"specular": 0.0, "markings": "none"},
}


def realistic_scene(i, seed, seconds, mix=False):
    """Shot ``i`` of the realistic benchmark and its look's name.

    ``mix`` keeps the sampler's cue (half the scenes) and 0-4 resting balls,
    which the look table otherwise removes so that the looks compare alone.
    """
    from cuespin.data_gen.sampler import sample_scenes

    scene = sample_scenes(i + 1, seed, look="realistic", codec="FFV1")[i]
    look = list(REALISTIC_LOOKS)[i % len(REALISTIC_LOOKS)]
    rng = np.random.default_rng([seed, i, 10])
    r = scene.render
    r.update(REALISTIC_LOOKS[look], max_duration=seconds)
    if not mix:
        r.update(cue=False, balls=[])
    if look == "highlight":
        r["specular"] = round(float(rng.uniform(0.3, 0.7)), 3)
    elif look == "markings":
        r["markings"] = ("dots", "logo")[int(rng.integers(2))]
    elif look == "blur":
        r["psf_sigma"] = round(float(rng.uniform(0.5, 1.0)), 3)
    return scene, look


def _errors(res, tuv, t, t0, r, cam, cloth=None):
    """The found share over frames wholly in view (and on the cloth), false
    positives over every frame, and the errors (px) and stated errors of the
    good moving frames.

    ``cloth``: per frame, whether the ball lies wholly on the playing surface
    (issue 10 counts frames "wholly in view and on open cloth"; a ball whose
    centre is past the cushion's nose rides the rail in the render).
    """
    n = min(res.n_frames, len(tuv))
    tuv, t = tuv[:n], t[:n]
    view = ((tuv[:, 0] >= r) & (tuv[:, 0] <= cam.width - 1 - r)
            & (tuv[:, 1] >= r) & (tuv[:, 1] <= cam.height - 1 - r))
    if cloth is not None:
        view &= cloth[:n]
    moving = view & (t > t0 + 0.02)
    ok = res.ok[:n]
    err = res.uv[:n] - tuv
    bad = ok & (np.hypot(*err.T) > 0.25 * r)
    good = ok & ~bad & moving
    # false centres are counted over every frame, in view or not (the stricter count)
    found = ok[view].mean() if view.any() else np.nan
    return found, int(bad.sum()), err[good], res.stderr_px[:n][good], good


def _track_stats(res, tuv, t, t0, r, cam, cloth=None):
    found, fp, e, se, good = _errors(res, tuv, t, t0, r, cam, cloth)
    out = {"found": found, "fp": fp, "n": len(e)}
    if len(e) < 4:
        return out, good
    z = e / se
    dm = e - e.mean(axis=0)
    # per image axis (u across the frame, v down it): a 4:2:0 writer's
    # chroma filter need not be the same along both
    out.update(z_u=float(np.sqrt(np.mean(z[:, 0] ** 2))), z_v=float(np.sqrt(np.mean(z[:, 1] ** 2))))
    out.update(rmse=float(np.sqrt(np.mean(e**2))), z=float(np.sqrt(np.mean(z**2))),
               z_raw=float(np.sqrt(np.mean(z**2) * res.look_factor)),
               z_dm=float(np.sqrt(np.mean((dm / se) ** 2))), bias=float(np.hypot(*e.mean(axis=0))),
               factor=float(res.look_factor), rho=float(res.look_rho))
    return out, good


def realistic_shot(args):
    """Render, transcode, track three ways and bound one realistic shot: one CSV row."""
    i, seed, seconds, tmp, frames_dir, codecs, mix = args
    import pandas as pd

    from cuespin.render import render_video
    from cuespin.render.draw import FrameRenderer
    from cuespin.track.bound import centroid_crb_realistic
    from cuespin.track.tracker import FIT_BLUR_PX, TrackerConfig

    scene, look = realistic_scene(i, seed, seconds, mix)
    cam = scene.camera
    path = Path(tmp) / f"real_{i}.avi"
    render_video(scene, path)
    truth = pd.read_csv(path.with_suffix(".truth.csv"))
    tuv, t = np.c_[truth.uc_px.values, truth.vc_px.values], truth.t.values
    cloth = scene.table.contains(np.c_[truth.x_m.values, truth.y_m.values], scene.physics.R)
    cap = cv2.VideoCapture(str(path))
    mj, grey = Path(tmp) / f"real_{i}_mjpg.avi", Path(tmp) / f"real_{i}_grey.avi"
    wm = wg = None
    while True:
        got, fr = cap.read()
        if not got:
            break
        if wm is None:
            size = (fr.shape[1], fr.shape[0])
            wm = cv2.VideoWriter(str(mj), cv2.VideoWriter_fourcc(*"MJPG"), cam.fps, size, True)
            wg = cv2.VideoWriter(str(grey), cv2.VideoWriter_fourcc(*"FFV1"), cam.fps, size, False)
        wm.write(fr)
        wg.write(cv2.cvtColor(fr, cv2.COLOR_BGR2GRAY))
    cap.release()
    wm.release()
    wg.release()
    row = {"i": i, "look": look, "fps": cam.fps, "noise": scene.render["noise_sigma"],
           "ball": scene.render["ball_name"], "felt": scene.render["felt_name"],
           "exposure": cam.exposure_s * cam.fps,
           "cue": bool(scene.render.get("cue", False)), "n_balls": len(scene.render.get("balls") or [])}
    cfg = TrackerConfig(threaded=False)
    goods = {}
    for name, video in (("ffv1", path), ("mjpg", mj), ("grey", grey)):
        if name not in codecs:
            continue
        res = track_video(video, scene, cfg)
        stats, goods[name] = _track_stats(res, tuv, t, scene.truth.t0, res.radius_px, cam, cloth)
        row.update({f"{name}_{k}": v for k, v in stats.items()})
        if frames_dir:
            n = min(res.n_frames, len(tuv))
            np.savez(Path(frames_dir) / f"shot{i}_{name}.npz", t=t[:n], tuv=tuv[:n], uv=res.uv[:n],
                     cov=res.cov_px[:n], good=goods[name], factor=res.look_factor, rho=res.look_rho,
                     fit_rms=res.fit_rms[:n] if res.fit_rms is not None else np.full(n, np.nan),
                     radius=res.radius_px, t0=scene.truth.t0, lossless=res.lossless,
                     luma_blind=bool(res.projection.luma_blind), shaded=res.look_shaded)
    for video in (path, mj, grey):
        video.unlink()
    if "ffv1" not in goods:  # the bound goes with the full table only
        row["bound"] = row["bound_grey"] = float("nan")
        return row
    r = FrameRenderer(scene)
    moving = np.flatnonzero(goods["ffv1"]) if goods["ffv1"].any() else np.flatnonzero(t > scene.truth.t0 + 0.02)
    b_col, b_grey = [], []
    for k in moving[np.linspace(0, len(moving) - 1, min(6, len(moving))).astype(int)]:
        nodes = r._uv_nodes[k]
        fit_blur = np.hypot(*(nodes[-1] - nodes[0])) * (1 + 1 / max(len(nodes) - 1, 1)) > FIT_BLUR_PX
        b_col.append(centroid_crb_realistic(r, int(k), fit_blur))
        b_grey.append(centroid_crb_realistic(r, int(k), fit_blur, grey_weights=LUMA))
    row["bound"] = float(np.sqrt(np.mean(np.square(b_col))))
    row["bound_grey"] = float(np.sqrt(np.mean(np.square(b_grey))))
    return row


def realistic(args):
    """The realistic-look table (see the module docstring), per shot and per look."""
    import csv
    from multiprocessing import Pool

    rows = []
    if args.frames_out:  # each worker writes its shot's npz there
        Path(args.frames_out).mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp, Pool(args.workers) as pool:
        shots = args.shots if args.shots else range(args.n)
        jobs = [(i, args.seed, args.seconds, tmp, args.frames_out, args.codecs, args.mix) for i in shots]
        out = None
        for row in pool.imap_unordered(realistic_shot, jobs):
            rows.append(row)
            print(f"shot {row['i']:3d} {row['look']:9} fps {row['fps']:3.0f} noise {row['noise']:4.1f} "
                  f"ffv1 rmse {row.get('ffv1_rmse', np.nan):.4f} z {row.get('ffv1_z', np.nan):.2f} "
                  f"(raw {row.get('ffv1_z_raw', np.nan):.2f}) mjpg z {row.get('mjpg_z', np.nan):.2f} "
                  f"(u {row.get('mjpg_z_u', np.nan):.2f}, v {row.get('mjpg_z_v', np.nan):.2f}) "
                  f"bound {row['bound']:.4f}", flush=True)
            if args.csv:
                if out is None:
                    out = open(args.csv, "w", newline="")
                    w = csv.DictWriter(out, fieldnames=sorted(row), restval="")
                    w.writeheader()
                w.writerow(row)
                out.flush()
    if set(args.codecs) == {"ffv1", "mjpg", "grey"}:
        realistic_table(rows)


def realistic_table(rows):
    """Per look: medians over shots (found % is the pooled share's minimum and mean)."""
    import pandas as pd

    df = pd.DataFrame(rows)
    print(f"\nrealistic looks: {len(df)} shots; per look the median over shots (found: mean, min; fp: frames)")
    print(f"{'look':9} {'n':>3} | {'found':>12} {'fp':>4} {'rmse':>7} {'bound':>7} {'ratio':>6} {'err/se':>6} "
          f"{'raw':>5} {'dm':>5} {'bias':>6} | {'MJPG rmse':>9} {'err/se':>6} {'raw':>5} | "
          f"{'grey rmse':>9} {'bound':>7} {'ratio':>6} {'err/se':>6}")
    for look, g in list(df.groupby("look", sort=False)) + [("all", df)]:
        def med(c):
            return float(np.nanmedian(g[c])) if c in g and np.isfinite(g[c]).any() else float("nan")
        print(f"{look:9} {len(g):3d} | {g.ffv1_found.mean():6.1%} {g.ffv1_found.min():5.1%} {int(g.ffv1_fp.sum()):4d} "
              f"{med('ffv1_rmse'):7.4f} {med('bound'):7.4f} {np.nanmedian(g.ffv1_rmse / g.bound):6.1f} "
              f"{med('ffv1_z'):6.2f} {med('ffv1_z_raw'):5.2f} {med('ffv1_z_dm'):5.2f} {med('ffv1_bias'):6.3f} | "
              f"{med('mjpg_rmse'):9.4f} {med('mjpg_z'):6.2f} {med('mjpg_z_raw'):5.2f} | "
              f"{med('grey_rmse'):9.4f} {med('bound_grey'):7.4f} {np.nanmedian(g.grey_rmse / g.bound_grey):6.1f} "
              f"{med('grey_z'):6.2f}")
    for codec in ("ffv1", "mjpg"):
        z = df[f"{codec}_z"].dropna()
        print(f"{codec}: err/se median {z.median():.2f}, share of shots within 0.8-1.25: "
              f"{np.mean((z >= 0.8) & (z <= 1.25)):.0%}, p10 {z.quantile(0.1):.2f}, p90 {z.quantile(0.9):.2f} "
              f"(before the look factor: median {df[f'{codec}_z_raw'].median():.2f}; per axis u / v: median "
              f"{df[f'{codec}_z_u'].median():.2f} / {df[f'{codec}_z_v'].median():.2f})")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("parts", nargs="*", default=["speed", "memory", "colour", "accuracy"])
    ap.add_argument("--n", type=int, default=60, help="realistic: shots")
    ap.add_argument("--seed", type=int, default=0, help="realistic: data_gen seed")
    ap.add_argument("--workers", type=int, default=2, help="realistic: worker processes")
    ap.add_argument("--seconds", type=float, default=0.6, help="realistic: video length cap (s)")
    ap.add_argument("--csv", default=None, help="realistic: write every shot's row here")
    ap.add_argument("--shots", type=int, nargs="+", default=None,
                    help="realistic: only these shots (indices of the --n set's sample)")
    ap.add_argument("--mix", action="store_true",
                    help="realistic: keep the sampler's cue and resting balls (default: removed, the looks alone)")
    ap.add_argument("--frames-out", default=None,
                    help="realistic: a directory to write each shot's per-frame track (npz) into")
    ap.add_argument("--codecs", nargs="+", default=None, type=str.lower,
                    choices=["ffv1", "mjpg", "grey", "mp4v", "h264"],
                    help="realistic: track only these of ffv1 mjpg grey (default all three; the table needs all "
                         "three; the CSV has what was tracked); speed: only these of mjpg ffv1 mp4v h264 (default "
                         "all four); memory: each of these (default mjpg)")
    ap.add_argument("--rest", action="store_true",
                    help="speed, memory: the slower shot that stops in view at frame 787 (the default shot "
                         "leaves the view at ~460); prints how the resting ball is followed")
    ap.add_argument("--fresh-noise", action="store_true",
                    help="speed, memory: new noise in every frame (a camera's sensor), not the rolled bank of 16 "
                         "(x264 codes the bank's frames in ~450 bytes: a cheap decode)")
    ap.add_argument("--video-dir", default=None,
                    help="speed, memory: write the videos here and reuse them (default: a temporary directory)")
    ap.add_argument("--summarize", default=None, help="realistic: only print the table of a CSV written before")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--threads", action="store_true", help="speed: each run's CPU by thread (Linux)")
    ap.add_argument("--quick", action="store_true", help="one radius in the accuracy table")
    ap.add_argument("--frames", type=int, nargs="+", default=[1000, 10000])
    args = ap.parse_args()
    if args.summarize:
        import pandas as pd
        realistic_table(pd.read_csv(args.summarize).to_dict("records"))
        return
    cv2.setNumThreads(2)
    names = {c.lower(): c for c in CODECS}
    if "realistic" in args.parts:
        args.codecs = args.codecs or ["ffv1", "mjpg", "grey"]
        if not set(args.codecs) <= {"ffv1", "mjpg", "grey"}:
            ap.error("realistic: --codecs of ffv1 mjpg grey")
        realistic(args)
        args.codecs = None
    if not set(args.codecs or ()) <= set(names):
        ap.error("speed, memory: --codecs of " + " ".join(names))
    with tempfile.TemporaryDirectory() as tmp:
        vdir = args.video_dir or tmp
        if "speed" in args.parts:
            speed(vdir, args.repeat, args.frames, args.threads,
                  codecs=[names[c] for c in args.codecs] if args.codecs else tuple(CODECS), rest=args.rest,
                  keep=args.video_dir is not None or "memory" in args.parts, fresh=args.fresh_noise)
        if "memory" in args.parts:
            for c in args.codecs or ["mjpg"]:
                memory(vdir, args.frames, names[c], rest=args.rest, fresh=args.fresh_noise)
        if "colour" in args.parts:
            colour(tmp, args.quick)
        if "accuracy" in args.parts:
            accuracy(tmp, args.quick)


if __name__ == "__main__":
    main()
