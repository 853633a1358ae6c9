"""abs.appearance: the filter statistics on closed-form cases, the transfer, the file formats.

Renders are small (32-48 pixels, few samples) and shared through module fixtures; the whole
file runs in well under a minute on two cores.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from abs.appearance import characterise, read_characterisation, renderer, transfer, write_characterisation
from abs.appearance.design import Sphere, SceneSpec, characterisation_design, heldout_design
from abs.appearance.files import read_geometry, write_geometry
from abs.appearance.geometry import sphere_geometry
from abs.appearance.histogram import match_global, match_local
from abs.appearance.lighting import lighting_image, sh9_coefficients
from abs.appearance.scenes import design_camera, scene_geometry
from abs.appearance.score import object_scores
from abs.appearance.statistics import Accumulator
from abs.errors import InputError

L0 = 0.5
RHO = (0.8, 0.5, 0.2)
GAINS = (1.25, 1.0, 0.7)


def _constant(value=L0):
    return np.full((32, 64, 3), value, np.float32)


def _lambertian_scene(name="lambert"):
    sphere = Sphere((0.0, 0.25, 0.0), 0.25, "wood", 0, {"type": "diffuse", "reflectance": list(RHO)})
    return SceneSpec(name, (0.5, 0.5, 0.5), (sphere,), box=False)


# -- closed form ------------------------------------------------------------------------------

def test_lighting_term_is_exact_for_maps_of_order_one():
    """L(ω) = a + b ω_y gives E(n)/π = a + (2/3) b n_y (the clamped cosine's band-1 gain)."""
    h, w = 129, 256
    y = np.cos(np.pi * np.arange(h) / (h - 1))
    env = np.repeat((1.0 + 0.6 * y)[:, None, None], w, axis=1) * np.array([1.0, 0.5, 0.25])
    normals = np.array([[0, 1, 0], [0, -1, 0], [1, 0, 0], [0, 0.6, 0.8]], float)
    got = lighting_image(sh9_coefficients(env), normals)
    want = (1.0 + 0.4 * normals[:, 1])[:, None] * np.array([1.0, 0.5, 0.25])
    np.testing.assert_allclose(got, want, rtol=2e-3)


@pytest.fixture(scope="module")
def lambertian():
    """abs's render of a diffuse sphere alone under a constant environment, with its stats."""
    spec = _lambertian_scene()
    return characterise(renderer("abs"), [spec], _constant(), size=48, spp=128, seed=3, n_bins=6)


def test_lambertian_sphere_statistics_are_closed_form(lambertian):
    """A convex Lambertian sphere under a constant map L0 has radiance ρ L0 at every pixel, and
    the lighting term is L0: α(θ) = ρ, λ(θ) = 0, ψ(θ) = 0 in every θ bin, up to Monte-Carlo
    noise (abs samples the environment too, so a pixel is not exact: at 128 spp its relative sd
    is about 1 %, and ψ is that variance, about 1e-4)."""
    c = lambertian
    has = c.counts[0] >= 20
    assert has.sum() >= 4  # the bins out to 60° at least
    np.testing.assert_allclose(c.alpha[0][has], np.tile(RHO, (has.sum(), 1)), rtol=0.015)
    pooled = np.nansum(c.counts[0][:, None] * c.alpha[0], axis=0) / c.counts[0].sum()
    np.testing.assert_allclose(pooled, RHO, rtol=0.005)
    assert np.abs(c.lam[0][has]).max() < 0.01
    assert np.abs(c.psi[0][has]).max() < 1e-3


def test_statistics_of_a_known_theta_filter():
    """Pixels ρ L f(θ) with f = 1 + cos θ: α in each bin is ρ times the bin's mean of f, and λ is
    the lighting's normalised mean minus the image's (f over the object's mean of f)."""
    cam = design_camera(48)
    g = scene_geometry(_lambertian_scene(), cam)
    light = np.full(g.ids.shape + (3,), L0)
    f = np.where(g.ids > 0, 1.0 + np.cos(np.nan_to_num(g.theta)), 0.0)
    image = light * np.array(RHO) * f[..., None]
    acc = Accumulator(("wood",), 6)
    acc.add(image, g, light)
    c = acc.finish("synthetic", {}, "-", {})
    on = g.ids > 0
    bins = np.clip(np.digitize(g.theta[on], c.theta_edges) - 1, 0, 5)
    for b in np.unique(bins):
        fb = f[on][bins == b]
        np.testing.assert_allclose(c.alpha[0, b], np.array(RHO) * fb.mean(), rtol=1e-6)
        np.testing.assert_allclose(c.lam[0, b], 1.0 - fb.mean() / f[on].mean(), atol=1e-6)
        np.testing.assert_allclose(c.psi[0, b], (fb / f[on].mean()).var(), rtol=1e-4)  # float32 θ


def test_geometry_from_the_analytic_sphere():
    cam = design_camera(48)
    spec = heldout_design()[0]
    g = scene_geometry(spec, cam)
    # The pixel nearest the projection of each centre sees the sphere head on.
    for i, s in enumerate(spec.spheres):
        p = cam.K @ (cam.R @ np.array(s.centre) + cam.t)
        u, v = np.round(p[:2] / p[2]).astype(int)
        assert g.ids[v, u] == i + 1
        assert g.theta[v, u] < np.radians(12)
    assert set(np.unique(g.ids)) == {0, 1, 2, 3}
    # Silhouettes are left out: every object pixel's 8 neighbours belong to some object.
    inner = g.ids > 0
    assert np.isnan(g.theta[~inner]).all() and np.isfinite(g.theta[inner]).all()
    np.testing.assert_allclose(np.linalg.norm(g.normals[inner], axis=-1), 1.0, atol=1e-5)


def test_nearer_sphere_wins():
    K = np.array([[20.0, 0, 15.5], [0, 20.0, 15.5], [0, 0, 1]])
    spheres = np.array([[0.0, 0.0, 5.0, 2.0], [0.0, 0.0, 3.0, 0.5]])  # 8 and 3.4 pixels across
    g = sphere_geometry(K, np.eye(3), np.zeros(3), 32, 32, spheres, ("a", "b"))
    assert g.ids[15, 15] == 2 and g.ids[15, 21] == 1 and g.ids[15, 18] == 0  # 18: an edge of b


# -- gains, identity, transfer ----------------------------------------------------------------

@pytest.fixture(scope="module")
def small():
    """abs twice (other seeds) and a known per-channel gain filter on a small design."""
    env = _constant(0.8) * np.array([1.0, 0.9, 0.8], np.float32)
    design = characterisation_design(1, classes=("wood", "plastic"), walls=("red", "white"))
    kw = {"size": 40, "spp": 16, "n_bins": 6}
    a = characterise(renderer("abs"), design, env, seed=0, **kw)
    a2 = characterise(renderer("abs"), design, env, seed=500, **kw)
    b = characterise(renderer("gains", {"gains": list(GAINS)}), design, env, seed=900, **kw)
    spec = SceneSpec("held", (0.6, 0.52, 0.08), (Sphere((-0.2, 0.18, 0.05), 0.18, "wood", 2),
                                                 Sphere((0.2, 0.18, -0.05), 0.18, "plastic", 2)))
    cam = design_camera(40)
    image = renderer("abs").render(spec, env, cam, 16, 77)
    again = renderer("abs").render(spec, env, cam, 16, 78)
    return a, a2, b, image, again, scene_geometry(spec, cam)


def test_known_gains_are_recovered_within_two_percent(small):
    a, _, b, image, _, g = small
    ratio = np.nansum(b.counts[..., None] * b.alpha, axis=(0, 1)) / np.nansum(
        a.counts[..., None] * a.alpha, axis=(0, 1))
    np.testing.assert_allclose(ratio, GAINS, rtol=0.02)
    out = transfer(image, g, a, b)
    on = g.ids > 0
    np.testing.assert_allclose(out[on].sum(0) / image[on].sum(0), GAINS, rtol=0.02)
    # Pixel by pixel it is a gain, not a reshuffle: the pixels move by nearly the same factors
    # (what varies is the two characterisations' noise in λ from bin to bin).
    ratio = out[on] / np.maximum(image[on], 1e-9)
    np.testing.assert_allclose(np.median(ratio, axis=0), GAINS, rtol=0.02)
    assert (ratio.std(axis=0) / np.array(GAINS)).max() < 0.03


def test_identity_stays_within_the_noise(small):
    """Transferring abs to abs (characterised with other seeds) changes the look by less than
    0.1 ΔE00 beyond the noise between two seeds."""
    a, a2, _, image, again, g = small
    before = object_scores(image, again, g)
    after = object_scores(transfer(image, g, a, a2), again, g)
    for b, t in zip(before, after):
        assert t["profile"] < b["profile"] + 0.1
        assert t["mean"] < b["mean"] + 0.1


def test_transfer_undoes_a_theta_dependent_filter(small):
    """Filter B = A · (1 + 0.8 cos θ) per pixel: characterised on the same images, the transfer
    of a new scene's image matches B's own image of it to far less than before."""
    a, _, _, image, _, g = small

    def filtered(img, geo):
        return img * np.where(geo.ids > 0, 1.0 + 0.8 * np.cos(np.nan_to_num(geo.theta)), 1.0)[..., None]

    env = _constant(0.8) * np.array([1.0, 0.9, 0.8], np.float32)
    design = characterisation_design(1, classes=("wood", "plastic"), walls=("red", "white"))
    cam = design_camera(40)
    acc_a, acc_b = Accumulator(a.classes, 6), Accumulator(a.classes, 6)
    sh = sh9_coefficients(env)
    for i, spec in enumerate(design):
        geo = scene_geometry(spec, cam)
        img = renderer("abs").render(spec, env, cam, 16, i)
        light = lighting_image(sh, geo.normals)
        acc_a.add(img, geo, light)
        acc_b.add(filtered(img, geo), geo, light)
    ca, cb = acc_a.finish("a", {}, "d", {}), acc_b.finish("b", {}, "d", {})
    target = filtered(image, g)
    before = object_scores(image, target, g)
    after = object_scores(transfer(image, g, ca, cb), target, g)
    for b, t in zip(before, after):
        assert t["profile"] < 0.25 * b["profile"]
        assert t["mean"] < 0.5 * b["mean"]


def test_histogram_matching_onto_own_histogram_is_nearly_identity(small):
    a, _, _, image, _, g = small
    acc = Accumulator(a.classes, 6)
    acc.add(image, g, np.ones_like(image))
    own = acc.finish("own", {}, "-", {})
    on = g.ids > 0
    for out in (match_global(image, g, own), match_local(image, g, own)):
        rel = np.abs(out[on] - image[on]) / np.maximum(image[on], 1e-3)
        assert np.median(rel) < 0.03  # 0.025-decade histogram bins


# -- file formats -----------------------------------------------------------------------------

def test_characterisation_round_trip(small, tmp_path):
    a = small[0]
    write_characterisation(tmp_path / "a.npz", a)
    back = read_characterisation(tmp_path / "a.npz")
    assert back.classes == a.classes and back.renderer == "abs" and back.design == a.design
    np.testing.assert_array_equal(back.alpha, a.alpha)
    np.testing.assert_array_equal(back.profiles, a.profiles)


def _rewrite(tmp_path, src, **changes):
    data = dict(np.load(src, allow_pickle=False))
    for k, v in changes.items():
        if v is None:
            data.pop(k)
        else:
            data[k] = v
    path = tmp_path / "bad.npz"
    np.savez(path, **data)
    return path


@pytest.mark.parametrize("change, field", [
    ({"alpha": None}, "alpha"),
    ({"meta": np.array(json.dumps({"format": "something/9"}))}, "meta.format"),
    ({"meta": np.array("{not json")}, "meta"),
    ({"counts": np.zeros((1, 6))}, "counts"),
    ({"theta_edges": np.array([0.0, 2.0])}, "theta_edges"),
    ({"alpha": "NAN"}, "alpha"),
    ({"hist_global": np.zeros((3, 5))}, "hist_global"),
    ({"profiles": np.array(["x"])}, "profiles"),
])
def test_characterisation_errors_name_file_and_field(small, tmp_path, change, field):
    good = tmp_path / "good.npz"
    write_characterisation(good, small[0])
    if change.get("alpha") == "NAN":
        a = small[0].alpha.copy()
        a[small[0].counts > 0] = np.nan
        change = {"alpha": a}
    bad = _rewrite(tmp_path, good, **change)
    with pytest.raises(InputError) as err:
        read_characterisation(bad)
    assert err.value.field == field and "bad.npz" in str(err.value)


def test_characterisation_file_is_data_not_code(tmp_path):
    for name, write in (("pickled.npz", lambda p: np.savez(p, meta=np.array([{"a": 1}], dtype=object))),
                        ("text.npz", lambda p: p.write_text("hello")),):
        path = tmp_path / name
        write(path)
        with pytest.raises(InputError) as err:
            read_characterisation(path)
        assert name in str(err.value)
    with pytest.raises(InputError, match="not found"):
        read_characterisation(tmp_path / "missing.npz")


def test_geometry_file_errors(small, tmp_path):
    g = small[5]
    write_geometry(tmp_path / "g.npz", g)
    back = read_geometry(tmp_path / "g.npz", g.ids.shape)
    np.testing.assert_array_equal(back.ids, g.ids)
    with pytest.raises(InputError) as err:
        read_geometry(tmp_path / "g.npz", (10, 10))
    assert err.value.field == "ids"
    bad = _rewrite(tmp_path, tmp_path / "g.npz", ids=g.ids + 7)
    with pytest.raises(InputError) as err:
        read_geometry(bad)
    assert err.value.field == "ids"
    theta = g.theta.copy()
    theta[g.ids > 0] = 3.0
    with pytest.raises(InputError) as err:
        read_geometry(_rewrite(tmp_path, tmp_path / "g.npz", theta=theta))
    assert err.value.field == "theta"


def test_transfer_refuses_mismatched_inputs(small):
    a, _, b, image, _, g = small
    with pytest.raises(InputError):
        transfer(image[:10], g, a, b)
    with pytest.raises(InputError):
        transfer(image, g, a, replace(b, theta_edges=np.linspace(0, 1, 7)))
    with pytest.raises(InputError):
        transfer(image, g, a, replace(b, design="other"), colour_matrix="global")
    with pytest.raises(InputError):
        transfer(image, g, a, b, colour_matrix="bogus")


def test_unknown_renderer_and_option():
    with pytest.raises(InputError, match="unknown renderer"):
        renderer("blender")
    with pytest.raises(InputError) as err:
        renderer("gains", {"gain": [1, 1, 1]})
    assert "gain" in err.value.field


# -- command line -----------------------------------------------------------------------------

def test_the_reconfigured_mitsuba_makes_every_clear_glass_thin():
    # The design's smooth glass compiles to abs's own plugin (abs_dielectric), its rough glass to
    # Mitsuba's roughdielectric: "thin instead of solid glass" must reach both (it once reached
    # only the rough one). Glass with absorption has no thin equivalent and stays solid.
    from abs.appearance.renderers import _reconfigure_bsdf
    from abs.appearance.scenes import material_bsdf

    smooth = material_bsdf({"type": "dielectric", "ior": 1.45}, "object1")
    assert smooth["type"] == "abs_dielectric"
    thin = _reconfigure_bsdf({**smooth, "id": "g"}, squared_roughness=True, thin_glass=True)
    assert thin == {"type": "thindielectric", "int_ior": 1.45, "ext_ior": 1.0, "id": "g"}
    rough = material_bsdf({"type": "roughdielectric", "ior": 1.5, "roughness": 0.1}, "object2")
    assert _reconfigure_bsdf(rough, True, True)["type"] == "thindielectric"
    tinted = {**smooth, "absorption": [1.0, 2.0, 3.0]}
    assert _reconfigure_bsdf(tinted, True, True) == tinted
    assert _reconfigure_bsdf(smooth, True, False) == smooth


def test_cli_characterise_and_transfer(tmp_path, capsys):
    from abs.cli.main import main

    common = ["--classes", "wood", "--walls", "white", "--samples", "1", "--size", "24", "--spp", "4",
              "--environment", "constant:0.7"]
    assert main(["appearance", "characterise", "--renderer", "abs", "--out", str(tmp_path / "a"),
                 *common]) == 0
    assert main(["appearance", "characterise", "--renderer", "gains", "--option", "gains=[2,1,1]",
                 "--out", str(tmp_path / "b"), "--seed", "5", *common]) == 0
    summary = json.loads((tmp_path / "a" / "characterisation.json").read_text())
    assert summary["renderer"] == "abs" and "wood" in summary["alpha"]
    scene = tmp_path / "a" / "scenes" / "wood-0-white"
    assert main(["appearance", "transfer", str(scene / "image.exr"), "--geometry",
                 str(scene / "geometry.npz"), "--from", str(tmp_path / "a" / "characterisation.npz"),
                 "--to", str(tmp_path / "b" / "characterisation.npz"), "--out", str(tmp_path / "t.exr"),
                 "--target", str(tmp_path / "b" / "scenes" / "wood-0-white" / "image.exr")]) == 0
    result = json.loads((tmp_path / "t.json").read_text())
    assert result["after"][0]["profile"] < result["before"][0]["profile"]
    assert main(["appearance", "environment", str(scene / "image.exr"), "--geometry",
                 str(scene / "geometry.npz"), "--out", str(tmp_path / "env.exr"), "--width", "32"]) == 0
    from abs.io.images import read_image
    assert read_image(tmp_path / "env.exr").shape == (16, 32, 3)
    assert main(["appearance", "characterise", "--renderer", "nope", "--out", str(tmp_path / "c"),
                 *common]) == 2
    assert main(["appearance", "transfer", str(scene / "image.exr"), "--geometry",
                 str(tmp_path / "a" / "characterisation.npz"), "--from", "x.npz", "--to", "y.npz",
                 "--out", str(tmp_path / "u.exr")]) == 2
    assert "meta.format" in capsys.readouterr().err


# -- lighting from the background -------------------------------------------------------------

def test_environment_from_background_of_a_constant_sky():
    """Spheres alone under a constant map: the background is the map, and so is the estimate."""
    from abs.appearance.background import background_to_world, environment_from_background

    spec = SceneSpec("sky", (0.5, 0.5, 0.5), (Sphere((0.0, 0.25, 0.0), 0.2, "wood", 0),), box=False)
    cam = design_camera(40)
    image = renderer("abs").render(spec, _constant(0.7), cam, 4, 0)
    env = environment_from_background(image, scene_geometry(spec, cam), width=64)
    assert env.shape == (32, 64, 3)
    np.testing.assert_allclose(env, 0.7, rtol=1e-4)
    to_world = background_to_world(cam.R)
    # The map's centre (u = 0.5, the horizon: local direction +z) is the camera's view direction.
    np.testing.assert_allclose(to_world[:3, :3] @ [0, 0, 1], cam.R[2], atol=1e-12)


def test_mesh_scene_geometry_matches_the_analytic_sphere():
    """The default scene's glass sphere mesh (radius 4 cm at (0, 0.04, 0)) ray cast: the ids are
    where the analytic sphere is, and θ agrees with the analytic one up to the tessellation."""
    from pathlib import Path

    from abs.appearance.mesh_geometry import mesh_scene_geometry
    from abs.camera.pinhole import intrinsics_from_fov, look_at
    from abs.render import Camera, compile_scene
    from abs.scene import load_scene

    scene = Path(__file__).resolve().parents[1] / "scenes" / "default" / "scene.toml"
    compiled = compile_scene(load_scene(scene))
    R, t = look_at(np.array([0.0, 0.1, 0.3]), np.array([0.0, 0.04, 0.0]))
    cam = Camera(intrinsics_from_fov(48, 36, np.radians(30)), R, t, 48, 36)
    mesh = mesh_scene_geometry(compiled, cam, {"sphere": "glass", "cloth": "fabric"})
    exact = sphere_geometry(cam.K, cam.R, cam.t, 48, 36, np.array([[0.0, 0.04, 0.0, 0.04]]), ("glass",))
    on = (mesh.ids == 1) & (exact.ids == 1)
    assert on.sum() > 0.9 * (exact.ids == 1).sum()
    assert np.all(exact.ids[mesh.ids == 1] == 1)  # the mesh sphere lies inside the exact one
    assert np.degrees(np.abs(mesh.theta[on] - exact.theta[on])).mean() < 3.0
    assert (mesh.ids == 2).sum() > 0 and mesh.classes == ("glass", "fabric")
    with pytest.raises(InputError):
        mesh_scene_geometry(compiled, cam, {"teapot": "glass"})
    from abs.cli.main import main

    assert main(["appearance", "geometry", str(scene), "nowhere", "--class", "sphere=crystal",
                 "--out", "unused"]) == 2
