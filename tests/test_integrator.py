"""abs's path tracer against Mitsuba's own, and its environment against Mitsuba's envmap."""

from __future__ import annotations

import cv2
import drjit as dr
import mitsuba as mi
import numpy as np

from abs.camera.pinhole import intrinsics_from_fov, look_at
from abs.render import Camera, Environment, compile_scene
from abs.scene import load_scene


def test_environment_matches_mitsuba_envmap():
    rng = np.random.default_rng(1)
    env = Environment(rng.uniform(0, 1, (16, 32, 3)).astype(np.float32), scale=2.0, rotation=0.3)
    reference = mi.load_dict(env.mitsuba_dict())
    d = rng.normal(size=(5000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    si = dr.zeros(mi.SurfaceInteraction3f, len(d))
    si.wi = -mi.Vector3f(d.T)
    # On CUDA, Mitsuba's envmap filters with the GPU's texture units, whose bilinear weights are
    # fixed point with 8 fractional bits (CUDA programming guide, "Linear Filtering"): each of the
    # two weights may be off by up to 1/256, times a neighbouring texel difference of up to the
    # data's range (1) times the scale (2). Measured on an H100: at most 0.0083 here. abs's own
    # lookup is exact in float32.
    atol = 2 * (1 / 256) * (1.0 * 2.0) if mi.variant().startswith("cuda") else 1e-5
    np.testing.assert_allclose(np.array(env.eval(mi.Vector3f(d.T))), np.array(reference.eval(si)),
                               rtol=1e-4, atol=atol)


def test_environment_pdf_is_normalised():
    rng = np.random.default_rng(2)
    env = Environment(rng.uniform(0, 5, (16, 32, 3)).astype(np.float32))
    d = rng.normal(size=(200000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    integral = np.array(env.pdf(mi.Vector3f(d.T))).mean() * 4 * np.pi
    assert abs(integral - 1.0) < 0.02
    directions, pdf = env.sample(mi.Point2f(rng.uniform(size=(2, 1000))))
    np.testing.assert_allclose(np.array(env.pdf(directions)), np.array(pdf), rtol=1e-2)


def test_matches_mitsuba_path_tracer(small_scene_dir):
    """Same geometry, same lighting, glass without absorption: abs and Mitsuba's ``path`` agree."""
    compiled = compile_scene(load_scene(small_scene_dir / "scene.toml"))
    compiled.set("glass.absorption", [0.0, 0.0, 0.0])
    eye, target, width, height, fov = [0.0, 0.12, 0.4], [0.0, 0.05, 0.0], 64, 48, 35.0
    R, t = look_at(np.array(eye), np.array(target))
    ours = compiled.render(Camera(intrinsics_from_fov(width, height, np.radians(fov)), R, t, width, height),
                           spp=256, seed=1, max_depth=8).numpy()
    d = compiled.mitsuba_dict()
    d["glass"] = {"type": "dielectric", "int_ior": 1.5, "ext_ior": 1.0, "id": "glass"}
    d["integrator"] = {"type": "path", "max_depth": 8}
    d["sensor"] = {"type": "perspective", "fov": fov, "fov_axis": "y",
                   "to_world": mi.ScalarTransform4f().look_at(origin=eye, target=target, up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": width, "height": height,
                            "rfilter": {"type": "tent"}, "pixel_format": "rgb"}}
    theirs = np.array(mi.render(mi.load_dict(d, optimize=False), spp=256, seed=2))
    assert np.abs(ours.mean(axis=(0, 1)) / theirs.mean(axis=(0, 1)) - 1).max() < 0.01
    blur = lambda x: cv2.blur(x, (5, 5))  # noqa: E731  (average out Monte Carlo noise)
    assert np.abs(blur(ours) - blur(theirs)).mean() / theirs.mean() < 0.02
