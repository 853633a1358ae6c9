"""The spectral renderer's worker process: ``python -m abs.appearance.spectral_worker JOB.json``.

Mitsuba renders in one variant per set of Python plugins: abs activates ``llvm_ad_rgb`` and binds
its own plugins to it on import, so a spectral rendering runs here, in a process of its own
(:mod:`abs.appearance.spectral` starts it). Everything arrives as files, nothing as a pickle:

- the job (JSON, format ``abs-spectral-job/1``): ``variant``, ``scene`` (a Mitsuba scene dictionary
  in which a transform is ``{"$transform": 4x4 rows}``), ``environment`` (an EXR file, lit as an
  ``envmap``), ``spp``, ``seed`` and ``output`` (a ``.npy`` file written here, ``(H, W, 3)`` float32
  linear RGB);
- abs's own plugins are replaced by spectral equivalents (:func:`spectral_scene`).

Exit status 0 on success; 2 with a one-line message on standard error for a job the worker
refuses (unknown variant, a plugin with no spectral equivalent); anything else is a crash.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

__all__ = ["decode", "spectral_scene", "main"]

JOB_FORMAT = "abs-spectral-job/1"


class JobError(Exception):
    """A job the worker refuses; the message names the field."""


def decode(value):
    """A JSON value of the job's ``scene`` as a Mitsuba dictionary value (transforms rebuilt)."""
    import mitsuba as mi

    if isinstance(value, dict):
        if set(value) == {"$transform"}:
            return mi.ScalarTransform4f(value["$transform"])
        return {key: decode(item) for key, item in value.items()}
    if isinstance(value, list):
        return [decode(item) for item in value]
    return value


# The grid on which an unbounded RGB parameter is given to Mitsuba as a spectrum, nm.
_LAMBDA_MIN, _LAMBDA_MAX, _LAMBDA_STEP = 360.0, 830.0, 5.0


def _unbounded(value, where: str):
    """``value`` with every ``{"type": "rgb"}`` above 1 given as a ``regular`` spectrum.

    Mitsuba 3.9 in a spectral variant turns an RGB parameter into its ``srgb`` reflectance
    spectrum, which silently clamps values above 1 to a flat 1: a conductor's ``eta`` [3.2, 2.7,
    2.3] and ``k`` [3.3, 3.2, 3.1] would render as eta = k = 1 (measured: 60-77 % darker metals
    than the RGB render under a white sky). Such a value is upsampled here instead, with the
    same model and scale as the MERL tables (:func:`abs.appearance.spectral_tabulated.
    spectral_coefficients`), and sampled every 5 nm over 360-830 nm.
    """
    if isinstance(value, dict):
        if value.get("type") == "rgb" and max(map(float, value["value"])) > 1.0:
            from abs.appearance.spectral_tabulated import spectral_coefficients, srgb_model

            import numpy as np

            rgb = np.asarray(value["value"], np.float64).reshape(3, 1)
            lam = np.arange(_LAMBDA_MIN, _LAMBDA_MAX + 0.5 * _LAMBDA_STEP, _LAMBDA_STEP)
            spectrum = srgb_model(spectral_coefficients(rgb)[0], lam)
            return {"type": "regular", "wavelength_min": _LAMBDA_MIN, "wavelength_max": _LAMBDA_MAX,
                    "values": ", ".join(f"{x:.6g}" for x in spectrum)}
        return {key: _unbounded(item, f"{where}.{key}") for key, item in value.items()}
    return value


def _spectral_bsdf(bsdf: dict, where: str) -> dict:
    """A BSDF of the scene as the spectral variant can load it.

    ``abs_dielectric`` (abs's per-channel IOR glass, a Python plugin of the RGB variant) becomes
    Mitsuba's ``dielectric`` when it is the same in every channel, clear and smooth (all the
    appearance design's glass); ``abs_tabulated`` is kept, registered here in its spectral form
    (:mod:`abs.appearance.spectral_tabulated`); stock plugins pass unchanged (Mitsuba upsamples
    their RGB values itself) except RGB values above 1, which Mitsuba would clamp
    (:func:`_unbounded`).
    """
    kind = bsdf.get("type")
    if kind == "abs_dielectric":
        from abs.appearance.spectral import stock_glass_ior

        ior = stock_glass_ior(bsdf)
        if ior is None:
            raise JobError(f"{where}: abs_dielectric with dispersion, absorption or roughness has "
                           f"no spectral equivalent here (ior {bsdf.get('ior', 1.5)}, absorption "
                           f"{bsdf.get('absorption', 0.0)})")
        return {"type": "dielectric", "int_ior": ior, "ext_ior": 1.0,
                **({"id": bsdf["id"]} if "id" in bsdf else {})}
    if isinstance(kind, str) and kind.startswith("abs_") and kind != "abs_tabulated":
        raise JobError(f"{where}: abs's plugin {kind!r} has no spectral form")
    return _unbounded(bsdf, where)


def spectral_scene(scene: dict) -> dict:
    """``scene`` with the BSDF of every top-level shape made spectral (the design's layout)."""
    out = {}
    for key, value in scene.items():
        if isinstance(value, dict) and value.get("type") != "scene" and "bsdf" in value:
            value = {**value, "bsdf": _spectral_bsdf(value["bsdf"], f"scene.{key}.bsdf")}
        out[key] = value
    return out


def _run(job_path: Path) -> None:
    try:
        job = json.loads(job_path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise JobError(f"{job_path}: cannot read the job: {exc}") from exc
    if job.get("format") != JOB_FORMAT:
        raise JobError(f"{job_path}: format: expected {JOB_FORMAT!r}, got {job.get('format')!r}")
    import mitsuba as mi
    import numpy as np

    from abs.io.images import read_image

    variant = job["variant"]
    if variant not in mi.variants():
        raise JobError(f"variant: Mitsuba variant {variant!r} is not in this installation "
                       f"(available: {', '.join(mi.variants())})")
    if not variant.startswith(("llvm", "scalar", "cuda")) or "spectral" not in variant:
        raise JobError(f"variant: {variant!r} is not a spectral variant")
    # abs's package imports above set llvm_ad_rgb (and its libLLVM); switch before any plugin
    # class of the spectral variant is defined.
    from abs.render.variant import set_variant
    set_variant(variant) if variant.startswith("llvm") else mi.set_variant(variant)
    from abs.appearance import spectral_tabulated
    spectral_tabulated.register()

    scene = spectral_scene(decode(job["scene"]))
    environment = read_image(job["environment"])
    scene["emitter"] = {"type": "envmap", "bitmap": mi.Bitmap(environment)}
    image = mi.render(mi.load_dict(scene), spp=int(job["spp"]), seed=int(job["seed"]))
    np.save(job["output"], np.asarray(image, np.float32)[..., :3], allow_pickle=False)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1:
        print("usage: python -m abs.appearance.spectral_worker JOB.json", file=sys.stderr)
        return 2
    try:
        _run(Path(argv[0]))
    except JobError as exc:
        print(str(exc), file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
