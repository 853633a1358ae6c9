"""A ``brdf_pca`` material renders, and its coefficients get gradients through the renderer."""

from __future__ import annotations

import mitsuba as mi
import numpy as np

from abs.brdf.basis import BRDFBasis
from abs.camera.pinhole import intrinsics_from_fov, look_at
from abs.io.merl import MERL_SIZE
from abs.render import Camera, compile_scene
from abs.scene import load_scene
from gradcheck import assert_gradients_agree, directional_gradient


def test_coefficients_gradient(silhouette_scene_dir, tmp_path):
    rng = np.random.default_rng(0)
    median = np.full(MERL_SIZE, 0.2, np.float32)
    components = (rng.normal(size=(2, MERL_SIZE)) * 0.3).astype(np.float32)
    BRDFBasis(mean=np.zeros(MERL_SIZE, np.float32), components=components, median=median,
              epsilon=1e-3).save(tmp_path / "basis.npz")
    (tmp_path / "sphere.ply").write_bytes((silhouette_scene_dir / "sphere.ply").read_bytes())
    (tmp_path / "env.exr").write_bytes((silhouette_scene_dir / "env.exr").read_bytes())
    (tmp_path / "scene.toml").write_text(
        '[environment]\nfile = "env.exr"\n\n[materials.paint]\ntype = "brdf_pca"\nbasis = "basis.npz"\n'
        'coefficients = [0.5, -0.3]\n\n[[objects]]\nname = "sphere"\nmesh = "sphere.ply"\nmaterial = "paint"\n')
    compiled = compile_scene(load_scene(tmp_path / "scene.toml"))
    R, t = look_at(np.array([0.0, 0.05, 0.3]), np.array([0.0, 0.05, 0.0]))
    camera = Camera(intrinsics_from_fov(24, 24, np.radians(25)), R, t, 24, 24)
    image = compiled.render(camera, spp=16).numpy()
    assert np.isfinite(image).all() and image[12, 12].mean() > 0
    weights = mi.TensorXf(rng.uniform(0, 1, (24, 24, 3)).astype(np.float32))
    assert_gradients_agree(*directional_gradient(compiled, camera, "paint.coefficients", [1.0, 0.5],
                                                 0.05, weights, max_depth=2))
