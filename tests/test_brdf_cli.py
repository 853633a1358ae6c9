"""``abs brdf``: materials, export and build-basis from the shared neural MERL fits."""

from __future__ import annotations

import numpy as np
import pytest

from abs.brdf.basis import BRDFBasis
from abs.brdf.nbrdf import nbrdf_archive_path, nbrdf_table
from abs.cli.main import main
from abs.io.merl import read_merl

pytestmark = pytest.mark.skipif(not nbrdf_archive_path().is_file(),
                                reason=f"shared data missing: {nbrdf_archive_path()} (see ../shared/README.md)")


def test_materials_and_export(tmp_path, capsys):
    assert main(["brdf", "materials"]) == 0
    assert "purple-paint" in capsys.readouterr().out.split()
    assert main(["brdf", "export", "purple-paint", "--out", str(tmp_path / "p.binary")]) == 0
    np.testing.assert_allclose(read_merl(tmp_path / "p.binary"), nbrdf_table("purple-paint"), rtol=1e-6)
    assert main(["brdf", "export", "no-such-paint", "--out", str(tmp_path / "x.binary")]) == 2
    assert "unknown materials no-such-paint" in capsys.readouterr().err


def test_build_basis_holds_out_materials(tmp_path, capsys):
    out = tmp_path / "basis.npz"
    names = "purple-paint,blue-rubber,red-plastic,white-paint"
    assert main(["brdf", "build-basis", "--out", str(out), "--materials", names,
                 "--exclude", "blue-rubber", "--components", "2"]) == 0
    basis = BRDFBasis.load(out)
    assert basis.n_components == 2
    assert sorted(basis.materials.tolist()) == ["purple-paint", "red-plastic", "white-paint"]
    assert "held out: blue-rubber" in capsys.readouterr().out
    assert main(["brdf", "build-basis", "--out", str(out), "--materials", names, "--exclude", "",
                 "--components", "4"]) == 2
    assert "--components: must be in [1, 3]" in capsys.readouterr().err


def test_plan_directions_writes_a_plan(tmp_path, capsys):
    import json

    basis_file = tmp_path / "basis.npz"
    assert main(["brdf", "build-basis", "--out", str(basis_file), "--materials",
                 "nylon,red-plastic,white-paint,gold-metallic-paint", "--components", "3"]) == 0
    plan_file = tmp_path / "plan.json"
    assert main(["brdf", "plan-directions", str(basis_file), "-n", "4", "--candidates", "500",
                 "--out", str(plan_file)]) == 0
    plan = json.loads(plan_file.read_text())
    assert len(plan["pairs"]) == 4 and plan["eta"] > 0
    errors = [p["expected_rmse"] for p in plan["pairs"]]
    assert errors == sorted(errors, reverse=True) and plan["criterion"] == "mapped"
    for pair in plan["pairs"]:
        wi, wo = np.array(pair["wi"]), np.array(pair["wo"])
        assert abs(np.linalg.norm(wi) - 1) < 1e-5 and wi[2] > 0 and wo[2] > 0
        assert pair["theta_i_deg"] == pytest.approx(np.degrees(np.arccos(wi[2])), abs=1e-2)
        assert pair["theta_i_deg"] <= 80.0 and pair["theta_o_deg"] <= 80.0
    assert main(["brdf", "plan-directions", str(basis_file), "-n", "501", "--candidates", "500",
                 "--out", str(plan_file)]) == 2
    assert "-n: n must lie in [1, 500]" in capsys.readouterr().err
    assert main(["brdf", "plan-directions", str(basis_file), "-n", "2", "--candidates", "500",
                 "--criterion", "radiance", "--out", str(plan_file)]) == 0
    assert json.loads(plan_file.read_text())["criterion"] == "radiance"
    assert main(["brdf", "plan-directions", str(basis_file), "-n", "2", "--criterion", "photons",
                 "--out", str(plan_file)]) == 2
    assert "--criterion: unknown criterion 'photons'" in capsys.readouterr().err
