"""Files of a sampling run.

A sample folder holds::

    chain.h5        emcee's HDF5 chain (group ``mcmc``) plus what it belongs to (group ``abs``)
    summary.json    per parameter: mean, sd, q05, q95, ess (lists per scalar), tau, r_hat, ...
    posterior.nc    ArviZ InferenceData (netCDF-4): walkers as chains, burn-in removed
    summary.csv     ArviZ's summary table (mean, sd, HDI, ESS, R-hat) of the same draws
    report/         report.html, corner plot, walker traces, posterior predictive images
"""

from __future__ import annotations

from pathlib import Path

from abs.runs.files import write_json

__all__ = ["write_sample_folder", "CHAIN_FILE", "SUMMARY_FILE", "NETCDF_FILE"]

CHAIN_FILE = "chain.h5"
SUMMARY_FILE = "summary.json"
NETCDF_FILE = "posterior.nc"


def write_sample_folder(folder: str | Path, result, report: bool = True) -> dict:
    """Write ``summary.json``, ``posterior.nc``, ``summary.csv`` and (unless ``report=False``)
    ``report/report.html`` for a :class:`~abs.sampling.SampleResult` whose chain is in
    ``folder/chain.h5``. Returns the summary."""
    import emcee

    from abs.sampling.inference_data import arviz, inference_data, write_netcdf

    folder = Path(folder)
    summary = result.summary()
    write_json(folder / SUMMARY_FILE, summary)
    idata = inference_data(result.chain, result.names, result.sizes, result.log_prob)
    write_netcdf(idata, folder / NETCDF_FILE)
    if result.chain.shape[0] >= 4:
        arviz().summary(idata).to_csv(folder / "summary.csv")
    if report:
        from abs.report.sample_report import write_sample_report

        full = emcee.backends.HDFBackend(str(folder / CHAIN_FILE), read_only=True).get_chain()
        write_sample_report(folder / "report", summary, full, result.chain, result.predictive)
    return summary
