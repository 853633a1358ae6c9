"""abs.appearance's normal step: light moved over the normal's azimuth φ within each θ bin.

Synthetic images on the design's geometry (no rendering): a filter that depends on φ is found
and undone; Monte-Carlo-like noise alone fails the split test and changes nothing.
"""

from __future__ import annotations

import numpy as np
import pytest

from abs.appearance import read_characterisation, transfer, write_characterisation
from abs.appearance.design import characterisation_design
from abs.appearance.normals import PHI_BINS, apply_normal_gains, phi_bins
from abs.appearance.scenes import design_camera, scene_geometry
from abs.appearance.statistics import Accumulator
from abs.appearance.transfer import normal_step
from abs.errors import InputError

CLASSES = ("metal", "wood")


def _upward(geo):
    """A φ filter: more light where the normal points up (``1 + 0.6 cos φ``, φ = 0 up)."""
    phi = np.arctan2(geo.normals[..., 0], geo.normals[..., 1])
    return np.where(geo.ids > 0, 1.0 + 0.6 * np.cos(phi), 1.0)[..., None]


def _pair(filter_b, seed=0):
    """Characterisations of A (a smooth shaded image per scene) and B = filter_b(A), and one new
    scene of each; 8 design scenes (2 classes x 4 walls) at 40 pixels."""
    rng = np.random.default_rng(seed)
    cam = design_camera(40)
    design = characterisation_design(1, classes=CLASSES)
    acc_a, acc_b = Accumulator(CLASSES, 6), Accumulator(CLASSES, 6)

    def shaded(geo):
        colour = rng.uniform(0.2, 0.8, 3)
        return colour * (0.5 + np.cos(np.nan_to_num(geo.theta)))[..., None] * np.ones(3)

    for spec in design:
        geo = scene_geometry(spec, cam)
        img = shaded(geo)
        acc_a.add(img, geo, np.ones_like(img))
        acc_b.add(filter_b(img, geo), geo, np.ones_like(img))
    geo = scene_geometry(design[1], cam)
    image = shaded(geo)
    return acc_a.finish("a", {}, "d", {}), acc_b.finish("b", {}, "d", {}), image, filter_b(image, geo), geo


def test_a_phi_filter_is_found_and_undone():
    a, b, image, target, geo = _pair(lambda img, geo: img * _upward(geo))
    gains, report = normal_step(a, b)
    assert set(gains) == set(CLASSES) and all(r["used"] for r in report.values())
    on = geo.ids > 0
    theta_only = transfer(image, geo, a, b)
    both = transfer(image, geo, a, b, normals=True)
    err_theta = np.abs(theta_only[on] / target[on] - 1)
    err_both = np.abs(both[on] / target[on] - 1)
    # 15° azimuth bins against a filter varying up to 0.6 · 15° ≈ 16 % a bin; θ alone is blind to it.
    assert np.median(err_theta) > 0.15 and np.median(err_both) < 0.05
    # Each θ bin keeps the mean the θ transfer gave it: the step only moves light within a bin.
    np.testing.assert_allclose(both[on].sum(0), theta_only[on].sum(0), rtol=1e-6)


def test_noise_alone_fails_the_split_test_and_changes_nothing():
    """B = A times independent 30 % pixel noise: gains of one half of the design do not predict
    the other's, so no class gets the step and the transfer is the θ transfer's."""
    rng = np.random.default_rng(7)
    a, b, image, _, geo = _pair(lambda img, geo: img * rng.lognormal(0.0, 0.3, img.shape))
    gains, report = normal_step(a, b)
    assert gains == {} and not any(r["used"] for r in report.values())
    np.testing.assert_array_equal(transfer(image, geo, a, b, normals=True), transfer(image, geo, a, b))


def test_phi_bins_and_apply_without_gains():
    normals = np.array([[0, 1, 0], [1, 0, 0], [0, -1, 0], [-1, 0, 0.0]])
    bins = phi_bins(normals)
    assert bins.tolist() == [PHI_BINS // 2, 3 * PHI_BINS // 4, 0, PHI_BINS // 4]
    geo = scene_geometry(characterisation_design(1, classes=("wood",))[0], design_camera(24))
    image = np.random.default_rng(1).uniform(0.1, 1.0, (24, 24, 3))
    np.testing.assert_array_equal(apply_normal_gains(image, geo, {}, np.linspace(0, np.pi / 2, 7)), image)


def test_phi_sums_in_the_file_and_files_without_them(tmp_path):
    a, b = _pair(lambda img, geo: img * _upward(geo))[:2]
    assert a.phi_sums.shape == (8, 2, 6, PHI_BINS, 3) and a.phi_counts.shape == (8, 2, 6, PHI_BINS)
    # Every object pixel is in exactly one cell.
    np.testing.assert_array_equal(a.phi_counts.sum(axis=(0, 3)), a.counts)
    write_characterisation(tmp_path / "a.npz", a)
    back = read_characterisation(tmp_path / "a.npz")
    np.testing.assert_array_equal(back.phi_sums, a.phi_sums)
    data = dict(np.load(tmp_path / "a.npz", allow_pickle=False))
    old = {k: v for k, v in data.items() if not k.startswith("phi_")}
    np.savez(tmp_path / "old.npz", **old)
    with pytest.raises(InputError) as err:
        normal_step(read_characterisation(tmp_path / "old.npz"), b)
    assert err.value.field == "phi_sums" and "again" in str(err.value)
    for change in ({"phi_counts": None}, {"phi_sums": data["phi_sums"][..., :2]},
                   {"phi_counts": -data["phi_counts"]},
                   {"phi_sums": np.full(data["phi_sums"].shape, np.nan)}):
        bad = dict(data)
        for k, v in change.items():
            if v is None:
                bad.pop(k)
            else:
                bad[k] = v
        np.savez(tmp_path / "bad.npz", **bad)
        with pytest.raises(InputError) as err:
            read_characterisation(tmp_path / "bad.npz")
        assert err.value.field.startswith("phi_") and "bad.npz" in str(err.value)
    image, geo = _pair(lambda img, geo: img)[2::2]
    with pytest.raises(InputError):
        transfer(image, geo, a, b, normals=True, theta=False)
