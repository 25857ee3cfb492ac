"""Seeded scene sampling and datasets of videos with their scene files."""

from cuespin.data_gen.sampler import CAMERAS, LOOKS, PRESETS, make_scene, sample_scene, sample_scenes, sample_shot

__all__ = ["CAMERAS", "LOOKS", "PRESETS", "make_scene", "sample_scene", "sample_scenes", "sample_shot"]
