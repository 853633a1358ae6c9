"""Markers in stereo photographs (abs/reassembly/circles.py, epipolar.py, triangulation.py,
stereo_markers.py, through_glass.py; ``abs reassemble markers|pipeline``).

The truth: markers (spheres of radius 1.5 mm) at known world positions, seen by two calibrated
cameras; the photographs are their exact perspective silhouettes drawn by
:func:`abs.reassembly.marker_images.marker_image` on a textured, noisy ground (not a Mitsuba
rendering). Seconds each."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from abs.camera.pinhole import intrinsics_from_fov, look_at, project
from abs.errors import InputError
from abs.reassembly.circles import detect_circles
from abs.reassembly.epipolar import fundamental_matrix, match_epipolar, sampson_distance_px
from abs.reassembly.marker_images import marker_image
from abs.reassembly.phantom import random_directions
from abs.reassembly.placement import place
from abs.reassembly.stereo_markers import MarkerImage, locate_markers
from abs.reassembly.through_glass import seen_through_glass
from abs.reassembly.triangulation import cluster_points

RADIUS = 1.5e-3
GLASS_R = 0.04  # the glass sphere of scenes/default/sphere.ply, metres
R0 = Rotation.from_rotvec([0.3, 1.0, -0.2]).as_matrix()  # object -> world, the truth
T0 = np.array([0.01, 0.04, -0.02])
EYES = ([0.12, 0.25, 0.45], [-0.15, 0.3, 0.42])
# seed 1: in both views the nearest two markers are 51 px apart at 960 px (radius 6 px)
CT = random_directions(7, np.random.default_rng(1), 0.5) * (GLASS_R + 0.5 * RADIUS)
WORLD = CT @ R0.T + T0
CAMS = [look_at(eye, T0) for eye in EYES]


def _K(width):
    return intrinsics_from_fov(width, width * 3 // 4, np.radians(20))


def _images(width, world=WORLD, cams=CAMS):
    K = _K(width)
    out = []
    for n, (R, t) in enumerate(cams):
        pixels = marker_image(K, R, t, width, width * 3 // 4, world, RADIUS, seed=n)
        out.append(MarkerImage(f"cam{n}", f"cam{n}.exr", K, R, t, detect_circles(pixels)))
    return out


@pytest.fixture(scope="module")
def images960():
    return _images(960)


# --- detection ------------------------------------------------------------------------------------

@pytest.mark.parametrize("width", [960, 2880])
def test_detection_finds_every_marker_at_two_image_sizes(width, images960):
    """Radius about 6 px at 960 px and 18 px at 2880 px: every marker, nothing else, and the
    centre within 0.3 px of the projected sphere centre."""
    images = images960 if width == 960 else _images(width)
    for m in images:
        truth = project(m.K, m.R, m.t, WORLD)
        assert len(m.circles) == len(WORLD), (width, m.name, m.circles.centres_px)
        d = np.linalg.norm(m.circles.centres_px[:, None] - truth[None], axis=2)
        assert sorted(np.argmin(d, axis=1)) == list(range(len(WORLD)))
        assert d.min(axis=1).max() < 0.3, d.min(axis=1)
        expected_r = m.K[0, 0] * RADIUS / np.linalg.norm(WORLD - (-m.R.T @ m.t), axis=1)
        np.testing.assert_allclose(np.sort(m.circles.radii_px), np.sort(expected_r), rtol=0.1)


def test_detection_ignores_light_discs_and_texture():
    K, (R, t) = _K(960), CAMS[0]
    pixels = marker_image(K, R, t, 960, 720, WORLD, RADIUS, texture=0.2, seed=3)
    light = pixels.copy()
    light[70:131, 70:131] = 0.05  # a dark square with a bright disc in it
    cv2.circle(light, (100, 100), 12, 1.0, -1)
    found = detect_circles(light)
    assert len(found) == len(WORLD)
    assert np.min(np.linalg.norm(found.centres_px - [100, 100], axis=1)) > 20
    bright = detect_circles(light, polarity="light")
    assert len(bright) == 1 and np.allclose(bright.centres_px, [100, 100], atol=0.3)


# --- epipolar geometry ----------------------------------------------------------------------------

def test_fundamental_matrix_from_the_cameras():
    """F from K, R, t agrees with OpenCV's 8-point estimate from projected points, and the
    Sampson distance is zero for true pairs and grows with the distance from the epipolar line."""
    K = _K(960)
    (R1, t1), (R2, t2) = CAMS
    F = fundamental_matrix(K, R1, t1, K, R2, t2)
    X = np.random.default_rng(0).uniform(-0.05, 0.05, (40, 3)) + T0
    x1, x2 = project(K, R1, t1, X), project(K, R2, t2, X)
    F8, _ = cv2.findFundamentalMat(x1, x2, cv2.FM_8POINT)
    F8 = F8 / np.linalg.norm(F8)
    assert min(np.abs(F - F8).max(), np.abs(F + F8).max()) < 1e-6
    d = sampson_distance_px(F, x1, x2)
    assert np.abs(np.diag(d)).max() < 1e-6
    # move x2 by 2 px across its epipolar line: the Sampson distance is about 2 / sqrt(2)
    line = np.column_stack([x1, np.ones(len(x1))]) @ F.T
    normal = line[:, :2] / np.linalg.norm(line[:, :2], axis=1, keepdims=True)
    moved = np.diag(sampson_distance_px(F, x1, x2 + 2 * normal))
    assert np.all((moved > 1.2) & (moved < 2.1)), moved


def test_ambiguous_match_on_one_epipolar_line_is_reported_not_guessed():
    """Two cameras side by side (epipolar lines are image rows): two markers at the same
    height and depth give one left detection two right candidates on its line."""
    K = _K(960)
    R = np.eye(3)
    cams = [(R, np.array([0.03, 0, 0.5])), (R, np.array([-0.03, 0, 0.5]))]
    x1 = project(K, *cams[0], np.array([[0.0, 0.0, 0.0], [0.05, 0.03, 0.0]]))
    x2 = project(K, *cams[1], np.array([[0.0, 0.0, 0.0], [0.05, 0.03, 0.0]]))
    # a third detection on the right, on the first marker's row
    x2 = np.vstack([x2, x2[0] + [40.0, 0.0]])
    m = match_epipolar(x1, x2, fundamental_matrix(K, *cams[0], K, *cams[1]), 1.5)
    assert {"left": 0, "right": [0, 2]} in m.ambiguous
    assert m.pairs.tolist() == [[1, 1]]  # only the sure one


def test_ambiguity_in_images_is_reported_and_left_out():
    """Real images with the side-by-side cameras: the detections on a shared row are left out
    and reported; the others are triangulated."""
    R = np.eye(3)
    cams = [(R, np.array([0.03, 0.0, 0.5])), (R, np.array([-0.03, 0.0, 0.5]))]
    world = np.array([[0.0, 0.0, 0.0], [0.02, 0.0, 0.0],  # same row in both images
                      [-0.02, 0.02, 0.01], [0.01, -0.025, 0.0], [0.03, 0.03, -0.01]])
    images = _images(960, world, cams)
    result = locate_markers(images)
    left = sorted(a["left"] for a in result.ambiguous if isinstance(a["left"], int))
    assert len(left) == 2, result.ambiguous
    # the ambiguous left detections are the two markers on the shared row
    shared = project(images[0].K, *cams[0], world[:2])
    d = np.linalg.norm(images[0].circles.centres_px[left][:, None] - shared[None], axis=2)
    assert d.min(axis=1).max() < 0.3
    assert len(result.points_m) == 3
    d = np.linalg.norm(result.points_m[:, None] - world[None], axis=2)
    assert set(np.argmin(d, axis=1)) == {2, 3, 4} and d.min(axis=1).max() < 2e-4


# --- triangulation and placement -----------------------------------------------------------------

def test_triangulated_markers_match_the_truth(images960):
    result = locate_markers(images960)
    assert len(result.points_m) == len(WORLD) and not result.ambiguous
    d = np.linalg.norm(result.points_m[:, None] - WORLD[None], axis=2)
    assert sorted(np.argmin(d, axis=1)) == list(range(len(WORLD)))
    assert d.min(axis=1).max() < 0.15e-3, d.min(axis=1)
    assert result.error_px.max() < 0.2


def test_clustering_keeps_the_best_point_and_drops_outliers():
    rng = np.random.default_rng(0)
    a, b = np.array([0.0, 0.0, 0.0]), np.array([0.01, 0.0, 0.0])
    points = np.vstack([a + rng.normal(0, 1e-5, (2, 3)),
                        a + [0.0, 0.0, 0.0004],  # links the outlier below to a's cluster
                        b + rng.normal(0, 1e-5, (2, 3)),
                        a + [0.0, 0.0, 0.0008]])  # 0.6 mm from the cluster's median: an outlier
    errors = np.array([0.3, 0.2, 0.5, 0.4, 0.1, 0.01])  # the outlier has the lowest error
    clusters = cluster_points(points, errors, merge_m=1e-3, outlier_m=0.3e-3)
    assert len(clusters) == 2
    first = clusters[0]
    assert first.index == 1 and first.outliers.tolist() == [5]
    assert clusters[1].index == 4


def test_placement_from_the_images_recovers_the_transform(images960):
    result = locate_markers(images960)
    placed = place(result.points_m, CT)
    rot_err_deg = np.degrees(Rotation.from_matrix(placed.R @ R0.T).magnitude())
    t_err_mm = np.linalg.norm(placed.t - T0) * 1e3
    assert placed.mean_distance_mm < 0.1, placed.residuals_mm
    assert rot_err_deg < 0.05 and t_err_mm < 0.1, (rot_err_deg, t_err_mm)


# --- bad inputs -------------------------------------------------------------------------------------

def test_fewer_than_three_markers_is_an_error_naming_the_images():
    images = _images(960, WORLD[:2])
    with pytest.raises(InputError, match="fewer than 3 matched markers") as exc:
        locate_markers(images)
    assert "cam0.exr" in str(exc.value) and "cam1.exr" in str(exc.value)


def test_ray_through_glass():
    glass = trimesh.creation.icosphere(4, radius=GLASS_R)
    eye = np.array([[0.0, 0.0, 0.5]])
    points = np.array([[0.0, 0.0, GLASS_R + 0.75e-3],  # near side: seen directly
                       [0.0, 0.0, -GLASS_R - 0.75e-3],  # far side: through the glass
                       [0.06, 0.0, 0.0],  # beside the glass
                       [0.0, GLASS_R + 0.75e-3, 0.0]])  # on top, the ray grazes the glass
    flags = seen_through_glass(points, eye, glass)[:, 0]
    assert flags.tolist() == [False, True, False, False]


def test_markers_seen_through_glass_are_left_out(images960):
    glass = trimesh.creation.icosphere(4, radius=GLASS_R).apply_translation(T0)
    result = locate_markers(images960, glass=glass, min_markers=0)
    eyes = np.array([-R.T @ t for R, t in CAMS])
    # the truth, analytically: the segment from a camera to a marker passes within GLASS_R of
    # the sphere's centre (before the marker itself)
    behind = np.zeros(len(WORLD), bool)
    for eye in eyes:
        d = (WORLD - eye) / np.linalg.norm(WORLD - eye, axis=1, keepdims=True)
        s = d @ (T0 - eye)
        closest = np.linalg.norm(eye + s[:, None] * d - T0, axis=1)
        behind |= (closest < GLASS_R) & (s < np.linalg.norm(WORLD - eye, axis=1))
    assert behind.any() and not behind.all()
    assert len(result.through_glass) == behind.sum()
    kept = np.argmin(np.linalg.norm(result.points_m[:, None] - WORLD[None], axis=2), axis=1)
    assert sorted(kept) == np.flatnonzero(~behind).tolist()
    # two markers in plain view and the ones behind the glass: fewer than 3 left, and the error
    # says why
    few = np.vstack([WORLD[~behind][:2], WORLD[behind]])
    with pytest.raises(InputError, match="fewer than 3 matched markers.*seen through glass"):
        locate_markers(_images(960, few), glass=glass)


# --- commands -----------------------------------------------------------------------------------

def _capture(tmp_path, world, width=960, cams=CAMS):
    from abs.io.capture import save_capture

    K = _K(width)
    views, pixels = [], {}
    for n, (R, t) in enumerate(cams):
        grey = marker_image(K, R, t, width, width * 3 // 4, world, RADIUS, seed=n)
        pixels[f"cam{n}"] = np.repeat(grey[..., None], 3, axis=2)
        views.append({"name": f"cam{n}", "K": K, "R": R, "t": t})
    save_capture(tmp_path / "capture", views, pixels)
    return tmp_path / "capture"


def test_reassemble_markers_command(tmp_path, capsys):
    from abs.cli.main import main

    folder = _capture(tmp_path, WORLD)
    out = tmp_path / "markers_world.json"
    argv = ["reassemble", "markers", str(folder / "cam0.exr"), str(folder / "cam1.exr"),
            "--cameras", str(folder / "cameras.json"), "--left-camera", "cam0",
            "--right-camera", "cam1", "--out", str(out)]
    assert main(argv) == 0
    data = json.loads(out.read_text())
    points = np.array(data["points_m"])
    assert points.shape == WORLD.shape and len(data["reprojection_error_px"]) == len(points)
    assert np.linalg.norm(points[:, None] - WORLD[None], axis=2).min(axis=1).max() < 0.15e-3
    # unknown camera, and a photograph of another size than the calibration
    assert main(argv[:7] + ["nope"] + argv[8:]) == 2
    assert "no view named 'nope'" in capsys.readouterr().err
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), np.full((30, 40, 3), 200, np.uint8))
    assert main(argv[:2] + [str(small)] + argv[3:]) == 2
    assert "calibrated at 960x720" in capsys.readouterr().err
    # two markers only: the error names the photographs
    few = _capture(tmp_path / "few", WORLD[:2])
    assert main(["reassemble", "markers", str(few / "cam0.exr"), str(few / "cam1.exr"),
                 "--cameras", str(few), "--left-camera", "cam0", "--right-camera", "cam1",
                 "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "fewer than 3 matched markers" in err and "cam0.exr" in err


def test_reassemble_pipeline(tmp_path, capsys):
    """Volume + photographs -> placed object -> deformed cloth, end to end: the CT phantom's
    markers placed by a known transform, photographed, and the pipeline's to_world compared with
    it."""
    from abs.cli.main import main
    from abs.reassembly.phantom import make_phantom
    from abs.reassembly.volume import write_raw_volume
    from abs.scene import load_scene

    phantom = make_phantom(0.5, n_markers=6, seed=3)
    ct = phantom.marker_centres_mm * 1e-3
    centre = phantom.glass_centre_mm * 1e-3
    # turn the markers towards the cameras (those on the far side are seen through the glass
    # and left out), then about that direction by a further 0.7 rad
    towards = np.array([0.0, 0.21, 0.29])
    facing, _ = Rotation.align_vectors([towards], [(ct - centre).mean(axis=0)])
    R = (Rotation.from_rotvec(0.7 * towards / np.linalg.norm(towards)) * facing).as_matrix()
    t = np.array([0.0, 0.007, 0.0]) - R @ centre  # the 8 mm sphere sunk 1 mm into the cloth
    world = ct @ R.T + t
    target = t + 0
    cams = [look_at(target + [0.1, 0.2, 0.3], target), look_at(target + [-0.12, 0.22, 0.28], target)]
    folder = _capture(tmp_path, world, 1280, cams)
    header = write_raw_volume(tmp_path / "ct" / "volume.json", phantom.volume)
    out = tmp_path / "placed" / "scene.toml"
    assert main(["reassemble", "pipeline", str(header), "--left", str(folder / "cam0.exr"),
                 "--right", str(folder / "cam1.exr"), "--cameras", str(folder),
                 "--left-camera", "cam0", "--right-camera", "cam1",
                 "--scene", "scenes/default/scene.toml", "--object", "vase", "--material", "glass",
                 "--rounds", "0", "--soft", "cloth", "--max-edge", "4",
                 "--out", str(out)]) == 0, capsys.readouterr().err
    placed = load_scene(out).object("vase")
    rot_err_deg = np.degrees(Rotation.from_matrix(placed.to_world[:3, :3] @ R.T).magnitude())
    assert rot_err_deg < 1.0, rot_err_deg
    assert np.linalg.norm(placed.to_world[:3, 3] - t) < 0.3e-3
    work = tmp_path / "placed" / "reassembly"
    checked = json.loads((work / "markers_world_checked.json").read_text())
    # the far-side markers were found, then left out as seen through the placed glass
    assert len(checked["through_glass"]) >= 1
    assert len(checked["points_m"]) + len(checked["through_glass"]) == len(ct)
    cloth = load_scene(out).object("cloth")
    assert cloth.mesh.name == "cloth_deformed.ply"
    assert trimesh.load(cloth.mesh, process=False).vertices[:, 1].min() < -0.0009
    report = json.loads((tmp_path / "placed" / "scene_placement.json").read_text())
    assert report["mean_distance_mm"] < 0.3
