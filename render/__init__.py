"""Top-down frames of a scene from the forward model, written as real video files."""

from cuespin.render.draw import FrameRenderer, FrameTruth, disc_coverage, render_settings, video_length
from cuespin.render.video import VideoError, read_truth_csv, render_video, truth_path

__all__ = ["FrameRenderer", "FrameTruth", "disc_coverage", "render_settings", "video_length",
           "VideoError", "read_truth_csv", "render_video", "truth_path"]
