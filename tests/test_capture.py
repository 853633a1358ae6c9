"""Tests for abs.io.capture (the capture-folder contract) and abs.camera.pinhole."""

from __future__ import annotations

import json

import numpy as np
import pytest

from abs.camera.pinhole import (camera_center, intrinsics_from_fov, look_at, project,
                                ray_directions)
from abs.errors import CaptureError
from abs.io.capture import load_capture, save_capture

W, H = 8, 6


def _views():
    K = intrinsics_from_fov(W, H, np.deg2rad(40))
    R0, t0 = look_at([0, 0.12, 0.45], [0, 0.05, 0])
    R1, t1 = look_at([0.3, 0.2, 0.3], [0, 0.05, 0])
    return [{"name": "v0", "K": K, "R": R0, "t": t0},
            {"name": "v1", "K": K.tolist(), "R": R1.tolist(), "t": t1.tolist(), "holdout": True}]


def _images():
    rng = np.random.default_rng(0)
    return {n: rng.uniform(0, 2, (H, W, 3)).astype(np.float32) for n in ("v0", "v1")}


@pytest.fixture
def capture_dir(tmp_path):
    mask = np.ones((H, W), bool)
    mask[0] = False
    save_capture(tmp_path / "cap", _views(), _images(), masks={"v1": mask})
    return tmp_path / "cap"


def _edit(folder, fn):
    path = folder / "cameras.json"
    data = json.loads(path.read_text())
    fn(data)
    path.write_text(json.dumps(data))


def _expect_error(folder, field):
    with pytest.raises(CaptureError) as err:
        load_capture(folder)
    message = str(err.value)
    assert "cameras.json" in message and field in message, message
    assert err.value.field == field
    return message


def test_roundtrip(capture_dir):
    cap = load_capture(capture_dir)
    images, views = _images(), _views()
    assert cap.names == ("v0", "v1")
    assert [v.name for v in cap.train_views] == ["v0"]
    assert [v.name for v in cap.holdout_views] == ["v1"]
    for spec in views:
        v = cap.view(spec["name"])
        np.testing.assert_array_equal(v.K, np.asarray(spec["K"]))
        np.testing.assert_array_equal(v.R, np.asarray(spec["R"]))
        np.testing.assert_array_equal(v.t, np.asarray(spec["t"]))
        assert (v.width, v.height) == (W, H)
        assert v.image.is_absolute() and v.image.name == f"{v.name}.exr"
        np.testing.assert_array_equal(v.read_image(), images[v.name])
    assert cap.view("v0").mask is None and cap.view("v0").read_mask().all()
    assert cap.view("v1").read_mask().sum() == (H - 1) * W
    np.testing.assert_allclose(cap.view("v0").center, [0, 0.12, 0.45], atol=1e-12)
    with pytest.raises(KeyError, match="v9"):
        cap.view("v9")
    # Copying a capture from its View objects keeps photographs and masks.
    copy = save_capture(capture_dir.parent / "copy", cap.views)
    assert copy.view("v1").read_mask().sum() == (H - 1) * W
    np.testing.assert_array_equal(copy.view("v1").read_image(), images["v1"])


def test_noise_images_round_trip_and_are_checked(tmp_path):
    images = _images()
    sd = {"v0": 0.01 + 0.02 * images["v0"]}  # shot-noise-like: grows with the light
    cap = save_capture(tmp_path / "cap", _views(), images, noise=sd)
    assert cap.view("v1").noise is None and cap.view("v1").read_noise() is None
    np.testing.assert_allclose(cap.view("v0").read_noise(), sd["v0"], rtol=1e-6)
    assert json.loads((tmp_path / "cap" / "cameras.json").read_text())["noise"] == {"v0": "noise/v0.exr"}
    # Copied from its View objects, a capture keeps them, unless its photograph is replaced.
    copy = save_capture(tmp_path / "copy", cap.views)
    np.testing.assert_allclose(copy.view("v0").read_noise(), sd["v0"], rtol=1e-6)
    assert save_capture(tmp_path / "new", cap.views, {"v0": 2 * images["v0"]}).view("v0").noise is None
    # A view named like a noise image keeps its own photograph.
    views = _views()
    views[1]["name"] = "v0_noise"
    both = save_capture(tmp_path / "both", views, {"v0": images["v0"], "v0_noise": images["v1"]},
                        noise=sd)
    np.testing.assert_array_equal(both.view("v0_noise").read_image(), images["v1"])
    np.testing.assert_allclose(both.view("v0").read_noise(), sd["v0"], rtol=1e-6)
    # A file naming an unknown view, a noise image of another size, a value not positive.
    folder = tmp_path / "cap"
    _edit(folder, lambda d: d["noise"].update(v9="noise/v0.exr"))
    _expect_error(folder, "noise.v9")
    _edit(folder, lambda d: d.update(noise={"v0": "v1.exr", "v1": "missing.exr"}))
    _expect_error(folder, "noise.v1")
    with pytest.raises(CaptureError) as err:
        save_capture(tmp_path / "bad", _views(), images, noise={"v0": -sd["v0"]})
    assert err.value.field == "noise['v0']" and "positive" in str(err.value)
    with pytest.raises(CaptureError, match="differs"):
        save_capture(tmp_path / "bad", _views(), images, noise={"v0": sd["v0"][:2]})
    from abs.io.images import write_exr
    write_exr(folder / "noise" / "v0.exr", np.zeros((H, W, 3), np.float32))
    _edit(folder, lambda d: d.update(noise={"v0": "noise/v0.exr"}))
    with pytest.raises(CaptureError, match="v0.exr.*not finite and positive"):
        load_capture(folder).view("v0").read_noise()


def test_views_are_immutable(capture_dir):
    v = load_capture(capture_dir).view("v0")
    with pytest.raises(Exception):
        v.name = "x"
    with pytest.raises(ValueError):
        v.K[0, 0] = 1.0


def test_singular_K(capture_dir):
    _edit(capture_dir, lambda d: d["views"][0].update(K=[[0, 0, 4], [0, 0, 3], [0, 0, 1]]))
    _expect_error(capture_dir, "views[0].K")


def test_bad_K_last_row(capture_dir):
    _edit(capture_dir, lambda d: d["views"][1].update(K=[[5, 0, 4], [0, 5, 3], [0, 1, 1]]))
    _expect_error(capture_dir, "views[1].K")


def test_non_orthonormal_R(capture_dir):
    _edit(capture_dir, lambda d: d["views"][0].update(
        R=(1.01 * np.asarray(d["views"][0]["R"])).tolist()))
    assert "orthonormal" in _expect_error(capture_dir, "views[0].R")


def test_reflection_R(capture_dir):
    _edit(capture_dir, lambda d: d["views"][0].update(
        R=(-np.asarray(d["views"][0]["R"])).tolist()))
    assert "det" in _expect_error(capture_dir, "views[0].R")


def test_bad_t(capture_dir):
    _edit(capture_dir, lambda d: d["views"][0].update(t=[0, 1]))
    _expect_error(capture_dir, "views[0].t")


def test_missing_image(capture_dir):
    (capture_dir / "v1.exr").unlink()
    assert "v1.exr" in _expect_error(capture_dir, "views[1].image")


def test_duplicate_names(capture_dir):
    _edit(capture_dir, lambda d: d["views"][1].update(name="v0"))
    _expect_error(capture_dir, "views[1].name")


def test_unusable_name(capture_dir):
    _edit(capture_dir, lambda d: d["views"][0].update(name="../x"))
    _expect_error(capture_dir, "views[0].name")


def test_unknown_key(capture_dir):
    _edit(capture_dir, lambda d: d["views"][0].update(holdOut=True))
    _expect_error(capture_dir, "views[0].holdOut")


def test_empty_views(capture_dir):
    _edit(capture_dir, lambda d: d.update(views=[]))
    _expect_error(capture_dir, "views")


def test_malformed_json(capture_dir):
    (capture_dir / "cameras.json").write_text('{"views": [')
    with pytest.raises(CaptureError, match="cameras.json.*not valid JSON"):
        load_capture(capture_dir)


def test_missing_cameras_json(tmp_path):
    with pytest.raises(CaptureError, match="cameras.json"):
        load_capture(tmp_path)


def test_save_rejects_bad_input(tmp_path):
    views = _views()
    views[0]["R"] = np.eye(3) * 2
    with pytest.raises(CaptureError) as err:
        save_capture(tmp_path / "c", views, _images())
    assert err.value.field == "views[0].R"
    with pytest.raises(CaptureError, match="missing photograph"):
        save_capture(tmp_path / "c", _views(), {"v0": _images()["v0"]})
    assert not (tmp_path / "c").exists()  # validation happens before any write


def test_project_look_at_consistency():
    K = intrinsics_from_fov(640, 480, np.deg2rad(40))
    assert (K[0, 2], K[1, 2]) == (319.5, 239.5)
    eye, target = np.array([0, 0.12, 0.45]), np.array([0, 0.05, 0])
    R, t = look_at(eye, target)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_allclose(camera_center(R, t), eye, atol=1e-12)
    uv = project(K, R, t, np.array([target, target + [0, 0.05, 0], target + [0.05, 0, 0]]))
    np.testing.assert_allclose(uv[0], [K[0, 2], K[1, 2]], atol=1e-9)  # optical axis -> (cx, cy)
    assert uv[1, 1] < uv[0, 1]  # up in the world -> smaller v (image y points down)
    assert uv[2, 0] > uv[0, 0]  # +x is to the right for a camera looking along -z
    assert np.isnan(project(K, R, t, eye + (eye - target))).all()  # behind the camera


def test_fov_edges_and_rays():
    K = intrinsics_from_fov(64, 48, np.deg2rad(60))
    R, t = look_at([0, 0, 0], [0, 0, 1], up=(0, -1, 0))  # camera frame == world frame
    np.testing.assert_allclose(R, np.eye(3), atol=1e-12)
    # The top edge of row 0 (v = -0.5) is half the field of view above the axis.
    top = np.array([0, -np.tan(np.deg2rad(30)), 1.0])
    np.testing.assert_allclose(project(K, R, t, top), [K[0, 2], -0.5], atol=1e-9)
    # Rays through projected pixels pass through the points.
    R, t = look_at([0.3, 0.2, 0.3], [0, 0.05, 0])
    X = np.array([[0.01, 0.02, 0.03], [-0.05, 0.1, 0.0]])
    origins, dirs = ray_directions(K, R, t, project(K, R, t, X))
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=1), 1.0)
    to_x = X - origins
    np.testing.assert_allclose(np.cross(dirs, to_x), 0.0, atol=1e-12)
    assert np.all(np.einsum("ij,ij->i", dirs, to_x) > 0)


def test_look_at_degenerate():
    with pytest.raises(ValueError):
        look_at([0, 1, 0], [0, 0, 0])  # looking straight down the up axis
    with pytest.raises(ValueError):
        look_at([0, 0, 0], [0, 0, 0])
