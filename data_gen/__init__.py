"""Seeded scene sampling and datasets of videos with their scene files."""

from cuespin.data_gen.sampler import LOOKS, PRESETS, make_scene, sample_scene, sample_scenes, sample_shot

__all__ = ["LOOKS", "PRESETS", "make_scene", "sample_scene", "sample_scenes", "sample_shot"]
