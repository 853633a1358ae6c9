"""Characterising a renderer: render the design, measure its filter statistics."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from abs.appearance.design import MATERIAL_CLASSES, SceneSpec, design_digest
from abs.appearance.geometry import Geometry
from abs.appearance.lighting import lighting_image, sh9_coefficients
from abs.appearance.renderers import Renderer
from abs.appearance.scenes import design_camera, scene_geometry
from abs.appearance.statistics import Accumulator, Characterisation

__all__ = ["characterise", "render_design"]

ImageSink = Callable[[SceneSpec, np.ndarray, Geometry], None]


def render_design(renderer: Renderer, scenes: list[SceneSpec], environment: np.ndarray,
                  size: int, spp: int, seed: int, on_image: ImageSink):
    """Render every scene (seed ``seed + index``) and hand each image to ``on_image``.

    Parameters
    ----------
    renderer : Renderer
        What renders (:mod:`abs.appearance.renderers`).
    scenes : list of SceneSpec
        The design.
    environment : np.ndarray
        Lat-long map ``(H, W, 3)``, linear RGB radiance.
    size, spp, seed : int
        Image side (pixels), samples per pixel, first seed.
    on_image : callable
        Called with ``(spec, image, geometry)`` for every scene, in order (storage, progress).
    """
    camera = design_camera(size)
    for i, spec in enumerate(scenes):
        image = renderer.render(spec, environment, camera, spp, seed + i)
        on_image(spec, image, scene_geometry(spec, camera))


def characterise(renderer: Renderer, scenes: list[SceneSpec], environment: np.ndarray, *,
                 size: int = 64, spp: int = 32, seed: int = 0, n_bins: int = 9,
                 on_image: ImageSink | None = None,
                 settings: dict | None = None) -> Characterisation:
    """The filter statistics of ``renderer`` on ``scenes`` (see :mod:`abs.appearance.statistics`).

    Parameters
    ----------
    n_bins : int
        θ bins over [0°, 90°] (9: 10° each).
    on_image : callable, optional
        Also called with every image (to store it), as in :func:`render_design`.
    settings : dict, optional
        Extra provenance written into the file (e.g. the environment's path).

    Other parameters are those of :func:`render_design`.
    """
    classes = tuple(c for c in MATERIAL_CLASSES if any(s.material_class == c for sc in scenes
                                                          for s in sc.spheres))
    acc = Accumulator(classes, n_bins)
    sh = sh9_coefficients(environment)

    def gather(spec, image, geometry):
        acc.add(image, geometry, lighting_image(sh, geometry.normals))
        if on_image is not None:
            on_image(spec, image, geometry)

    render_design(renderer, scenes, environment, size, spp, seed, gather)
    return acc.finish(renderer.name, renderer.options, design_digest(scenes),
                      {"size": size, "spp": spp, "seed": seed, **(settings or {})})
