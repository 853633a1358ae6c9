"""``abs fit`` recovers the coefficients of a held-out measured material from synthetic photographs.

A small basis (K = 3) is built from ten measured materials of the shared data, without
purple-paint; the truth is purple-paint's projection onto it (the best the basis can represent),
rendered on a sphere under a real HDR panorama (shared data: a sun and a sky give both specular
and diffuse cues) with shot and read noise. The fit starts from the mean table (c = 0) with the
basis' own population prior (training coefficients have sd 1/sqrt(m − 1)).

Measured (spp 32, 2 refinement steps): errors of 0.02 on coefficients of 0.06-0.15, up to six
Laplace standard errors: the Monte-Carlo bias the refinement does not fully remove
(docs/fitting.md, "Open problems"), hence the absolute slack below. With K = 4 the fixed-seed
bias grows to 0.3 along the specular component and needs about 8 refinement steps (docs/brdf.md;
reported, not tested: a minute more).
"""

from __future__ import annotations

import numpy as np
import pytest

from abs import load_scene
from abs.brdf.measured import measured_table
from abs.brdf.nbrdf import nbrdf_archive_path
from abs.brdf.pca import build_basis
from abs.brdf.reconstruct import project_table
from abs.fitting import FitSettings, fit
from abs.io.shared_data import shared_data_dir
from abs.simulate import simulate_capture

ENVIRONMENT = shared_data_dir() / "polyhaven_hdri_1k" / "royal_esplanade_1k.hdr"
pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not (nbrdf_archive_path().is_file() and ENVIRONMENT.is_file()),
                       reason=f"shared data missing: {nbrdf_archive_path()} or {ENVIRONMENT} "
                              "(see ../shared/README.md)"),
]

HELD_OUT = "purple-paint"
K = 3
TRAINING = ("red-plastic", "gold-metallic-paint", "white-paint", "black-phenolic", "blue-fabric",
            "chrome-steel", "pink-felt", "specular-blue-phenolic", "nylon", "alum-bronze")

_SCENE = """
[render]
spp = 16
max_depth = 3

[environment]
file = "env.hdr"

[materials.paint]
type = "brdf_pca"
basis = "basis.npz"
coefficients = {coefficients}

[[objects]]
name = "sphere"
mesh = "sphere.ply"
material = "paint"

[fit]
parameters = ["paint.coefficients"]

[fit.priors."paint.coefficients"]
mean = {prior_mean}
sd = {prior_sd}
"""


def test_fit_recovers_held_out_material_coefficients(tmp_path, small_scene_dir):
    basis = build_basis(TRAINING, measured_table, n_components=K)
    basis.save(tmp_path / "basis.npz")
    truth = project_table(basis, measured_table(HELD_OUT))
    # The start (the mean table) is far from a held-out material.
    assert np.linalg.norm(truth) > 0.15
    (tmp_path / "sphere.ply").write_bytes((small_scene_dir / "sphere.ply").read_bytes())
    (tmp_path / "env.hdr").write_bytes(ENVIRONMENT.read_bytes())
    # The basis' own population prior: training coefficients have mean 0 and sd 1/sqrt(m − 1).
    prior_sd = [float(np.std(basis.training_coefficients[:, 0], ddof=1))] * K
    assert prior_sd[0] == pytest.approx(1 / np.sqrt(len(TRAINING) - 1))
    prior = {"prior_mean": [0.0] * K, "prior_sd": prior_sd}
    (tmp_path / "truth.toml").write_text(_SCENE.format(coefficients=truth.tolist(), **prior))
    (tmp_path / "start.toml").write_text(_SCENE.format(coefficients=[0.0] * K, **prior))
    simulate_capture(load_scene(tmp_path / "truth.toml"), tmp_path / "capture", n_cameras=4, width=48,
                     height=36, spp=512, shot_noise=1e-4, read_noise=0.003, seed=3)
    result = fit(tmp_path / "start.toml", tmp_path / "capture",
                 settings=FitSettings(spp=32, max_iterations=8, refinement_steps=2))
    fitted = result.values["paint.coefficients"]
    stderr = result.vector.split(result.uncertainty.stderr)["paint.coefficients"]
    # Coefficients: within 3 standard errors plus a slack of 10 % of the prior sd (the MC bias).
    assert np.all(np.abs(fitted - truth) < 3 * stderr + 0.1 * prior_sd[0]), (fitted, truth, stderr)
    # The BRDF: the mapped table error Qᵀ(c − c_true) (rows of Q are orthogonal with norms σ_k) is
    # a small fraction of the start's (measured 0.22).
    sigma = basis.singular_values[:K]
    assert np.linalg.norm(sigma * (fitted - truth)) < 0.35 * np.linalg.norm(sigma * truth)
    # The renderings: closer to the photographs, also on the held-out view (measured 0.69, 0.77;
    # the rest is photograph noise).
    assert result.metrics["train_rmse"]["after"] < 0.8 * result.metrics["train_rmse"]["before"]
    assert result.metrics["holdout_rmse"]["after"] < 0.85 * result.metrics["holdout_rmse"]["before"]
