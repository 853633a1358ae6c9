"""abs.lightstage (issue 27, part 2): projection, normalisation, surface points, per-point fits,
and ``abs lightstage`` on a simulated rig session, with its errors for bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from abs.camera.pinhole import intrinsics_from_fov, look_at
from abs.cli.main import main
from abs.lightstage.attenuation import Attenuation
from abs.lightstage.fit import fit_channel
from abs.lightstage.geometry import Camera, Led, RigGeometry, turntable_rotation
from abs.lightstage.measure import measure, pose_view
from abs.lightstage.models import MODELS
from abs.lightstage.normalise import normalise
from abs.lightstage.raycast import MeshTracer
from abs.lightstage.session import LightGroup
from abs.lightstage.surface import build_surface_points


def _plane_rig(width=16, height=12):
    """A 40 cm square in the object's x-y plane (normal +z), a camera 1 m away on +z, one LED."""
    verts = np.array([[-0.2, -0.2, 0.0], [0.2, -0.2, 0.0], [0.2, 0.2, 0.0], [-0.2, 0.2, 0.0]])
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    K = intrinsics_from_fov(width, height, np.deg2rad(10.0))
    R, t = look_at(np.array([0.0, 0.0, 1.0]), np.zeros(3))
    led_pos = np.array([0.3, 0.4, 0.6])
    leds = {"b00l00": Led(led_pos, -led_pos / np.linalg.norm(led_pos), np.array([1.0, 2.0, 0.5]))}
    geometry = RigGeometry((Camera(K, R, t, width, height),), leds, np.array([0.0, 1.0, 0.0]),
                           np.zeros(3), Attenuation(4.0), gain=50.0)
    return geometry, MeshTracer(verts, faces), verts, faces


def test_pose_view_projects_pixels_onto_the_turned_mesh():
    """Each pixel's hit, turned back into the world, projects to that pixel and lies on the plane
    turned by the turntable angle."""
    geometry, tracer, _, _ = _plane_rig()
    angle = 25.0
    view = pose_view(geometry, tracer, 0, angle)
    assert len(view.pixel) == 16 * 12  # the square fills the small field of view
    rot = turntable_rotation(geometry.turntable_axis, angle)
    world = view.hits.point @ rot.T
    cam = geometry.cameras[0]
    x_cam = world @ cam.R.T + cam.t
    uv = (x_cam @ cam.K.T)[:, :2] / x_cam[:, 2:]
    expected = np.stack([view.pixel % 16, view.pixel // 16], 1)
    np.testing.assert_allclose(uv, expected, atol=1e-3)
    np.testing.assert_allclose(view.hits.point[:, 2], 0.0, atol=1e-6)
    # The known point: the centre ray hits the turntable centre, seen along +z at any angle.
    np.testing.assert_allclose(view.hits.normal, np.tile([0.0, 0.0, 1.0], (len(view.pixel), 1)), atol=1e-6)


def test_measurement_divides_out_led_distance_and_attenuation():
    """A Lambertian plane imaged under one LED measures kd / pi cos(theta_l) exactly."""
    geometry, tracer, verts, faces = _plane_rig()
    view = pose_view(geometry, tracer, 0, 0.0)
    led = geometry.leds["b00l00"]
    p = view.hits.point
    to = led.position - p
    d2 = np.sum(to * to, 1)
    wi = to / np.sqrt(d2)[:, None]
    att = np.clip(-wi @ led.axis, 0, 1) ** 4
    kd = np.array([0.5, 0.3, 0.8])
    cos = wi[:, 2]
    radiance = kd / np.pi * (cos * att / d2)[:, None] * led.intensity * (200 / 255)
    image = np.zeros((12 * 16, 3))
    image[view.pixel] = geometry.gain * radiance  # pixel value per second
    points = build_surface_points(verts, faces, 0.1)
    meas = measure(geometry, tracer, points, [LightGroup(0, 0.0, "b00l00", 200, (), (1.0,))],
                   [image.reshape(12, 16, 3)], holdout_every=0)
    assert len(meas) == len(view.pixel)
    np.testing.assert_allclose(meas.value, kd / np.pi * meas.light[:, 2:3], rtol=1e-4)
    to_eye = np.array([0.0, 0.0, 1.0]) - meas.position  # the camera at (0, 0, 1), table at 0 deg
    np.testing.assert_allclose(meas.view, to_eye / np.linalg.norm(to_eye, axis=1, keepdims=True),
                               atol=1e-5)


def test_shadow_rays_drop_occluded_pixels():
    """A second square between the LED and the plane shadows part of it: no measurement there."""
    geometry, _, verts, faces = _plane_rig()
    # Half-way to the LED (z = 0.3): it shadows the plane's x, y in [0, 0.3], a quarter of what the
    # camera sees, and hides nothing from the camera (its view of the plane passes at |x|, |y| < 0.04).
    blocker = np.array([[0.15, 0.2, 0.3], [0.3, 0.2, 0.3], [0.3, 0.35, 0.3], [0.15, 0.35, 0.3]])
    tracer = MeshTracer(np.concatenate([verts, blocker]), np.concatenate([faces, faces + 4]))
    view = pose_view(geometry, tracer, 0, 0.0)
    on_plane = np.abs(view.hits.point[:, 2]) < 1e-6
    from abs.lightstage.measure import led_irradiance

    _, factor = led_irradiance(geometry, tracer, view, "b00l00", 255)
    shadowed = on_plane & (factor[:, 0] == 0)
    assert on_plane.all()
    p = view.hits.point
    np.testing.assert_array_equal(shadowed, (p[:, 0] > 0) & (p[:, 1] > 0))


def test_normalisation_is_invariant_under_rotation():
    rng = np.random.default_rng(3)
    n = rng.normal(size=(200, 3))
    l = rng.normal(size=(200, 3))
    v = rng.normal(size=(200, 3))
    a = normalise(n, l, v)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))  # a rotation, not a reflection
    b = normalise(n @ q.T, l @ q.T, v @ q.T)
    for name in ("theta_l", "theta_v", "phi", "theta_h", "theta_d"):
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), atol=1e-9)
    np.testing.assert_allclose(np.cos(a.phi_d), np.cos(b.phi_d), atol=1e-9)
    # The canonical frame: light in the x-z plane, cosines those of the original vectors.
    np.testing.assert_allclose(a.light[:, 1], 0.0, atol=1e-12)
    unit = lambda x: x / np.linalg.norm(x, axis=1, keepdims=True)  # noqa: E731
    np.testing.assert_allclose(a.cos_l, np.sum(unit(n) * unit(l), 1), atol=1e-12)
    np.testing.assert_allclose(a.cos_h, np.sum(unit(n) * unit(unit(l) + unit(v)), 1), atol=1e-9)


def test_surface_points_cover_triangles_evenly_and_look_up_hits():
    mesh = trimesh.creation.icosphere(2, 0.05)
    points = build_surface_points(mesh.vertices, mesh.faces, 0.005)
    assert np.all(points.depth == 2)  # edges of ~16 mm at 5 mm spacing: ceil(log2(3.1)) = 2
    assert len(points) == 16 * len(mesh.faces)
    rng = np.random.default_rng(0)
    tri = rng.integers(0, len(mesh.faces), 5000)
    bary = rng.random((5000, 2))
    bary[bary.sum(1) > 1] = 1 - bary[bary.sum(1) > 1]
    pid = points.lookup(tri, bary)
    assert np.all(pid >= 0) and np.all(points.triangle[pid] == tri)
    f = mesh.faces[tri]
    x = ((1 - bary.sum(1))[:, None] * mesh.vertices[f[:, 0]] + bary[:, :1] * mesh.vertices[f[:, 1]]
         + bary[:, 1:] * mesh.vertices[f[:, 2]])
    # The owning point is the centroid of the leaf cell: within one cell of the hit.
    assert np.max(np.linalg.norm(x - points.position[pid], axis=1)) < 0.016 / 4 * 0.7


def _hemisphere(rng, m):
    v = rng.normal(size=(m, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    v[:, 2] = np.abs(v[:, 2]) + 0.05
    return v


@pytest.mark.parametrize("model, truth, rtol", [
    ("lambert", [0.6], 0.02),
    ("blinn_phong", [0.3, 0.5, 60.0], 0.1),
    ("cook_torrance", [0.3, 0.5, 0.2], 0.1),
])
def test_point_fits_recover_known_parameters(model, truth, rtol):
    rng = np.random.default_rng(7)
    m = 400
    iso = normalise(np.tile([0.0, 0.0, 1.0], (m, 1)), _hemisphere(rng, m), _hemisphere(rng, m))
    cos = (iso.cos_l, iso.cos_v, iso.cos_h)
    y = MODELS[model](np.array(truth), *cos)
    y = y + rng.normal(size=m) * 0.003
    y[:8] += 1.0  # outliers (a wrong normal, a stray reflection): the robust loss ignores them
    fits = fit_channel(*cos, y)
    assert fits[model].converged
    np.testing.assert_allclose(fits[model].params, truth, rtol=rtol)
    if model != "lambert":
        assert fits[model].rms < fits["lambert"].rms


def _tiny_session(tmp_path):
    plan = tmp_path / "plan.json"
    plan.write_text(json.dumps({"turntable": {"positions": 4}, "global_light": {"level": 255, "exposures_s": [0.02]},
                                "leds": {"boards": 2, "leds_per_board": 4}, "exposures_s": [0.01, 0.04],
                                "settle_s": 0.0}))
    session = tmp_path / "session"
    assert main(["rig", "capture", "--simulate", "--plan", str(plan), "--out", str(session),
                 "--sim-size", "64x48"]) == 0
    return session


def test_cli_measure_fit_render_on_a_simulated_session(tmp_path, capsys):
    session = _tiny_session(tmp_path)
    assert (session / "geometry.json").exists() and (session / "mesh.ply").exists()
    # A coarser mesh than the session's (320 triangles, one surface point each) keeps the fit short.
    mesh = tmp_path / "coarse.ply"
    trimesh.creation.icosphere(2, 0.05).export(mesh)
    assert main(["lightstage", "measure", str(session), "--mesh", str(mesh), "--spacing", "0.02"]) == 0
    out = session / "lightstage"
    assert main(["lightstage", "fit", str(out), "--min-measurements", "6"]) == 0
    assert main(["lightstage", "render", str(out), "--write", "1"]) == 0
    fit = json.loads((out / "fit.json").read_text())
    assert fit["converged_fraction"]["lambert"] > 0.95
    evaluation = json.loads((out / "evaluation.json").read_text())
    # The simulated sphere is Lambertian: the fitted albedos render the held-out frames closely.
    assert evaluation["mae_eq_4_1"]["lambert"] < 0.03
    assert (out / "renders" / "0000-lambert.exr").exists()
    # Fitted albedo against the simulator's texture at the fitted points.
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from abs.lightstage.fit import ModelFits
    from abs.lightstage.pipeline import load_mesh, prepare
    from rig.sim.optics import albedo_at

    fits = ModelFits.load(out / "fits.npz")
    _, points = prepare(load_mesh(mesh), 0.02)
    sel = fits.count > 0
    err = np.abs(fits.params["lambert"][sel, :, 0] - albedo_at(points.position[sel]))
    assert np.median(err) < 0.01


def test_cli_errors_for_bad_input(tmp_path, capsys):
    assert main(["lightstage", "measure", str(tmp_path / "nowhere")]) == 2
    assert "session folder not found" in capsys.readouterr().err
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["lightstage", "measure", str(empty)]) == 2
    assert "manifest.json: not found" in capsys.readouterr().err
    (empty / "manifest.json").write_text(json.dumps({"format": "abs-rig-session/1", "frames": []}))
    assert main(["lightstage", "measure", str(empty)]) == 2
    assert "no LED frames" in capsys.readouterr().err
    session = _tiny_session(tmp_path)
    capsys.readouterr()
    assert main(["lightstage", "measure", str(session), "--mesh", str(tmp_path / "missing.ply")]) == 2
    assert "mesh not found" in capsys.readouterr().err
    (session / "geometry.json").unlink()
    assert main(["lightstage", "measure", str(session)]) == 2
    assert "geometry file not found" in capsys.readouterr().err
    bad = tmp_path / "geometry.json"
    bad.write_text(json.dumps({"format": "abs-lightstage-geometry/1", "cameras": [{"K": [[1, 0]],
                                "R": np.eye(3).tolist(), "t": [0, 0, 0], "width": 4, "height": 3}],
                               "leds": {"b00l00": {"position": [0, 1, 0], "axis": [0, -1, 0]}}}))
    assert main(["lightstage", "measure", str(session), "--geometry", str(bad)]) == 2
    assert "cameras[0].K" in capsys.readouterr().err
    assert main(["lightstage", "fit", str(tmp_path / "nothing")]) == 2
    assert "run 'abs lightstage measure' first" in capsys.readouterr().err


def test_geometry_file_round_trip_and_tabulated_attenuation(tmp_path):
    from abs.lightstage.geometry import read_geometry, write_geometry

    geometry, _, _, _ = _plane_rig()
    table = Attenuation(None, (0.0, 30.0, 60.0), (1.0, 0.5, 0.0))
    geometry = RigGeometry(geometry.cameras, geometry.leds, geometry.turntable_axis,
                           geometry.turntable_center, table, geometry.gain)
    write_geometry(geometry, tmp_path / "g.json")
    back = read_geometry(tmp_path / "g.json")
    np.testing.assert_allclose(back.cameras[0].K, geometry.cameras[0].K)
    np.testing.assert_allclose(back.leds["b00l00"].intensity, [1.0, 2.0, 0.5])
    cos = np.cos(np.deg2rad([0.0, 15.0, 45.0, 70.0, 120.0]))
    np.testing.assert_allclose(back.attenuation(cos), [1.0, 0.75, 0.25, 0.0, 0.0], atol=1e-12)
    assert back.gain == 50.0


def test_measured_regions_render_like_the_analytic_model_they_tabulate():
    """A region material given Blinn-Phong as a function of Rusinkiewicz angles renders what the
    analytic Blinn-Phong material renders (same angles, same cos(theta_l) factor), and its regions
    split the frame where ``region_at`` says."""
    from abs.lightstage.render import AnalyticMaterial, MeasuredRegions, render_view

    geometry, tracer, _, _ = _plane_rig(32, 24)
    view = pose_view(geometry, tracer, 0, 20.0)
    kd, ks, e = np.array([0.2, 0.4, 0.6]), 0.5, 30.0

    def blinn_phong(theta_h, theta_d, phi_d):
        return kd / np.pi + ks * (e + 8) / (8 * np.pi) * np.cos(theta_h)[:, None] ** e

    analytic = AnalyticMaterial("blinn_phong", lambda p: np.broadcast_to(
        np.stack([kd, np.full(3, ks), np.full(3, e)], 1)[None], (len(p), 3, 3)))
    both = MeasuredRegions(lambda p: (p[:, 0] > 0).astype(int),
                           (blinn_phong, lambda th, td, pd: np.zeros((len(th), 3))))
    a = render_view(geometry, tracer, view, "b00l00", 255, 0.01, analytic)
    b = render_view(geometry, tracer, view, "b00l00", 255, 0.01, both)
    x = view.hits.point[:, 0]
    flat_a, flat_b = a.reshape(-1, 3)[view.pixel], b.reshape(-1, 3)[view.pixel]
    assert flat_a[x <= 0].max() > 0.05  # lit, and not clipped everywhere
    np.testing.assert_allclose(flat_b[x <= 0], flat_a[x <= 0], rtol=1e-9, atol=1e-12)
    assert np.all(flat_b[x > 0] == 0.0)


def test_brdf_pca_coefficients_come_back_from_rendered_frames():
    """Frames rendered from known per-point brdf_pca coefficients (a 2-component basis: overall
    level, and a lobe in theta_h), measured and fitted per point, give the coefficients back: the
    round trip through irradiance division, normalisation and the MERL entry lookup."""
    from abs.brdf.basis import BRDFBasis
    from abs.io.merl import MERL_SHAPE, MERL_SIZE
    from abs.lightstage.pcafit import PcaFits, fit_pca_points, pca_reflectance
    from abs.lightstage.render import render_view

    theta_h = (np.arange(90) / 90.0) ** 2 * (np.pi / 2)
    lobe = np.broadcast_to(np.exp(-(theta_h / 0.2) ** 2)[None, :, None, None], MERL_SHAPE).reshape(-1)
    basis = BRDFBasis(mean=np.zeros(MERL_SIZE, np.float32),
                      components=np.stack([np.ones(MERL_SIZE), 3.0 * lobe]).astype(np.float32),
                      median=np.full(MERL_SIZE, 0.3 / np.pi, np.float32), epsilon=1e-3)
    geometry, tracer, verts, faces = _plane_rig(32, 24)
    points = build_surface_points(verts, faces, 0.2)  # a few points on the 40 cm square
    truth = np.stack([np.linspace(-0.3, 0.3, len(points)), np.linspace(0.8, 0.2, len(points))], 1)
    reflectance = pca_reflectance(basis, PcaFits(truth, np.ones(len(points), int)), points)
    groups, images = [], []
    for p, angle in enumerate(np.linspace(-40.0, 40.0, 9)):
        view = pose_view(geometry, tracer, 0, angle)
        groups.append(LightGroup(p, angle, "b00l00", 255, (), (1.0,)))
        images.append(render_view(geometry, tracer, view, "b00l00", 255, 1e-3, reflectance) / 1e-3)
    assert max(float(im.max()) for im in images) < 0.98e3  # nothing clipped
    meas = measure(geometry, tracer, points, groups, images, holdout_every=0)
    fits = fit_pca_points(basis, meas, len(points), eta=1e-6)  # noise-free: next to no prior
    fitted = fits.count > 0
    assert fitted.sum() >= len(points) // 2
    np.testing.assert_allclose(fits.coefficients[fitted], truth[fitted], atol=1e-3)
