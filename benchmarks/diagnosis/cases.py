"""The diagnosis proof suite's scenes and cases: synthetic captures in which effects are present in
the photographs (the truth scene file) but absent from the scene file given to ``abs diagnose``.

Two scenes, built on the fly:

- ``sphere``: a glass sphere on a cloth in front of a printed checkerboard (the test scenes'
  layout) in a bright room (``tests/conftest.py``'s ``make_soft_env``); fitted: ``environment.scale``.
- ``cloth``: the sphere scene with the cloth's reflectance fitted as well (a scattering cloth
  reflects a different fraction of light than its nominal reflectance, which a user would fit);
- ``box``: a painted box and a clear glass sphere on the cloth in front of the checkerboard;
  fitted: ``environment.scale`` and the paint's reflectance.
- ``noisy``: the sphere scene whose glass mesh is a scan of the sphere with noise
  (``sphere_noisy.ply``: the same vertices moved along their radii by 0.5 mm, RMS); fitted:
  ``environment.scale``.
- ``noisybox``: the box scene with that noisy glass mesh; fitted as the box scene.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path


__all__ = ["Case", "CASES", "QUICK", "build_scene"]

#: RMS radial noise of the ``noisy`` scene's glass mesh (m), about 1/13 of its edges' length.
NOISE_M = 0.0005


@dataclass(frozen=True)
class Case:
    """A capture with hidden effects.

    ``truth`` overrides TOML fields of the given scene (parameter name -> true value): the hidden
    effect rendered by abs's own model. ``photographs`` names an independent truth renderer of
    :data:`TRUTH_RENDERERS` and its settings: the hidden effect made by physics that abs's model
    only approximates (as in real photographs). ``upscale`` multiplies the suite's image width and
    height for this case: an effect finer than the suite's pixels (a subsurface spread of
    millimetres) needs photographs that resolve it, as real megapixel photographs do.
    ``photo_spp_factor`` multiplies the photographs' samples per pixel: a truth renderer that
    converges slowly (a random walk through a scattering medium) needs more samples for its
    Monte-Carlo noise to stay below the sensor noise, as it is in real photographs.
    """

    name: str
    scene: str
    hidden: tuple[str, ...]            # effect names expected in the verdict, most important first
    truth: dict = field(default_factory=dict)
    photographs: tuple[str, dict] | None = None
    upscale: int = 1
    photo_spp_factor: int = 1

    def describe_truth(self) -> str:
        if self.photographs is None:
            return ""
        kind, settings = self.photographs
        return f"{kind}(" + ", ".join(f"{k}={v}" for k, v in settings.items()) + ")"


def _model(compiled, camera, spp, seed):
    return compiled.render(camera, spp=spp, seed=seed).numpy()


def _natural_vignetting(compiled, camera, spp, seed, strength):
    from abs.render.sensor_truth import natural_vignetting

    return natural_vignetting(_model(compiled, camera, spp, seed), camera, strength)


def _veiling_glare(compiled, camera, spp, seed, fraction, sigma_frac, floor):
    from abs.render.sensor_truth import veiling_glare

    return veiling_glare(_model(compiled, camera, spp, seed), fraction, sigma_frac * camera.width, floor)


def _filmic_response(compiled, camera, spp, seed, white):
    from abs.render.sensor_truth import filmic_response

    return filmic_response(_model(compiled, camera, spp, seed), white)


def _white_balance_shift(compiled, camera, spp, seed, cct):
    from abs.render.sensor_truth import white_balance_shift

    return white_balance_shift(_model(compiled, camera, spp, seed), cct)


def _turned_environment(compiled, camera, spp, seed, rotation_vector):
    """The scene under its environment map turned by ``rotation_vector`` (radians, world frame),
    through the map's fixed ``to_world`` frame (scipy's rotation), not abs's fitted
    ``orientation``."""
    import numpy as np
    from scipy.spatial.transform import Rotation

    from abs.render.environment import Environment

    env = compiled.environment
    turn = np.eye(4)
    turn[:3, :3] = Rotation.from_rotvec(rotation_vector).as_matrix()
    # ``rotation`` (about +y) applies after ``to_world``; turning the whole frame means
    # R_turn R_y to_world = R_y (R_y^-1 R_turn R_y) to_world.
    r = float(np.asarray(env.rotation)[0])
    ry = np.eye(4)
    ry[:3, :3] = Rotation.from_rotvec([0.0, r, 0.0]).as_matrix()
    turned = Environment(np.asarray(env.data.numpy()), float(np.asarray(env.scale)[0]),
                         np.linalg.inv(ry) @ turn @ ry @ env.to_world_np, r,
                         float(np.asarray(env.inverse_distance)[0]), np.asarray(env.center).ravel())
    compiled.environment = turned
    try:
        return _model(compiled, camera, spp, seed)
    finally:
        compiled.environment = env


def _turned_cameras(compiled, camera, spp, seed, rotation_vector):
    """The scene through the camera turned about its own centre by ``rotation_vector`` (radians,
    camera frame: x right, y down, z forward; scipy's rotation), rendered by the path tracer:
    the photographs' camera is not the calibrated one that ``cameras.json`` states, as when a
    mount or a calibration is off by a fraction of a degree. abs's model of it is a resampling
    by a principal-point shift (``[sensor] intrinsics_offset``), exact only to first order."""
    from scipy.spatial.transform import Rotation

    from abs.render import Camera

    turn = Rotation.from_rotvec(rotation_vector).as_matrix()
    # x_cam' = Q x_cam = Q R X + Q t: the same centre, turned.
    turned = Camera(camera.K, turn @ camera.R, turn @ camera.t, camera.width, camera.height, camera.block)
    return _model(compiled, turned, spp, seed)


def _clean_glass_mesh(compiled, camera, spp, seed, clean_mesh):
    """The scene with its noisy glass mesh replaced by the clean one it was scanned from
    (``clean_mesh``, a file beside the noisy one with the same vertices in the same order):
    its vertex positions and the normals Mitsuba computes for it on loading, so the photographs
    show the object and the scene file carries the scan's noise."""
    import drjit as dr
    import mitsuba as mi

    noisy = next(o for o in compiled.scene.objects if o.mesh.name == "sphere_noisy.ply")
    clean = mi.traverse(mi.load_dict({"type": "ply", "filename": str(noisy.mesh.parent / clean_mesh)}))
    sid = compiled.shape_ids[noisy.name]
    keys = [f"{sid}.vertex_positions", f"{sid}.vertex_normals"]
    saved = [type(compiled.params[k])(compiled.params[k]) for k in keys]
    for k, name in zip(keys, ("vertex_positions", "vertex_normals")):
        compiled.params[k] = type(clean[name])(clean[name])
    compiled.params.update()
    try:
        return _model(compiled, camera, spp, seed)
    finally:
        for k, v in zip(keys, saved):
            compiled.params[k] = v
        compiled.params.update()
        dr.eval()


def _chrome_probe_map(compiled, camera, spp, seed, eta, k):
    """The scene under the world its light-probe map came from: the scene file's map still
    carries the chrome ball's reflectance (exact conductor Fresnel of complex IOR ``eta + i k``
    per R, G, B, ``abs.probe.fresnel``, relative to normal incidence), seen from the scene file's
    ``probe_view``, so the photographs' light is the map divided by it. abs's model of it is
    Schlick's shape, not the exact Fresnel equations."""
    import numpy as np

    from abs.probe.fresnel import conductor_reflectance
    from abs.probe.unwrap import latlong_directions
    from abs.render.environment import Environment

    env = compiled.environment
    data = np.asarray(env.data.numpy(), np.float64)
    h, w = data.shape[:2]
    view = np.asarray(compiled.scene.environment.probe_view, np.float64)
    cos_i = np.sqrt(np.clip(0.5 * (1.0 + latlong_directions(w, h) @ view), 0.0, 1.0))
    excess = conductor_reflectance(cos_i, eta, k) / conductor_reflectance(np.ones(1), eta, k)[0]
    spec = compiled.scene.environment
    compiled.environment = Environment((data / excess).astype(np.float32), spec.scale, spec.to_world,
                                       spec.rotation, spec.inverse_distance, spec.center, spec.orientation)
    try:
        return _model(compiled, camera, spp, seed)
    finally:
        compiled.environment = env


def _scattering_cloth(compiled, camera, spp, seed, mean_free_path):
    from abs.render.medium_truth import render_with_medium

    return render_with_medium(compiled, camera, "cloth", mean_free_path, spp=spp, seed=seed)


def _mitsuba_threads(compiled, camera, spp, seed, material, anisotropy, roughness=(0.3, 1.0)):
    """The cloth ``material`` as Mitsuba's own BSDFs, rendered by abs's path tracer: a
    ``blendbsdf`` of its ``diffuse`` and two anisotropic GGX ``roughconductor`` lobes without
    Fresnel (``material = "none"``, coloured by the reflectance) of threads along the material's
    ``thread_direction`` and across it, weighted ``anisotropy`` = [warp, weft]. Single scattering
    only: the light the threads mask is lost (abs's model returns it), so the cloth is also
    darker. Mitsuba's anisotropic lobes lie in the shading frame, whose first tangent on a mesh
    without texture coordinates turns from triangle to triangle, so each (flat, y = const)
    object of the material becomes a Mitsuba ``rectangle`` of its extent, whose first tangent is
    +x; the thread direction must be along or across it."""
    import mitsuba as mi
    import numpy as np

    from abs.render import PathTracer

    d = compiled.mitsuba_dict(include_environment=False)
    rho = d[material]["reflectance"]
    shapes = {shape.id(): shape for shape in compiled.mitsuba_scene.shapes()}
    for obj in compiled.scene.objects:
        if obj.material != material:
            continue
        sid = compiled.shape_ids[obj.name]
        box = shapes[sid].bbox()
        lo, hi = np.array(box.min, float).ravel(), np.array(box.max, float).ravel()
        if hi[1] - lo[1] > 1e-6:
            raise ValueError(f"{obj.name}: needs a flat object in a plane y = const")
        d[sid] = {"type": "rectangle", "bsdf": {"type": "ref", "id": material},
                  "to_world": mi.ScalarTransform4f().translate((lo + hi) / 2).rotate([1, 0, 0], -90)
                  .scale([(hi[0] - lo[0]) / 2, (hi[2] - lo[2]) / 2, 1.0])}
    along = abs(float(compiled.scene.materials[material].thread_direction[0]))
    if not (along > 0.999 or along < 1e-3):
        raise ValueError(f"{material}: the thread direction must be along x or across it (in y = const)")
    warp = tuple(roughness) if along > 0.5 else tuple(roughness[::-1])

    def lobe(au, av):
        return {"type": "roughconductor", "material": "none", "distribution": "ggx", "alpha_u": au,
                "alpha_v": av, "specular_reflectance": rho}

    a, b = map(float, anisotropy)
    threads = {"type": "blendbsdf", "weight": b / (a + b), "bsdf_0": lobe(*warp), "bsdf_1": lobe(*warp[::-1])}
    d[material] = {"type": "blendbsdf", "id": material, "weight": a + b,
                   "bsdf_0": {"type": "diffuse", "reflectance": rho}, "bsdf_1": threads}
    scene = mi.load_dict(d, optimize=False)
    tracer = PathTracer(max_depth=compiled.scene.render.max_depth)
    return tracer.render(scene, compiled.environment, camera, spp, seed).numpy()


def _plain_mitsuba(compiled, camera, spp, seed):
    """Mitsuba's own integrator and plugins (stock ``dielectric`` at the green IOR, ``volpath``,
    ``envmap``), not abs's path tracer: a null case whose photographs share no code path with
    the model the diagnosis fits (the glass suite's photographs, ``benchmarks/glass_fit.py``)."""
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from glass_fit import mitsuba_photograph

    # At the spp asked for everywhere: the suite's recorded null runs were rendered so (the glass
    # suite's photographs take more samples where the glass is seen).
    return mitsuba_photograph(compiled, camera, spp, seed, glass_spp_factor=1)


#: Independent truth renderers: ``f(compiled, camera, spp, seed, **settings) -> (H, W, 3)``.
TRUTH_RENDERERS = {
    "natural_vignetting": _natural_vignetting,   # cos^4 law, not abs's polynomial
    "veiling_glare": _veiling_glare,             # blurred image + floor, not a constant offset
    "filmic_response": _filmic_response,         # Reinhard curve, not a power law
    "scattering_cloth": _scattering_cloth,       # volumetric slab in volpath, not a spread exit point
    "white_balance_shift": _white_balance_shift,  # Bradford adaptation in XYZ (colour-science)
    "turned_environment": _turned_environment,   # the map's to_world turned, not its orientation
    "turned_cameras": _turned_cameras,           # cameras rotated in the path tracer, not resampled
    "clean_glass_mesh": _clean_glass_mesh,       # the clean mesh, not smoothed normals
    "chrome_probe_map": _chrome_probe_map,       # exact conductor Fresnel, not Schlick's shape
    "mitsuba_threads": _mitsuba_threads,         # Mitsuba's single-scattering lobes, not abs's
    "plain_mitsuba": _plain_mitsuba,             # Mitsuba's integrator and plugins, no effect
}


CASES = [
    Case("sphere-absorption", "sphere", ("absorption",), {"glass.absorption": [3.0, 6.0, 10.0]}),
    Case("sphere-vignetting", "sphere", ("vignetting",),
         photographs=("natural_vignetting", {"strength": 0.6})),
    Case("sphere-stray_light", "sphere", ("stray_light",),
         photographs=("veiling_glare", {"fraction": 0.04, "sigma_frac": 0.15, "floor": [0.03, 0.03, 0.035]})),
    Case("sphere-null", "sphere", ()),
    # Nothing missing, photographed by plain Mitsuba: what abs's renderer differs in from
    # Mitsuba's (sampling, the glass plugin, the environment's lookup) must not look like physics.
    Case("sphere-null-mitsuba", "sphere", (), photographs=("plain_mitsuba", {})),
    # Nothing missing in the scene whose cloth reflectance is fitted too (the trade-off cases').
    Case("cloth-null", "cloth", ()),
    Case("sphere-absorption+vignetting", "sphere", ("absorption", "vignetting"),
         {"glass.absorption": [3.0, 6.0, 10.0]}, ("natural_vignetting", {"strength": 0.6})),
    Case("sphere-camera_response", "sphere", ("camera_response",),
         photographs=("filmic_response", {"white": 3.0})),
    Case("sphere-env_distance", "sphere", ("env_distance",), {"environment.inverse_distance": [1.0]}),
    Case("sphere-surface_roughness", "sphere", ("surface_roughness",), {"glass.roughness": [0.15]}),
    Case("cloth-subsurface", "cloth", ("subsurface",),
         photographs=("scattering_cloth", {"mean_free_path": 0.002}), upscale=2,
         photo_spp_factor=64),
    Case("sphere-subsurface", "sphere", ("subsurface",), {"cloth.subsurface": [0.015]}, upscale=2),
    Case("box-pose", "box", ("pose",), {"box.pose": [0.01, 0.0, -0.008, 0.0, 0.1, 0.0]}),
    Case("box-pose-4mm", "box", ("pose",), {"box.pose": [0.004, 0.0, -0.003, 0.0, 0.04, 0.0]}),
    Case("box-camera_response", "box", ("camera_response",),
         photographs=("filmic_response", {"white": 3.0})),
    Case("box-vignetting", "box", ("vignetting",), photographs=("natural_vignetting", {"strength": 0.6})),
    Case("box-null", "box", ()),
    # A 5500 K white balance error: red up 4 %, blue down 16 %, some green into red.
    Case("sphere-colour_transform", "sphere", ("colour_transform",),
         photographs=("white_balance_shift", {"cct": 5500})),
    Case("box-colour_transform", "box", ("colour_transform",),
         photographs=("white_balance_shift", {"cct": 5500})),
    # The map tilted by 8 degrees about x and 5 about z: highlights and refractions misplaced.
    Case("sphere-environment_rotation", "sphere", ("environment_rotation",),
         photographs=("turned_environment", {"rotation_vector": [0.14, 0.0, 0.09]})),
    # The same tilt over the box scene: the box's painted faces and highlights move as well.
    Case("box-environment_rotation", "box", ("environment_rotation",),
         photographs=("turned_environment", {"rotation_vector": [0.14, 0.0, 0.09]})),
    # Every camera turned by 0.46 degrees about its x axis and 0.63 about its y axis: to first
    # order a principal-point error of (-0.74, -0.54) px at the suite's 48x36 (fx = 67.2 px).
    Case("sphere-camera_misalignment", "sphere", ("camera_misalignment",),
         photographs=("turned_cameras", {"rotation_vector": [0.008, -0.011, 0.0]})),
    Case("box-camera_misalignment", "box", ("camera_misalignment",),
         photographs=("turned_cameras", {"rotation_vector": [0.008, -0.011, 0.0]})),
    # The scene file's glass mesh carries a scan's noise (0.5 mm); the photographs show the
    # clean sphere. At the suite's 48x36 the sphere spans about 12 pixels and the score test's
    # predicted BIC gain was -3.1 (first of all candidates, but not fitted), so the photographs
    # resolve it at twice the size, as for subsurface.
    Case("noisy-surface_detail", "noisy", ("surface_detail",),
         photographs=("clean_glass_mesh", {"clean_mesh": "sphere.ply"}), upscale=2),
    Case("noisybox-surface_detail", "noisybox", ("surface_detail",),
         photographs=("clean_glass_mesh", {"clean_mesh": "sphere.ply"}), upscale=2),
    # The map was unwrapped from a chromium ball photographed from +z (the cameras' side) without
    # dividing by its Fresnel reflectance (optical constants of tests/test_probe.py).
    Case("sphere-probe_fresnel", "sphere", ("probe_fresnel",),
         photographs=("chrome_probe_map", {"eta": [3.28, 3.05, 2.37], "k": [3.31, 3.31, 3.14]})),
    Case("box-probe_fresnel", "box", ("probe_fresnel",),
         photographs=("chrome_probe_map", {"eta": [3.28, 3.05, 2.37], "k": [3.31, 3.31, 3.14]})),
    # The seed's trade-off: the scene file's cloth is too bright (0.7 for a true 0.55) and the
    # glass absorbs. The catalogue has no effect for a wrong reflectance, so the cloth's
    # reflectance is fitted (the ``cloth`` scene) and the case asks whether absorption is still
    # found with it, at what amount, and which baseline parameters the report flags as
    # compensating.
    Case("cloth-absorption+dark_cloth", "cloth", ("absorption",),
         {"glass.absorption": [3.0, 6.0, 10.0], "cloth.reflectance": [0.55, 0.55, 0.5]}),
    # Woven cloth (issue 28): 10 % of the cloth's reflected light in the lobe of threads along x
    # and 30 % in that of threads along z (towards the cameras), abs's energy-conserving model.
    # Under the suite's soft room an energy-conserving lobe changes little (under uniform light
    # it changes nothing): 0.01-0.03 RMS at 48x36, 256 spp.
    Case("sphere-cloth_anisotropy", "sphere", ("cloth_anisotropy",), {"cloth.anisotropy": [0.1, 0.3]}),
    Case("box-cloth_anisotropy", "box", ("cloth_anisotropy",), {"cloth.anisotropy": [0.1, 0.3]}),
    # The same weights photographed through Mitsuba's blendbsdf of diffuse and roughconductor
    # lobes (single scattering: about 20 % of the lobes' light is lost, so the cloth is darker
    # too); its reflectance is fitted (the ``cloth`` scene), as a user would.
    Case("cloth-cloth_anisotropy", "cloth", ("cloth_anisotropy",),
         photographs=("mitsuba_threads", {"material": "cloth", "anisotropy": [0.1, 0.3]})),
    Case("box-absorption+stray_light", "box", ("absorption", "stray_light"),
         {"glass.absorption": [3.0, 6.0, 10.0]},
         ("veiling_glare", {"fraction": 0.04, "sigma_frac": 0.15, "floor": [0.03, 0.03, 0.035]})),
]

#: The quick default: every effect once, a two-effect case and both nulls.
QUICK = ["sphere-absorption", "sphere-vignetting", "sphere-stray_light", "sphere-camera_response",
         "sphere-env_distance", "sphere-surface_roughness", "sphere-subsurface", "cloth-subsurface",
         "box-pose", "box-camera_response", "sphere-colour_transform",
         "sphere-environment_rotation", "sphere-camera_misalignment", "sphere-probe_fresnel",
         "noisy-surface_detail", "sphere-cloth_anisotropy", "sphere-null", "box-null",
         "sphere-absorption+vignetting"]


def _conftest() -> None:
    """The test suite's scene builders (``tests/conftest.py``) are the suite's too."""
    import sys

    tests = str(Path(__file__).resolve().parents[2] / "tests")
    if tests not in sys.path:
        sys.path.insert(0, tests)


def _assets(root: Path) -> None:
    import trimesh

    _conftest()
    from conftest import make_backdrop, make_checker, make_soft_env, make_sphere_and_floor, write_mesh

    make_soft_env(root / "env.exr")
    make_checker(root / "checker.png")
    make_sphere_and_floor(root)
    make_backdrop(root)
    box = trimesh.creation.box(extents=[0.06, 0.05, 0.05])
    box.apply_translation([-0.07, 0.025, 0.0])
    write_mesh(root / "box.ply", box)


def build_scene(root: Path, kind: str) -> Path:
    """Write the assets and the given (effect-free) scene file of ``kind``; returns its path."""
    root.mkdir(parents=True, exist_ok=True)
    if not (root / "env.exr").exists():
        _assets(root)
    _conftest()
    from conftest import box_object_toml, make_noisy_sphere, sphere_scene_toml

    box = ["environment.scale", "paint.reflectance"]
    fit = {"box": box, "sphere": ["environment.scale"], "cloth": ["environment.scale", "cloth.reflectance"],
           "noisy": ["environment.scale"], "noisybox": box}[kind]
    text = sphere_scene_toml(fit, absorption=[0.0, 0.0, 0.0]) + (box_object_toml() if fit is box else "")
    if kind.startswith("noisy"):
        if not (root / "sphere_noisy.ply").exists():
            make_noisy_sphere(root / "sphere_noisy.ply", NOISE_M, seed=0)
        text = text.replace('mesh = "sphere.ply"', 'mesh = "sphere_noisy.ply"')
    path = root / f"{kind}.toml"
    path.write_text(text)
    return path
