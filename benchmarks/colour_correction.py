"""Colour correction on real chart measurements: ΔE00 of linear, root-polynomial and refined fits.

Data: ``../shared/data/colour_correction_rgbxyz_uea/`` (Fang, Gong, Mackiewicz & Finlayson's
Colour Correction Toolbox): measured camera RGB and XYZ of a 24-patch chart (Han Gong, outdoor,
cloudy) and of a 96-patch set photographed with a Nikon and a Sigma camera. For each set and
method the correction is fitted by leave-one-out (fit on all patches but one, ΔE00 on that one,
for every patch) and also on all patches (training error). CIELAB's white is the measured XYZ of
the brightest patch of the set (the chart's white). Methods:

- ``linear``: 3x3 least squares;
- ``linear+dE``: the same refined by mean ΔE00 (BFGS);
- ``root-polynomial``: degree-2 root-polynomial least squares (Finlayson et al. 2015);
- ``root-polynomial+dE``: the same refined by mean ΔE00 (the seed's method; seed: 1.97 ± 1.21).

Writes ``benchmarks/results/colour_correction.json``.

    python benchmarks/colour_correction.py
"""

from __future__ import annotations

import json
import platform
import time
from pathlib import Path

import numpy as np

from abs.colour.correction import calibrate, delta_e00, expand
from abs.io.shared_data import shared_data_dir

ROOT = Path(__file__).resolve().parents[1]
SETS = {
    "uea-24-outdoor-cloudy": ("HanGong_2015_Outdoor_Cloudy_RGB", "HanGong_2015_Outdoor_Cloudy_XYZ"),
    "uea-96-nikon": ("Michal_New_Castle_Nikon_RGB", "Michal_New_Castle_Nikon_XYZ"),
    "uea-96-sigma": ("Michal_New_Castle_Sigma_RGB", "Michal_New_Castle_Sigma_XYZ"),
}
METHODS = {"linear": (1, False), "linear+dE": (1, True), "root-polynomial": (2, False),
           "root-polynomial+dE": (2, True)}


def _stats(v) -> dict:
    v = np.asarray(v)
    return {"mean": float(v.mean()), "sd": float(v.std(ddof=1)), "median": float(np.median(v)),
            "max": float(v.max())}


def main() -> None:
    from scipy.io import loadmat  # only the benchmark reads MATLAB files

    folder = shared_data_dir() / "colour_correction_rgbxyz_uea" / "rgbxyz"
    if not folder.is_dir():
        raise SystemExit(f"shared data absent: {folder} (see ../shared/README.md)")
    results = {"seed_reference": {"mean": 1.97, "sd": 1.21},
               "split": "leave-one-out (test) and all patches (train)",
               "white": "XYZ of the brightest patch of each set", "machine": platform.processor(),
               "sets": {}}
    for name, (rgb_file, xyz_file) in SETS.items():
        rgb = loadmat(folder / f"{rgb_file}.mat")["RGB"].astype(np.float64)
        xyz = loadmat(folder / f"{xyz_file}.mat")["XYZ"].astype(np.float64)
        white = xyz[np.argmax(xyz[:, 1])]
        rows = {}
        for method, (degree, refine) in METHODS.items():
            start = time.perf_counter()
            train = calibrate(rgb, xyz, white, degree=degree, refine=refine)
            loo = []
            for i in range(len(rgb)):
                keep = np.arange(len(rgb)) != i
                c = calibrate(rgb[keep], xyz[keep], white, degree=degree, refine=refine)
                loo.append(float(delta_e00(expand(rgb[i:i + 1], degree) @ c.matrix.T,
                                           xyz[i:i + 1], white)[0]))
            rows[method] = {"test_loo": _stats(loo), "train": _stats(train.delta_e_after),
                            "seconds": round(time.perf_counter() - start, 1)}
            print(f"{name:24s} {method:20s} LOO {np.mean(loo):.2f} ± {np.std(loo, ddof=1):.2f}   "
                  f"train {train.delta_e_after.mean():.2f} ± {train.delta_e_after.std(ddof=1):.2f}",
                  flush=True)
        results["sets"][name] = {"patches": int(len(rgb)), "files": [rgb_file, xyz_file],
                                 "methods": rows}
    out = ROOT / "benchmarks" / "results" / "colour_correction.json"
    out.write_text(json.dumps(results, indent=2) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
