"""Bad scene files fail with one clear error naming the file and the field."""

from __future__ import annotations

import shutil

import pytest

from abs.cli.main import main
from abs.errors import SceneError
from abs.scene import load_scene


@pytest.fixture()
def scene_copy(small_scene_dir, tmp_path):
    for f in small_scene_dir.iterdir():
        shutil.copy(f, tmp_path / f.name)
    return tmp_path / "scene.toml"


def _edit(path, old, new):
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))


@pytest.mark.parametrize("old,new,field,words", [
    ('mesh = "sphere.ply"', 'mesh = "missing.ply"', "objects[0].mesh", "not found"),
    ('type = "dielectric"', 'type = "glas"', "materials.glass.type", "unknown material type"),
    ("ior = [1.5, 1.5, 1.5]", "ior = [1.5, 1.5]", "materials.glass.ior", "shape"),
    ("absorption = [2.0, 4.0, 8.0]", "absorption = [2.0, nan, 8.0]", "materials.glass.absorption", "NaN"),
    ("absorption = [2.0, 4.0, 8.0]", "absorbtion = [2.0, 4.0, 8.0]", "materials.glass.absorbtion", "unknown field"),
    ('material = "glass"', 'material = "glaas"', "objects[0].material", "unknown material"),
    ('parameters = ["glass.absorption"]', 'parameters = ["glass.absorptions"]', "fit.parameters[0]", "unknown parameter"),
    ("spp = 16", "spp = 0", "render.spp", ">= 1"),
    ('file = "env.exr"', 'file = "env.txt"', "environment.file", "unsupported"),
])
def test_bad_field_is_named(scene_copy, old, new, field, words):
    _edit(scene_copy, old, new)
    with pytest.raises(SceneError) as info:
        load_scene(scene_copy)
    message = str(info.value)
    assert str(scene_copy) in message and field in message and words in message


def test_malformed_toml(scene_copy):
    scene_copy.write_text("[render\nspp = 3")
    with pytest.raises(SceneError, match="not valid TOML"):
        load_scene(scene_copy)


def test_singular_transform(scene_copy):
    _edit(scene_copy, 'material = "glass"', 'material = "glass"\nto_world = [[0,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]')
    with pytest.raises(SceneError, match=r"objects\[0\].to_world: the 3x3 part is singular"):
        load_scene(scene_copy)


def test_cli_reports_bad_scene(scene_copy, tmp_path, capsys):
    _edit(scene_copy, 'mesh = "sphere.ply"', 'mesh = "nope.ply"')
    assert main(["simulate", str(scene_copy), "--cameras", "1", "--out", str(tmp_path / "cap")]) == 2
    err = capsys.readouterr().err
    assert "objects[0].mesh" in err and "nope.ply" in err


def test_roundtrip_values(small_scene_dir):
    scene = load_scene(small_scene_dir / "scene.toml")
    glass = scene.materials["glass"]
    assert glass.ior_rgb.tolist() == [1.5, 1.5, 1.5]
    assert glass.absorption_per_m.tolist() == [2.0, 4.0, 8.0]
    assert scene.fit_parameters == ("glass.absorption",)
    assert [o.name for o in scene.objects] == ["sphere", "floor", "board"]
