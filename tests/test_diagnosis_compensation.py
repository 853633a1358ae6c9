"""Compensation made visible: a baseline parameter that moves by more than its standard error when
an effect is added is flagged, in the finding's explanation, in diagnosis.json and in the report;
one that moves within its standard error, or has none, is not."""

from __future__ import annotations

import json

import numpy as np

from abs.diagnosis.compensation import FLAG_STDERR, parameter_shifts, describe_shifts


def _shifts():
    # The seed's example: absorption fitted too high to make up for a too-bright cloth. Adding
    # the cloth's effect moves the absorption back by 4 standard errors in the blue channel; the
    # environment scale moves by half a standard error (refit scatter, not compensation); the
    # effect's own parameter is not in the fit without it; an unidentifiable scalar has NaN.
    before = {"glass.absorption": [3.0, 6.0, 12.0], "environment.scale": [1.0], "cloth.reflectance": [0.5]}
    stderr = {"glass.absorption": [0.5, 0.5, 0.5], "environment.scale": [0.02], "cloth.reflectance": [np.nan]}
    after = {"glass.absorption": [3.1, 5.8, 10.0], "environment.scale": [1.01], "cloth.reflectance": [0.9],
             "cloth.subsurface": [0.004]}
    return {s.parameter: s for s in parameter_shifts(before, stderr, after)}


def test_shifts_are_measured_in_the_reference_fits_standard_errors():
    shifts = _shifts()
    assert set(shifts) == {"glass.absorption", "environment.scale", "cloth.reflectance"}
    np.testing.assert_allclose(shifts["glass.absorption"].in_stderr, [0.2, -0.4, -4.0])
    np.testing.assert_allclose(shifts["environment.scale"].in_stderr, [0.5])
    assert np.isnan(shifts["cloth.reflectance"].in_stderr).all()
    assert shifts["glass.absorption"].compensating
    assert not shifts["environment.scale"].compensating
    assert not shifts["cloth.reflectance"].compensating  # no standard error: cannot say
    # The threshold is one standard error, either direction.
    (edge,) = parameter_shifts({"a.b": [0.0, 0.0]}, {"a.b": [1.0, 1.0]},
                               {"a.b": [FLAG_STDERR * 0.999, -FLAG_STDERR * 1.001]})
    assert edge.compensating and np.abs(edge.in_stderr)[0] < FLAG_STDERR


def test_the_flag_reads_in_the_explanation_and_the_contract():
    shifts = list(_shifts().values())
    text = describe_shifts(shifts)
    assert "glass.absorption from 3/6/12 to 3.1/5.8/10" in text and "-4.0 standard errors" in text
    assert "environment.scale" not in text and "compensating" in text
    assert describe_shifts([s for s in shifts if not s.compensating]) == ""
    entry = json.loads(json.dumps(_shifts()["glass.absorption"].to_json()))  # JSON-clean
    assert entry == {"parameter": "glass.absorption", "before": [3.0, 6.0, 12.0],
                     "after": [3.1, 5.8, 10.0], "stderr": [0.5, 0.5, 0.5],
                     "shift_in_stderr": [0.2, -0.4, -4.0], "compensating": True}
    assert json.loads(json.dumps(_shifts()["cloth.reflectance"].to_json()))["shift_in_stderr"] == [None]


def test_a_finding_explains_and_reports_its_compensation(tmp_path):
    """Through :class:`Finding` and the HTML table, without running a diagnosis."""
    from abs.diagnosis.diagnose import Finding, _explanation
    from abs.diagnosis.effects import Candidate
    from abs.diagnosis.select import Comparison
    from abs.report.diagnosis_report import _compensation_table

    shifts = list(_shifts().values())
    candidate = Candidate("stray_light", "sensor", ("sensor.stray_light",))
    explanation = _explanation(candidate, {"sensor.stray_light": np.array([0.04, 0.04, 0.05])}, shifts)
    assert explanation.startswith("Stray light") and explanation.endswith(
        "was compensating for the missing effect.")
    comparison = Comparison(0.06, 0.02, 25.0, 1e-5, -2400.0, 3, True, "passed")
    finding = Finding(candidate, explanation, {"sensor.stray_light": [0.04, 0.04, 0.05]}, comparison,
                      {}, shifts)
    entries = finding.to_json()["compensation"]
    assert [e["compensating"] for e in entries] == [True, False, False]
    table = _compensation_table([finding])
    assert table.count("<b>yes: compensating</b>") == 1 and "glass.absorption" in table
    assert "-4.0" in table and "&gt; 1 s.e." in table
