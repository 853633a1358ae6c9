"""Posterior predictive images: the mean rendering and per-pixel spread over posterior draws.

Every draw is rendered with the same seed (common random numbers), so the per-pixel standard
deviation shows how the parameters' uncertainty moves the image, not Monte-Carlo noise; the mean
still carries the noise of one render at ``spp``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["PredictiveView", "posterior_predictive"]


@dataclass(frozen=True)
class PredictiveView:
    """One view: photograph, mean rendering and per-pixel sd over posterior draws (H, W, 3),
    full resolution, linear RGB."""

    name: str
    holdout: bool
    photograph: np.ndarray
    mean: np.ndarray
    sd: np.ndarray


def posterior_predictive(model, chain: np.ndarray, draws: int, spp: int, seed: int,
                         clamp: float | None = None) -> list[PredictiveView]:
    """Render every view of the model's capture (holdout views included) at ``draws`` posterior
    samples spread evenly over the flattened ``chain``.

    Parameters
    ----------
    model : abs.model.ForwardModel
        The sampled model; its renders are counted by its counter.
    chain : ndarray, shape (S, W, P)
        Steps, walkers, scalars (the model vector's units).
    draws : int
        Posterior samples to render.
    spp : int
        Samples per pixel.
    seed : int
        The one seed of every draw's render (common random numbers).
    clamp : float or None
        Clamp of the compared renderings, as in the likelihood.

    Returns
    -------
    list of PredictiveView
    """
    flat = chain.reshape(-1, chain.shape[-1])
    if draws < 1 or flat.shape[0] == 0:
        return []
    picks = flat[np.linspace(0, flat.shape[0] - 1, min(draws, flat.shape[0])).astype(int)]
    problem = model.problem("all", 1, clamp)
    out = []
    for obs in problem.observations:
        images = np.stack([problem.render(obs, theta, spp, seed) for theta in picks])
        out.append(PredictiveView(obs.name, obs.holdout, obs.photograph, images.mean(axis=0),
                                  images.std(axis=0, ddof=1) if len(picks) > 1
                                  else np.zeros_like(images[0])))
    problem.set_values(picks.mean(axis=0))
    return out
