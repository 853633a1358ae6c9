"""The fit report: a self-contained HTML page whose every link is a PNG written beside it."""

from __future__ import annotations

import re

import cv2
import numpy as np
import pytest

from abs.report import ReportView, write_fit_report

PARAMETERS = {
    "glass.absorption": {"value": [3.9, 1.6, 2.4], "stderr": [0.1, 0.05, 0.08], "unit": "1/m",
                         "initial": [2, 2, 2], "truth": [4, 1.5, 2.5]},
    "glass.ior": {"value": 1.49, "stderr": None, "unit": "", "initial": 1.5},
    "environment.rotation": {"value": [0.1], "stderr": [0.01], "unit": "rad", "initial": [0.0]},
}


def _summary() -> dict:
    names = ["glass.absorption[0]", "glass.absorption[1]", "glass.absorption[2]", "glass.ior",
             "environment.rotation"]
    corr = np.eye(len(names))
    corr[0, 3] = corr[3, 0] = -0.7
    return {"parameters": PARAMETERS,
            "correlation": {"names": names, "matrix": corr.tolist()},
            "train_rmse": {"before": 0.12, "after": 0.01},
            "holdout_rmse": {"before": 0.13, "after": 0.02},
            "train_ssim": {"before": 0.7, "after": 0.98},
            "renders": 42, "samples_rendered": 1234567, "wall_s": 12.5, "iterations": 3,
            "method": "lm"}


def _history() -> list[dict]:
    return [{"iteration": i, "loss": 0.1 / (i + 1) ** 2,
             "values": {"glass.absorption": [2 + 0.6 * i, 2 - 0.1 * i, 2 + 0.1 * i],
                        "glass.ior": 1.5 - 0.003 * i, "environment.rotation": [0.03 * i]}}
            for i in range(4)]


def _views() -> list[ReportView]:
    rng = np.random.default_rng(0)

    def image():
        return rng.uniform(0.0, 2.0, (24, 32, 3)).astype(np.float32)

    return [ReportView("cam 0", False, image(), image(), image()),
            ReportView("cam/1", True, image(), image(), image())]


def test_report_links_and_content(tmp_path):
    path = write_fit_report(tmp_path / "report", _summary(), _views(), _history())
    assert path == tmp_path / "report" / "report.html" and path.is_file()
    page = path.read_text(encoding="utf-8")
    for name in PARAMETERS:
        assert name in page
    assert "holdout" in page
    assert not re.search(r"<(script|link)\b", page)  # self-contained

    links = re.findall(r'(?:src|href)="([^"]*)"', page)
    assert len(links) == 5  # loss, parameter traces, correlation, two views
    for link in links:
        assert link.endswith(".png") and "/" not in link
        pixels = cv2.imread(str(path.parent / link))
        assert pixels is not None and pixels.shape[0] > 0 and pixels.shape[1] > 0


def test_report_tolerates_missing_optional_data(tmp_path):
    summary = {"parameters": {"glass.ior": {"value": 1.49, "stderr": None}}}
    view = _views()[0]
    page = write_fit_report(tmp_path, summary, [view], []).read_text(encoding="utf-8")
    assert "glass.ior" in page and "—" in page
    assert re.findall(r'src="([^"]*)"', page) == ["view_00_cam_0.png"]


def test_view_shapes_must_match():
    image = np.zeros((24, 32, 3), np.float32)
    with pytest.raises(ValueError, match="differs"):
        ReportView("cam", False, image, image[:, :-1], image)
