"""``roughness`` of the ``dielectric`` material: the smooth glass exactly at 0, Mitsuba's rough
dielectric (same Beckmann microfacet model) at alpha > 0, and gradients equal to finite
differences (zero at alpha = 0, where the symmetric spread changes the image at second order)."""

from __future__ import annotations

import cv2
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from abs.camera.pinhole import intrinsics_from_fov, look_at
from abs.errors import SceneError
from abs.render import Camera, compile_scene
from abs.scene import load_scene
from gradcheck import assert_gradients_agree, directional_gradient

W = H = 24


def _smooth_reference(wi, ior, channel_ior, sample1):
    """The smooth interface's sample (direction, weight) as abs computed it before roughness
    existed (radiance mode, both lobes enabled)."""
    cos_i = mi.Frame3f.cos_theta(wi)
    f_r = mi.Color3f(*[mi.fresnel(cos_i, c)[0] for c in ior])
    f_k, cos_t, _, eta_ti = mi.fresnel(cos_i, channel_ior)
    p_r = dr.detach(f_k)
    select_r = sample1 <= p_r
    wo = dr.select(select_r, mi.reflect(wi), mi.refract(wi, cos_t, eta_ti))
    weight = dr.select(select_r, f_r / dr.maximum(p_r, 1e-12),
                       (1.0 - f_r) / dr.maximum(1.0 - p_r, 1e-12) * dr.square(eta_ti))
    return wo, weight


def test_zero_roughness_is_the_smooth_interface_bitwise():
    ior = [1.45, 1.5, 1.6]
    bsdf = mi.load_dict({"type": "abs_dielectric", "ior": ior, "roughness": 0.0})
    rng = np.random.default_rng(0)
    n = 4000
    wi = rng.normal(size=(n, 3))
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)  # both sides: entering and leaving
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(wi.T.astype(np.float32))
    si.time = mi.Float(1.0)  # the green pass: refracts with ior[1]
    si.t = mi.Float(0.1)  # no absorption: exp(-0 * t) = 1
    s1 = mi.Float(rng.uniform(size=n).astype(np.float32))
    s2 = mi.Point2f(rng.uniform(size=(2, n)).astype(np.float32))
    bs, weight = bsdf.sample(mi.BSDFContext(), si, s1, s2)
    wo, expected = _smooth_reference(si.wi, ior, mi.Float(ior[1]), s1)
    assert np.array_equal(np.array(bs.wo), np.array(wo))
    assert np.array_equal(np.array(weight), np.array(expected))


@pytest.fixture(scope="module")
def glass(glass_scene_dir):
    compiled = compile_scene(load_scene(glass_scene_dir / "scene.toml"))
    compiled.set("glass.absorption", [0.0, 0.0, 0.0])
    R, t = look_at(np.array([0.0, 0.06, 0.3]), np.array([0.0, 0.05, 0.0]))
    return compiled, R, t


def test_rough_glass_matches_mitsuba_roughdielectric(glass):
    """Same microfacet model, independent implementation (Mitsuba samples visible normals)."""
    compiled, R, t = glass
    width, height, fov, alpha = 48, 36, 30.0, 0.2
    compiled.set("glass.roughness", [alpha])
    try:
        ours = compiled.render(Camera(intrinsics_from_fov(width, height, np.radians(fov)), R, t,
                                      width, height), spp=256, seed=1, max_depth=8).numpy()
    finally:
        compiled.set("glass.roughness", [0.0])
    d = compiled.mitsuba_dict()
    d["glass"] = {"type": "roughdielectric", "distribution": "beckmann", "alpha": alpha,
                  "int_ior": 1.5, "ext_ior": 1.0, "id": "glass"}
    d["integrator"] = {"type": "path", "max_depth": 8}
    eye = -R.T @ t
    d["sensor"] = {"type": "perspective", "fov": fov, "fov_axis": "y",
                   "to_world": mi.ScalarTransform4f().look_at(origin=eye.tolist(), target=[0.0, 0.05, 0.0],
                                                              up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": width, "height": height,
                            "rfilter": {"type": "tent"}, "pixel_format": "rgb"}}
    theirs = np.array(mi.render(mi.load_dict(d, optimize=False), spp=256, seed=2))
    # The glass covers the middle of the image: compare there, after averaging out noise.
    blur = lambda x: cv2.blur(x, (5, 5))[8:-8, 12:-12]  # noqa: E731
    assert np.abs(blur(ours).mean() / blur(theirs).mean() - 1) < 0.02
    assert np.abs(blur(ours) - blur(theirs)).mean() / blur(theirs).mean() < 0.04


@pytest.mark.parametrize("alpha", [0.05, 0.2])
def test_roughness_gradient(glass, alpha):
    compiled, R, t = glass
    camera = Camera(intrinsics_from_fov(W, H, np.radians(25)), R, t, W, H)
    weights = mi.TensorXf(np.random.default_rng(3).uniform(0, 1, (H, W, 3)).astype(np.float32))
    compiled.set("glass.roughness", [alpha])
    try:
        res = directional_gradient(compiled, camera, "glass.roughness", [1.0], 0.02, weights,
                                   seeds=6, spp=64)
    finally:
        compiled.set("glass.roughness", [0.0])
    assert_gradients_agree(*res, rel=0.1)


def test_roughness_derivative_at_zero_is_zero(glass):
    compiled, R, t = glass
    camera = Camera(intrinsics_from_fov(W, H, np.radians(25)), R, t, W, H)
    x = mi.Float([0.0])
    dr.enable_grad(x)
    compiled.set("glass.roughness", x)
    image = compiled.render(camera, spp=4, seed=0, max_depth=4)
    # Dr.Jit may prune the unselected rough branch from the graph altogether.
    dr.backward(dr.sum(image, axis=None), flags=dr.ADFlag.Default | dr.ADFlag.AllowNoGrad)
    compiled.set("glass.roughness", [0.0])
    assert float(dr.grad(x)[0]) == 0.0


def test_roughness_field_validation(glass_scene_dir, tmp_path):
    text = (glass_scene_dir / "scene.toml").read_text()
    for asset in ("sphere.ply", "env.exr"):
        (tmp_path / asset).write_bytes((glass_scene_dir / asset).read_bytes())
    (tmp_path / "scene.toml").write_text(text.replace('type = "dielectric"', 'type = "dielectric"\nroughness = -0.1'))
    with pytest.raises(SceneError, match="materials.glass.roughness: must be >= 0"):
        load_scene(tmp_path / "scene.toml")
    (tmp_path / "scene.toml").write_text(text.replace('type = "dielectric"', 'type = "dielectric"\nroughness = 0.1'))
    scene = load_scene(tmp_path / "scene.toml")
    assert scene.materials["glass"].roughness == 0.1
    assert compile_scene(scene).get("glass.roughness") == pytest.approx([0.1])
