"""Shared parts of the fitting recipes: command line, one fit stage with its output.

Not a recipe itself: the scripts next to it import it (Python puts a script's own folder on
``sys.path``, so ``import common`` works wherever the script is run from).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import abs
from abs.runs.fit_folder import write_fit_folder
from abs.report.text import summary_lines
from abs.simulate import read_truth


def parser(doc: str) -> argparse.ArgumentParser:
    """A parser with the recipe's docstring as help and the common SCENE CAPTURE --out DIR."""
    p = argparse.ArgumentParser(description=doc,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scene", type=Path, help="scene file (TOML); its values are the starting point")
    p.add_argument("capture", type=Path, help="capture folder (cameras.json)")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    return p


def fit_stage(scene, capture: Path, names: list[str], settings, out: Path,
              initial: dict | None = None) -> dict:
    """Fit ``names`` with ``settings``, write the fit folder ``out`` and print the result.

    Parameters
    ----------
    scene : Scene
        Starting point (its current values).
    capture : Path
        Capture folder.
    names : list of str
        Parameters to fit.
    settings : abs.FitSettings
    out : Path
    initial : dict, optional
        Starting values by parameter name instead of the scene's.
        Fit folder: fit.json, the fitted scene.toml, renders/ and report/.

    Returns
    -------
    dict
        The fit's summary (the content of fit.json).
    """
    def progress(state) -> None:
        print(f"  iteration {state.iteration}: RMSE {state.history[-1]['loss']:.4g}", flush=True)

    print(f"fitting {', '.join(names)} -> {out}", flush=True)
    result = abs.fit(scene, capture, names, settings, on_iteration=progress,
                     truth=read_truth(capture, names), initial=initial)
    summary = write_fit_folder(out, scene, result)
    print("\n".join(summary_lines(summary)))
    print(f"wrote {out / 'fit.json'} and {out / 'report' / 'report.html'}", flush=True)
    return summary
