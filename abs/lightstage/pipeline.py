"""The steps of ``abs lightstage`` as functions: mesh, measure, fit, held-out evaluation.

Files of a light-stage folder (written by the command, read by the next step):

- ``measurements.npz``: :class:`~abs.lightstage.measure.Measurements`;
- ``groups.json``: the session's light groups (position, angle, LED, files, held-out flag);
- ``points.npz``: the surface points (position, normal, triangle, barycentrics);
- ``fits.npz``: :class:`~abs.lightstage.fit.ModelFits`;
- ``fit.json``: converged fractions and parameter summaries;
- ``evaluation.json`` and ``renders/``: held-out MAE per model (thesis Eq. 4.1) and renders.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np

from abs.errors import InputError
from abs.lightstage.fit import ModelFits, fit_points
from abs.lightstage.geometry import RigGeometry
from abs.lightstage.measure import Measurements, pose_view
from abs.lightstage.models import MODELS, PARAMETERS
from abs.lightstage.normalise import normalise
from abs.lightstage.raycast import MeshTracer
from abs.lightstage.render import Reflectance, mae, render_view
from abs.lightstage.surface import SurfacePoints, build_surface_points

__all__ = ["load_mesh", "prepare", "fit_measurements", "evaluate_held_out", "HeldOutFrame",
           "parameter_summary"]

HeldOutFrame = tuple[int, float, str, int, float, np.ndarray]
"""``(camera, angle_deg, light, level, exposure_s, observed image)`` of one held-out frame."""


def load_mesh(path: str | Path):
    """The object's mesh (any format trimesh reads), in the object's frame, metres."""
    import trimesh

    path = Path(path)
    if not path.exists():
        raise InputError(path, "", "mesh not found (give --mesh, or put mesh.ply in the session folder)")
    try:
        mesh = trimesh.load(path, force="mesh", process=True)
    except Exception as exc:  # trimesh raises many types for unreadable files
        raise InputError(path, "", f"not a readable mesh ({type(exc).__name__}: {exc})") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise InputError(path, "", "no triangles in this mesh")
    return mesh


def prepare(mesh, spacing_m: float, max_depth: int = 6) -> tuple[MeshTracer, SurfacePoints]:
    """The ray tracer and the uniformly spaced surface points of ``mesh``."""
    normals = np.asarray(mesh.vertex_normals)
    tracer = MeshTracer(mesh.vertices, mesh.faces, normals)
    return tracer, build_surface_points(mesh.vertices, mesh.faces, spacing_m, max_depth, normals)


def fit_measurements(meas: Measurements, n_points: int, min_measurements: int = 8,
                     max_measurements: int | None = 400, progress=None) -> ModelFits:
    """Normalise the fitting (not held-out) measurements and fit every model per point."""
    train = meas.select(~meas.held_out)
    iso = normalise(train.normal.astype(np.float64), train.light.astype(np.float64),
                    train.view.astype(np.float64))
    return fit_points(train.point, iso.cos_l, iso.cos_v, iso.cos_h, train.value.astype(np.float64),
                      n_points, min_measurements, max_measurements, progress)


def evaluate_held_out(geometry: RigGeometry, tracer: MeshTracer, frames: Iterable[HeldOutFrame],
                      reflectances: dict[str, Reflectance],
                      on_render: Callable[[int, str, np.ndarray], None] | None = None,
                      select: Callable[[np.ndarray], np.ndarray] | None = None) -> dict[str, float]:
    """Thesis Eq. 4.1 over held-out frames: MAE of pixel values in [0, 1] inside the object mask.

    The mask of a frame is the pixels whose ray hits the mesh (and, with ``select``, whose hit
    point, object frame, it accepts: ``select(points) -> (N,) bool``, e.g. one material's region).
    Returns ``{model: MAE}`` pooled over every frame's masked pixels and channels;
    ``on_render(frame_index, model, image)`` sees each render.
    """
    sums = {m: 0.0 for m in reflectances}
    count = 0
    view, key = None, None
    for k, (camera, angle, light, level, exposure, observed) in enumerate(frames):
        if key != (camera, angle):
            view, key = pose_view(geometry, tracer, camera, angle), (camera, angle)
        mask = np.zeros(view.shape[0] * view.shape[1], bool)
        mask[view.pixel if select is None else view.pixel[select(view.hits.point)]] = True
        n = 0
        for m, refl in reflectances.items():
            image = render_view(geometry, tracer, view, light, level, exposure, refl)
            s, n = mae(image, observed, mask)
            sums[m] += s
            if on_render is not None:
                on_render(k, m, image)
        count += n
    if count == 0:
        raise InputError(None, "held-out", "no held-out pixels on the object")
    return {m: sums[m] / count for m in reflectances}


def parameter_summary(fits: ModelFits) -> dict:
    """Median (over fitted points) of each model's parameters per channel, for ``fit.json``."""
    out = {}
    fitted = fits.count > 0
    for m in MODELS:
        p = fits.params[m][fitted]
        out[m] = {name: np.nanmedian(p[:, :, i], axis=0).round(5).tolist() if len(p) else None
                  for i, name in enumerate(PARAMETERS[m])}
    return out
