"""Run folders: what a fit, a sampling run, a diagnosis or a study leaves on disk.

One place for the rules every run folder follows, so the recipes (``abs fit``, ``abs sample``,
``abs diagnose``, ``abs study``) cannot drift apart:

- :mod:`abs.runs.files`: JSON written atomically, optimiser checkpoints, and the refusal of a
  checkpoint or chain that belongs to another run (naming the differing field);
- :mod:`abs.runs.identity`: what makes two runs the same run (the resume identities);
- :mod:`abs.runs.fit_folder`: a fit's folder (``fit.json``, fitted scene, renders, report).

This package sits above :mod:`abs.report` and :mod:`abs.scene` (it writes reports and scene
files) and below fitting, sampling and diagnosis (they checkpoint through it); see
docs/architecture.md.
"""
