"""Spectral optical constants -> per-channel values (abs.colour.refractiveindex, .spectral)."""

from __future__ import annotations

import numpy as np
import pytest

from abs.colour import channel_centroids_m, optical_constants_rgb, read_refractiveindex_yaml
from abs.errors import InputError
from abs.io.shared_data import shared_data_dir

# SCHOTT N-BK7 Sellmeier coefficients (SCHOTT Zemax catalogue 2017-01-20b, as stored by
# refractiveindex.info, data/specs/schott/optical/N-BK7.yml) and the catalogue's indices at the
# Fraunhofer lines F (486.13 nm), d (587.56 nm), C (656.27 nm): 1.52238, 1.51680, 1.51432.
BK7 = """DATA:
  - type: formula 2
    wavelength_range: 0.3 2.5
    coefficients: 0 1.03961212 0.00600069867 0.231792344 0.0200179144 1.01046945 103.560653
  - type: tabulated k
    data: |
        0.30 1.0e-8
        2.50 1.0e-8
"""


def _write(tmp_path, text, name="m.yml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_bk7_sellmeier_matches_catalogue_at_fraunhofer_lines(tmp_path):
    glass = read_refractiveindex_yaml(_write(tmp_path, BK7))
    n = glass.n(np.array([486.13e-9, 587.56e-9, 656.27e-9]))
    np.testing.assert_allclose(n, [1.52238, 1.51680, 1.51432], atol=2e-5)


def test_bk7_channels_ordered_and_close_to_n_at_centroids(tmp_path):
    glass = read_refractiveindex_yaml(_write(tmp_path, BK7))
    rgb = np.array(optical_constants_rgb(glass)["ior_rgb"])
    # Normal dispersion: blue sees the highest index.
    assert rgb[0] < rgb[1] < rgb[2]
    # n is nearly linear over a channel's band, so the channel value is n at the channel's
    # centroid up to the curvature term (and r-bar's negative lobe): within 1e-3.
    np.testing.assert_allclose(rgb, glass.n(channel_centroids_m()), atol=1e-3)
    # Centroids of the CIE 1931 RGB CMFs lie in the red, green and blue bands.
    c = channel_centroids_m() * 1e9
    assert 600 < c[0] < 660 and 520 < c[1] < 570 and 430 < c[2] < 480


def test_constant_spectrum_stays_constant_and_absorption_is_4pik_over_lambda(tmp_path):
    text = "DATA:\n  - type: tabulated nk\n    data: |\n        0.30 1.7 2.0e-7\n        0.90 1.7 2.0e-7\n"
    values = optical_constants_rgb(read_refractiveindex_yaml(_write(tmp_path, text)))
    np.testing.assert_allclose(values["ior_rgb"], [1.7] * 3, rtol=1e-12)
    np.testing.assert_allclose(values["k_rgb"], [2e-7] * 3, rtol=1e-12)
    # alpha_c = 4 pi k * mean(1/lambda) over channel c: close to 4 pi k / centroid (within the
    # curvature of 1/lambda over the band, and r-bar's negative lobe for R): within 2 %.
    alpha = np.array(values["absorption_per_m"])
    np.testing.assert_allclose(alpha, 4 * np.pi * 2e-7 / channel_centroids_m(), rtol=0.02)
    assert alpha[0] < alpha[1] < alpha[2]


def test_absorption_of_a_line_spectrum_follows_beer_lambert(tmp_path):
    # k proportional to lambda makes 4 pi k / lambda constant: alpha = 4 pi * 1e-7 / 1e-6 per m.
    text = ("DATA:\n  - type: tabulated nk\n    data: |\n        0.30 1.5 0.3e-7\n"
            "        0.90 1.5 0.9e-7\n")
    values = optical_constants_rgb(read_refractiveindex_yaml(_write(tmp_path, text)))
    np.testing.assert_allclose(values["absorption_per_m"], [4 * np.pi * 0.1] * 3, rtol=1e-9)


def test_cauchy_formula(tmp_path):
    text = ("DATA:\n  - type: formula 5\n    wavelength_range: 0.3 1.0\n"
            "    coefficients: 1.5 0.004 -2\n")
    glass = read_refractiveindex_yaml(_write(tmp_path, text))
    np.testing.assert_allclose(glass.n(np.array([0.5e-6])), [1.5 + 0.004 / 0.25])


def test_yaml_without_k_names_file_and_field(tmp_path):
    path = _write(tmp_path, BK7.split("  - type: tabulated k")[0], "no_k.yml")
    with pytest.raises(InputError, match=r"no_k\.yml: DATA: no extinction coefficient k"):
        optical_constants_rgb(read_refractiveindex_yaml(path))


def test_range_not_covering_the_visible_is_an_error(tmp_path):
    text = "DATA:\n  - type: tabulated nk\n    data: |\n        0.40 1.5 0\n        0.70 1.5 0\n"
    with pytest.raises(InputError, match=r"DATA\[0\]: 'tabulated nk' covers 400.0-700.0 nm"):
        optical_constants_rgb(read_refractiveindex_yaml(_write(tmp_path, text)))


def test_unknown_formula_and_bad_numbers(tmp_path):
    with pytest.raises(InputError, match=r"DATA\[0\]\.type: unsupported 'formula 9'"):
        read_refractiveindex_yaml(_write(tmp_path, "DATA:\n  - type: formula 9\n"))
    with pytest.raises(InputError, match=r"DATA\[0\]\.data: not a table of numbers"):
        read_refractiveindex_yaml(_write(tmp_path, "DATA:\n  - type: tabulated nk\n    data: 1 2 x\n"))
    with pytest.raises(InputError, match=r"DATA: missing"):
        read_refractiveindex_yaml(_write(tmp_path, "REFERENCES: none\n"))


def test_shared_chromium_matches_published_values_near_channel_centroids():
    path = shared_data_dir() / "refractiveindex_info/data/main/Cr/nk/Johnson.yml"
    if not path.is_file():
        pytest.skip(f"shared data absent: {path}")
    chrome = read_refractiveindex_yaml(path)
    values = optical_constants_rgb(chrome)
    # Johnson & Christy tabulate n = 3.18..3.84, k = 3.30..3.57 over 540-660 nm: the metal's
    # R and G channel values must lie in the published visible range (n 2.0-3.9, k 3.0-3.6).
    assert all(2.0 < v < 3.9 for v in values["ior_rgb"])
    assert all(3.0 < v < 3.6 for v in values["k_rgb"])


def test_cli_glass_rgb_writes_a_materials_table_with_its_source(tmp_path):
    import tomllib

    from abs.cli.main import main

    path = _write(tmp_path, BK7, "N-BK7.yml")
    out = tmp_path / "glass.toml"
    assert main(["glass", "rgb", str(path), "--name", "lens", "--out", str(out)]) == 0
    text = out.read_text()
    assert "N-BK7.yml" in text.splitlines()[0]
    table = tomllib.loads(text)["materials"]["lens"]
    assert table["type"] == "dielectric"
    np.testing.assert_allclose(table["ior"], optical_constants_rgb(read_refractiveindex_yaml(path))["ior_rgb"])
    np.testing.assert_allclose(table["absorption"], 4 * np.pi * 1e-8 / channel_centroids_m(), rtol=0.02)
    no_k = _write(tmp_path, BK7.split("  - type: tabulated k")[0], "no_k.yml")
    assert main(["glass", "rgb", str(no_k)]) == 2
