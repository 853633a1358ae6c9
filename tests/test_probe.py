"""Mirror-ball unwrapping (abs.probe) against an analytically rendered chrome ball."""

from __future__ import annotations

import numpy as np
import pytest

from abs.camera.pinhole import intrinsics_from_fov, look_at, ray_directions
from abs.errors import InputError
from abs.probe import ProbeView, conductor_reflectance, latlong_directions, merge_views, unwrap_view

CHROME_ETA, CHROME_K = np.array([3.28, 3.05, 2.37]), np.array([3.31, 3.31, 3.14])
CENTER, RADIUS = np.array([0.0, 0.1, 0.0]), 0.05


def _environment(d):
    """A smooth, colourful analytic environment (radiance towards direction d)."""
    return np.stack([1.0 + 0.6 * d[..., 0], 1.2 + 0.8 * d[..., 1], 1.0 - 0.5 * d[..., 2]], -1)


def _photograph(eye, size=64, fov_deg=14.0, supersample=3):
    """A pinhole photograph of a chrome ball, ray traced in numpy (box-filtered pixels)."""
    K = intrinsics_from_fov(size, size, np.radians(fov_deg))
    R, t = look_at(eye, CENTER)
    offsets = (np.arange(supersample) + 0.5) / supersample - 0.5
    image = np.zeros((size, size, 3))
    for dy in offsets:
        for dx in offsets:
            jj, ii = np.mgrid[0:size, 0:size]
            uv = np.stack([ii.ravel() + dx, jj.ravel() + dy], -1).astype(float)
            origin, d = ray_directions(K, R, t, uv)
            oc = origin - CENTER
            b = np.sum(oc * d, -1)
            disc = b**2 - (np.sum(oc * oc, -1) - RADIUS**2)
            hit = disc > 0
            s = -b - np.sqrt(np.maximum(disc, 0))
            n = (origin + s[:, None] * d - CENTER) / RADIUS
            cos = np.sum(-d * n, -1)
            r = d + 2 * cos[:, None] * n
            value = _environment(r) * conductor_reflectance(cos, CHROME_ETA, CHROME_K)
            image += np.where(hit[:, None], value, 0.0).reshape(size, size, 3)
    return ProbeView("view.exr", image / supersample**2, K, R, t)


def test_conductor_fresnel_known_values():
    # Normal incidence: ((n-1)^2 + k^2) / ((n+1)^2 + k^2); grazing: 1; k = 0: dielectric (n 1.5
    # at 60 degrees: 0.0891867, from the s and p Fresnel equations).
    f = conductor_reflectance(np.array([1.0, 0.0]), [3.0], [3.3])
    np.testing.assert_allclose(f[:, 0], [(4 + 3.3**2) / (16 + 3.3**2), 1.0])
    np.testing.assert_allclose(conductor_reflectance(np.array(0.5), [1.5], [0.0]), [0.0891867], atol=1e-7)


def test_latlong_directions_follow_mitsuba_envmap():
    d = latlong_directions(8, 5)
    np.testing.assert_allclose(d[0, :, 1], 1.0)  # top row: zenith (+y)
    np.testing.assert_allclose(d[-1, :, 1], -1.0, atol=1e-12)
    # Mitsuba's u = atan2(x, -z) / 2 pi is the column centre (i + 0.5) / W.
    u = np.arctan2(d[2, :, 0], -d[2, :, 2]) / (2 * np.pi) % 1.0
    np.testing.assert_allclose(u, (np.arange(8) + 0.5) / 8)


def _errors(view, **kw):
    dirs = latlong_directions(48, 24)
    pin, w = unwrap_view(view, CENTER, RADIUS, dirs, eta_rgb=CHROME_ETA, k_rgb=CHROME_K, **kw)
    good = w > 0.3  # away from the outline, where a pixel spans many directions
    return np.abs(pin - _environment(dirs))[good].mean() / _environment(dirs)[good].mean(), good


def test_pinhole_unwrap_recovers_the_environment_and_beats_orthographic():
    view = _photograph(eye=[0.0, 0.1, 0.45])  # 9 radii away: perspective matters
    err_pin, good = _errors(view, model="pinhole")
    err_ortho, _ = _errors(view, model="orthographic")
    err_closed, _ = _errors(view, model="pinhole", iterations=0)
    assert good.sum() > 200
    assert err_pin < 0.01, err_pin
    assert err_ortho > 3 * err_pin, (err_ortho, err_pin)
    assert err_closed > 3 * err_pin, (err_closed, err_pin)  # the closed formula: 1.9 % vs 0.09 %


def test_fresnel_division_matters():
    view = _photograph(eye=[0.0, 0.1, 0.45])
    dirs = latlong_directions(48, 24)
    raw, w = unwrap_view(view, CENTER, RADIUS, dirs)
    good = w > 0.3
    ratio = raw[good] / _environment(dirs)[good]
    # Without division the map is the environment times chromium's reflectance (0.55-0.6).
    assert 0.5 < ratio.mean() < 0.65


def test_two_views_merge_and_cover_more():
    a = _photograph(eye=[0.0, 0.1, 0.45])
    b = _photograph(eye=[0.45, 0.1, 0.0])
    dirs = latlong_directions(48, 24)
    ua = unwrap_view(a, CENTER, RADIUS, dirs, eta_rgb=CHROME_ETA, k_rgb=CHROME_K)
    ub = unwrap_view(b, CENTER, RADIUS, dirs, eta_rgb=CHROME_ETA, k_rgb=CHROME_K)
    merged, weight = merge_views([ua, ub])
    assert (weight > 0.3).sum() > (ua[1] > 0.3).sum()
    good = weight > 0.3
    err = np.abs(merged - _environment(dirs))[good].mean() / _environment(dirs)[good].mean()
    assert err < 0.01, err


def test_view_that_does_not_see_the_ball_is_an_error():
    view = _photograph(eye=[0.0, 0.1, 0.45])
    with pytest.raises(InputError, match=r"view\.exr: ball: .* does not see the ball"):
        unwrap_view(view, CENTER + np.array([1.0, 0.0, 0.0]), RADIUS, latlong_directions(8, 4))
    with pytest.raises(InputError, match=r"view\.exr: ball: camera is .* inside the ball"):
        unwrap_view(view, CENTER, 1.0, latlong_directions(8, 4))


def _outline_px(K, R, t, n=24):
    """Pixels of the ball's true outline: sphere points whose tangent ray meets the camera centre."""
    from abs.camera.pinhole import project

    c = -R.T @ t
    dist = np.linalg.norm(CENTER - c)
    a = (CENTER - c) / dist
    e1 = np.cross(a, [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a, e1)
    ang = np.linspace(0, 2 * np.pi, n, endpoint=False)
    rim = CENTER - a * RADIUS**2 / dist + np.sqrt(RADIUS**2 - RADIUS**4 / dist**2) * (
        np.cos(ang)[:, None] * e1 + np.sin(ang)[:, None] * e2)
    return project(K, R, t, rim)


def test_ball_triangulated_from_its_outline_in_two_views():
    from abs.probe.ball import triangulate_ball

    cams, outlines = [], []
    for eye in ([0.0, 0.1, 0.45], [0.4, 0.2, 0.1]):
        K = intrinsics_from_fov(64, 64, np.radians(14.0))
        R, t = look_at(eye, CENTER + np.array([0.01, 0.0, 0.0]))  # ball off the image centre
        cams.append((K, R, t))
        outlines.append(_outline_px(K, R, t))
    centre, radius = triangulate_ball(cams, outlines)
    np.testing.assert_allclose(centre, CENTER, atol=1e-9)
    np.testing.assert_allclose(radius, RADIUS, rtol=1e-9)


def test_cli_unwrap_matches_the_api_and_refuses_a_view_without_the_ball(tmp_path):
    from abs.cli.main import main
    from abs.io.capture import save_capture
    from abs.io.images import read_image

    view = _photograph(eye=[0.0, 0.1, 0.45])
    save_capture(tmp_path / "cap", [{"name": "front", "K": view.K, "R": view.R, "t": view.t}],
                 {"front": view.image.astype(np.float32)})
    yml = tmp_path / "chrome.yml"
    yml.write_text("DATA:\n  - type: tabulated nk\n    data: |\n        0.30 3.28 3.31\n"
                   "        0.90 3.28 3.31\n")
    out = tmp_path / "env.exr"
    args = ["probe", "unwrap", str(tmp_path / "cap"), "--center", "0,0.1,0", "--radius", "0.05",
            "--width", "48", "--fresnel", str(yml), "--out", str(out)]
    assert main(args) == 0
    api, _ = unwrap_view(ProbeView("front", view.image.astype(np.float32), view.K, view.R, view.t),
                         CENTER, RADIUS, latlong_directions(48, 24), eta_rgb=[3.28] * 3, k_rgb=[3.31] * 3)
    np.testing.assert_allclose(read_image(out), api, rtol=1e-4, atol=1e-5)
    args[4] = "2,0.1,0"  # a ball outside the view
    assert main(args) == 2


def test_cli_unwrap_with_the_ball_triangulated_from_outlines(tmp_path):
    import json

    from abs.cli.main import main
    from abs.io.capture import save_capture
    from abs.io.images import read_image

    views = {"a": _photograph(eye=[0.0, 0.1, 0.45]), "b": _photograph(eye=[0.45, 0.1, 0.0])}
    save_capture(tmp_path / "cap", [{"name": n, "K": v.K, "R": v.R, "t": v.t} for n, v in views.items()],
                 {n: v.image.astype(np.float32) for n, v in views.items()})
    outlines = tmp_path / "outlines.json"
    # Outline pixels rounded to 0.1 px, as a careful annotation would give.
    outlines.write_text(json.dumps({n: np.round(_outline_px(v.K, v.R, v.t), 1).tolist()
                                    for n, v in views.items()}))
    common = ["probe", "unwrap", str(tmp_path / "cap"), "--width", "48"]
    assert main(common + ["--outlines", str(outlines), "--out", str(tmp_path / "tri.exr")]) == 0
    assert main(common + ["--center", "0,0.1,0", "--radius", "0.05", "--out", str(tmp_path / "known.exr")]) == 0
    tri, known = read_image(tmp_path / "tri.exr"), read_image(tmp_path / "known.exr")
    assert np.mean(np.abs(tri - known)) < 0.01 * np.mean(known)
    outlines.write_text(json.dumps({"a": [[1, 2], [3, 4], [5, 6]]}))
    assert main(common + ["--outlines", str(outlines), "--out", str(tmp_path / "x.exr")]) == 2


def test_map_texels_are_the_directions_mitsubas_envmap_looks_them_up_at():
    """The unwrapped map drops into a scene: Mitsuba's envmap, evaluated at each texel's
    direction, returns exactly that texel."""
    import mitsuba as mi

    rng = np.random.default_rng(3)
    texels = rng.uniform(0.1, 1.0, (6, 12, 3)).astype(np.float32)
    emitter = mi.load_dict({"type": "envmap", "bitmap": mi.Bitmap(texels)})
    d = latlong_directions(12, 6)[1:-1].reshape(-1, 3)  # the pole rows are one direction each
    si = mi.SurfaceInteraction3f()
    # Mitsuba's emitters are evaluated for light arriving along -wi: wi points back into the map.
    si.wi = mi.Vector3f(*(np.ascontiguousarray(-d[:, i], np.float32) for i in range(3)))
    got = np.asarray(emitter.eval(si)).T  # (3, N) -> (N, 3)
    np.testing.assert_allclose(got, texels[1:-1].reshape(-1, 3), rtol=1e-4)  # float32 bilinear
