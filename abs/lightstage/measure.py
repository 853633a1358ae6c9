"""Every pixel of every frame onto the mesh: light-stage measurements of ``f_r cos(theta_l)``.

For a frame taken at turntable angle ``a`` with one LED on, each pixel's camera ray is cast
against the mesh (in the object's frame, :mod:`~abs.lightstage.raycast`); from the hit point a
shadow ray goes to the LED. A lit pixel's value (per second of exposure, HDR-merged) is

``pixel = gain * L = gain * f_r(l, v) cos(theta_l) * I * (level / 255) * att(theta_led) / d^2``

so dividing by ``gain``, the LED's intensity and level, its radial attenuation ``att`` at the
angle off its axis and the inverse-square distance leaves ``f_r cos(theta_l)`` (1/sr) per channel:
the measurement. Shadowed pixels, pixels seen at grazing or from behind, and pixels clipped in
every exposure carry no information about ``f_r`` and are dropped.

Light groups are split into fitting and held-out sets (thesis: a fifth of the images held out):
group (position ``p``, LED ``k`` in sorted name order) is held out when ``(p + k) % 5 == 0``, so
every view and every LED appears in both sets, and the held-out images are new view/light pairs.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from abs.camera.pinhole import ray_directions
from abs.errors import InputError
from abs.lightstage.geometry import RigGeometry
from abs.lightstage.raycast import Hits, MeshTracer
from abs.lightstage.session import LightGroup
from abs.lightstage.surface import SurfacePoints

__all__ = ["Measurements", "PoseView", "pose_view", "led_irradiance", "is_held_out", "measure",
           "groups_json"]

MIN_COS = 0.05
"""Measurements with ``n.l`` or ``n.v`` below this are dropped (grazing: the normal's error
dominates, and the pixel straddles the silhouette)."""


def is_held_out(position: int, light: str, geometry: RigGeometry, every: int = 5) -> bool:
    """Whether light group (``position``, ``light``) belongs to the held-out set."""
    k = sorted(geometry.leds).index(light)
    return (position + k) % every == 0


@dataclass(frozen=True)
class PoseView:
    """What one camera sees of the object at one turntable angle.

    Attributes
    ----------
    pixel : np.ndarray
        (N,) flat pixel index (``v * width + u``) of every pixel whose ray hits the mesh.
    hits : Hits
        The hits of those rays (object frame).
    view : np.ndarray
        (N, 3) unit directions from the hit points to the camera (object frame).
    to_object : np.ndarray
        (3, 3) rotation from world into object frame at this angle.
    center : np.ndarray
        (3,) the turntable centre (a fixed point of the rotation).
    shape : tuple of int
        Image ``(height, width)``.
    """

    pixel: np.ndarray
    hits: Hits
    view: np.ndarray
    to_object: np.ndarray
    center: np.ndarray
    shape: tuple[int, int]

    def world_to_object(self, x: np.ndarray) -> np.ndarray:
        return (np.asarray(x) - self.center) @ self.to_object.T + self.center


def pose_view(geometry: RigGeometry, tracer: MeshTracer, camera: int, angle_deg: float) -> PoseView:
    """Cast one ray per pixel centre of ``camera`` at turntable angle ``angle_deg``."""
    cam = geometry.cameras[camera]
    v, u = np.mgrid[0:cam.height, 0:cam.width]
    origins, dirs = ray_directions(cam.K, cam.R, cam.t, np.stack([u.ravel(), v.ravel()], 1).astype(float))
    rot, center = geometry.object_to_world(angle_deg)
    to_object = rot.T
    o = (origins - center) @ to_object.T + center
    d = dirs @ to_object.T
    hits = tracer.intersect(o, d)
    idx = np.nonzero(hits.valid)[0]
    sub = Hits(hits.valid[idx], hits.triangle[idx], hits.barycentric[idx], hits.point[idx], hits.normal[idx])
    return PoseView(idx, sub, -d[idx], to_object, center, (cam.height, cam.width))


def led_irradiance(geometry: RigGeometry, tracer: MeshTracer, view: PoseView, light: str,
                   level: int) -> tuple[np.ndarray, np.ndarray]:
    """Light direction and the LED's ``I * att / d^2`` at every hit of ``view``.

    Returns
    -------
    wi : np.ndarray
        (N, 3) unit directions to the LED (object frame).
    factor : np.ndarray
        (N, 3) ``I (level / 255) att / d^2`` per channel (W/(m^2 sr) per unit ``f_r cos``), 0 where
        the LED is shadowed, behind the surface or behind itself.
    """
    led = geometry.leds[light]
    q = view.world_to_object(led.position)
    axis = led.axis @ view.to_object.T
    p, n = view.hits.point, view.hits.normal
    to = q - p
    d2 = np.sum(to * to, 1)
    wi = to / np.sqrt(d2)[:, None]
    att = geometry.attenuation(-wi @ axis)
    lit = (np.sum(wi * n, 1) > 0) & (att > 0)
    if lit.any():
        idx = np.nonzero(lit)[0]
        lit[idx] = tracer.visible(p[idx], n[idx], np.broadcast_to(q, (len(idx), 3)))
    factor = (led.intensity[None, :] * (level / 255.0) * (att / d2)[:, None]) * lit[:, None]
    return wi, factor


@dataclass(frozen=True)
class Measurements:
    """Light-stage measurements (object frame; M of them).

    Attributes
    ----------
    point : np.ndarray
        (M,) surface point index (:class:`~abs.lightstage.surface.SurfacePoints`).
    position, normal, light, view : np.ndarray
        (M, 3) hit point (metres), unit normal, unit direction to the LED, unit direction to the
        camera.
    value : np.ndarray
        (M, 3) ``f_r cos(theta_l)`` per RGB channel, 1/sr.
    group : np.ndarray
        (M,) index of the light group (frame bracket) the measurement came from.
    held_out : np.ndarray
        (M,) bool, from a held-out group.
    """

    point: np.ndarray
    position: np.ndarray
    normal: np.ndarray
    light: np.ndarray
    view: np.ndarray
    value: np.ndarray
    group: np.ndarray
    held_out: np.ndarray

    def __len__(self) -> int:
        return len(self.point)

    def select(self, mask: np.ndarray) -> Measurements:
        return Measurements(*(getattr(self, f)[mask] for f in self.__dataclass_fields__))

    def save(self, path: str | Path) -> None:
        np.savez_compressed(path, **{f: getattr(self, f) for f in self.__dataclass_fields__})

    @staticmethod
    def load(path: str | Path) -> Measurements:
        with np.load(path) as z:
            return Measurements(*(z[f] for f in Measurements.__dataclass_fields__))


def measure(geometry: RigGeometry, tracer: MeshTracer, points: SurfacePoints,
            groups: list[LightGroup], images: list[np.ndarray] | None = None,
            holdout_every: int = 5, log=None) -> Measurements:
    """Measurements from every lit, visible, unclipped pixel of every light group.

    Parameters
    ----------
    geometry, tracer, points
        The rig, the mesh (object frame) and its surface points.
    groups : list of LightGroup
        The session's LED groups (:func:`~abs.lightstage.session.read_session_groups`).
    images : list of np.ndarray, optional
        Their merged images (H, W, 3), pixel value per second; read from the groups' files when
        omitted.
    holdout_every : int
        Held-out split (:func:`is_held_out`); 0 holds nothing out.
    log : callable, optional
        Progress messages.
    """
    parts: list[tuple] = []
    views: dict[tuple[int, float], PoseView] = {}
    for gi, g in enumerate(groups):
        if g.light not in geometry.leds:
            raise InputError(None, "leds", f"the session's light {g.light!r} is not in the geometry file")
        key = (g.camera, g.angle_deg)
        if key not in views:
            views = {key: pose_view(geometry, tracer, g.camera, g.angle_deg)}  # one pose at a time
            if log:
                log(f"position {g.position} ({g.angle_deg:g} deg): {len(views[key].pixel)} pixels on the mesh")
        view = views[key]
        image = g.image() if images is None else images[gi]
        pix = image.reshape(-1, 3)[view.pixel].astype(np.float64)
        wi, factor = led_irradiance(geometry, tracer, view, g.light, g.level)
        n = view.hits.normal
        keep = ((factor.min(1) > 0) & np.all(np.isfinite(pix), 1)
                & (np.sum(n * wi, 1) > MIN_COS) & (np.sum(n * view.view, 1) > MIN_COS))
        idx = np.nonzero(keep)[0]
        value = pix[idx] / (geometry.gain * factor[idx])
        held = holdout_every > 0 and is_held_out(g.position, g.light, geometry, holdout_every)
        parts.append((points.lookup(view.hits.triangle[idx], view.hits.barycentric[idx]),
                      view.hits.point[idx], n[idx], wi[idx], view.view[idx], value,
                      np.full(len(idx), gi), np.full(len(idx), held)))
    cols = list(zip(*parts))
    f32 = [np.concatenate(c).astype(np.float32) for c in cols[1:6]]
    return Measurements(np.concatenate(cols[0]).astype(np.int64), *f32,
                        np.concatenate(cols[6]).astype(np.int64), np.concatenate(cols[7]).astype(bool))


def groups_json(groups: list[LightGroup], geometry: RigGeometry, holdout_every: int = 5) -> str:
    """The groups' identities and held-out flags as JSON, stored beside the measurements."""
    return json.dumps([{"position": g.position, "angle_deg": g.angle_deg, "light": g.light,
                        "level": g.level, "camera": g.camera,
                        "files": [str(f) for f in g.files], "exposures_s": list(g.exposures_s),
                        "held_out": bool(holdout_every > 0 and is_held_out(g.position, g.light, geometry,
                                                                           holdout_every))}
                       for g in groups], indent=1)
