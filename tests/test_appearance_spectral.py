"""The ``mitsuba`` renderer's ``spectral`` option: rendering in a spectral variant, in a worker.

What is physically true and tested: a single bounce of white light off any reflectance renders
spectrally to (nearly) its RGB value, because Mitsuba's sRGB upsampling is built to round-trip;
a grey reflectance is flat, so grey stays grey through any number of bounces. Light that bounces
between saturated surfaces differs: the product of two upsampled spectra is not the upsampled
product of their RGB values, so the interreflected light's weak channels change. A conductor's
RGB ``eta`` and ``k`` above 1 must reach Mitsuba unclamped. Renders are
16x16 pixels; each worker start costs about 2 s.
"""

from __future__ import annotations

import numpy as np
import pytest

from abs.appearance import renderer
from abs.appearance.design import SceneSpec, Sphere
from abs.appearance.scenes import design_camera, scene_geometry
from abs.appearance.spectral import encode, render_spectral
from abs.errors import InputError

SIZE = 16
# Every reconfiguration off: only ``spectral`` differs between the two renders compared.
NEUTRAL = {"max_depth": 8, "squared_roughness": False, "thin_glass": False,
           "white_balance": [1.0, 1.0, 1.0], "exposure": 1.0}
WHITE = np.ones((16, 32, 3), np.float32)


def _sphere_scene(table, box=False, walls=(0.5, 0.5, 0.5)):
    sphere = Sphere((0.0, 0.25, 0.0), 0.25, "wood", 0, table)
    return SceneSpec("spectral", walls, (sphere,), floor=walls, box=box)


def _sphere_pixels(spec, spectral, spp, seed):
    camera = design_camera(SIZE)
    image = renderer("mitsuba", {**NEUTRAL, "spectral": spectral}).render(spec, WHITE, camera, spp, seed)
    return image[scene_geometry(spec, camera).ids == 1]


def _difference(spec, spp):
    """Mean sphere colour of the RGB render, and the mean and standard error of the per-pixel
    difference spectral − RGB (independent seeds: the paired difference leaves out the shading
    that both renders share, so its spread is Monte-Carlo noise)."""
    rgb = _sphere_pixels(spec, False, spp, 1)
    delta = _sphere_pixels(spec, True, spp, 2) - rgb
    return rgb.mean(0), delta.mean(0), delta.std(0) / np.sqrt(len(delta))


def test_grey_sphere_spectral_matches_rgb_within_noise():
    spec = _sphere_scene({"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]})
    rgb, delta, error = _difference(spec, 64)
    # Closed form under a unit white sky: radiance = reflectance.
    np.testing.assert_allclose(rgb, 0.5, atol=0.01)
    assert np.all(np.abs(delta) < 4 * error + 1e-3), (delta, error)
    # Grey stays grey: the spectral render's channels agree with each other.
    assert np.ptp(rgb + delta) < 0.02, rgb + delta


def test_saturated_single_bounce_round_trips_but_interreflection_differs():
    red = [0.8, 0.05, 0.05]
    alone = _sphere_scene({"type": "diffuse", "reflectance": red})
    rgb, delta, error = _difference(alone, 64)
    # One bounce of white light: the upsampled spectrum renders back to its RGB within 3 %
    # (or the noise).
    assert np.all(np.abs(delta) < np.maximum(0.03 * rgb, 4 * error)), (rgb, delta, error)

    # The same sphere in a box of the same red: most of its light has bounced off red walls.
    boxed = _sphere_scene({"type": "diffuse", "reflectance": red}, box=True, walls=tuple(red))
    rgb, delta, error = _difference(boxed, 128)
    # The green channel of red-on-red light: the upsampled red's green tail, squared, is darker
    # than 0.05² (measured 18 % darker at 64 spp, 23 % at 128); it must differ beyond noise.
    assert -delta[1] > 5 * error[1], (rgb, delta, error)
    assert -delta[1] / rgb[1] > 0.1, (rgb, delta)
    assert abs(delta[0]) < 0.03 * rgb[0], (rgb, delta)  # red, mostly first bounce, round-trips


def test_conductor_with_rgb_ior_above_one_round_trips():
    # Mitsuba 3.9's srgb spectrum clamps eta [3.2, 2.7, 2.3] and k [3.3, 3.2, 3.1] to 1, which
    # renders this metal about 60 % darker; the worker sends them as unclamped spectra.
    spec = _sphere_scene({"type": "conductor", "roughness": 0.1})
    rgb, delta, error = _difference(spec, 32)
    assert np.all(np.abs(delta) < np.maximum(0.05 * rgb, 4 * error)), (rgb, delta, error)


def test_merl_class_renders_spectrally():
    from abs.appearance.scenes import merl_file

    try:
        merl_file("blue-fabric")
    except Exception as exc:  # noqa: BLE001 - the shared neural fits may be absent
        pytest.skip(f"no MERL fit available: {exc}")
    spec = _sphere_scene({"type": "merl", "name": "blue-fabric"})
    rgb = _sphere_pixels(spec, False, 32, 1).mean(0)
    spectral = _sphere_pixels(spec, True, 32, 2).mean(0)
    # One bounce of white light off the table: the per-entry upsampling round-trips.
    np.testing.assert_allclose(spectral, rgb, rtol=0.06)
    assert spectral[2] > 1.5 * spectral[0]  # still blue


def test_missing_variant_is_an_input_error_naming_the_option():
    spec = _sphere_scene({"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]})
    r = renderer("mitsuba", {"spectral": True, "spectral_variant": "llvm_ad_nonexistent"})
    with pytest.raises(InputError, match="spectral=true.*refused.*llvm_ad_nonexistent"):
        r.render(spec, WHITE, design_camera(SIZE), 4, 0)


def test_worker_crash_is_an_input_error():
    scene = {"type": "scene", "thing": {"type": "no_such_plugin"},
             "sensor": {"type": "perspective", "film": {"type": "hdrfilm", "width": 4, "height": 4}}}
    with pytest.raises(InputError, match=r"--option spectral.*exit status.*no_such_plugin"):
        render_spectral(scene, WHITE, 4, 0, field="--option spectral")


def test_glass_with_dispersion_is_refused_by_the_worker():
    scene = {"type": "scene",
             "ball": {"type": "sphere", "bsdf": {"type": "abs_dielectric", "ior": [1.5, 1.52, 1.55]}},
             "sensor": {"type": "perspective", "film": {"type": "hdrfilm", "width": 4, "height": 4}}}
    with pytest.raises(InputError, match="scene.ball.bsdf: abs_dielectric with dispersion"):
        render_spectral(scene, WHITE, 4, 0)


def test_values_json_cannot_hold_are_refused_with_their_path():
    import mitsuba as mi

    with pytest.raises(InputError, match=r"scene\.emitter\.bitmap"):
        encode({"emitter": {"type": "envmap", "bitmap": mi.Bitmap(WHITE)}})
    transform = mi.ScalarTransform4f().translate([1.0, 2.0, 3.0])
    assert encode({"t": transform})["t"]["$transform"][0][3] == 1.0


def test_spectral_option_must_be_a_boolean():
    spec = _sphere_scene({"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]})
    with pytest.raises(InputError, match="--option spectral"):
        renderer("mitsuba", {"spectral": "yes"}).render(spec, WHITE, design_camera(SIZE), 4, 0)


def test_worker_replaces_clear_abs_glass_by_stock_dielectric():
    from abs.appearance.spectral_worker import spectral_scene

    scene = {"type": "scene",
             "ball": {"type": "sphere", "bsdf": {"type": "abs_dielectric", "ior": [1.45] * 3,
                                                 "absorption": [0.0] * 3, "roughness": 0.0,
                                                 "id": "ball_bsdf"}},
             "paint": {"type": "sphere", "bsdf": {"type": "abs_tabulated", "filename": "x.binary"}}}
    out = spectral_scene(scene)
    assert out["ball"]["bsdf"] == {"type": "dielectric", "int_ior": 1.45, "ext_ior": 1.0, "id": "ball_bsdf"}
    assert out["paint"]["bsdf"] == scene["paint"]["bsdf"]  # registered in spectral form by the worker
    assert scene["ball"]["bsdf"]["type"] == "abs_dielectric"  # the input is left as it was
