"""More samples where glass is seen (``Camera.boost``): unbiased, less noisy there, the same
elsewhere, and the same in every render mode (primal, recording, forward derivatives)."""

from __future__ import annotations

import dataclasses

import mitsuba as mi
import numpy as np
import pytest

from abs.model import build_model
from abs.model.counter import RenderCounter
from abs.model.observations import Observation, boost_where_seen
from abs.render.camera import SampleBoost
from abs.scene import load_scene
from conftest import sphere_in_view

W, H, SPP = 24, 18, 8
BOX = SampleBoost(6, 4, 18, 14, 4)


@pytest.fixture(scope="module")
def scene(small_scene_dir):
    return sphere_in_view(small_scene_dir, W, H)


def _inside() -> np.ndarray:
    m = np.zeros((H, W), bool)
    m[BOX.y0:BOX.y1, BOX.x0:BOX.x1] = True
    return m


def test_boosted_pixels_are_less_noisy_and_unbiased_the_others_unchanged(scene):
    compiled, camera = scene
    boosted = dataclasses.replace(camera, boost=BOX)
    plain = np.array([compiled.render(camera, SPP, seed=s).numpy() for s in range(8)])
    more = np.array([compiled.render(boosted, SPP, seed=s).numpy() for s in range(8)])
    inside = _inside()
    # Bit for bit reproducible (block sums, no atomic adds).
    np.testing.assert_array_equal(compiled.render(boosted, SPP, seed=0).numpy(), more[0])
    # Outside the rectangle a boosted render traces exactly the unboosted render's lanes.
    np.testing.assert_array_equal(more[:, ~inside], plain[:, ~inside])
    # Inside, four times the samples: the variance over seeds falls by about four.
    ratio = more.var(axis=0)[inside].mean() / plain.var(axis=0)[inside].mean()
    assert 0.15 < ratio < 0.45, ratio
    # Unbiased: the mean over seeds agrees with the unboosted mean within their noise.
    diff = more.mean(axis=0)[inside] - plain.mean(axis=0)[inside]
    se = np.sqrt((more.var(axis=0)[inside] + plain.var(axis=0)[inside]) / 8)
    assert abs(diff.sum()) < 4 * np.sqrt(np.sum(se ** 2))


def test_every_render_mode_sees_the_same_boosted_samples(scene):
    compiled, camera = scene
    boosted = dataclasses.replace(camera, boost=BOX)
    image = compiled.render(boosted, SPP, seed=5).numpy()
    # Recorded at the scene's own absorption: its reweighting is that render's, up to rounding.
    recording = compiled.record(boosted, SPP, seed=5, absorption_per_m=compiled.get("glass.absorption"))
    recorded = compiled.render_recorded(recording, boosted).numpy()
    np.testing.assert_allclose(recorded, image, rtol=1e-4, atol=1e-6)
    forward, derivative = compiled.render_forward(boosted, {"glass.absorption": [1.0, 1.0, 1.0]},
                                                  spp=SPP, seed=5)
    np.testing.assert_allclose(forward.numpy(), image, rtol=1e-5, atol=1e-6)
    _, d_recorded = compiled.render_recorded_forward(recording, boosted,
                                                     {"glass.absorption": [1.0, 1.0, 1.0]})
    np.testing.assert_allclose(d_recorded.numpy(), derivative.numpy(), rtol=2e-2, atol=1e-5)
    # Path replay of the same samples: the gradient of sum(w * image) is the forward
    # derivative's sum(w * d image) (absorption changes no path).
    w = np.random.default_rng(0).normal(size=(H, W, 3))
    replayed, gradient = compiled.render_backward(boosted, w, ["glass.absorption"], spp=SPP, seed=5)
    np.testing.assert_allclose(replayed, image, rtol=1e-5, atol=1e-6)
    assert np.sum(gradient["glass.absorption"]) == pytest.approx(float(np.sum(w * derivative.numpy())),
                                                                  rel=1e-3)


def test_the_boost_covers_where_the_glass_is_seen_and_its_samples_count(scene, small_scene_dir):
    compiled, camera = scene
    obs = Observation("v", False, camera, np.zeros((H, W, 3)), np.ones((H, W), bool))
    bounds = compiled.transmissive_bounds()
    assert len(bounds) == 1
    boost = boost_where_seen(obs, bounds, 4).camera.boost
    assert boost is not None and boost.factor == 4
    # Every pixel whose centre sees the glass first lies in the rectangle.
    v, u = np.mgrid[0:H, 0:W].astype(np.float32)
    origin, direction = camera.rays(mi.Float(u.ravel()), mi.Float(v.ravel()))
    hit = compiled.mitsuba_scene.ray_intersect(mi.Ray3f(origin, direction))
    glass = [s for s in compiled.mitsuba_scene.shapes() if s.bsdf().id() == "glass"][0]
    seen = (hit.is_valid().numpy() & (hit.shape == mi.ShapePtr(glass)).numpy()).reshape(H, W)
    ys, xs = np.nonzero(seen)
    assert ys.size > 10
    assert boost.y0 <= ys.min() and ys.max() < boost.y1 and boost.x0 <= xs.min() and xs.max() < boost.x1
    assert boost.pixels < W * H  # it is a rectangle around the glass, not the image
    assert boost_where_seen(obs, bounds, 1) is obs and boost_where_seen(obs, [], 4) is obs
    counter = RenderCounter()
    counter.add(dataclasses.replace(camera, boost=boost), SPP)
    assert counter.samples == (W * H + 3 * boost.pixels) * SPP
    with pytest.raises(ValueError, match="outside"):
        dataclasses.replace(camera, boost=SampleBoost(0, 0, W + 1, H, 2))
    with pytest.raises(ValueError, match="factor >= 2"):
        SampleBoost(0, 0, 4, 4, 1)


def test_a_model_with_a_glass_boost_boosts_its_problems(small_scene_dir, tmp_path):
    from abs.simulate import simulate_capture

    simulate_capture(load_scene(small_scene_dir / "scene.toml"), tmp_path / "capture", n_cameras=2,
                     width=W, height=H, spp=16, seed=3)
    model = build_model(small_scene_dir / "scene.toml", tmp_path / "capture", ["glass.absorption"],
                        glass_spp_factor=3)
    cameras = [o.camera for o in model.problem("train", 2).observations]
    assert all(c.boost is not None and c.boost.factor == 3 and c.block == 2 for c in cameras)
    plain = build_model(small_scene_dir / "scene.toml", tmp_path / "capture", ["glass.absorption"])
    assert all(o.camera.boost is None for o in plain.problem("train").observations)
