"""The structured-light variational study: BRDF samples against closed forms, the study end to
end at reduced size (local pool and Dask), and its physics (the basis beats a Lambertian fit;
larger scanner errors give larger errors)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import SHARED

needs_shared = pytest.mark.skipif(not (SHARED / "data" / "merl_nbrdf").is_dir(),
                                  reason="../shared/data/merl_nbrdf not present (see ../shared/README.md)")

# A small training set (none of them studied): enough for the basis to beat a Lambertian fit.
TRAINING = ("gray-plastic", "green-plastic", "blue-metallic-paint", "alum-bronze", "pink-fabric",
            "specular-blue-phenolic")
MATERIAL = "green-metallic-paint"


def _rig():
    from abs.studies.sl_rig import default_rig

    return default_rig(96, 72, steps=4)


def test_lambertian_samples_equal_albedo_over_pi():
    """A constant table ρ/π must come back as ρ/π from every kept sample: checks the conversion
    f = L / ((ωi·n) I / d²), the reprojection and the back-facing/shadow tests together."""
    from abs.io.merl import MERL_SHAPE
    from abs.studies.sl_capture import render_scan
    from abs.studies.sl_noise import ScanEstimate, perturb
    from abs.studies.sl_rig import icosphere
    from abs.studies.sl_sampling import brdf_samples

    rho = np.array([0.6, 0.4, 0.2])
    table = np.broadcast_to((rho / np.pi)[:, None, None, None], MERL_SHAPE).astype(np.float32)
    rig, mesh = _rig(), icosphere(3)
    images = render_scan(rig, mesh, table, spp=2)
    exact = ScanEstimate(mesh, rig.light_position, rig.light_intensity)
    samples = brdf_samples(images, rig, exact)
    assert samples.count > 500
    assert (samples.wi[:, 2] > 0).all() and (samples.wo[:, 2] > 0).all()
    ratio = samples.f / (rho / np.pi)
    assert np.allclose(np.median(ratio, axis=0), 1.0, atol=0.01)
    assert np.mean(np.abs(ratio - 1.0) < 0.05) > 0.9
    # A scanner that believes the light 20 % brighter measures every value 1/1.2 as large.
    brighter = ScanEstimate(mesh, rig.light_position, 1.2 * rig.light_intensity)
    assert np.allclose(brdf_samples(images, rig, brighter).f, samples.f / 1.2, rtol=1e-6)
    # Tilted normals drop or distort samples but never keep a back-facing one.
    tilted = brdf_samples(images, rig, perturb(exact, "normal_tilt", 30.0, np.random.default_rng(1)))
    assert (tilted.wi[:, 2] > 0).all() and (tilted.wo[:, 2] > 0).all()


def test_shadowed_vertices_are_rejected():
    """A light inside the sphere lights no vertex from outside: every sample fails the tests."""
    from abs.studies.sl_capture import render_scan
    from abs.studies.sl_noise import ScanEstimate
    from abs.studies.sl_rig import icosphere
    from abs.studies.sl_sampling import brdf_samples

    rig, mesh = _rig(), icosphere(1)
    images = render_scan(rig, mesh, np.full((3, 90, 90, 180), 0.1, np.float32), spp=1)
    # Light behind the sphere as seen from the cameras: lit vertices all face away from them.
    hidden = ScanEstimate(mesh, np.array([0.0, 0.0, -0.5]), 1.0)
    assert brdf_samples(images, rig, hidden).count == 0


@needs_shared
@pytest.mark.slow
def test_true_samples_match_the_table():
    """Samples of a measured material agree with its table (the renderer's own lookup)."""
    import drjit as dr
    import mitsuba as mi

    from abs.brdf.measured import measured_table
    from abs.studies.sl_capture import render_scan, sample_scene
    from abs.studies.sl_noise import ScanEstimate
    from abs.studies.sl_rig import icosphere
    from abs.studies.sl_sampling import brdf_samples

    table = measured_table(MATERIAL)
    rig, mesh = _rig(), icosphere(3)
    samples = brdf_samples(render_scan(rig, mesh, table, spp=2), rig,
                           ScanEstimate(mesh, rig.light_position, rig.light_intensity))
    bsdf = sample_scene(mesh, table).shapes()[0].bsdf()
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    si.wi = mi.Vector3f(*[mi.Float(samples.wo[:, i].astype(np.float32)) for i in range(3)])
    light = mi.Vector3f(*[mi.Float(samples.wi[:, i].astype(np.float32)) for i in range(3)])
    value = bsdf.eval(mi.BSDFContext(), si, light)
    truth = np.stack([np.asarray(value[i]) for i in range(3)], axis=1) / samples.wi[:, 2:3]
    ratio = samples.f / truth
    assert np.allclose(np.median(ratio, axis=0), 1.0, atol=0.02)
    assert np.mean(np.abs(ratio - 1.0) < 0.1) > 0.85


@pytest.fixture(scope="module")
def small_basis(tmp_path_factory):
    from abs.brdf.measured import measured_table
    from abs.brdf.pca import build_basis

    path = tmp_path_factory.mktemp("sl_basis") / "basis.npz"
    build_basis(list(TRAINING), measured_table, len(TRAINING) - 1).save(path)
    return path


def _config(basis, **overrides):
    from abs.studies.sl_scanner import StudyConfig

    settings = dict(basis=str(basis), materials=(MATERIAL,), tessellations=(1,), noise_tessellation=1,
                    noise={"normal_tilt": [5.0, 30.0]}, repetitions=2, width=64, height=48, spp=1,
                    score_size=24, score_spp=4, steps=10)
    settings.update(overrides)
    return StudyConfig(**settings)


@needs_shared
@pytest.mark.slow
def test_study_end_to_end(small_basis, tmp_path):
    """Reduced study in two local worker processes: outputs, physics, resume."""
    from abs.studies.sl_study import run_study

    out = tmp_path / "study"
    summary = run_study(_config(small_basis), out, workers=2)
    for name in ("study.json", "table1.md", "table2.md", "report.html", f"profile_{MATERIAL}.png"):
        assert (out / name).is_file(), name
    assert json.loads((out / "study.json").read_text())["table1"] == summary["table1"]
    row = summary["table1"][MATERIAL]["1"]
    assert row["samples"] > 50
    # The basis explains the material far better than the best Lambertian fit to the same samples.
    assert row["mean"] < 0.6 * row["lambert_mean"]
    tilt = summary["table2"]["normal_tilt"]
    assert tilt["30"][MATERIAL]["mean"] > tilt["5"][MATERIAL]["mean"] + 1.0
    assert tilt["5"][MATERIAL]["repetitions"] == 2
    assert "normal tilt" in (out / "table2.md").read_text()
    # Rerunning resumes from the per-task results: nothing is recomputed.
    assert run_study(_config(small_basis), out)["tasks_run"] == 0


@needs_shared
@pytest.mark.slow
def test_dask_gives_the_local_result(small_basis, tmp_path):
    """One task on an in-process Dask cluster equals the same task run locally (same seeds)."""
    distributed = pytest.importorskip("dask.distributed")
    from abs.studies.parallel import map_tasks
    from abs.studies.sl_scanner import run_task, study_tasks

    task = study_tasks(_config(small_basis, noise={}))[0]
    local = run_task(task)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        [(_, remote)] = list(map_tasks(run_task, [task], scheduler=cluster.scheduler_address))
    assert remote["delta_e_mean"] == pytest.approx(local["delta_e_mean"], rel=1e-6)
    assert remote["samples"] == local["samples"]


@needs_shared
def test_cli_rejects_bad_input(tmp_path, capsys):
    """Unknown materials and error types are InputErrors naming the option (exit status 2)."""
    from abs.cli.main import main

    base = ["study", "sl-scanner", "--out", str(tmp_path), "--basis", str(tmp_path / "none.npz")]
    assert main(base + ["--materials", "no-such-material"]) == 2
    assert "--materials" in capsys.readouterr().err
    assert main(base + ["--noise", "earthquake"]) == 2
    assert "--noise" in capsys.readouterr().err
    assert main(base + ["--repetitions", "0"]) == 2
    assert main(base) == 2  # the basis file does not exist
    assert "basis file not found" in capsys.readouterr().err
