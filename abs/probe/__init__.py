"""Light probes: environment maps from photographs of a chrome ball (``abs probe unwrap``).

A package of its own, beside :mod:`abs.camera`, because unwrapping is camera geometry (project
a ball point with a calibrated pinhole camera, triangulate the ball) that only borrows one
colour quantity, chromium's per-channel complex IOR, from :mod:`abs.colour`.
"""

from abs.probe.ball import outline_cone, triangulate_ball
from abs.probe.fresnel import conductor_reflectance
from abs.probe.unwrap import ProbeView, latlong_directions, merge_views, unwrap_view

__all__ = ["conductor_reflectance", "outline_cone", "triangulate_ball", "ProbeView", "latlong_directions", "unwrap_view", "merge_views"]
