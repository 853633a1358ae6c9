"""``write_scene``: load -> write elsewhere with new values -> load gives the same scene, with the
new values and the same asset files."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from abs.params.names import parameter_specs
from abs.scene import load_scene, write_scene
from abs.scene.fields import Fields
from abs.scene.materials.base import Material, register

DEFAULT_SCENE = Path(__file__).resolve().parents[1] / "scenes" / "default" / "scene.toml"


@register
class _Decal(Material):
    """A material type this module defines, with an asset under a name write.py cannot know."""

    type_name = "test_decal"

    @classmethod
    def from_fields(cls, name: str, fields: Fields) -> "_Decal":
        fields.check_known({"type", "artwork", "opacity"})
        self = cls(name)
        self.artwork = fields.file("artwork")
        self.opacity = fields.number("opacity", 1.0)
        self._toml = {"type": cls.type_name, "artwork": fields.string("artwork"), "opacity": self.opacity}
        return self

    def to_mitsuba(self) -> dict:
        return {"type": "diffuse"}


def assert_same_scene(a, b, changed=None):
    """Every field of ``b`` equals ``a``'s, except parameters in ``changed`` (name -> value)."""
    changed = changed or {}
    assert a.render == b.render
    assert a.environment.file == b.environment.file and b.environment.file.is_file()
    np.testing.assert_array_equal(a.environment.to_world, b.environment.to_world)
    assert [o.name for o in a.objects] == [o.name for o in b.objects]
    for oa, ob in zip(a.objects, b.objects):
        assert (oa.mesh, oa.material) == (ob.mesh, ob.material) and ob.mesh.is_file()
        np.testing.assert_array_equal(oa.to_world, ob.to_world)
    assert list(a.materials) == list(b.materials)
    for name, ma in a.materials.items():
        mb = b.materials[name]
        assert type(ma) is type(mb)
        assert ma.file_fields() == mb.file_fields()
        assert all(path.is_file() for path in mb.file_fields().values())
        ta, tb = ma.to_toml(), mb.to_toml()
        for key in [*ma.file_fields(), *(n.split(".", 1)[1] for n in changed if n.startswith(name + "."))]:
            ta.pop(key), tb.pop(key)
        assert ta == tb
    specs_a, specs_b = parameter_specs(a), parameter_specs(b)
    assert specs_a.keys() == specs_b.keys()
    for name, spec in specs_b.items():
        expected = changed.get(name, specs_a[name].initial)
        if expected is None:
            assert spec.initial is None
        else:
            np.testing.assert_array_equal(spec.initial, np.atleast_1d(expected), err_msg=name)
    assert a.fit_parameters == b.fit_parameters
    assert a.fit_priors.keys() == b.fit_priors.keys()
    for name, prior in a.fit_priors.items():
        np.testing.assert_array_equal(prior.mean, b.fit_priors[name].mean)
        np.testing.assert_array_equal(prior.sd, b.fit_priors[name].sd)


def new_values(scene, rng):
    """A new value for every parameter of fixed size, inside its bounds."""
    values = {}
    for name, spec in parameter_specs(scene).items():
        if spec.size == -1:
            continue
        lower = spec.lower if np.isfinite(spec.lower) else -1.0
        upper = spec.upper if np.isfinite(spec.upper) else lower + 2.0
        values[name] = rng.uniform(lower, upper, spec.size)
    return values


@pytest.fixture()
def every_material_scene(tmp_path, small_scene_dir) -> Path:
    """Every material type, assets in sub-folders, a rotated environment, priors."""
    root = tmp_path / "source"
    for sub in ("assets/meshes", "assets/brdf", "textures"):
        (root / sub).mkdir(parents=True)
    (root / "assets/meshes/sphere.ply").write_bytes((small_scene_dir / "sphere.ply").read_bytes())
    (root / "assets/env.exr").write_bytes((small_scene_dir / "env.exr").read_bytes())
    (root / "textures/checker.png").write_bytes((small_scene_dir / "checker.png").read_bytes())
    # Loading only checks that these exist (the tables are read when compiled).
    (root / "assets/brdf/paint.binary").write_bytes(b"")
    (root / "assets/brdf/basis.npz").write_bytes(b"")
    materials = {
        "glass": 'type = "dielectric"\nior = 1.5\nabsorption = [1.0, 2.0, 3.0]',
        "cloth": 'type = "diffuse"\nreflectance = "../textures/checker.png"',
        "grey": 'type = "diffuse"\nreflectance = 0.4',
        "metal": 'type = "conductor"\nroughness = 0.2',
        "frosted": 'type = "roughdielectric"\nior = 1.45\nroughness = 0.3',
        "shell": 'type = "plastic"\nreflectance = [0.2, 0.3, 0.4]\nroughness = 0.1',
        "measured": 'type = "merl"\nfile = "brdf/paint.binary"',
        "pca": 'type = "brdf_pca"\nbasis = "brdf/basis.npz"\ncoefficients = [0.5, -0.3, 0.1]',
        "decal": 'type = "test_decal"\nartwork = "../textures/checker.png"\nopacity = 0.5',
    }
    text = ['[render]\nspp = 3\nmax_depth = 5\n',
            '[environment]\nfile = "env.exr"\nscale = 0.5\nrotation = 1.25\n'
            'to_world = [[0, 0, 1, 0], [0, 1, 0, 0], [-1, 0, 0, 0], [0, 0, 0, 1]]\n']
    text += [f"[materials.{name}]\n{fields}\n" for name, fields in materials.items()]
    for i, name in enumerate(materials):
        text.append(f'[[objects]]\nname = "obj_{name}"\nmesh = "meshes/sphere.ply"\nmaterial = "{name}"\n'
                    f'to_world = [[1, 0, 0, {0.1 * i}], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]\n'
                    f'pose = [0.001, 0, 0, 0, 0.01, {i}]\n')
    text.append('[fit]\nparameters = ["glass.ior", "environment.rotation"]\n\n'
                '[fit.priors."glass.ior"]\nmean = 1.52\nsd = [0.01, 0.02, 0.03]\n\n'
                '[fit.priors."environment.scale"]\nmean = 1\nsd = 0.5\n\n'
                '[fit.priors."obj_glass.pose"]\nmean = [0, 0, 0, 0, 0, 0]\nsd = 0.1\n')
    (root / "assets/scene.toml").write_text("\n".join(text))
    return root / "assets/scene.toml"


@pytest.mark.parametrize("fixture", ["small_scene_dir", "silhouette_scene_dir", "glass_scene_dir"])
def test_roundtrip_test_scenes(request, fixture, tmp_path):
    scene = load_scene(request.getfixturevalue(fixture) / "scene.toml")
    values = new_values(scene, np.random.default_rng(1))
    written = write_scene(scene, tmp_path / "elsewhere" / "fitted.toml", values)
    assert written == (tmp_path / "elsewhere" / "fitted.toml").resolve()
    assert_same_scene(scene, load_scene(written), values)


def test_roundtrip_default_scene(tmp_path):
    scene = load_scene(DEFAULT_SCENE)
    values = {"glass.ior": [1.51, 1.52, 1.53], "glass.absorption": np.array([3.0, 1.0, 2.0]),
              "environment.scale": np.float32(1.25), "environment.rotation": np.array([0.1]),
              "sphere.pose": np.arange(6) * 1e-3, "tablecloth.reflectance": [0.75, 0.75, 0.7]}
    written = write_scene(scene, tmp_path / "fit" / "scene.toml", values)
    text = written.read_text()
    header = "".join(line for line in text.splitlines() if line.startswith("#"))
    assert text.startswith("# Written by abs from ") and str(DEFAULT_SCENE) in header
    assert 'reflectance = "../../' in text  # the texture, from the new folder
    values["environment.scale"] = 1.25  # exactly representable in float32
    assert_same_scene(scene, load_scene(written), values)


def test_roundtrip_every_material(every_material_scene, tmp_path):
    scene = load_scene(every_material_scene)
    values = new_values(scene, np.random.default_rng(2))
    written = write_scene(scene, tmp_path / "out" / "fitted.toml", values)
    data = tomllib.loads(written.read_text())
    assert data["materials"]["measured"]["file"] == "../source/assets/brdf/paint.binary"
    assert data["materials"]["pca"]["basis"] == "../source/assets/brdf/basis.npz"
    assert data["materials"]["decal"]["artwork"] == "../source/textures/checker.png"
    assert data["materials"]["frosted"]["roughness"] == values["frosted.roughness"][0]  # a float
    assert data["objects"][0]["pose"] == values["obj_glass.pose"].tolist()
    again = load_scene(written)
    assert_same_scene(scene, again, values)
    # Nothing is lost or drifts when a written file is written again, from another folder.
    rewritten = write_scene(again, tmp_path / "out2" / "deeper" / "scene.toml")
    assert_same_scene(again, load_scene(rewritten))


def test_same_folder_without_values(every_material_scene):
    scene = load_scene(every_material_scene)
    written = write_scene(scene, every_material_scene.with_name("copy.toml"))
    data = tomllib.loads(written.read_text())
    assert data["environment"]["file"] == "env.exr"
    assert data["objects"][0]["mesh"] == "meshes/sphere.ply"
    assert data["fit"]["priors"]["environment.scale"] == {"mean": 1.0, "sd": 0.5}
    assert "Values replaced" not in written.read_text()
    assert_same_scene(scene, load_scene(written))


@pytest.mark.parametrize("name,value,error,words", [
    ("glass.ior", [1.5, 1.5], ValueError, "glass.ior: expected 3"),
    ("glass.ior", [[1.5, 1.5, 1.5]], ValueError, "glass.ior: expected 3"),
    ("environment.scale", [1.0, 2.0], ValueError, "environment.scale: expected 1"),
    ("sphere.pose", np.zeros(3), ValueError, "sphere.pose: expected 6"),
    ("glass.absorption", [1.0, np.nan, 1.0], ValueError, "glass.absorption: contains NaN"),
    ("glass.ior", [0.5, 1.5, 1.5], ValueError, "glass.ior: [0.5, 1.5, 1.5] outside"),
    ("backdrop.reflectance", np.zeros((4, 4, 3)), ValueError, "backdrop.reflectance: has no fixed size"),
    ("glass.ior", ["a", "b", "c"], ValueError, "glass.ior: expected 3"),
    ("glass.iorr", [1.5, 1.5, 1.5], KeyError, "unknown parameter 'glass.iorr'"),
    ("environment.scal", 1.0, KeyError, "unknown parameter 'environment.scal'"),
])
def test_bad_values(small_scene_dir, tmp_path, name, value, error, words):
    scene = load_scene(small_scene_dir / "scene.toml")
    with pytest.raises(error) as info:
        write_scene(scene, tmp_path / "scene.toml", {name: value})
    assert words in str(info.value)
    assert not (tmp_path / "scene.toml").exists()
