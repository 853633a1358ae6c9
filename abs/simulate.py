"""Synthetic captures of a scene: calibrated cameras around it, photographs rendered at high spp,
optional sensor noise, and a record of the truth. Tests and benchmarks fit against these.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Callable

import numpy as np

from abs.camera.pinhole import intrinsics_from_fov, look_at
from abs.errors import read_json
from abs.scene.scene import Scene

__all__ = ["place_cameras", "simulate_capture", "add_sensor_noise", "read_truth"]


def _object_bounds(compiled) -> list[tuple[np.ndarray, np.ndarray]]:
    return [(np.array(box.min, float).ravel(), np.array(box.max, float).ravel())
            for box in (shape.bbox() for shape in compiled.mitsuba_scene.shapes())]


def place_cameras(compiled, n_cameras: int, width: int, height: int, fov_deg: float = 30.0,
                  azimuth_range_deg: tuple[float, float] = (-50.0, 50.0),
                  elevation_deg: float = 20.0, object_fraction: float = 0.5) -> list[dict]:
    """Cameras on an arc in front of the scene (+z side, +y up), looking at its solid objects.

    The target is the centre of the bounding box of all non-flat objects (e.g. the glass on the
    table, not the table or backdrop); the distance makes that box's bounding sphere span
    ``object_fraction`` of the vertical field of view (default: about half). ``elevation_deg``
    is the cameras' angle above the horizontal (degrees): low elevations see the backdrop
    through a low object, as a photographer framing glass before a printed pattern does.

    Returns
    -------
    list of dict
        ``name``, ``K``, ``R``, ``t`` per camera (OpenCV convention).
    """
    bounds = _object_bounds(compiled)
    solid = [(lo, hi) for lo, hi in bounds if np.min(hi - lo) > 1e-6] or bounds
    lo = np.min([b[0] for b in solid], axis=0)
    hi = np.max([b[1] for b in solid], axis=0)
    target = (lo + hi) / 2
    radius = max(float(np.linalg.norm(hi - lo)) / 2, 1e-3)
    if not 0 < object_fraction < 1:
        raise ValueError(f"object_fraction must lie in (0, 1), got {object_fraction}")
    distance = radius / np.tan(np.radians(fov_deg) * object_fraction / 2)
    K = intrinsics_from_fov(width, height, np.radians(fov_deg))
    azimuths = np.linspace(*azimuth_range_deg, n_cameras) if n_cameras > 1 else [0.0]
    elev = np.radians(elevation_deg)
    views = []
    for i, az in enumerate(np.radians(azimuths)):
        eye = target + distance * np.array([np.cos(elev) * np.sin(az), np.sin(elev), np.cos(elev) * np.cos(az)])
        R, t = look_at(eye, target)
        views.append({"name": f"v{i}", "K": K, "R": R, "t": t})
    return views


def add_sensor_noise(image: np.ndarray, shot_noise: float, read_noise: float,
                     rng: np.random.Generator) -> np.ndarray:
    """Poisson-Gaussian sensor noise approximated as Gaussian with variance
    ``shot_noise * I + read_noise**2`` per pixel and channel (I: linear intensity)."""
    variance = shot_noise * np.maximum(image, 0.0) + read_noise ** 2
    return (image + rng.normal(size=image.shape) * np.sqrt(variance)).astype(np.float32)


def simulate_capture(scene: Scene, folder: str | Path, n_cameras: int = 4, width: int = 320,
                     height: int = 240, fov_deg: float = 30.0, spp: int = 512,
                     n_holdout: int | None = None, shot_noise: float = 0.0, read_noise: float = 0.0,
                     seed: int = 0, on_view: Callable[[str], None] | None = None,
                     render: Callable | None = None, elevation_deg: float = 20.0,
                     object_fraction: float = 0.5):
    """Render a synthetic capture folder of ``scene`` from cameras placed by :func:`place_cameras`
    (``fov_deg``, ``elevation_deg`` and ``object_fraction`` are passed on).

    Writes ``cameras.json``, one EXR per view and ``simulation.json`` (settings and the true value
    of every scalar parameter). The last ``n_holdout`` views are holdout views (default: 1 when
    there are at least 3 views).

    ``render(compiled, camera, spp, seed) -> (H, W, 3) ndarray`` replaces abs's renderer for the
    photographs (before noise): benchmarks make photographs with physics that the fitted model
    only approximates (:mod:`abs.render.sensor_truth`, :mod:`abs.render.medium_truth`).

    Returns
    -------
    abs.io.capture.Capture
    """
    from abs.io.capture import save_capture
    from abs.render import Camera, compile_scene

    folder = Path(folder)
    compiled = compile_scene(scene)
    views = place_cameras(compiled, n_cameras, width, height, fov_deg, elevation_deg=elevation_deg,
                          object_fraction=object_fraction)
    n_holdout = (1 if n_cameras >= 3 else 0) if n_holdout is None else n_holdout
    rng = np.random.default_rng(seed)
    images = {}
    for i, view in enumerate(views):
        view["holdout"] = i >= n_cameras - n_holdout
        camera = Camera(np.asarray(view["K"]), np.asarray(view["R"]), np.asarray(view["t"]), width, height)
        view_seed = 10_000 + seed * 1000 + i
        image = (compiled.render(camera, spp=spp, seed=view_seed).numpy() if render is None
                 else np.asarray(render(compiled, camera, spp, view_seed), np.float32))
        images[view["name"]] = add_sensor_noise(image, shot_noise, read_noise, rng)
        if on_view is not None:
            on_view(view["name"])
    capture = save_capture(folder, views, images)
    truth = {name: compiled.get(name).tolist() for name, spec in compiled.specs.items()
             if spec.size != -1}
    record = {"scene": str(scene.source), "spp": spp, "seed": seed, "shot_noise": shot_noise,
              "read_noise": read_noise, "width": width, "height": height, "fov_deg": fov_deg,
              "elevation_deg": elevation_deg, "object_fraction": object_fraction, "truth": truth}
    (folder / "simulation.json").write_text(json.dumps(record, indent=2))
    return capture


def read_truth(capture: str | Path, names) -> dict[str, list] | None:
    """True values of ``names`` recorded in a synthetic capture's ``simulation.json``, or ``None``
    for a real capture (or when none of ``names`` was recorded)."""
    path = Path(capture) / "simulation.json"
    if not path.exists():
        return None
    known = read_json(path, what="simulation record").get("truth", {})
    return {n: known[n] for n in names if n in known} or None
