"""An object may share its material's name (issue 22's contract defect).

The scene-file contract names parameters ``<material>.<field>`` and ``<object>.pose``; a ``cloth``
material on a ``cloth`` object is the common case, and a file written by another tool with exactly
the contract's fields must load. ``pose`` is an object's only parameter, so ``cloth.pose`` is the
object's and a material field named ``pose`` is refused instead.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from abs import load_scene
from abs.errors import SceneError
from abs.render import Camera, compile_scene
from abs.camera.pinhole import intrinsics_from_fov, look_at
from abs.scene.write import write_scene
from conftest import make_env, make_sphere_and_floor

# A cloth floor of material "cloth" and a painted ball of material "ball": both objects share
# their material's name.
_SCENE = """
[render]
spp = 16
max_depth = 6

[environment]
file = "env.exr"

[materials.cloth]
type = "diffuse"
reflectance = {reflectance}

[materials.ball]
type = "diffuse"
reflectance = [0.3, 0.4, 0.6]

[[objects]]
name = "cloth"
mesh = "floor.ply"
material = "cloth"
pose = {pose}

[[objects]]
name = "ball"
mesh = "sphere.ply"
material = "ball"

[fit]
parameters = ["cloth.reflectance"]
"""

_POSE = [0.0, 0.004, 0.0, 0.0, 0.02, 0.0]


def _write(root: Path, reflectance=(0.7, 0.7, 0.65), pose=(0.0,) * 6, name: str = "scene.toml") -> Path:
    if not (root / "env.exr").exists():
        make_env(root / "env.exr")
        make_sphere_and_floor(root)
    path = root / name
    path.write_text(_SCENE.format(reflectance=list(map(float, reflectance)), pose=list(map(float, pose))))
    return path


@pytest.fixture(scope="module")
def scene_dir(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("shared_names")
    _write(root, pose=_POSE)
    return root


def test_a_material_and_an_object_may_share_a_name(scene_dir):
    scene = load_scene(scene_dir / "scene.toml")
    assert scene.object("cloth").material == "cloth" and "cloth" in scene.materials
    compiled = compile_scene(scene)
    specs = compiled.specs
    # cloth.pose is the object's (6 numbers, from [[objects]]), cloth.reflectance the material's.
    assert specs["cloth.pose"].size == 6 and specs["cloth.pose"].moves_paths
    np.testing.assert_allclose(specs["cloth.pose"].initial, _POSE)
    np.testing.assert_allclose(compiled.get("cloth.pose"), _POSE)
    np.testing.assert_allclose(compiled.get("cloth.reflectance"), [0.7, 0.7, 0.65], rtol=1e-6)
    assert {"ball.pose", "ball.reflectance", "cloth.subsurface"} <= set(specs)


def test_the_shared_name_pose_moves_the_object_and_leaves_the_material(scene_dir):
    compiled = compile_scene(load_scene(scene_dir / "scene.toml"))
    key = f"{compiled.shape_ids['cloth']}.vertex_positions"
    before = np.array(compiled.params[key]).reshape(-1, 3)
    compiled.set("cloth.pose", [0.0, 0.01, 0.0, 0.0, 0.0, 0.0])
    after = np.array(compiled.params[key]).reshape(-1, 3)
    # From _POSE to this pose: up by 6 mm (the rotation about +y kept the floor in its plane).
    assert np.allclose(after[:, 1] - before[:, 1], 0.01 - 0.004, atol=1e-6)
    np.testing.assert_allclose(compiled.get("cloth.reflectance"), [0.7, 0.7, 0.65], rtol=1e-6)
    compiled.set("cloth.reflectance", [0.2, 0.3, 0.4])
    np.testing.assert_allclose(np.array(compiled.params[key]).reshape(-1, 3), after)
    np.testing.assert_allclose(compiled.get("cloth.pose"), [0.0, 0.01, 0.0, 0.0, 0.0, 0.0])


def test_a_scene_with_shared_names_renders_like_one_without(scene_dir, tmp_path):
    # The same scene with the objects renamed: same pixels (same seed), so sharing a name
    # changes nothing but the names.
    text = (scene_dir / "scene.toml").read_text()
    renamed = text.replace('name = "cloth"', 'name = "floor"').replace('name = "ball"', 'name = "sphere"')
    for asset in ("env.exr", "floor.ply", "sphere.ply"):
        (tmp_path / asset).write_bytes((scene_dir / asset).read_bytes())
    (tmp_path / "scene.toml").write_text(renamed)
    R, t = look_at(np.array([0.0, 0.25, 0.45]), np.array([0.0, 0.03, 0.0]))
    camera = Camera(intrinsics_from_fov(32, 24, np.radians(35)), R, t, 32, 24)
    shared = compile_scene(load_scene(scene_dir / "scene.toml")).render(camera, spp=8, seed=3).numpy()
    plain = compile_scene(load_scene(tmp_path / "scene.toml")).render(camera, spp=8, seed=3).numpy()
    assert shared.shape == (24, 32, 3) and np.all(np.isfinite(shared)) and shared.mean() > 0.01
    np.testing.assert_allclose(shared, plain, rtol=1e-5, atol=1e-6)


def test_written_values_go_to_the_object_and_the_material(scene_dir, tmp_path):
    scene = load_scene(scene_dir / "scene.toml")
    pose = [0.001, 0.0, -0.002, 0.0, 0.01, 0.0]
    out = write_scene(scene, tmp_path / "written" / "scene.toml",
                      {"cloth.pose": pose, "cloth.reflectance": [0.4, 0.5, 0.6]})
    back = load_scene(out)
    np.testing.assert_allclose(back.object("cloth").pose, pose)
    np.testing.assert_allclose(back.materials["cloth"].reflectance_rgb, [0.4, 0.5, 0.6])


def test_the_pose_effect_finds_the_shared_name_object(scene_dir, tmp_path):
    from abs.diagnosis.effects import effects

    path = _write(tmp_path)  # no pose: both objects at the null pose
    scene = load_scene(path)
    # The flat cloth slides invisibly in its plane and is left out; the solid ball is a target.
    assert effects()["pose"].targets(scene, compile_scene(scene)) == ["ball"]


def test_a_material_field_named_pose_is_refused(scene_dir, tmp_path):
    text = _SCENE.format(reflectance=[0.5, 0.5, 0.5], pose=[0.0] * 6).replace(
        'reflectance = [0.3, 0.4, 0.6]', 'reflectance = [0.3, 0.4, 0.6]\npose = [0, 0, 0, 0, 0, 0]')
    for asset in ("env.exr", "floor.ply", "sphere.ply"):
        (tmp_path / asset).write_bytes((scene_dir / asset).read_bytes())
    (tmp_path / "bad.toml").write_text(text)
    with pytest.raises(SceneError) as info:
        load_scene(tmp_path / "bad.toml")
    message = str(info.value)
    assert "bad.toml" in message and "materials.ball.pose" in message
    assert "may not have a field named 'pose'" in message


def test_a_scene_with_shared_names_fits(tmp_path):
    from abs.fitting import FitSettings, fit
    from abs.simulate import simulate_capture

    truth = load_scene(_write(tmp_path, name="truth.toml"))
    simulate_capture(truth, tmp_path / "capture", n_cameras=3, width=32, height=24, spp=256,
                     read_noise=0.003, seed=2)
    start = _write(tmp_path, reflectance=(0.5, 0.5, 0.5), name="start.toml")
    result = fit(start, tmp_path / "capture",
                 settings=FitSettings(spp=8, max_iterations=8, refinement_steps=2, eval_spp=8))
    np.testing.assert_allclose(result.values["cloth.reflectance"], [0.7, 0.7, 0.65], atol=0.03)
    assert result.metrics["holdout_rmse"]["after"] < result.metrics["holdout_rmse"]["before"]
