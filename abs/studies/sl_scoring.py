"""The study's error measure: CIEDE2000 between tone-mapped renderings of the true and the
reconstructed BRDF on a sphere under an environment map (the seed paper's score).

Both renderings use abs's path tracer with the same seed (the same sample directions), so their
difference is the BRDF's, not Monte-Carlo noise. They are tone-mapped identically with Reinhard's
global operator (key 0.18, log-average luminance of the *true* rendering, L/(1 + L) on
luminance, colours scaled with it) and a 2.2 display gamma. The display values are decoded with
the same gamma to linear sRGB, converted to CIE L*a*b* (D65) and compared with CIEDE2000 on the
pixels the sphere covers; the score is the mean and standard deviation over those pixels.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from abs.camera.pinhole import intrinsics_from_fov, look_at
# The score itself lives in abs.metrics (shared with abs.appearance); re-exported here.
from abs.metrics import GAMMA, REINHARD_KEY, ciede2000_image, log_average_luminance, reinhard  # noqa: F401
from abs.render.bsdfs import tabulated as _tabulated  # noqa: F401  (registers abs_tabulated)
from abs.render.camera import Camera
from abs.render.environment import Environment
from abs.render.integrator import PathTracer
from abs.render.jit import from_numpy

__all__ = ["DEFAULT_ENVIRONMENT", "ScoreSettings", "Scorer", "ciede2000_image", "reinhard"]

DEFAULT_ENVIRONMENT = "polyhaven_hdri_1k/royal_esplanade_1k.hdr"
"""Environment map of the score, relative to the shared data folder."""


@dataclass(frozen=True)
class ScoreSettings:
    """Rendering of the score: image size (pixels), samples per pixel, seed, environment file."""

    size: int = 128
    spp: int = 64
    seed: int = 0
    environment: str = DEFAULT_ENVIRONMENT


class Scorer:
    """Renders a 100 mm sphere with a BRDF table under the environment and scores tables.

    Parameters
    ----------
    truth : np.ndarray
        The true table (MERL layout, 1/sr).
    environment : np.ndarray
        (H, W, 3) lat-long environment map, linear RGB.
    settings : ScoreSettings
        Image size, spp and seed.
    """

    def __init__(self, truth: np.ndarray, environment: np.ndarray, settings: ScoreSettings):
        self.settings = settings
        self.scene = mi.load_dict({"type": "scene", "sphere": {
            "type": "sphere", "radius": 0.05, "bsdf": {"type": "abs_tabulated", "id": "brdf"}}})
        self.params = mi.traverse(self.scene)
        self.key = next(k for k in self.params.keys() if k.endswith("table"))  # noqa: SIM118 (SceneParameters)
        self.environment = Environment(environment)
        size = settings.size
        R, t = look_at(np.array([0.0, 0.05, 0.35]), np.zeros(3))
        self.camera = Camera(intrinsics_from_fov(size, size, np.deg2rad(22.0)), R, t, size, size)
        self.mask = self._coverage()
        self.truth_image = self.render(truth)
        self.log_average = log_average_luminance(self.truth_image)
        self.truth_display = reinhard(self.truth_image, self.log_average)

    @classmethod
    def from_shared(cls, truth: np.ndarray, settings: ScoreSettings) -> Scorer:
        """With the environment map ``settings.environment`` from the shared data folder."""
        from abs.io.images import read_image
        from abs.io.shared_data import shared_data_dir

        path = Path(settings.environment)
        if not path.is_absolute():
            path = shared_data_dir() / path
        return cls(truth, read_image(path), settings)

    def _coverage(self) -> np.ndarray:
        w = h = self.settings.size
        idx = dr.arange(mi.UInt32, w * h)
        origin, d = self.camera.rays(mi.Float(idx % w), mi.Float(idx // w))
        hit = self.scene.ray_intersect(mi.Ray3f(origin, d)).is_valid()
        return np.asarray(hit, bool).reshape(h, w)

    def render(self, table: np.ndarray) -> np.ndarray:
        """(size, size, 3) linear rendering of the sphere with ``table`` (1/sr, MERL layout)."""
        self.params[self.key] = from_numpy(mi.Float, np.maximum(np.asarray(table, np.float32), 0.0))
        self.params.update()
        # Two segments: a convex sphere alone sees only the environment (no inter-reflection).
        image = PathTracer(max_depth=2).render(self.scene, self.environment, self.camera,
                                               self.settings.spp, seed=self.settings.seed)
        return np.asarray(image, np.float32)

    def score(self, table: np.ndarray) -> dict:
        """CIEDE2000 of ``table`` against the truth: mean and sd over the sphere's pixels, and
        the per-pixel map (NaN off the sphere)."""
        display = reinhard(self.render(table), self.log_average)
        delta = ciede2000_image(self.truth_display, display)
        on = delta[self.mask]
        return {"mean": float(on.mean()), "sd": float(on.std()), "display": display,
                "delta_e": np.where(self.mask, delta, np.nan)}
