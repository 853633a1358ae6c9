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
    # Without the paper's tables (a user without ../shared/docs) the study runs and says so.
    summary = run_study(_config(small_basis), out, workers=2, paper_tables=tmp_path / "absent.md")
    for name in ("paper_comparison.md", "report.html"):
        assert "published tables were not found" in (out / name).read_text(), name
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
    if PAPER_FILE.is_file():  # the default file: the published cell beside abs's
        row = summary["table1"][MATERIAL]["1"]
        line = f"| icosphere 1 | {MATERIAL} | 2.77 ± 2.93 | {row['mean']:.2f} ± {row['sd']:.2f} |"
        assert line in (out / "paper_comparison.md").read_text()


@needs_shared
@pytest.mark.slow
def test_dask_gives_the_local_result(small_basis, tmp_path):
    """One task on an in-process Dask cluster equals the same task run locally (same seeds)."""
    distributed = pytest.importorskip("dask.distributed")
    from abs.pools import worker_pool
    from abs.studies.sl_scanner import run_task, study_tasks

    task = study_tasks(_config(small_basis, noise={}))[0]
    local = run_task(task)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        with worker_pool(scheduler=cluster.scheduler_address) as pool:
            [(_, remote)] = list(pool.as_completed(run_task, [task]))
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
    assert main(base + ["--paper-tables", str(tmp_path / "tables.md")]) == 2  # checked before the run
    assert "tables.md: --paper-tables: file not found" in capsys.readouterr().err


# -- the paper's published tables beside abs's ---------------------------------------------------
PAPER_FILE = SHARED / "docs" / "sl-study-paper-tables.md"

# A small file in the layout of ../shared/docs/sl-study-paper-tables.md (values made up).
PAPER_EXAMPLE = """# Published numbers

Some text.

## Table 1: geometric detail
| | blue-rubber | purple-paint |
|---|---|---|
| Icosphere 1 | 0.77 ± 1.02 | 1.56 ± 1.96 |
| Icosphere 5* | 0.52 ± 0.96 | 1.58 ± 1.55 |

## Table 2: noise in the scanner

| noise | σ | blue-rubber | purple-paint |
|---|---|---|---|
| Ideal | | 0.41 ± 0.67 | 0.55 ± 0.75 |
| Vertex position | 1 mm | 0.66 ± 1.15 | 0.91 ± 1.56 |
| | 3 mm | 2.50 ± 2.82 | 2.11 ± 3.16 |
| Normal (polar tilt) | 5° | 0.42 ± 0.63 | 0.68 ± 1.03 |
| Light intensity | 20 % | 1.75 ± 1.75 | 1.86 ± 2.10 |

## Settings
- not read
"""


def test_paper_tables_parse_into_the_study_layout():
    from abs.studies.sl_paper import parse_paper_tables

    paper = parse_paper_tables(PAPER_EXAMPLE, "example.md")
    assert paper.table1 == {"blue-rubber": {"1": {"mean": 0.77, "sd": 1.02}, "5*": {"mean": 0.52, "sd": 0.96}},
                            "purple-paint": {"1": {"mean": 1.56, "sd": 1.96}, "5*": {"mean": 1.58, "sd": 1.55}}}
    assert paper.ideal["purple-paint"] == {"mean": 0.55, "sd": 0.75}
    # Keys as abs's table2 writes them: NOISE_TYPES names, levels f"{level:g}" in the type's unit.
    assert paper.table2 == {
        "vertex_position": {"1": {"blue-rubber": {"mean": 0.66, "sd": 1.15}, "purple-paint": {"mean": 0.91, "sd": 1.56}},
                            "3": {"blue-rubber": {"mean": 2.5, "sd": 2.82}, "purple-paint": {"mean": 2.11, "sd": 3.16}}},
        "normal_tilt": {"5": {"blue-rubber": {"mean": 0.42, "sd": 0.63}, "purple-paint": {"mean": 0.68, "sd": 1.03}}},
        "light_intensity": {"20": {"blue-rubber": {"mean": 1.75, "sd": 1.75}, "purple-paint": {"mean": 1.86, "sd": 2.1}}},
    }


@pytest.mark.parametrize(("old", "new", "line", "words"), [
    ("| Icosphere 1 | 0.77 ± 1.02 |", "| Icosphere 1 | 0.77 ~ 1.02 |", 8, "expected 'mean ± sd'"),
    ("| | 3 mm | 2.50 ± 2.82 | 2.11 ± 3.16 |", "| | 3 mm | 2.50 ± 2.82 |", 17, "3 cells, the header has 4"),
    ("| Normal (polar tilt) | 5° |", "| Normal (polar tilt) | 5 mm |", 18, "measured in deg"),
    ("| Light intensity |", "| Earthquake |", 19, "unknown error type"),
    ("| Icosphere 5* |", "| Sphere 5 |", 9, "Icosphere N"),
    ("|---|---|---|\n| Icosphere 1", "| Icosphere 1", 7, "separator"),
])
def test_malformed_paper_table_names_file_and_line(old, new, line, words):
    from abs.errors import InputError
    from abs.studies.sl_paper import parse_paper_tables

    assert old in PAPER_EXAMPLE
    with pytest.raises(InputError, match=words) as caught:
        parse_paper_tables(PAPER_EXAMPLE.replace(old, new, 1), "example.md")
    assert caught.value.source == "example.md"
    assert caught.value.field == f"line {line}"


def test_missing_paper_table_is_named(tmp_path):
    from abs.errors import InputError
    from abs.studies.sl_paper import read_paper_tables

    path = tmp_path / "tables.md"
    path.write_text(PAPER_EXAMPLE.replace("## Table 2: noise", "## Noise"), encoding="utf-8")
    with pytest.raises(InputError, match="Table 2") as caught:
        read_paper_tables(path)
    assert caught.value.source == str(path)


@pytest.mark.skipif(not PAPER_FILE.is_file(), reason=f"{PAPER_FILE} not present (see ../shared/README.md)")
def test_the_real_paper_file_parses():
    """Every published cell lands in the study's layout, with values copied from the paper."""
    from abs.studies.sl_noise import NOISE_TYPES
    from abs.studies.sl_paper import read_paper_tables

    paper = read_paper_tables(PAPER_FILE)
    materials = ["blue-rubber", "green-metallic-paint", "purple-paint", "specular-black-phenolic"]
    assert list(paper.table1) == materials
    assert all(list(rows) == ["1", "3", "5", "5*"] for rows in paper.table1.values())
    assert paper.table1["green-metallic-paint"]["5*"] == {"mean": 5.19, "sd": 5.2}
    # Table 2's levels are the study's own (sl_noise.py) for every error type.
    assert {n: list(levels) for n, levels in paper.table2.items()} == \
        {n: [f"{x:g}" for x in t.levels] for n, t in NOISE_TYPES.items()}
    assert all(list(row) == materials for levels in paper.table2.values() for row in levels.values())
    assert paper.table2["normal_tilt"]["30"]["specular-black-phenolic"] == {"mean": 5.24, "sd": 8.31}
    assert paper.table2["light_intensity"]["20"]["blue-rubber"] == {"mean": 1.75, "sd": 1.75}
    # The paper's Table 2 "Ideal" row is its Table 1 icosphere 5 row.
    assert paper.ideal == {m: paper.table1[m]["5"] for m in materials}


def _summary():
    """A study.json's tables for the example's materials: abs 1.5 ± 1.0 error-free, 2.0 with error."""
    cell1 = {"mean": 1.5, "sd": 1.0, "samples": 100, "lambert_mean": 3.0, "lambert_sd": 2.0}
    cell2 = {"mean": 2.0, "sd": 0.25, "pixel_sd": 0.5, "repetitions": 30, "samples_mean": 100.0}
    return {"config": {"noise_tessellation": 1, "materials": ["blue-rubber"]}, "runtime_s": 1.0,
            "table1": {"blue-rubber": {"1": cell1}},
            "table2": {"vertex_position": {"1": {"blue-rubber": cell2}}}}


def test_comparison_pairs_cells_and_tests_two_sd():
    from abs.studies.sl_compare import compare_tables, convention_summary
    from abs.studies.sl_paper import parse_paper_tables

    cells = compare_tables(_summary(), parse_paper_tables(PAPER_EXAMPLE))
    by_key = {(c.table, c.row, c.material): c for c in cells}
    assert len(cells) == 4 + 2 + 8  # every published cell, abs's or not
    one = by_key[("1", "icosphere 1", "blue-rubber")]
    assert one.difference == pytest.approx(1.5 - 0.77)
    assert one.within_2sd  # 0.73 <= 2 √(1.02² + 1²) = 2.86
    # The paper's ideal row meets abs's error-free cell on the error study's subdivision (here 1).
    assert by_key[("2", "ideal", "blue-rubber")].abs_mean == 1.5
    vertex = by_key[("2", "vertex position 1 mm", "blue-rubber")]
    assert vertex.difference == pytest.approx(2.0 - 0.66)
    assert vertex.within_2sd  # 1.34 <= 2 √(1.15² + 0.5²) = 2.51
    assert vertex.abs_repetition_sd == 0.25
    assert vertex.paper_rise == pytest.approx(0.66 - 0.41) and vertex.abs_rise == pytest.approx(2.0 - 1.5)
    assert by_key[("2", "vertex position 3 mm", "blue-rubber")].abs_mean is None
    assert by_key[("1", "icosphere 5*", "purple-paint")].within_2sd is None
    # A difference beyond two combined sds: abs 4.0 ± 0.5 against 0.66 ± 1.15.
    far = _summary()
    far["table2"]["vertex_position"]["1"]["blue-rubber"].update(mean=4.0)
    far_cell = [c for c in compare_tables(far, parse_paper_tables(PAPER_EXAMPLE)) if c.row.startswith("vertex")
                and c.material == "blue-rubber" and c.abs_mean is not None][0]
    assert not far_cell.within_2sd and not far_cell.within_2sd_repetitions  # 3.34 > 2.51
    counts = convention_summary(cells)
    assert counts["table1"] == {"published": 4, "compared": 1, "within_pixel": 1, "within_repetition": 0,
                                "error_cells": 0, "abs_higher": 1}
    assert counts["abs_pixel_sd_over_mean"] == pytest.approx(0.25)
    assert counts["abs_repetition_sd_over_mean"] == pytest.approx(0.125)


def test_report_says_when_the_paper_file_is_absent(tmp_path, monkeypatch, capsys):
    """Without ../shared the report and `abs study sl-paper` still work and say the file is missing;
    with it, the report holds the published values beside abs's."""
    from abs.cli.main import main
    from abs.studies.sl_paper import parse_paper_tables
    from abs.studies.sl_report import paper_markdown, write_html

    summary = _summary()
    study = tmp_path / "study.json"
    study.write_text(json.dumps(summary))
    monkeypatch.setenv("ABS_SHARED_DATA", str(tmp_path / "no-shared" / "data"))
    assert main(["study", "sl-paper", "--study", str(study)]) == 0
    out = capsys.readouterr().out
    assert "were not found" in out and str(tmp_path / "no-shared" / "docs") in out
    html = write_html(tmp_path / "report.html", summary, [], paper_markdown(summary, None, "x.md")).read_text()
    assert "were not found (looked for x.md)" in html and "subdiv. 1" in html
    # With the tables: each published cell beside abs's.
    text = paper_markdown(summary, parse_paper_tables(PAPER_EXAMPLE, "example.md"))
    assert "| vertex position 1 mm | blue-rubber | 0.66 ± 1.15 | 2.00 ± 0.50 | 0.25 | +1.34 | yes | yes | +0.25 / +0.50 |" in text
    assert "<td>0.66 ± 1.15</td>" in write_html(tmp_path / "report.html", summary, [], text).read_text()
    # An explicit file that does not exist is an error naming it.
    assert main(["study", "sl-paper", "--study", str(study), "--paper-tables", str(tmp_path / "none.md")]) == 2
    assert "none.md" in capsys.readouterr().err


@pytest.mark.skipif(not PAPER_FILE.is_file(), reason=f"{PAPER_FILE} not present (see ../shared/README.md)")
def test_docs_show_the_comparison_of_the_committed_run():
    """docs/sl-study.md's side-by-side tables are what the code makes of the committed full-size
    run (benchmarks/results/sl_study.json) and the published file."""
    from pathlib import Path

    from abs.studies.sl_compare import compare_tables, markdown_comparison
    from abs.studies.sl_paper import read_paper_tables

    root = Path(__file__).resolve().parents[1]
    summary = json.loads((root / "benchmarks" / "results" / "sl_study.json").read_text())
    assert summary["config"]["repetitions"] == 30 and summary["config"]["width"] == 640
    tables = markdown_comparison(compare_tables(summary, read_paper_tables(PAPER_FILE)))
    assert tables in (root / "docs" / "sl-study.md").read_text()
