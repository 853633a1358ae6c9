"""Shared fixtures: a variant for every test and small synthetic scenes built on the fly."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from abs.render.variant import set_variant

set_variant()

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
DIAGNOSIS_SUITE = Path(__file__).resolve().parents[1] / "benchmarks" / "diagnosis"


def use_diagnosis_suite() -> None:
    """Make the diagnosis proof suite's scripts (``cases``, ``run``) importable: tests reuse its
    scenes and cases, and ``run.py`` imports ``cases`` by name from its own folder."""
    if str(DIAGNOSIS_SUITE) not in sys.path:
        sys.path.insert(0, str(DIAGNOSIS_SUITE))


def assert_same_rendering(image: np.ndarray, reference: np.ndarray) -> None:
    """Two renders of the same model with the same seed agree up to float32 round-off.

    Not bitwise: the film adds a pixel's samples from parallel threads, and their order can change
    the last bit (seen once in CI: 1 ulp in one pixel of 192). A change of the model moves many
    pixels by far more than that, so few may differ at all.
    """
    np.testing.assert_allclose(image, reference, rtol=1e-6, atol=0)
    assert np.mean(image != reference) < 0.02


def write_mesh(path: Path, mesh) -> None:
    import trimesh

    mesh.export(path)
    assert isinstance(mesh, trimesh.Trimesh)


def sphere_in_view(scene_dir: Path, width: int, height: int):
    """The small scene compiled, and a camera 0.32 m in front of its glass sphere, slightly above
    (30° vertical field of view)."""
    from abs.camera.pinhole import intrinsics_from_fov, look_at
    from abs.render import Camera, compile_scene
    from abs.scene import load_scene

    compiled = compile_scene(load_scene(scene_dir / "scene.toml"))
    R, t = look_at(np.array([0.0, 0.08, 0.32]), np.array([0.0, 0.05, 0.0]))
    return compiled, Camera(intrinsics_from_fov(width, height, np.radians(30)), R, t, width, height)


def make_env(path: Path, width: int = 64, height: int = 32) -> None:
    """A dim enclosure with one bright band and a coloured patch (so rotation has a gradient)."""
    from abs.io.images import write_exr

    v, u = np.mgrid[0:height, 0:width]
    env = np.full((height, width, 3), 0.05, np.float32)
    env[(v > height * 0.15) & (v < height * 0.3)] = [4.0, 4.0, 3.6]
    env[(u > width * 0.6) & (u < width * 0.75) & (v < height * 0.6)] += np.float32([1.5, 0.3, 0.2])
    env[v > height * 0.6] = [0.3, 0.3, 0.3]
    write_exr(path, env)


def make_soft_env(path: Path, width: int = 64, height: int = 32) -> None:
    """A bright room rather than a dark enclosure with one hot band: a sky gradient, a soft window
    band and a coloured patch. Peaky lighting makes the caustics under glass so noisy (RMSE 0.16
    at 32 spp with :func:`make_env`) that weak effects drown in Monte-Carlo noise."""
    from abs.io.images import write_exr

    v, u = np.mgrid[0:height, 0:width]
    elevation = 1.0 - (v + 0.5) / height  # 1 at the zenith, 0 at the nadir
    env = (0.35 + 0.5 * elevation)[..., None] * np.float32([1.0, 1.0, 0.95])
    env = env + (np.exp(-((v - height * 0.22) / (0.06 * height)) ** 2) * 1.2)[..., None]
    env[(u > width * 0.6) & (u < width * 0.75) & (v < height * 0.6)] += np.float32([0.6, 0.15, 0.1])
    write_exr(path, env.astype(np.float32))


def make_checker(path: Path, n: int = 64) -> None:
    import cv2

    v, u = np.mgrid[0:n, 0:n]
    img = np.where(((u // 8) + (v // 8)) % 2 == 0, 230, 120).astype(np.uint8)
    cv2.imwrite(str(path), np.dstack([img] * 3))


def make_sphere_and_floor(root: Path) -> None:
    """``sphere.ply`` (radius 5 cm, resting on y = 0) and ``floor.ply`` (60 cm square, y = 0)."""
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.05)
    sphere.apply_translation([0, 0.05, 0])
    write_mesh(root / "sphere.ply", sphere)
    floor = trimesh.Trimesh(vertices=[[-0.3, 0, -0.3], [0.3, 0, -0.3], [0.3, 0, 0.3], [-0.3, 0, 0.3]],
                            faces=[[0, 2, 1], [0, 3, 2]], process=False)
    write_mesh(root / "floor.ply", floor)


def make_noisy_sphere(path: Path, noise_m: float, seed: int = 0) -> None:
    """``make_sphere_and_floor``'s sphere (same vertices and faces, in the same order) with every
    vertex moved along its radius by Gaussian noise of ``noise_m`` metres: a scan's noise."""
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.05)
    radial = sphere.vertices / np.linalg.norm(sphere.vertices, axis=1, keepdims=True)
    sphere.vertices = sphere.vertices + radial * np.random.default_rng(seed).normal(0.0, noise_m, (len(radial), 1))
    sphere.apply_translation([0, 0.05, 0])
    write_mesh(path, sphere)


def make_backdrop(root: Path) -> None:
    """``backdrop.obj``: a 60 x 30 cm board with texture coordinates, 12 cm behind the origin."""
    import trimesh

    back = trimesh.Trimesh(vertices=[[-0.3, 0, -0.12], [0.3, 0, -0.12], [0.3, 0.3, -0.12], [-0.3, 0.3, -0.12]],
                           faces=[[0, 1, 2], [0, 2, 3]], process=False)
    back.visual = trimesh.visual.TextureVisuals(uv=np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float))
    write_mesh(root / "backdrop.obj", back)


def sphere_scene_toml(fit: list[str], absorption: list[float] | None = None, max_depth: int = 8) -> str:
    """The scene file of the glass sphere (``sphere.ply``) on a cloth (``floor.ply``) in front of a
    checkerboard (``backdrop.obj``, ``checker.png``) under ``env.exr``; ``absorption`` (1/m RGB)
    is written only when given, ``fit`` lists the ``[fit]`` parameters."""
    glass = "" if absorption is None else f"absorption = {list(map(float, absorption))}\n"
    return f"""
[render]
spp = 16
max_depth = {max_depth}

[environment]
file = "env.exr"
scale = 1.0

[materials.glass]
type = "dielectric"
ior = [1.5, 1.5, 1.5]
{glass}
[materials.cloth]
type = "diffuse"
reflectance = [0.7, 0.7, 0.65]

[materials.backdrop]
type = "diffuse"
reflectance = "checker.png"

[[objects]]
name = "sphere"
mesh = "sphere.ply"
material = "glass"

[[objects]]
name = "floor"
mesh = "floor.ply"
material = "cloth"

[[objects]]
name = "board"
mesh = "backdrop.obj"
material = "backdrop"

[fit]
parameters = {fit!r}
""".replace("'", '"')


def with_second_glass(text: str) -> str:
    """A :func:`sphere_scene_toml` scene with a second glass sphere of another material
    (``tint``, absorption 2, 6, 10 per metre) beside the first."""
    return text.replace("[materials.cloth]", """[materials.tint]
type = "dielectric"
ior = [1.5, 1.5, 1.5]
absorption = [2.0, 6.0, 10.0]

[[objects]]
name = "second"
mesh = "sphere.ply"
material = "tint"
pose = [0.07, 0.0, -0.05, 0.0, 0.0, 0.0]

[materials.cloth]""")


def box_object_toml(pose: str | None = None) -> str:
    """A painted box (``box.ply``) as scene-file text; ``pose`` is written as given when given
    (a list, or a ``str.format`` placeholder such as ``"{pose}"``)."""
    line = "" if pose is None else f"pose = {pose}\n"
    return f"""
[materials.paint]
type = "diffuse"
reflectance = [0.6, 0.4, 0.3]

[[objects]]
name = "box"
mesh = "box.ply"
material = "paint"
{line}"""


@pytest.fixture(scope="session")
def small_scene_dir(tmp_path_factory) -> Path:
    """A glass icosphere on a diffuse floor in front of a textured backdrop, lit by an env map."""
    root = tmp_path_factory.mktemp("small_scene")
    make_sphere_and_floor(root)
    make_backdrop(root)
    make_env(root / "env.exr")
    make_checker(root / "checker.png")
    (root / "scene.toml").write_text(sphere_scene_toml(["glass.absorption"], absorption=[2.0, 4.0, 8.0]))
    return root


def _single_sphere_scene(root: Path, small_scene_dir: Path, name: str, fields: str) -> Path:
    """``small_scene_dir``'s sphere alone, with material ``name`` of the given TOML ``fields``,
    under ``env.exr`` (copied from ``small_scene_dir`` unless ``root`` already has one)."""
    (root / "sphere.ply").write_bytes((small_scene_dir / "sphere.ply").read_bytes())
    if not (root / "env.exr").exists():
        (root / "env.exr").write_bytes((small_scene_dir / "env.exr").read_bytes())
    (root / "scene.toml").write_text(f"""
[environment]
file = "env.exr"

[materials.{name}]
{fields}

[[objects]]
name = "sphere"
mesh = "sphere.ply"
material = "{name}"
""")
    return root


@pytest.fixture(scope="session")
def silhouette_scene_dir(tmp_path_factory, small_scene_dir) -> Path:
    """A diffuse sphere alone under a uniform white environment."""
    from abs.io.images import write_exr

    root = tmp_path_factory.mktemp("silhouette_scene")
    write_exr(root / "env.exr", np.ones((16, 32, 3), np.float32))
    return _single_sphere_scene(root, small_scene_dir,
                                'paint', 'type = "diffuse"\nreflectance = [0.5, 0.5, 0.5]')


@pytest.fixture(scope="session")
def glass_scene_dir(tmp_path_factory, small_scene_dir) -> Path:
    """A glass sphere alone under the structured environment (no edges seen through it)."""
    return _single_sphere_scene(
        tmp_path_factory.mktemp("glass_scene"), small_scene_dir,
        'glass', 'type = "dielectric"\nior = [1.5, 1.5, 1.5]\nabsorption = [2.0, 4.0, 8.0]')


def analytic_tables(count: int, seed: int = 2) -> list[np.ndarray]:
    """Blinn-Phong-like isotropic tables (1/sr) with random colour, gloss and exponent; 0 below the
    horizon like a MERL table."""
    from abs.io.merl import merl_sample_angles

    rng = np.random.default_rng(seed)
    theta_h, theta_d, phi_d = merl_sample_angles()
    along = np.cos(theta_d) * np.cos(theta_h)
    across = np.sin(theta_d) * np.cos(phi_d) * np.sin(theta_h)
    valid = (along + across > 0) & (along - across > 0)
    tables = []
    for _ in range(count):
        diffuse = rng.uniform(0.02, 0.3, 3)[:, None, None, None] / np.pi
        gloss, exponent = rng.uniform(0.1, 3.0), rng.uniform(5, 200)
        lobe = gloss * (exponent + 2) / (2 * np.pi) * np.cos(theta_h) ** exponent * (1 + 0.5 * np.sin(theta_d) ** 4)
        tables.append(((diffuse + lobe) * valid).astype(np.float32))
    return tables
