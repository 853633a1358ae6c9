"""The independent truth renderer of subsurface scattering (a scattering slab in Mitsuba's
``volpath``): its albedo inversion, and agreement with abs's plain diffuse cloth when the medium's
mean free path is far below a pixel."""

from __future__ import annotations

import cv2
import numpy as np

from abs.camera.pinhole import intrinsics_from_fov, look_at
from abs.render import Camera, compile_scene
from abs.render.medium_truth import _diffuse_reflectance, albedo_for_reflectance, render_with_medium
from abs.scene import load_scene


def test_albedo_inversion():
    r = np.array([0.05, 0.3, 0.7])
    np.testing.assert_allclose(_diffuse_reflectance(albedo_for_reflectance(r)), r, rtol=1e-9)


def test_thin_medium_looks_like_the_diffuse_cloth(small_scene_dir):
    compiled = compile_scene(load_scene(small_scene_dir / "scene.toml"))
    R, t = look_at(np.array([0.0, 0.2, 0.25]), np.array([0.0, 0.0, 0.0]))
    camera = Camera(intrinsics_from_fov(32, 24, np.radians(30)), R, t, 32, 24)
    ours = compiled.render(camera, spp=64, seed=0, max_depth=6).numpy()
    truth = render_with_medium(compiled, camera, "cloth", mean_free_path=2e-4, spp=64, max_depth=200)
    assert truth.shape == ours.shape
    blur = lambda x: cv2.blur(x, (5, 5))  # noqa: E731
    # Same geometry and camera (pixel-aligned), similar cloth brightness; a semi-infinite medium
    # is not exactly Lambertian, hence the loose bound.
    assert abs(truth.mean() / ours.mean() - 1) < 0.1
    assert np.abs(blur(truth) - blur(ours)).mean() / ours.mean() < 0.15
