"""``<object>.placement``: an object slid on the ground plane and turned about +y
(``docs/conventions.md``), the pose ``[tx, 0, tz, 0, ry, 0]`` with half its freedoms.

Tested: it moves the mesh exactly as that pose does and composes with a pose; the scene file
loads, writes and refuses it where it does not belong, naming the field; its derivatives (a
silhouette's boundary term) agree with finite differences; and the diagnosis offers it as the
pose's alternative, never both for one object.
"""

from __future__ import annotations

from pathlib import Path

import mitsuba as mi
import numpy as np
import pytest
import trimesh

from abs.camera.pinhole import intrinsics_from_fov, look_at
from abs.render import Camera, compile_scene
from abs.errors import SceneError
from abs.scene import load_scene, write_scene
from conftest import write_mesh
from gradcheck import assert_gradients_agree, directional_gradient

_SCENE = """
[environment]
file = "env.exr"

[materials.paint]
type = "diffuse"
reflectance = [0.5, 0.5, 0.5]

[[objects]]
name = "box"
mesh = "box.ply"
material = "paint"
{extra}
"""


def _box_scene(root: Path, extra: str = "") -> Path:
    """An unlit box (a 6 x 5 x 4 cm block standing on y = 0, off the origin) under a uniform
    white environment: at ``max_depth = 1`` the image is the box's silhouette alone."""
    from abs.io.images import write_exr

    root.mkdir(parents=True, exist_ok=True)
    write_exr(root / "env.exr", np.ones((16, 32, 3), np.float32))
    box = trimesh.creation.box(extents=[0.06, 0.05, 0.04])
    box.apply_translation([0.01, 0.025, -0.005])
    write_mesh(root / "box.ply", box)
    path = root / "scene.toml"
    path.write_text(_SCENE.format(extra=extra))
    return path


def _positions(compiled) -> np.ndarray:
    key = f"{compiled.shape_ids['box']}.vertex_positions"
    return np.array(compiled.params[key], np.float64).reshape(-1, 3)


def _rot(rotvec) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_rotvec(rotvec).as_matrix()


def test_placement_is_the_pose_on_the_ground_plane_and_composes_with_it(tmp_path):
    compiled = compile_scene(load_scene(_box_scene(tmp_path)))
    rest = _positions(compiled)
    centre = rest.mean(axis=0)
    compiled.set("box.placement", [0.004, -0.003, 0.2])
    placed = _positions(compiled)
    compiled.set("box.placement", [0.0, 0.0, 0.0])
    np.testing.assert_array_equal(_positions(compiled), rest)  # the null value is exact
    compiled.set("box.pose", [0.004, 0.0, -0.003, 0.0, 0.2, 0.0])
    np.testing.assert_allclose(placed, _positions(compiled), atol=1e-7)
    # Heights do not change: it slides and turns on the plane.
    np.testing.assert_allclose(placed[:, 1], rest[:, 1], atol=1e-7)

    # Composition: x' = R(r) R_y(ry) (x - c) + c + t_placement + t_pose.
    pose = np.array([0.001, 0.002, 0.003, 0.05, -0.1, 0.02])
    placement = np.array([0.004, -0.003, 0.2])
    compiled.set("box.pose", pose)
    compiled.set("box.placement", placement)
    expected = ((rest - centre) @ (_rot(pose[3:]) @ _rot([0.0, placement[2], 0.0])).T + centre
                + np.array([placement[0], 0.0, placement[1]]) + pose[:3])
    np.testing.assert_allclose(_positions(compiled), expected, atol=2e-7)


def test_scene_file_loads_writes_and_refuses_placement(tmp_path):
    scene = load_scene(_box_scene(tmp_path / "a", "placement = [0.004, -0.003, 0.1]"))
    np.testing.assert_allclose(scene.objects[0].placement, [0.004, -0.003, 0.1])
    compiled = compile_scene(scene)
    np.testing.assert_allclose(compiled.get("box.placement"), [0.004, -0.003, 0.1], rtol=1e-6)
    spec = compiled.specs["box.placement"]
    assert spec.size == 3 and spec.moves_paths and spec.unit == "m, m, rad"
    np.testing.assert_array_equal(spec.null, np.zeros(3))

    written = write_scene(scene, tmp_path / "a" / "out.toml", {"box.placement": [0.001, 0.002, -0.05]})
    np.testing.assert_allclose(load_scene(written).objects[0].placement, [0.001, 0.002, -0.05])
    # An object without one is written as before: no placement line.
    plain = load_scene(_box_scene(tmp_path / "b"))
    assert "placement" not in write_scene(plain, tmp_path / "b" / "out.toml").read_text()

    with pytest.raises(SceneError, match=r"scene\.toml: objects\[0\]\.placement: expected shape \[3\]"):
        load_scene(_box_scene(tmp_path / "c", "placement = [0.0, 0.0]"))
    bad = _box_scene(tmp_path / "d")
    bad.write_text(bad.read_text().replace('reflectance = [0.5, 0.5, 0.5]',
                                           'reflectance = [0.5, 0.5, 0.5]\nplacement = [0.0, 0.0, 0.0]'))
    with pytest.raises(SceneError, match=r"scene\.toml: materials\.paint\.placement: a material may not have a field "
                                         r"named 'placement'"):
        load_scene(bad)


@pytest.mark.parametrize("direction", [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], ids=["slide", "turn"])
def test_placement_gradient_matches_finite_differences(tmp_path, direction):
    """The box seen obliquely from above: sliding along x and turning about +y move its
    silhouette, whose boundary term (edge sampling) is the whole derivative at ``max_depth = 1``."""
    compiled = compile_scene(load_scene(_box_scene(tmp_path)))
    R, t = look_at(np.array([0.12, 0.12, 0.22]), np.array([0.01, 0.02, -0.005]))
    camera = Camera(intrinsics_from_fov(24, 24, np.radians(30)), R, t, 24, 24)
    v, u = np.mgrid[0:24, 0:24] / 23.0
    weights = mi.TensorXf(np.repeat((u + 2 * v)[..., None], 3, axis=2).astype(np.float32))
    h = 0.003 if direction[0] else 0.05
    res = directional_gradient(compiled, camera, "box.placement", direction, h, weights,
                               max_depth=1, spp=128, seeds=4)
    assert_gradients_agree(*res, rel=0.1)
    without = directional_gradient(compiled, camera, "box.placement", direction, h, weights,
                                   max_depth=1, spp=16, seeds=2, edges=False, mode="recorded")
    assert without[0] == 0.0  # plain AD sees nothing: the edge term is all of it


def test_diagnosis_offers_placement_as_the_poses_alternative(tmp_path):
    from abs.diagnosis.diagnose import _remaining
    from abs.diagnosis.effects import effects

    scene = load_scene(_box_scene(tmp_path / "a"))
    compiled = compile_scene(scene)
    (placement,) = effects()["placement"].candidates(scene, compiled)
    (pose,) = effects()["pose"].candidates(scene, compiled)
    assert placement.parameters == ("box.placement",) and pose.parameters == ("box.pose",)
    # Once one form is accepted for the box, the other is no longer a candidate.
    assert _remaining([pose, placement], [placement]) == []
    assert _remaining([pose, placement], [pose]) == []
    assert _remaining([pose, placement], []) == [pose, placement]
    # A scene file that already places the box (either form) offers neither.
    for extra in ("placement = [0.001, 0.0, 0.0]", "pose = [0.0, 0.0, 0.0, 0.0, 0.01, 0.0]"):
        placed = load_scene(_box_scene(tmp_path / extra[:4], extra))
        compiled = compile_scene(placed)
        assert effects()["placement"].candidates(placed, compiled) == []
        assert effects()["pose"].candidates(placed, compiled) == []
