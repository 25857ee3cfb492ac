"""cuespin: a billiard ball's initial velocity and spin from video.

The stages install as subpackages of this one name (``cuespin.physics``,
``cuespin.track``, ...); their folders sit at the repository root.
"""

__version__ = "0.2.0"
