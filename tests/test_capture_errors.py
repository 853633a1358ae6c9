"""A malformed cameras.json fails with an error naming the file and the field."""

from __future__ import annotations

import json

import numpy as np
import pytest

from abs.errors import CaptureError
from abs.io.capture import load_capture, save_capture


@pytest.fixture()
def capture_dir(tmp_path):
    K = [[100.0, 0, 15.5], [0, 100.0, 11.5], [0, 0, 1]]
    save_capture(tmp_path, [{"name": "v0", "K": K, "R": np.eye(3), "t": [0, 0, 1]}],
                 {"v0": np.full((24, 32, 3), 0.5, np.float32)})
    return tmp_path


def _edit(folder, **changes):
    path = folder / "cameras.json"
    data = json.loads(path.read_text())
    data["views"][0].update(changes)
    path.write_text(json.dumps(data))


@pytest.mark.parametrize("change,field", [
    ({"K": [[0, 0, 15.5], [0, 100.0, 11.5], [0, 0, 1]]}, "views[0].K"),
    ({"R": [[1, 0, 0], [0, 1, 0], [0, 0, 2]]}, "views[0].R"),
    ({"t": [0, 0]}, "views[0].t"),
    ({"image": "missing.exr"}, "views[0].image"),
])
def test_bad_view_is_named(capture_dir, change, field):
    _edit(capture_dir, **change)
    with pytest.raises(CaptureError) as info:
        load_capture(capture_dir)
    assert "cameras.json" in str(info.value) and field in str(info.value)


def test_roundtrip(capture_dir):
    view = load_capture(capture_dir).views[0]
    assert (view.width, view.height) == (32, 24) and not view.holdout
    np.testing.assert_allclose(view.read_image(), 0.5)
