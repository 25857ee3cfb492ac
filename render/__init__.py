"""Frames of a scene from the forward model, written as real video files.

Plain grey or realistic colour (:mod:`cuespin.render.look`), through any camera.
"""

from cuespin.render.draw import (FrameRenderer, FrameTruth, ball_motion, disc_coverage,
                                 polygon_coverage_batch, render_settings, video_length)
from cuespin.render.video import VideoError, read_truth_csv, render_video, truth_path

__all__ = ["FrameRenderer", "FrameTruth", "ball_motion", "disc_coverage", "polygon_coverage_batch",
           "render_settings", "video_length", "VideoError", "read_truth_csv", "render_video", "truth_path"]
