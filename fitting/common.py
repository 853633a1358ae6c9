"""Shared parts of the fitting recipes: command line, known truth, one fit stage with output.

Not a recipe itself: the scripts next to it import it (Python puts a script's own folder on
``sys.path``, so ``import common`` works wherever the script is run from).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import abs
from abs.io.fit_files import write_fit_folder


def parser(doc: str) -> argparse.ArgumentParser:
    """A parser with the recipe's docstring as help and the common SCENE CAPTURE --out DIR."""
    p = argparse.ArgumentParser(description=doc,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scene", type=Path, help="scene file (TOML); its values are the starting point")
    p.add_argument("capture", type=Path, help="capture folder (cameras.json)")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    return p


def truth(capture: Path, names) -> dict | None:
    """True values recorded by ``abs simulate`` (synthetic captures only), copied into fit.json."""
    path = Path(capture) / "simulation.json"
    if not path.exists():
        return None
    known = json.loads(path.read_text()).get("truth", {})
    return {n: known[n] for n in names if n in known} or None


def fit_stage(scene, capture: Path, names: list[str], settings, out: Path) -> dict:
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
                     truth=truth(capture, names))
    summary = write_fit_folder(out, scene, result)
    for name, entry in summary["parameters"].items():
        values = ", ".join(f"{v:.5g} ± {s:.2g}" if s is not None else f"{v:.5g} (unconstrained)"
                           for v, s in zip(entry["value"], entry["stderr"]))
        print(f"{name} = [{values}] {entry['unit']}")
    for split in ("train", "holdout"):
        rmse = summary[f"{split}_rmse"]
        if rmse["before"] is not None:
            print(f"{split} RMSE {rmse['before']:.4g} -> {rmse['after']:.4g}")
    print(f"wrote {out / 'fit.json'} and {out / 'report' / 'report.html'}", flush=True)
    return summary
