"""``anisotropy`` of the ``diffuse`` material (the ``cloth_anisotropy`` effect): Mitsuba's own
``diffuse`` exactly at ``[0, 0]``; away from it the lobe Mitsuba's ``roughconductor`` (GGX,
``material = "none"``) computes, reciprocal and energy-bounded; derivatives equal to finite
differences; bad input named by file and field; the effect offers itself where it is missing."""

from __future__ import annotations

from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from abs.diagnosis.effects import effects
from abs.errors import SceneError
from abs.render import PathTracer, compile_scene
from abs.render.bsdfs.diffuse import DiffuseBSDF
from abs.scene import load_scene, write_scene
from gradcheck import assert_gradients_agree, directional_gradient, gradient_setup

W = H = 24
NAME = "cloth.anisotropy"


@pytest.fixture(scope="module")
def setup(small_scene_dir):
    # The small scene with threads (at [0, 0]) on both diffuse materials: a diffuse material whose
    # file names none of the threads' fields is Mitsuba's own diffuse, without the parameter.
    text = (small_scene_dir / "scene.toml").read_text()
    path = small_scene_dir / "threads.toml"
    path.write_text(text.replace('type = "diffuse"', 'type = "diffuse"\nanisotropy = [0.0, 0.0]'))
    # Looking down at the floor at a slant, where the threads' lobes reflect the environment.
    return gradient_setup(path, W, [0.0, 0.15, 0.3], [0.0, 0.02, 0.0], 40, 4)


def test_without_threads_a_diffuse_material_is_mitsubas(small_scene_dir):
    """No thread field in the file: Mitsuba's diffuse, no anisotropy parameter, written back
    without thread fields; the effect still offers the material (it adds the field)."""
    scene = load_scene(small_scene_dir / "scene.toml")
    compiled = compile_scene(scene)
    assert compiled.mitsuba_dict()["cloth"]["type"] == "diffuse"
    assert NAME not in compiled.specs
    assert "anisotropy" not in scene.materials["cloth"].to_toml()
    assert "cloth" in effects()["cloth_anisotropy"].targets(scene, compiled)


def _stock(compiled) -> mi.Scene:
    """The compiled scene with every ``abs_diffuse`` replaced by Mitsuba's ``diffuse`` of the same
    reflectance (colour or texture)."""
    d = compiled.mitsuba_dict(include_environment=False)
    for name, material in compiled.scene.materials.items():
        if d[name]["type"] == "abs_diffuse":
            d[name] = {"type": "diffuse", "reflectance": d[name]["reflectance"], "id": name}
    return mi.load_dict(d, optimize=False)


def _same_model(image, reference):
    """Two renders of the same model, one through Mitsuba's C++ ``diffuse`` and one through the
    Python plugin: equal up to float round-off, which here is not quite bitwise (a CI run found
    10 of 1728 values 2-7e-6 apart, relative: the two BSDFs' kernels are compiled separately and
    may round or contract their arithmetic differently). A change of the model moves pixels by
    orders more."""
    np.testing.assert_allclose(image, reference, rtol=2e-5, atol=1e-7)


def test_null_is_mitsubas_diffuse(setup):
    """At [0, 0] the plugin skips the lobes (unless the weights are attached to the AD graph);
    with the lobes traced, weighted by 0, it renders the same image."""
    compiled, camera, _ = setup
    assert compiled.get(NAME).tolist() == [0.0, 0.0]
    image = compiled.render(camera, spp=4, seed=2, max_depth=4).numpy()
    stock = PathTracer(max_depth=4).render(_stock(compiled), compiled.environment, camera, 4, 2)
    _same_model(image, stock.numpy())
    bsdfs = [s.bsdf() for s in compiled.mitsuba_scene.shapes() if isinstance(s.bsdf(), DiffuseBSDF)]
    assert len(bsdfs) == 2 and not any(b.lobes for b in bsdfs)
    for b in bsdfs:
        b.lobes = True
    try:
        traced = compiled.render(camera, spp=4, seed=2, max_depth=4).numpy()
    finally:
        for b in bsdfs:
            b.parameters_changed([])
    assert not any(b.lobes for b in bsdfs)
    _same_model(traced, stock.numpy())
    # and the weights change it: the check is not vacuous
    compiled.set(NAME, [0.3, 0.1])
    try:
        moved = compiled.render(camera, spp=4, seed=2, max_depth=4).numpy()
    finally:
        compiled.set(NAME, [0.0, 0.0])
    assert np.abs(moved - image).max() > 1e-2


def _interaction(n: int, seed: int):
    """Surface interactions on the plane z = 0 with Mitsuba's frame (s = +x) and random
    incident directions above it, and random outgoing directions (local frame)."""
    rng = np.random.default_rng(seed)

    def hemisphere():
        v = rng.normal(size=(n, 3))
        v[:, 2] = np.abs(v[:, 2]) + 0.05
        return v / np.linalg.norm(v, axis=1, keepdims=True)

    wi, wo = hemisphere(), hemisphere()
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.n = mi.Normal3f(0, 0, 1)
    si.sh_frame = mi.Frame3f(mi.Vector3f(1, 0, 0), mi.Vector3f(0, 1, 0), mi.Vector3f(0, 0, 1))
    si.wi = mi.Vector3f(*[mi.Float(wi[:, i].astype(np.float32)) for i in range(3)])
    return si, mi.Vector3f(*[mi.Float(wo[:, i].astype(np.float32)) for i in range(3)]), wi, wo


def _bsdf(anisotropy, thread=(1.0, 0.0, 0.0), roughness=(0.3, 1.0)) -> mi.BSDF:
    return mi.load_dict({"type": "abs_diffuse", "reflectance": {"type": "rgb", "value": [0.6, 0.5, 0.4]},
                         "anisotropy_warp": anisotropy[0], "anisotropy_weft": anisotropy[1],
                         "thread_direction": mi.ScalarVector3f(*thread),
                         "thread_along": roughness[0], "thread_across": roughness[1]})


def test_single_scattering_is_mitsubas_anisotropic_microfacet_lobe():
    """``f_s`` of the warp (weft) is Mitsuba's ``roughconductor`` (GGX, no Fresnel) with alphas
    (along, across) ((across, along)) in the threads' frame; a thread direction along the
    frame's first tangent is that frame, one along the second swaps warp and weft."""
    si, wo, _, _ = _interaction(4096, 0)
    ctx = mi.BSDFContext()

    def conductor(au, av):
        b = mi.load_dict({"type": "roughconductor", "material": "none", "distribution": "ggx",
                          "alpha_u": au, "alpha_v": av, "sample_visible": False})
        return np.array(b.eval(ctx, si, wo))[0] / np.array(wo.z)

    bsdf = _bsdf([0.0, 0.0])
    for weft, (au, av) in ((False, (0.3, 1.0)), (True, (1.0, 0.3))):
        np.testing.assert_allclose(np.array(bsdf.single_scattering(si.wi, wo, weft)), conductor(au, av),
                                   rtol=2e-5, atol=1e-7)
    # Through the whole BSDF: turning the thread direction by 90 degrees swaps warp and weft.
    a = np.array(_bsdf([0.3, 0.1]).eval(ctx, si, wo))
    b = np.array(_bsdf([0.1, 0.3], thread=(0.0, 1.0, 0.0)).eval(ctx, si, wo))
    np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-7)


@pytest.mark.parametrize("roughness", [(0.3, 1.0), (0.05, 0.5)])
def test_lobes_are_reciprocal_and_conserve_energy(roughness):
    """Reciprocal; every direction's albedo is the reflectance's (to 1.5 %, the albedo table's interpolation):
    the lobes only redistribute the light the Lambertian would reflect."""
    ctx = mi.BSDFContext()
    bsdf = _bsdf([0.5, 0.5], thread=(0.6, 0.8, 0.0), roughness=roughness)
    si, wo, _, _ = _interaction(2048, 1)
    forward = np.array(bsdf.eval(ctx, si, wo)).T / np.array(wo.z)[:, None]
    swapped = dr.zeros(mi.SurfaceInteraction3f, 2048)
    swapped.sh_frame, swapped.n, swapped.wi = si.sh_frame, si.n, wo
    backward = np.array(bsdf.eval(ctx, swapped, si.wi)).T / np.array(si.wi.z)[:, None]
    np.testing.assert_allclose(forward, backward, rtol=1e-4, atol=1e-7)
    # Directional albedo by the BSDF's own (cosine-weighted) samples, 2^18 per direction.
    n = 1 << 18
    rng = np.random.default_rng(2)
    u = mi.Point2f(*[mi.Float(rng.uniform(size=n).astype(np.float32)) for _ in range(2)])
    for theta, phi in ((0.0, 0.0), (1.0, 0.0), (1.0, 1.2), (1.4, 0.5), (1.5, 1.5)):
        si = dr.zeros(mi.SurfaceInteraction3f, n)
        si.sh_frame = mi.Frame3f(mi.Vector3f(1, 0, 0), mi.Vector3f(0, 1, 0), mi.Vector3f(0, 0, 1))
        si.wi = mi.Vector3f(*[float(x) for x in (np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi),
                                                 np.cos(theta))])
        _, weight = bsdf.sample(ctx, si, mi.Float(0.5), u)
        albedo = np.array(weight).mean(axis=1) / np.array([0.6, 0.5, 0.4])
        np.testing.assert_allclose(albedo, 1.0, atol=0.015, err_msg=f"theta {theta}, phi {phi}")


@pytest.mark.parametrize("at, mode", [([0.0, 0.0], "forward"), ([0.0, 0.0], "replay"),
                                      ([0.3, 0.1], "forward")])
def test_gradient_against_finite_differences(setup, at, mode):
    """Forward mode (the fits' Jacobians, the score test) and path replay (gradients), at the
    null value and away from it. Weights along the image's change: the lobes conserve energy,
    so random positive weights see little of it."""
    compiled, camera, _ = setup
    renders = []
    for value in ([0.3, 0.2], [0.0, 0.0]):
        compiled.set(NAME, value)
        renders.append(compiled.render(camera, spp=64, seed=11, max_depth=4).numpy())
    weights = mi.TensorXf((renders[0] - renders[1]).astype(np.float32))
    compiled.set(NAME, at)
    try:
        res = directional_gradient(compiled, camera, NAME, [1.0, 0.5], 0.05, weights, seeds=3,
                                   spp=16, mode=mode)
    finally:
        compiled.set(NAME, [0.0, 0.0])
    assert_gradients_agree(*res, rel=0.05)


def _scene_text(small_scene_dir, tmp_path, extra: str) -> Path:
    for asset in ("sphere.ply", "floor.ply", "backdrop.obj", "env.exr", "checker.png"):
        (tmp_path / asset).write_bytes((small_scene_dir / asset).read_bytes())
    text = (small_scene_dir / "scene.toml").read_text()
    (tmp_path / "scene.toml").write_text(
        text.replace('reflectance = [0.7, 0.7, 0.65]', 'reflectance = [0.7, 0.7, 0.65]\n' + extra))
    return tmp_path / "scene.toml"


@pytest.mark.parametrize("extra, message", [
    ("anisotropy = [0.2, 0.7]", r"scene.toml: materials.cloth.anisotropy: all entries must be <= 0.5"),
    ("anisotropy = [-0.1, 0.0]", r"scene.toml: materials.cloth.anisotropy: all entries must be >= 0"),
    ("anisotropy = [0.1, 0.1, 0.1]", r"scene.toml: materials.cloth.anisotropy: expected shape \[2\]"),
    ("thread_direction = [0, 0, 0]", r"scene.toml: materials.cloth.thread_direction: must not be zero"),
    ("thread_roughness = [0.01, 1.0]", r"scene.toml: materials.cloth.thread_roughness: all entries must be >= 0.05"),
])
def test_bad_fields_are_named(small_scene_dir, tmp_path, extra, message):
    with pytest.raises(SceneError, match=message):
        load_scene(_scene_text(small_scene_dir, tmp_path, extra))


def test_effect_offers_itself_and_round_trips(small_scene_dir, tmp_path):
    """Offered for every diffuse material in use at [0, 0] and not fitted; releases
    ``<material>.anisotropy``; a written value is read back, reaches the BSDF, and the material
    is no longer a target."""
    scene = load_scene(_scene_text(small_scene_dir, tmp_path, 'thread_direction = [0, 0, 2]'))
    effect = effects()["cloth_anisotropy"]
    candidates = effect.candidates(scene, compile_scene(scene))
    assert {c.target: c.parameters for c in candidates} == {
        "cloth": ("cloth.anisotropy",), "backdrop": ("backdrop.anisotropy",)}
    assert not effect.zero_null_derivative
    data = {"materials": {"cloth": {"type": "diffuse"}}}
    effect.add(data, "cloth")
    assert data["materials"]["cloth"]["anisotropy"] == [0.0, 0.0]
    assert "0.2" in effect.explain("cloth", {"cloth.anisotropy": np.array([0.2, 0.05])})
    path = write_scene(scene, tmp_path / "written" / "scene.toml", {NAME: [0.2, 0.05]})
    again = load_scene(path)
    np.testing.assert_array_equal(again.materials["cloth"].anisotropy, [0.2, 0.05])
    np.testing.assert_array_equal(again.materials["cloth"].thread_direction, [0.0, 0.0, 1.0])
    compiled = compile_scene(again)
    assert compiled.get(NAME) == pytest.approx([0.2, 0.05])
    np.testing.assert_allclose(np.array(compiled.params[NAME]), [0.2, 0.05], rtol=1e-6)
    assert [c.target for c in effect.candidates(again, compiled)] == ["backdrop"]


def test_fits_with_the_effect_render_more_samples(small_scene_dir, tmp_path, monkeypatch):
    """A model with the threads' lobes is fitted at ``fit_spp_factor`` times the samples (a
    fixed-seed fit at few samples follows the noise the lobes' weights put into each sample) and
    without refinement; a model without it at the settings' own."""
    from abs.diagnosis import select
    from abs.fitting import FitSettings

    seen = []
    monkeypatch.setattr(select, "fit", lambda scene, capture, names, settings, **kw: seen.append(settings))
    monkeypatch.setattr(select, "model_identity", lambda *args: {})  # no capture here
    scene = load_scene(_scene_text(small_scene_dir, tmp_path, ""))
    (candidate,) = [c for c in effects()["cloth_anisotropy"].candidates(scene, compile_scene(scene))
                    if c.target == "cloth"]
    settings = FitSettings(spp=8)
    select.fit_model(scene, None, (), {}, settings, tmp_path / "control.toml")
    select.fit_model(scene, None, (candidate,), {}, settings, tmp_path / "trial.toml")
    assert [s.spp for s in seen] == [8, 8 * effects()["cloth_anisotropy"].fit_spp_factor]
    assert effects()["cloth_anisotropy"].fit_spp_factor > 1
    # and without the Gauss-Newton refinement, whose noisy cross-curvature steps jumped
    assert [s.refinement_steps for s in seen] == [settings.refinement_steps, 0]


def test_models_with_the_effect_are_compared_on_crossed_errors():
    """The lobes reweight each sample by its own amount, so shared seeds no longer cancel the
    two models' noise: the holdout comparison uses independent renders' crossed errors."""
    from types import SimpleNamespace

    from abs.diagnosis.effects.base import Candidate
    from abs.diagnosis.select import _changes_sampling

    control = SimpleNamespace(candidates=())
    lobes = SimpleNamespace(candidates=(Candidate("cloth_anisotropy", "cloth", ("cloth.anisotropy",)),))
    stray = SimpleNamespace(candidates=(Candidate("stray_light", "sensor", ("sensor.stray_light",)),))
    assert _changes_sampling(control, lobes)
    assert not _changes_sampling(control, stray)
