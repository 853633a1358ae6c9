"""Light calibration (issue 27, part 3): LED positions from a mirror ball's highlights, the radial
attenuation and intensities from a grey board, recovered from simulated frames of a rig whose truth
differs from its geometry file; ``abs lightstage calibrate`` and its errors for bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from abs.camera.pinhole import project
from abs.cli.main import main
from abs.lightstage.calibration import CalibrationData, calibrate
from abs.lightstage.calsim import (BALL_CENTER, BALL_RADIUS, BOARD_ALBEDO, BOARD_CORNERS, ball_frame,
                                   board_frame, perturbed_rig, write_calibration_folder)
from abs.lightstage.dome import dome_geometry
from abs.lightstage.geometry import read_geometry, write_geometry
from abs.lightstage.greyboard import LedFrame, board_samples, board_tracer, fit_board
from abs.lightstage.ledball import triangulate_led


def _dome(rings=2, per_ring=4):
    """A small dome: ``rings`` rings of ``per_ring`` LEDs on a 0.5 m hemisphere, 64x48 camera."""
    pos = np.zeros((rings, per_ring, 3))
    for b in range(rings):
        el = np.deg2rad(15.0 + 40.0 * b)
        for i in range(per_ring):
            az = 2.0 * np.pi * (i + 0.5 * b) / per_ring
            pos[b, i] = 0.5 * np.array([np.cos(el) * np.sin(az), np.sin(el), np.cos(el) * np.cos(az)])
    return dome_geometry(pos, np.array([0.0, 0.1, 0.45]), 16.0, 64, 48, 4.0, 1.0, 100.0)


def _errors_mm(a, b):
    return np.array([1e3 * np.linalg.norm(a.leds[k].position - b.leds[k].position) for k in sorted(a.leds)])


def test_resized_camera_sees_the_same_point_at_scaled_pixels():
    cam = _dome().cameras[0]
    big = cam.resized(4 * cam.width, 4 * cam.height)
    X = np.array([[0.01, 0.02, -0.03], [-0.05, 0.0, 0.04]])
    uv, uv4 = project(cam.K, cam.R, cam.t, X), project(big.K, big.R, big.t, X)
    # Pixel centres: pixel (0, 0) of the small image covers pixels 0..3 of the big one, centre 1.5.
    np.testing.assert_allclose(uv4, 4.0 * (uv + 0.5) - 0.5, atol=1e-9)
    with pytest.raises(ValueError, match="not a scaled"):
        cam.resized(128, 48)


def test_triangulation_finds_the_point_where_the_lines_cross():
    rng = np.random.default_rng(0)
    led = np.array([0.1, 0.4, -0.2])
    pts = rng.normal(0.0, 0.05, (5, 3))
    dirs = (led - pts) / np.linalg.norm(led - pts, axis=1)[:, None]
    prior = led + np.array([0.02, -0.01, 0.015])
    # Exact lines from a ball circling 5 cm from the axis, 0.5 m from the LED cross at a few
    # degrees: with a direction uncertainty of 5 mrad assumed, the prior 27 mm off keeps a
    # millimetre's pull along them; estimated from the lines' (zero) scatter, none.
    loose = triangulate_led(pts, dirs, prior, sigma_prior_m=0.02, sigma_direction_rad=0.005)
    assert 2e-4 < np.linalg.norm(loose.position - led) < 3e-3
    fix = triangulate_led(pts, dirs, prior, sigma_prior_m=0.02)
    assert fix.sigma_direction_rad < 1e-3  # from the first solve's residuals (the prior's pull)
    assert np.linalg.norm(fix.position - led) < 5e-5 and fix.rms_line_distance_m < 5e-5
    # No lines: the prior.
    alone = triangulate_led(np.zeros((0, 3)), np.zeros((0, 3)), led)
    np.testing.assert_allclose(alone.position, led)
    assert alone.lines == 0


def test_mirror_ball_recovers_perturbed_led_positions():
    """LEDs moved by ~14 mm (8 mm per axis) from the file come back to within a millimetre or two."""
    designed = _dome()
    rng = np.random.default_rng(5)
    truth = perturbed_rig(designed, rng)
    frames = [LedFrame(a, k, 255, 0.01, ball_frame(truth, a, k, rng, scale=8))
              for a in np.arange(0.0, 360.0, 45.0) for k in sorted(designed.leds)]
    calibrated, report = calibrate(designed, CalibrationData(BALL_CENTER, BALL_RADIUS, None, None, frames, []))
    before, after = _errors_mm(designed, truth), _errors_mm(calibrated, truth)
    assert report["leds_without_highlight"] == []
    assert all(v["highlight_lines"] == 8 for v in report["leds"].values())
    assert np.median(before) > 8.0
    assert np.median(after) < 1.0 and np.all(after < 3.0) and np.all(after < before)
    # Nothing but the positions changes without a board.
    assert calibrated.attenuation == designed.attenuation


def test_grey_board_recovers_attenuation_exponent_and_intensities():
    """With the positions right, the board gives the cos^10 profile (file: cos^4) and each LED's
    RGB intensity (spread +-25 %) to a few percent."""
    designed = _dome()
    rng = np.random.default_rng(6)
    truth = perturbed_rig(designed, rng, exponent=10.0)
    tracer = board_tracer(BOARD_CORNERS)
    frames = [LedFrame(0.0, k, 255, 0.02, board_frame(truth, tracer, 0.0, k, 0.02, rng))
              for k in sorted(designed.leds)]
    # The file with the true positions but the designed intensities and profile.
    known_positions = designed.__class__(designed.cameras, {k: designed.leds[k].__class__(
        truth.leds[k].position, designed.leds[k].axis, designed.leds[k].intensity) for k in designed.leds},
        designed.turntable_axis, designed.turntable_center, designed.attenuation, designed.gain)
    fit = fit_board(board_samples(known_positions, tracer, frames, BOARD_ALBEDO))
    assert abs(fit.exponent - 10.0) < 0.5
    assert fit.max_angle_deg > 10.0
    for k in designed.leds:
        np.testing.assert_allclose(fit.intensity[k], truth.leds[k].intensity, rtol=0.03)
    # A wrong albedo scales every intensity by the same factor (common units).
    half = fit_board(board_samples(known_positions, tracer, frames, 0.5 * BOARD_ALBEDO))
    for k in designed.leds:
        np.testing.assert_allclose(half.intensity[k], 2.0 * fit.intensity[k], rtol=1e-9)


def test_cli_calibrate_writes_a_refined_geometry_file(tmp_path, capsys):
    designed = _dome(rings=2, per_ring=3)
    rng = np.random.default_rng(7)
    truth = perturbed_rig(designed, rng)
    folder = write_calibration_folder(truth, tmp_path / "cal", np.arange(0.0, 360.0, 60.0), rng, ball_scale=8)
    write_geometry(designed, tmp_path / "designed.json")
    assert main(["lightstage", "calibrate", str(folder), "--geometry", str(tmp_path / "designed.json")]) == 0
    assert "wrote" in capsys.readouterr().out
    refined = read_geometry(folder / "geometry.json")
    report = json.loads((folder / "calibration-report.json").read_text())
    assert report["ball_frames"] == 6 * 6 and report["board_frames"] == 6
    assert np.median(_errors_mm(refined, truth)) < 1.5 < 5.0 < np.median(_errors_mm(designed, truth))
    assert abs(refined.attenuation.exponent - 10.0) < 1.0
    for k in designed.leds:
        np.testing.assert_allclose(refined.leds[k].intensity, truth.leds[k].intensity, rtol=0.05)


def test_cli_calibrate_errors_name_the_file_and_field(tmp_path, capsys):
    designed = _dome(rings=1, per_ring=2)
    write_geometry(designed, tmp_path / "g.json")
    geometry = str(tmp_path / "g.json")
    folder = tmp_path / "cal"
    folder.mkdir()
    assert main(["lightstage", "calibrate", str(folder), "--geometry", geometry]) == 2
    assert "calibration.json: calibration file not found" in capsys.readouterr().err
    good = {"format": "abs-lightstage-calibration/1", "ball": {"center": [0.04, 0, 0], "radius": 0.025},
            "frames": [{"target": "ball", "angle_deg": 0, "light": "b00l00", "exposure_s": 0.01,
                        "file": "f.exr"}]}
    cases = [({"format": "other"}, "format: expected"),
             ({"ball": {"center": [0, 0], "radius": 0.02}}, "ball.center: expected finite numbers of shape (3,)"),
             ({"ball": {"center": [0, 0, 0], "radius": -1}}, "ball.radius: must be > 0"),
             ({"frames": [{**good["frames"][0], "target": "board"}]}, "board: frames[0] is a board frame"),
             ({"frames": [{**good["frames"][0], "exposure_s": 0}]}, "frames[0].exposure_s"),
             ({"frames": []}, "frames: expected a non-empty array"),
             ({}, "f.exr")]  # the frame file is missing
    for change, message in cases:
        (folder / "calibration.json").write_text(json.dumps({**good, **change}))
        assert main(["lightstage", "calibrate", str(folder), "--geometry", geometry]) == 2
        err = capsys.readouterr().err
        assert "calibration.json" in err or "f.exr" in err, err
        assert message in err, (message, err)
    # A light the geometry file does not have.
    from abs.io.images import write_exr

    write_exr(folder / "f.exr", np.zeros((48, 64, 3), np.float32))
    (folder / "calibration.json").write_text(json.dumps(
        {**good, "frames": [{**good["frames"][0], "light": "b09l09"}]}))
    assert main(["lightstage", "calibrate", str(folder), "--geometry", geometry]) == 2
    assert "'b09l09' is not in the geometry file" in capsys.readouterr().err
