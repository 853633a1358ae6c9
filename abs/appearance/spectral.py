"""Render a Mitsuba scene dictionary in a spectral variant, in a worker process.

abs runs Mitsuba's ``llvm_ad_rgb`` variant and binds its Python plugins to it on import, so a
spectral rendering cannot happen in abs's own process. :func:`render_spectral` writes the scene
(JSON) and the environment map (EXR) to a temporary folder, runs
``python -m abs.appearance.spectral_worker`` on them (:mod:`abs.appearance.spectral_worker`) and
reads the image back (``.npy``, read without pickles). Nothing of the user's is pickled.

Scene values that JSON cannot hold: a ``mi.ScalarTransform4f`` travels as ``{"$transform": rows}``;
anything else (a ``mi.Bitmap``, a texture object) is refused with the dictionary path that holds
it. The worker's refusals and crashes become an :class:`~abs.errors.InputError` on the field the
caller names (e.g. ``--option spectral``), quoting the worker's message.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from abs.errors import InputError
from abs.io.images import write_exr

__all__ = ["DEFAULT_SPECTRAL_VARIANT", "encode", "render_spectral", "stock_glass_ior"]

DEFAULT_SPECTRAL_VARIANT = "llvm_ad_spectral"
_MESSAGE_TAIL = 1500  # characters of the worker's standard error quoted in an error


def stock_glass_ior(bsdf: dict) -> float | None:
    """The IOR of an ``abs_dielectric`` scene-dictionary BSDF that stock Mitsuba glass
    reproduces (one IOR for every channel, clear, smooth); ``None`` for any other."""
    ior = np.broadcast_to(np.asarray(bsdf.get("ior", 1.5), np.float64), 3)
    clear = not np.any(np.asarray(bsdf.get("absorption", 0.0), np.float64))
    if np.ptp(ior) == 0 and clear and float(bsdf.get("roughness", 0.0)) == 0.0:
        return float(ior[0])
    return None


def encode(value, where: str = "scene"):
    """A Mitsuba scene-dictionary value as JSON data; ``where`` names it in errors."""
    import mitsuba as mi

    if isinstance(value, dict):
        return {str(k): encode(v, f"{where}.{k}") for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [encode(v, f"{where}[{i}]") for i, v in enumerate(value)]
    if isinstance(value, (bool, int, float, str)) or value is None:
        return value
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, mi.ScalarTransform4f):
        return {"$transform": np.asarray(value.matrix, np.float64).tolist()}
    raise InputError(None, where, f"a {type(value).__name__} cannot be sent to the spectral "
                                  "worker; give scene values as numbers, lists, strings or "
                                  "transforms")


def render_spectral(scene: dict, environment: np.ndarray, spp: int, seed: int, *,
                    variant: str = DEFAULT_SPECTRAL_VARIANT, field: str = "spectral",
                    timeout_s: float | None = None) -> np.ndarray:
    """Render ``scene`` lit by ``environment`` in a spectral Mitsuba variant.

    Parameters
    ----------
    scene : dict
        Mitsuba scene dictionary with an integrator and a sensor (``hdrfilm``, ``rgb``) and no
        emitter; abs's plugins ``abs_tabulated`` and clear, non-dispersive ``abs_dielectric``
        are replaced by their spectral forms in the worker.
    environment : np.ndarray
        ``(H, W, 3)`` lat-long linear RGB radiance (W m⁻² sr⁻¹ as abs uses it), lit as an
        ``envmap`` (Mitsuba upsamples it, illuminant-weighted, to spectra).
    spp, seed : int
        Samples per pixel and the sampler's seed.
    variant : str
        A spectral Mitsuba variant (``llvm_ad_spectral`` or ``scalar_spectral``).
    field : str
        What the caller calls this setting, named in errors (e.g. ``"--option spectral"``).
    timeout_s : float, optional
        Kill the worker after this many seconds.

    Returns
    -------
    np.ndarray
        ``(height, width, 3)`` float32 linear sRGB (Mitsuba's film converts the spectra via CIE XYZ).

    Raises
    ------
    InputError
        On ``field`` when the worker refuses the job, crashes, times out or writes no image.
    """
    job_scene = encode(scene)
    with tempfile.TemporaryDirectory(prefix="abs-spectral-") as tmp:
        tmp = Path(tmp)
        write_exr(tmp / "environment.exr", np.asarray(environment, np.float32))
        job = {"format": "abs-spectral-job/1", "variant": variant, "scene": job_scene,
               "environment": str(tmp / "environment.exr"), "spp": int(spp), "seed": int(seed),
               "output": str(tmp / "image.npy")}
        (tmp / "job.json").write_text(json.dumps(job), encoding="utf-8")
        # The worker must import this abs, whatever the installed one is.
        env = dict(os.environ)
        root = str(Path(__file__).resolve().parents[2])
        env["PYTHONPATH"] = os.pathsep.join([root, *filter(None, [env.get("PYTHONPATH")])])
        try:
            done = subprocess.run([sys.executable, "-m", "abs.appearance.spectral_worker",
                                   str(tmp / "job.json")], capture_output=True, text=True,
                                  env=env, timeout=timeout_s)
        except subprocess.TimeoutExpired as exc:
            raise InputError(None, field, f"the spectral worker ({variant}) did not finish in "
                                          f"{timeout_s} s") from exc
        message = done.stderr.strip()[-_MESSAGE_TAIL:]
        if done.returncode == 2:
            raise InputError(None, field, f"the spectral worker refused the job: {message}")
        if done.returncode != 0:
            # The traceback's last line says what broke; the tail before it says where.
            last = message.splitlines()[-1] if message else "(no message)"
            raise InputError(None, field, f"the spectral worker ({variant}) failed with exit "
                                          f"status {done.returncode}: {last}\n{message}")
        try:
            image = np.load(tmp / "image.npy", allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise InputError(None, field, f"the spectral worker wrote no readable image: {exc}") from exc
    return np.asarray(image, np.float32)
