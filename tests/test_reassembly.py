"""Reassembly (abs/reassembly, docs/reassembly.md): volume files, meshing of a synthetic CT
phantom with known truth, marker placement, soft deformation and the ``abs reassemble`` command.

All volumes are small (0.5 mm voxels, a 16 mm glass sphere): seconds each."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from abs.errors import InputError
from abs.reassembly.cleaning import (boundary_loops, carve_spheres, decimate, fill_holes,
                                     sqrt3_subdivide)
from abs.reassembly.deform import deform_soft, refine
from abs.reassembly.meshing import MeshingSettings, mesh_volume, read_markers, write_meshing
from abs.reassembly.phantom import make_phantom
from abs.reassembly.placement import kabsch, match_markers, place
from abs.reassembly.spheres import fit_sphere
from abs.reassembly.volume import (Volume, read_raw_volume, read_slices, read_volume,
                                   write_raw_volume, write_slices)

VOXEL = 0.5


@pytest.fixture(scope="module")
def phantom():
    return make_phantom(VOXEL, n_markers=6, seed=3)


@pytest.fixture(scope="module")
def meshed(phantom):
    return mesh_volume(phantom.volume, MeshingSettings(min_faces=2000, rounds=4))


def _nearest(truth: np.ndarray, found: np.ndarray) -> np.ndarray:
    """Index of the true marker nearest each found one."""
    return np.argmin(np.linalg.norm(found[:, None] - truth[None], axis=2), axis=1)


# --- volume files -------------------------------------------------------------------------------

def test_raw_volume_round_trip(tmp_path):
    data = np.arange(2 * 3 * 4, dtype=np.uint16).reshape(2, 3, 4) * 1000
    header = write_raw_volume(tmp_path / "v.json", Volume(data, [0.2, 0.3, 0.4]))
    assert (tmp_path / "v.raw").stat().st_size == data.nbytes
    meta = json.loads(header.read_text())
    assert meta["shape"] == [2, 3, 4] and meta["byte_order"] == "little"
    back = read_volume(header)
    np.testing.assert_array_equal(back.data, data)
    np.testing.assert_allclose(back.voxel_size_mm, [0.2, 0.3, 0.4])
    # voxel [k, j, i] sits at (i sx, j sy, k sz)
    np.testing.assert_allclose(back.index_to_mm([1, 2, 3]), [0.6, 0.6, 0.4])


def test_big_endian_raw_volume(tmp_path):
    data = np.array([[[1, 258]]], dtype=np.uint16)
    data.astype(">u2").tofile(tmp_path / "b.raw")
    (tmp_path / "b.json").write_text(json.dumps({"file": "b.raw", "shape": [1, 1, 2], "dtype": "uint16",
                                                 "voxel_size_mm": 1, "byte_order": "big"}))
    np.testing.assert_array_equal(read_raw_volume(tmp_path / "b.json").data, data)


@pytest.mark.parametrize("change, field, words", [
    ({"dtype": "complex64"}, "dtype", "expected one of"),
    ({"shape": [2, 3]}, "shape", "3 positive integers"),
    ({"shape": [2, 3, 5]}, "file", "needs"),  # size mismatch
    ({"voxel_size_mm": -1}, "voxel_size_mm", "positive"),
    ({"file": "missing.raw"}, "file", "not found"),
    ({"byte_order": "middle"}, "byte_order", "little"),
])
def test_bad_header(tmp_path, change, field, words):
    write_raw_volume(tmp_path / "v.json", Volume(np.zeros((2, 3, 4), np.uint16), 0.5))
    meta = json.loads((tmp_path / "v.json").read_text())
    meta.update(change)
    (tmp_path / "v.json").write_text(json.dumps(meta))
    with pytest.raises(InputError) as exc:
        read_raw_volume(tmp_path / "v.json")
    assert exc.value.field == field and words in exc.value.message
    assert str(tmp_path / "v.json") in str(exc.value)


def test_missing_and_malformed_headers(tmp_path):
    with pytest.raises(InputError, match="not found"):
        read_volume(tmp_path / "nothing.json")
    (tmp_path / "h.json").write_text("{not json")
    with pytest.raises(InputError, match="h.json: not valid JSON"):
        read_raw_volume(tmp_path / "h.json")
    (tmp_path / "h.json").write_text(json.dumps({"file": "x.raw", "shape": [1, 1, 1], "dtype": "uint16"}))
    with pytest.raises(InputError) as exc:
        read_raw_volume(tmp_path / "h.json")
    assert exc.value.field == "voxel_size_mm" and exc.value.message == "missing"


@pytest.mark.parametrize("suffix", [".tif", ".png"])
def test_slice_stack_round_trip(tmp_path, suffix):
    data = (np.random.default_rng(0).integers(0, 65535, (3, 5, 7))).astype(np.uint16)
    write_slices(tmp_path / "s", Volume(data, 0.25), suffix)
    back = read_volume(tmp_path / "s", 0.25)
    assert back.data.dtype == np.uint16
    np.testing.assert_array_equal(back.data, data)


def test_slice_errors(tmp_path):
    with pytest.raises(InputError, match="needs the voxel size"):
        (tmp_path / "s").mkdir()
        read_volume(tmp_path / "s")
    with pytest.raises(InputError, match="no slice images"):
        read_slices(tmp_path / "s", 0.5)
    import tifffile

    tifffile.imwrite(tmp_path / "s" / "a.tif", np.zeros((4, 4), np.uint16))
    tifffile.imwrite(tmp_path / "s" / "b.tif", np.zeros((4, 5), np.uint16))
    with pytest.raises(InputError, match="the first slice"):
        read_slices(tmp_path / "s", 0.5)
    tifffile.imwrite(tmp_path / "s" / "b.tif", np.zeros((4, 4, 3), np.uint16))
    with pytest.raises(InputError, match="single-channel"):
        read_slices(tmp_path / "s", 0.5)
    with pytest.raises(InputError, match="not found"):
        read_slices([tmp_path / "s" / "a.tif", tmp_path / "none.tif"], 0.5)


# --- the phantom ----------------------------------------------------------------------------------

def test_no_single_threshold_separates_glass_from_markers(phantom):
    """Streaks lift glass beside a marker above the marker threshold and air beside a marker
    above the glass threshold."""
    from abs.reassembly.surfaces import auto_thresholds

    th = auto_thresholds(phantom.volume)
    data = phantom.volume.data.astype(float)
    k, j, i = np.indices(data.shape)
    pts = np.stack([i, j, k], -1) * VOXEL
    d_markers = np.min([np.linalg.norm(pts - c, axis=-1) - r
                        for c, r in zip(phantom.marker_centres_mm, phantom.marker_radii_mm)], axis=0)
    d_glass = np.linalg.norm(pts - phantom.glass_centre_mm, axis=-1) - phantom.glass_radius_mm
    outside_markers = d_markers > 0.5 * VOXEL  # no marker in the voxel (partial volume included)
    assert np.any(data[outside_markers & (d_glass < -0.5 * VOXEL)] > th.marker)  # glass above marker level
    assert np.any(data[outside_markers & (d_glass > 0.5 * VOXEL)] > th.glass)  # air above glass level


# --- meshing ------------------------------------------------------------------------------------

def test_meshing_recovers_markers(phantom, meshed):
    assert len(meshed.markers) == len(phantom.marker_centres_mm)
    found = meshed.centres_mm
    idx = _nearest(phantom.marker_centres_mm, found)
    assert len(set(idx)) == len(idx)
    centre_err = np.linalg.norm(found - phantom.marker_centres_mm[idx], axis=1)
    radius_err = np.abs(meshed.radii_mm - phantom.marker_radii_mm[idx])
    assert centre_err.max() < 0.3 * VOXEL, centre_err
    assert radius_err.max() < 0.3 * VOXEL, radius_err


def test_glass_mesh_is_close_to_the_true_surface(phantom, meshed):
    glass = meshed.glass
    assert glass.is_watertight and glass.is_winding_consistent and glass.volume > 0
    pts, _ = trimesh.sample.sample_surface(glass, 20000, seed=0)
    d = phantom.glass_distance_mm(pts)
    assert d.mean() < 0.5 * VOXEL, d.mean()
    assert np.percentile(d, 95) < 1.0 * VOXEL, np.percentile(d, 95)
    # the markers are gone: no surface beyond the glass sphere where they were
    assert np.linalg.norm(glass.vertices - phantom.glass_centre_mm, axis=1).max() < \
        phantom.glass_radius_mm + phantom.marker_radii_mm.max()


def test_meshing_of_a_thin_walled_mesh_phantom():
    """A glass tube with 3 mm walls (a mesh phantom, as the bowl of scenes/default): markers
    found, the cleaned mesh closed and near the true surface."""
    from abs.reassembly.phantom import mesh_distance

    tube = trimesh.creation.annulus(r_min=6, r_max=9, height=8, sections=64)
    probe = np.array([[0.0, 0.0, 0.0], [7.5, 0.0, 0.0], [12.0, 0.0, 0.0], [0.0, 9.0, 2.0]])
    np.testing.assert_allclose(mesh_distance(tube, probe), [6.0, -1.5, 3.0, 0.0], atol=0.05)
    phantom = make_phantom(VOXEL, glass_mesh_mm=tube, n_markers=5, marker_gap_mm=6, seed=0)
    result = mesh_volume(phantom.volume, MeshingSettings(rounds=1))
    assert len(result.markers) == 5
    idx = _nearest(phantom.marker_centres_mm, result.centres_mm)
    assert len(set(idx)) == 5
    assert np.linalg.norm(result.centres_mm - phantom.marker_centres_mm[idx], axis=1).max() < 0.3 * VOXEL
    assert result.glass.is_watertight
    pts, _ = trimesh.sample.sample_surface(result.glass, 20000, seed=0)
    d = phantom.glass_distance_mm(pts)
    assert d.mean() < 0.5 * VOXEL and np.percentile(d, 95) < 1.0 * VOXEL, (d.mean(), np.percentile(d, 95))


def test_volume_without_markers_is_refused():
    plain = make_phantom(VOXEL, n_markers=0 + 1, marker=0.0, streak=0.0, seed=1)
    with pytest.raises(InputError, match="no markers"):
        mesh_volume(plain.volume)


def test_dense_block_beside_the_markers(phantom):
    """A dense plate (a clamp, a label) beside the object: every marker is still found, and the
    spheres RANSAC may fit to the plate's rounded corners (2 to 3 voxels across, as small as the
    markers) are left unpaired by the placement. (Thresholds by hand: a plate this large would
    be taken for the glass by the histogram.)"""
    settings = MeshingSettings(glass_threshold=700, marker_threshold=2700, rounds=0)
    data = phantom.volume.data.copy()
    data[1:3, 5:25, 5:25] = 4200  # 1 x 10 x 10 mm, below the glass
    found = mesh_volume(Volume(data, VOXEL), settings).centres_mm
    d = np.linalg.norm(found[:, None] - phantom.marker_centres_mm[None], axis=2)
    assert np.all(d.min(axis=0) < 0.3 * VOXEL)  # every true marker found
    measured, order, R, t = _scene_markers(phantom.marker_centres_mm * 1e-3, 0.05e-3, seed=2)
    result = place(measured, found * 1e-3)
    assert len(result.pairs) == len(measured)
    np.testing.assert_array_equal(d.argmin(axis=1)[result.pairs[:, 1]], order[result.pairs[:, 0]])


def test_no_sphere_in_the_radius_range_is_refused(phantom):
    with pytest.raises(InputError, match="no markers: no sphere of radius 3 to 5 mm"):
        mesh_volume(phantom.volume, MeshingSettings(marker_radius_mm=(3.0, 5.0)))


def test_marker_threshold_above_every_voxel_is_refused(phantom):
    with pytest.raises(InputError, match="no markers"):
        mesh_volume(phantom.volume, MeshingSettings(glass_threshold=600, marker_threshold=60000))


def test_write_and_read_markers(tmp_path, meshed):
    path = write_meshing(meshed, tmp_path)
    centres, radii = read_markers(tmp_path)
    np.testing.assert_allclose(centres, meshed.centres_mm)
    glass = trimesh.load(tmp_path / "glass.ply", process=False)
    np.testing.assert_allclose(glass.bounds, meshed.glass.bounds * 1e-3, atol=1e-9)
    assert json.loads(path.read_text())["glass_mesh_unit"] == "m"


# --- mesh cleaning ------------------------------------------------------------------------------

def test_sphere_fit_is_exact_on_a_sphere():
    d = np.random.default_rng(0).normal(size=(50, 3))
    pts = 2.5 * d / np.linalg.norm(d, axis=1, keepdims=True) + [1, 2, 3]
    c, r, rms = fit_sphere(pts)
    np.testing.assert_allclose(c, [1, 2, 3], atol=1e-9)
    assert abs(r - 2.5) < 1e-9 and rms < 1e-9


def test_carve_fill_decimate_sqrt3():
    s = trimesh.creation.icosphere(3, radius=10.0)
    carved = carve_spheres(s, [[10, 0, 0], [0, 10, 0]], [1.5, 1.5], epsilon=0.5)
    assert len(boundary_loops(carved)) == 2
    closed = fill_holes(carved)
    assert closed.is_watertight and closed.is_winding_consistent and closed.volume > 0
    sub = sqrt3_subdivide(closed)
    assert len(sub.faces) == 3 * len(closed.faces)
    assert sub.is_watertight and sub.is_winding_consistent
    # √3 relaxes vertices toward the limit surface: it stays close to the sphere
    assert np.abs(np.linalg.norm(sub.vertices, axis=1) - 10).max() < 0.3
    dec = decimate(sub, 0.33)
    assert abs(len(dec.faces) - 0.33 * len(sub.faces)) <= 4 and dec.is_watertight


def test_repair_closes_a_pinched_mesh():
    """Two closed boxes sharing an edge (4 faces on it) and a duplicated face: repaired into one
    closed piece."""
    from abs.reassembly.cleaning import repair_closed

    a = trimesh.creation.box(extents=[1, 1, 1])
    b = trimesh.creation.box(extents=[1, 1, 1])
    b.apply_translation([1, 1, 0])  # touches a along the edge x = y = 0.5
    pinched = trimesh.util.concatenate([a, b])
    pinched.merge_vertices()
    pinched = trimesh.Trimesh(pinched.vertices, np.vstack([pinched.faces, pinched.faces[:1]]), process=False)
    assert not pinched.is_watertight
    fixed = repair_closed(pinched)
    assert fixed.is_watertight and fixed.is_winding_consistent and fixed.volume > 0


# --- placement ------------------------------------------------------------------------------------

def _scene_markers(ct_m, noise_m, seed=0, drop=0):
    rng = np.random.default_rng(seed)
    R = Rotation.random(random_state=seed).as_matrix()
    t = np.array([0.02, 0.04, -0.01])
    measured = ct_m @ R.T + t + rng.normal(0, noise_m, ct_m.shape)
    order = rng.permutation(len(ct_m))[: len(ct_m) - drop]
    return measured[order], order, R, t


def test_placement_recovers_a_rigid_transform(phantom):
    ct = phantom.marker_centres_mm * 1e-3
    measured, order, R, t = _scene_markers(ct, 0.1e-3, seed=4, drop=1)
    result = place(measured, ct)
    np.testing.assert_array_equal(result.pairs[:, 1], order[result.pairs[:, 0]])
    assert len(result.pairs) == len(measured)
    assert np.isclose(np.linalg.det(result.R), 1)
    rot_err_deg = np.degrees(Rotation.from_matrix(result.R @ R.T).magnitude())
    t_err_mm = np.linalg.norm(result.t - t) * 1e3
    assert result.mean_distance_mm < 0.3, result.residuals_mm
    assert rot_err_deg < 1.5 and t_err_mm < 0.3, (rot_err_deg, t_err_mm)
    np.testing.assert_allclose(result.to_world[:3, :3], result.R)


def test_placement_with_pairs_given_by_hand(phantom):
    ct = phantom.marker_centres_mm * 1e-3
    measured, order, R, t = _scene_markers(ct, 0.0, seed=5)
    pairs = [(i, int(order[i])) for i in range(3)]
    result = place(measured, ct, pairs)
    np.testing.assert_allclose(result.R, R, atol=1e-9)
    np.testing.assert_allclose(result.t, t, atol=1e-9)
    with pytest.raises(InputError, match="at least 3"):
        place(measured, ct, pairs[:2])
    with pytest.raises(InputError, match="paired twice"):
        place(measured, ct, [(0, 1), (1, 1), (2, 2)])


def test_kabsch_never_reflects():
    pts = np.random.default_rng(1).normal(size=(6, 3))
    mirrored = pts * [-1, 1, 1]
    R, _ = kabsch(pts, mirrored)
    assert np.isclose(np.linalg.det(R), 1)


def test_fewer_than_three_markers_is_refused(phantom):
    ct = phantom.marker_centres_mm * 1e-3
    measured, *_ = _scene_markers(ct, 0.0, drop=len(ct) - 2)
    with pytest.raises(InputError, match="at least 3 markers"):
        place(measured, ct)
    # three measured points that match no three CT markers
    with pytest.raises(InputError, match="fewer than 3 matched markers"):
        match_markers(np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.2, 0]]), ct)


def test_mirrored_volume_is_refused_not_placed():
    """Slices stored in the opposite order mirror the object: no rigid transform pairs all the
    measured markers, and placement says so instead of placing a subset."""
    for seed in range(4):
        ct = make_phantom(VOXEL, n_markers=7, seed=seed).marker_centres_mm * 1e-3
        R = Rotation.random(random_state=seed).as_matrix()
        measured = (ct * [-1, 1, 1]) @ R.T + [0, 0.04, 0]
        with pytest.raises(InputError, match="mirrored|ambiguous"):
            place(measured, ct)


def test_unpaired_measured_markers_can_be_allowed(phantom):
    ct = phantom.marker_centres_mm * 1e-3
    measured, order, R, t = _scene_markers(ct, 0.05e-3, seed=6)
    extra = np.vstack([measured, [0.5, 0.5, 0.5]])  # a false detection far away
    with pytest.raises(InputError, match=f"measured marker\\(s\\) {len(measured)} match no CT marker"):
        place(extra, ct)
    result = place(extra, ct, allow_unpaired=True)
    assert len(result.pairs) == len(measured)


def test_symmetric_layout_is_refused_not_guessed():
    square = np.array([[0, 0, 0], [0.01, 0, 0], [0.01, 0.01, 0], [0, 0.01, 0]])
    with pytest.raises(InputError, match="ambiguous"):
        match_markers(square + 0.05, square)


# --- soft deformation ---------------------------------------------------------------------------

def _inside_convex(mesh: trimesh.Trimesh, points: np.ndarray) -> np.ndarray:
    lo, hi = mesh.bounds
    points = points[np.all((points >= lo) & (points <= hi), axis=1)]  # only these can be inside
    n = mesh.face_normals
    offset = np.einsum("ij,ij->i", n, mesh.vertices[mesh.faces[:, 0]])
    return np.all(points @ n.T - offset < 0, axis=1)


def test_soft_deformation_removes_the_intersection():
    hard = trimesh.creation.icosphere(3, radius=0.04)
    hard.apply_translation([0, 0.04 - 0.002, 0])  # 2 mm into the cloth
    cloth = trimesh.Trimesh([[-.1, 0, -.1], [.1, 0, -.1], [.1, 0, .1], [-.1, 0, .1]], [[0, 2, 1], [0, 3, 2]])
    cloth = refine(cloth, 0.002)
    before, _ = trimesh.sample.sample_surface(cloth, 100000, seed=0)
    assert _inside_convex(hard, before).any()
    result = deform_soft(cloth, hard)
    np.testing.assert_allclose(result.normal, [0, 1, 0], atol=1e-9)
    after, _ = trimesh.sample.sample_surface(result.mesh, 100000, seed=0)
    assert not _inside_convex(hard, after).any()
    assert not _inside_convex(hard, result.mesh.vertices).any()
    assert 0.0019 < result.max_push < 0.003
    # vertices out of contact did not move, and moved ones only went down
    still = np.setdiff1d(np.arange(len(cloth.vertices)), result.soft_contact)
    np.testing.assert_array_equal(result.mesh.vertices[still], cloth.vertices[still])
    assert np.all(result.mesh.vertices[:, 1] <= cloth.vertices[:, 1])
    far = np.linalg.norm(cloth.vertices[:, [0, 2]], axis=1) > 0.03
    np.testing.assert_array_equal(result.mesh.vertices[far], cloth.vertices[far])


def test_deformation_without_contact_is_refused():
    hard = trimesh.creation.icosphere(2, radius=0.01)
    hard.apply_translation([0, 0.5, 0])
    cloth = refine(trimesh.Trimesh([[-.1, 0, -.1], [.1, 0, -.1], [.1, 0, .1]], [[0, 2, 1]]), 0.01)
    with pytest.raises(InputError, match="do not touch"):
        deform_soft(cloth, hard)


# --- the command ----------------------------------------------------------------------------------

def test_reassemble_commands(tmp_path, phantom, capsys):
    from abs.cli.main import main
    from abs.scene import load_scene

    header = write_raw_volume(tmp_path / "ct" / "volume.json", phantom.volume)
    assert main(["reassemble", "mesh", str(header), "--out", str(tmp_path / "mesh"),
                 "--rounds", "1"]) == 0
    centres, _ = read_markers(tmp_path / "mesh" / "markers.json")
    ct = centres * 1e-3
    measured, order, R, t = _scene_markers(ct, 0.05e-3, seed=7)
    (tmp_path / "measured.json").write_text(json.dumps({"points_m": measured.tolist()}))
    scene = "scenes/default/scene.toml"
    out = tmp_path / "placed" / "scene.toml"
    assert main(["reassemble", "place", str(tmp_path / "mesh"), "--measured", str(tmp_path / "measured.json"),
                 "--scene", scene, "--object", "vase", "--material", "glass", "--out", str(out)]) == 0
    placed = load_scene(out).object("vase")
    assert placed.mesh.name == "glass.ply"
    np.testing.assert_allclose(placed.to_world[:3, :3], R, atol=0.02)
    np.testing.assert_allclose(placed.to_world[:3, 3], t, atol=3e-4)
    report = json.loads((tmp_path / "placed" / "scene_placement.json").read_text())
    assert report["mean_distance_mm"] < 0.2 and len(report["residuals_mm"]) == len(ct)

    # the default sphere rests on the cloth: lower it 2 mm into it, then deform the cloth
    sunk = tmp_path / "sunk.toml"
    from abs.reassembly.scene_pose import place_object_in_scene

    lower = np.eye(4)
    lower[1, 3] = -0.002
    place_object_in_scene(scene, sunk, "sphere", lower)
    deformed = tmp_path / "deformed" / "scene.toml"
    assert main(["reassemble", "deform", "--scene", str(sunk), "--hard", "sphere", "--soft", "cloth",
                 "--max-edge", "4", "--out", str(deformed)]) == 0
    cloth = load_scene(deformed).object("cloth")
    mesh = trimesh.load(cloth.mesh, process=False)
    assert cloth.mesh.name == "cloth_deformed.ply" and mesh.vertices[:, 1].min() < -0.0019

    assert main(["reassemble", "place", str(tmp_path / "mesh"), "--measured", str(tmp_path / "measured.json"),
                 "--scene", scene, "--object", "vase", "--pairs", "0:1", "1:2", "--out", str(out)]) == 2
    assert "at least 3" in capsys.readouterr().err


def test_reassemble_mesh_reads_a_slice_folder(tmp_path, phantom, capsys):
    from abs.cli.main import main

    write_slices(tmp_path / "slices", phantom.volume, ".tif")
    assert main(["reassemble", "mesh", str(tmp_path / "slices"), "--out", str(tmp_path / "m")]) == 2
    assert "needs the voxel size" in capsys.readouterr().err
    assert main(["reassemble", "mesh", str(tmp_path / "slices"), "--voxel-size", str(VOXEL),
                 "--rounds", "0", "--out", str(tmp_path / "m")]) == 0
    centres, radii = read_markers(tmp_path / "m")
    idx = _nearest(phantom.marker_centres_mm, centres)
    assert len(centres) == 6 and np.linalg.norm(centres - phantom.marker_centres_mm[idx], axis=1).max() < 0.3 * VOXEL
