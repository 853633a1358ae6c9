"""Parameters carry their own null value and setter (issue 22): the compiled scene writes every
parameter through its spec, and diagnosis effects find their targets by null values and material
capabilities, so a new material type is one registered class and nothing else changes."""

from __future__ import annotations

import numpy as np
import pytest

from abs.diagnosis.effects import effects
from abs.params import parameter_specs
from abs.params.setters import AttributeSetter, MaterialApplySetter, MitsubaKeySetter, PoseSetter
from abs.render import compile_scene
from abs.scene import load_scene
from abs.scene.fields import Fields
from abs.scene.materials import Material, ParameterSpec, register
from abs.scene.materials import base as materials_base


def test_every_parameter_has_a_setter_and_its_owners_null_value(small_scene_dir):
    specs = parameter_specs(load_scene(small_scene_dir / "scene.toml"))
    assert all(spec.setter is not None for spec in specs.values())
    assert specs["environment.scale"].setter == AttributeSetter("environment", "scale")
    assert specs["sensor.response"].setter == AttributeSetter("sensor", "response")
    assert specs["sphere.pose"].setter == PoseSetter("sphere")
    assert specs["glass.ior"].setter == MitsubaKeySetter("glass.ior")
    nulls = {name: None if spec.null is None else spec.null.tolist() for name, spec in specs.items()}
    assert nulls["glass.absorption"] == [0.0] * 3 and nulls["glass.roughness"] == [0.0]
    assert nulls["cloth.subsurface"] == [0.0] and nulls["sphere.pose"] == [0.0] * 6
    assert nulls["sensor.response"] == [1.0] * 3 and nulls["environment.inverse_distance"] == [0.0]
    assert nulls["glass.ior"] is None and nulls["cloth.reflectance"] is None
    assert nulls["environment.scale"] is None
    assert not specs["glass.absorption"].at_null() and specs["glass.roughness"].at_null()


def test_set_writes_through_the_spec(small_scene_dir):
    compiled = compile_scene(load_scene(small_scene_dir / "scene.toml"))
    for name, value in {"environment.scale": [1.5], "sensor.stray_light": [0.1, 0.2, 0.3],
                        "glass.ior": [1.4, 1.5, 1.6], "cloth.reflectance": [0.2, 0.3, 0.4],
                        "sphere.pose": [0.001, 0.0, 0.0, 0.0, 0.0, 0.0]}.items():
        compiled.set(name, value)
        np.testing.assert_allclose(compiled.get(name), value, rtol=1e-6)
    assert float(compiled.environment.scale[0]) == pytest.approx(1.5)
    np.testing.assert_allclose(np.array(compiled.sensor.stray_light), [0.1, 0.2, 0.3], rtol=1e-6)
    np.testing.assert_allclose(np.array(compiled.params["glass.ior"]).ravel(), [1.4, 1.5, 1.6], rtol=1e-6)


class _Tint(Material):
    """A stand-in for a new material type: glass-like (transmissive), with an ``absorption`` of
    null value 0 and a ``tint`` bound by its own setter."""

    type_name = "test_tint"
    transmissive = True
    written: list = []

    @classmethod
    def from_fields(cls, name: str, fields: Fields) -> "_Tint":
        fields.check_known({"type", "absorption", "tint"})
        self = cls(name)
        self.absorption = fields.rgb("absorption", 0.0, lower=0.0)
        self.tint = fields.number("tint", 0.5)
        self._toml = {"type": cls.type_name, "absorption": self.absorption.tolist(), "tint": self.tint}
        return self

    def to_mitsuba(self) -> dict:
        return {"type": "abs_dielectric", "ior": [1.5] * 3, "absorption": self.absorption.tolist(),
                "roughness": 0.0}

    def parameters(self) -> dict[str, ParameterSpec]:
        return {"absorption": ParameterSpec("absorption", 3, "1/m", 0.0, np.inf, "absorption", null=0.0),
                "tint": ParameterSpec("tint", 1, "1", 0.0, 1.0, None)}

    def apply(self, field: str, value, mitsuba_params) -> None:
        type(self).written.append((self.name, field, float(value[0])))


@pytest.fixture()
def tint_type():
    register(_Tint)
    try:
        yield _Tint
    finally:
        materials_base._REGISTRY.pop(_Tint.type_name)
        _Tint.written.clear()


def test_a_new_material_type_needs_no_change_elsewhere(tint_type, small_scene_dir, tmp_path):
    for name in ("sphere.ply", "floor.ply", "env.exr"):
        (tmp_path / name).write_bytes((small_scene_dir / name).read_bytes())
    (tmp_path / "scene.toml").write_text("""
[environment]
file = "env.exr"

[materials.tinted]
type = "test_tint"
tint = 0.25

[materials.cloth]
type = "diffuse"

[[objects]]
name = "tinted"
mesh = "sphere.ply"
material = "tinted"

[[objects]]
name = "cloth"
mesh = "floor.ply"
material = "cloth"
""")
    scene = load_scene(tmp_path / "scene.toml")
    compiled = compile_scene(scene)
    assert compiled.specs["tinted.tint"].setter == MaterialApplySetter("tinted", "tint")
    compiled.set("tinted.tint", [0.75])
    assert tint_type.written[-1] == ("tinted", "tint", 0.75)
    compiled.set("tinted.absorption", [1.0, 2.0, 3.0])
    np.testing.assert_allclose(np.array(compiled.params["tinted.absorption"]).ravel(), [1.0, 2.0, 3.0])
    # The glass effects ask capabilities and null values: the new type is a target of absorption;
    # its object is glass, so not of pose; surface roughness needs a roughness field it lacks.
    targets = {name: e.targets(scene, compiled) for name, e in effects().items()}
    assert targets["absorption"] == ["tinted"] and targets["surface_roughness"] == []
    assert "tinted" not in targets["pose"]
