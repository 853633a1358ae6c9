"""Image comparison metrics: exact values on hand-made images, masks, refusal of bad input."""

from __future__ import annotations

import numpy as np
import pytest

from abs.metrics import log_error, rmse, ssim


@pytest.fixture
def image() -> np.ndarray:
    return np.random.default_rng(0).uniform(0.0, 1.0, (24, 32, 3)).astype(np.float32)


def test_identical_images(image):
    assert rmse(image, image) == 0.0
    assert ssim(image, image) == pytest.approx(1.0, abs=1e-12)
    assert np.all(log_error(image, image) == -6.0)


def test_rmse_constant_offsets():
    a = np.zeros((4, 5, 3))
    assert rmse(a + 0.3, a) == pytest.approx(0.3, rel=1e-12)
    b = a.copy()
    b[..., 0] = 0.6  # one channel off by 0.6, two exact: sqrt(0.36 / 3)
    assert rmse(a, b) == pytest.approx(np.sqrt(0.12), rel=1e-12)


def test_rmse_mask():
    a = np.zeros((4, 5, 3))
    b = a.copy()
    b[:, 3:] = 2.0  # error only in columns 3, 4
    mask = np.zeros((4, 5), bool)
    mask[:, :3] = True
    assert rmse(a, b, mask) == 0.0
    mask[0, 4] = True  # one error pixel among 13 selected
    assert rmse(a, b, mask) == pytest.approx(np.sqrt(4.0 / 13), rel=1e-12)
    assert rmse(a, b, np.ones((4, 5), bool)) == rmse(a, b)


def test_ssim_tone_mapping_and_noise(image):
    ones = np.ones((24, 32, 3))
    assert ssim(2.0 * ones, 3.0 * ones) == pytest.approx(1.0)  # both clip to white
    noise = np.random.default_rng(1).normal(0.0, 0.05, image.shape)
    slightly, very = ssim(image + noise, image), ssim(image + 4 * noise, image)
    assert 0.0 < very < slightly < 1.0


def test_ssim_mask():
    rng = np.random.default_rng(2)
    a = rng.uniform(0.0, 1.0, (40, 64, 3))
    b = a.copy()
    b[:, 48:] = rng.uniform(0.0, 1.0, (40, 16, 3))  # differ only in the right quarter
    left = np.zeros((40, 64), bool)
    left[:, :32] = True  # further than the window radius (5 px) from the difference
    assert ssim(a, b, left) == pytest.approx(1.0, abs=1e-9)
    assert ssim(a, b, ~left) < ssim(a, b) < 1.0


def test_log_error_values():
    a = np.zeros((2, 2, 3))
    b = a.copy()
    b[0, 1] = [3.0, 4.0, 0.0]      # distance 5
    b[1, 0] = [0.0, 0.0, 1e-3]     # distance 1e-3
    b[1, 1] = [1e-8, 0.0, 0.0]     # below the floor
    expected = np.array([[-6.0, np.log10(5.0)], [-3.0, -6.0]])
    np.testing.assert_allclose(log_error(a, b), expected, rtol=1e-12)
    assert log_error(a, b).shape == (2, 2)


@pytest.mark.parametrize("metric", [rmse, ssim, log_error])
def test_bad_input(metric, image):
    bad = image.copy()
    bad[3, 4, 1] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        metric(bad, image)
    with pytest.raises(ValueError, match="non-finite"):
        metric(image, bad)
    with pytest.raises(ValueError, match="shape"):
        metric(image[:-1], image)


@pytest.mark.parametrize("metric", [rmse, ssim])
def test_bad_mask(metric, image):
    with pytest.raises(ValueError, match="no pixel"):
        metric(image, image, np.zeros((24, 32), bool))
    with pytest.raises(ValueError, match="shape"):
        metric(image, image, np.ones((32, 24), bool))
