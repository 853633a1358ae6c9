"""Posterior sampling: how certain the fitted parameters are (``abs.sample``).

emcee's ensemble sampler on the posterior of the same parameters, bounds and priors as
``abs.fit``, with a Gaussian likelihood whose variance holds the photographs' noise and the
renderer's Monte-Carlo noise (docs/sampling.md).
"""

from abs.sampling.sample import SampleResult, SampleSettings, read_start, sample

__all__ = ["sample", "SampleSettings", "SampleResult", "read_start"]
