"""BRDF samples from the scanner's HDR images.

For every vertex of the scanner's mesh, every turntable step and every camera, the vertex is
projected into the image (OpenCV convention), the radiance ``L`` there is read by bilinear
interpolation, and, with ``ωi`` towards the light at distance ``d`` and ``ωo`` towards the camera,

    f(ωi, ωo) = L / ((ωi·n) I / d²)

is one BRDF sample (1/sr, per RGB channel). A sample is kept only when the vertex faces both the
light and the camera (ωi·n > 0, ωo·n > 0: the back-facing test), neither the light nor the camera
is hidden by the mesh (shadow and visibility rays, Mitsuba's ``ray_test``), it projects inside
the image, and the four pixels it is interpolated from are valid (:func:`valid_pixels`: not next to a
pixel without signal, so not partly covered by background or unlit surface).
Everything uses the scanner's estimate (:class:`~abs.studies.sl_noise.ScanEstimate`),
never the truth, except the images themselves.
"""

from __future__ import annotations

from dataclasses import dataclass

import mitsuba as mi
import numpy as np

from abs.render.jit import from_numpy
from abs.studies.sl_capture import SURFACE_OFFSET_M, sample_scene
from abs.studies.sl_noise import ScanEstimate, tangent_frame
from abs.studies.sl_rig import ScannerRig

__all__ = ["BRDFSamples", "bilinear", "brdf_samples", "valid_pixels"]


@dataclass(frozen=True)
class BRDFSamples:
    """BRDF observations in each vertex's local frame (z = the scanner's normal).

    Attributes
    ----------
    wi : np.ndarray
        (M, 3) unit directions towards the light.
    wo : np.ndarray
        (M, 3) unit directions towards the camera.
    f : np.ndarray
        (M, 3) BRDF values, 1/sr, R, G, B.
    candidates : int
        Vertex-view pairs examined before the tests.
    """

    wi: np.ndarray
    wo: np.ndarray
    f: np.ndarray
    candidates: int

    @property
    def count(self) -> int:
        return int(self.f.shape[0])


def valid_pixels(image: np.ndarray) -> np.ndarray:
    """Pixels whose 3 x 3 neighbourhood all holds signal (some channel > 0), (H, W) bool.

    The scanner's valid-pixel mask: a pixel next to one without signal may be partly covered by
    background (silhouettes) or unlit surface (shadow edges), so its value is no surface radiance.
    """
    signal = np.pad(image.max(axis=2) > 0.0, 1, constant_values=False)
    h, w = image.shape[:2]
    valid = np.ones((h, w), bool)
    for dv in range(3):
        for du in range(3):
            valid &= signal[dv:dv + h, du:du + w]
    return valid


def bilinear(image: np.ndarray, u: np.ndarray, v: np.ndarray,
             valid: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Bilinear lookup of an (H, W, C) image at pixel positions (pixel centres at integers).

    Positions must lie in [0, W-1] x [0, H-1]. Returns the values (N, C) and whether all four
    pixels blended are ``valid`` (:func:`valid_pixels` of the image when omitted).
    """
    h, w = image.shape[:2]
    valid = valid_pixels(image) if valid is None else valid
    u0 = np.clip(np.floor(u).astype(np.int64), 0, max(w - 2, 0))
    v0 = np.clip(np.floor(v).astype(np.int64), 0, max(h - 2, 0))
    fu = (u - u0)[:, None]
    fv = (v - v0)[:, None]
    u1, v1 = np.minimum(u0 + 1, w - 1), np.minimum(v0 + 1, h - 1)
    ok = valid[v0, u0] & valid[v0, u1] & valid[v1, u0] & valid[v1, u1]
    top = image[v0, u0] * (1 - fu) + image[v0, u1] * fu
    bottom = image[v1, u0] * (1 - fu) + image[v1, u1] * fu
    return top * (1 - fv) + bottom * fv, ok


def _unoccluded(scene: mi.Scene, origins: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """Whether the segments origins -> targets (N, 3) are free of the scene's surfaces."""
    if not len(origins):  # Dr.Jit aborts on zero-width ray batches
        return np.zeros(0, bool)
    delta = targets - origins
    dist = np.linalg.norm(delta, axis=1)
    d = delta / dist[:, None]
    o = mi.Point3f(*[from_numpy(mi.Float, origins[:, i]) for i in range(3)])
    ray = mi.Ray3f(o, mi.Vector3f(*[from_numpy(mi.Float, d[:, i]) for i in range(3)]),
                   from_numpy(mi.Float, dist * (1.0 - 1e-4)), 0.0, mi.Color0f())
    return ~np.asarray(scene.ray_test(ray), bool)


def brdf_samples(images: np.ndarray, rig: ScannerRig, estimate: ScanEstimate) -> BRDFSamples:
    """All BRDF samples of a scan under the scanner's estimate.

    Parameters
    ----------
    images : np.ndarray
        (steps, cameras, H, W, 3) radiance from :func:`~abs.studies.sl_capture.render_scan`.
    rig : ScannerRig
        Cameras and turntable (the cameras are taken as exactly calibrated).
    estimate : ScanEstimate
        The scanner's mesh, light position and light intensity.
    """
    mesh = estimate.mesh
    p, n = mesh.vertices, mesh.normals / np.linalg.norm(mesh.normals, axis=1, keepdims=True)
    tangent, bitangent = tangent_frame(n)
    occluder = sample_scene(mesh)
    origin = p + n * SURFACE_OFFSET_M
    out_wi, out_wo, out_f = [], [], []
    candidates = 0
    masks = [[valid_pixels(image) for image in step] for step in images]
    for k, angle in enumerate(rig.turntable_angles):
        light = rig.light_at_step(angle, estimate.light_position)
        to_light = light - p
        dist2 = np.einsum("ij,ij->i", to_light, to_light)
        wi = to_light / np.sqrt(dist2)[:, None]
        cos_i = np.einsum("ij,ij->i", wi, n)
        lit = cos_i > 0.0
        lit[lit] = _unoccluded(occluder, origin[lit], np.broadcast_to(light, (int(lit.sum()), 3)))
        for c, cam in enumerate(rig.cameras):
            cam_k = cam.at_step(angle)
            candidates += len(p)
            centre = cam_k.center
            wo = centre - p
            wo /= np.linalg.norm(wo, axis=1, keepdims=True)
            x_cam = p @ cam_k.R.T + cam_k.t
            uvw = x_cam @ cam_k.K.T
            u, v = uvw[:, 0] / uvw[:, 2], uvw[:, 1] / uvw[:, 2]
            keep = lit & (np.einsum("ij,ij->i", wo, n) > 0.0) & (x_cam[:, 2] > 0.0)
            keep &= (u >= 0) & (u <= cam.width - 1) & (v >= 0) & (v <= cam.height - 1)
            idx = np.flatnonzero(keep)
            idx = idx[_unoccluded(occluder, origin[idx], np.broadcast_to(centre, (len(idx), 3)))]
            if not len(idx):
                continue
            radiance, signal = bilinear(images[k, c], u[idx], v[idx], masks[k][c])
            idx, radiance = idx[signal], radiance[signal]
            irradiance = cos_i[idx] * estimate.light_intensity / dist2[idx]
            frame = (tangent[idx], bitangent[idx], n[idx])
            out_wi.append(np.stack([np.einsum("ij,ij->i", wi[idx], a) for a in frame], axis=1))
            out_wo.append(np.stack([np.einsum("ij,ij->i", wo[idx], a) for a in frame], axis=1))
            out_f.append(radiance / irradiance[:, None])
    if not out_f:
        empty = np.zeros((0, 3))
        return BRDFSamples(empty, empty, empty, candidates)
    return BRDFSamples(np.concatenate(out_wi), np.concatenate(out_wo), np.concatenate(out_f), candidates)
