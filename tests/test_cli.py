"""``abs simulate`` then ``abs render`` end to end on a small scene."""

from __future__ import annotations

import json


from abs.cli.main import main
from abs.io.capture import load_capture
from abs.io.images import read_image


def test_simulate_then_render(small_scene_dir, tmp_path):
    capture_dir, out = tmp_path / "capture", tmp_path / "render"
    assert main(["simulate", str(small_scene_dir / "scene.toml"), "--cameras", "3", "--out", str(capture_dir),
                 "--width", "40", "--height", "30", "--spp", "16", "--read-noise", "0.01"]) == 0
    capture = load_capture(capture_dir)
    assert [v.name for v in capture.views] == ["v0", "v1", "v2"]
    assert [v.holdout for v in capture.views] == [False, False, True]
    truth = json.loads((capture_dir / "simulation.json").read_text())["truth"]
    assert truth["glass.absorption"] == [2.0, 4.0, 8.0]

    assert main(["render", str(small_scene_dir / "scene.toml"), str(capture_dir), "--out", str(out),
                 "--spp", "16"]) == 0
    for view in capture.views:
        photo, render = read_image(view.image), read_image(out / f"{view.name}.exr")
        assert render.shape == photo.shape == (30, 40, 3)
        assert (out / f"{view.name}.png").is_file()
        # Same scene, same cameras: the render matches the photograph up to noise.
        assert abs(render.mean() / photo.mean() - 1) < 0.05
