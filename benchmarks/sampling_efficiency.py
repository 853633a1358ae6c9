"""Effective samples per second and per render: emcee rendering every evaluation, emcee on
path-length recordings, and the adaptive independence sampler, on the same posterior, in one run.

One synthetic glass capture (default scene; glass absorption per RGB channel and the environment
scale), one ``abs.fit``; then ``abs.sample`` twice from the same start: rendering both fixed-seed
renders at every evaluation (``reweight=False``, as before path-length recordings), and from
recordings (``abs.render.path_lengths``: the two seeds' renders are made once and reweighted at
every evaluation). The rendered run's prepared posterior is then sampled by the independence
Metropolis-Hastings sampler of ``abs.sampling.independence`` (a Student-t proposal from the
Laplace covariance at the mode, adapted by importance sampling on a third of its evaluations).
Effective sample size per scalar: samples / integrated autocorrelation time (emcee's estimator,
burn-in removed); the worst scalar counts. Renders per row: the chain's likelihood renders, and
for the recorded run also everything its preparation rendered (noise model, mode, calibration),
since there the chain renders nothing. Whether the recorded and rendered posteriors are equal is
measured by importance weights on the recorded chain (:func:`importance_check`), free of the
rendered samplers' own mixing error. Writes ``benchmarks/results/sampling_efficiency.json``.

    python benchmarks/sampling_efficiency.py [--evaluations 240 --recorded-evaluations 32000 --width 32 --height 24 --spp 512]
"""

from __future__ import annotations

import argparse
import json
import platform
import tempfile
import time
from pathlib import Path

import numpy as np
from emcee.autocorr import integrated_time

from abs.fitting import FitSettings, fit
from abs.runs.files import write_json
from abs.sampling import SampleSettings, sample
from abs.sampling.independence import independence_sampler
from sampling_data import PARAMETER, make_dataset

RESULTS = Path(__file__).resolve().parent / "results" / "sampling_efficiency.json"
TRUTH = np.array([4.0, 6.0, 8.0])


def importance_check(recorded, rendered_posterior, points: int) -> dict:
    """The rendered posterior's moments from the recorded chain, by importance weights.

    The rendered samplers' moments carry their own mixing error (two of them, sampling the very
    same rendered posterior, differed by up to 0.41 sd in 960 evaluations), which is larger than
    the difference under test. Instead, at ``points`` samples spread over the recorded chain both
    log-posteriors are evaluated (the rendered one renders its two fixed-seed images), and the
    weights ``exp(lp_rendered - lp_recorded)`` turn the recorded chain's samples into samples of
    the rendered posterior: the difference of weighted and unweighted moments over the same
    samples is the posteriors' difference, without either sampler's mixing error (equal
    posteriors: weights all alike, ``log_weight_sd`` near 0).
    """
    flat = recorded.chain.reshape(-1, recorded.chain.shape[-1])
    thetas = flat[np.linspace(0, len(flat) - 1, points).round().astype(int)]
    lp_recorded = np.array([recorded.posterior(t) for t in thetas])
    t0 = time.perf_counter()
    lp_rendered = np.array([rendered_posterior(t) for t in thetas])
    wall = time.perf_counter() - t0
    log_w = lp_rendered - lp_recorded
    w = np.exp(log_w - log_w.max())
    w /= w.sum()
    mean, sd = thetas.mean(axis=0), thetas.std(axis=0)
    mean_w = w @ thetas
    sd_w = np.sqrt(w @ (thetas - mean_w) ** 2)
    return {"points": points, "renders": 2 * points, "wall_s": wall,
            "log_weight_sd": float(np.std(log_w)), "weights_ess": float(1.0 / np.sum(w ** 2)),
            "mean_shift_in_sd": ((mean_w - mean) / sd).tolist(), "sd_ratio": (sd_w / sd).tolist()}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--evaluations", type=int, default=240, help="log-posterior evaluations per sampler")
    p.add_argument("--width", type=int, default=32)
    p.add_argument("--height", type=int, default=24)
    p.add_argument("--spp", type=int, default=512, help="sampler renders (abs sample's default)")
    p.add_argument("--fit-spp", type=int, default=64, help="the starting fit's renders")
    p.add_argument("--walkers", type=int, default=8)
    p.add_argument("--recorded-evaluations", type=int, default=32000,
                   help="log-posterior evaluations of the recorded run (they render nothing)")
    p.add_argument("--importance-points", type=int, default=200,
                   help="recorded-chain samples at which the rendered posterior is evaluated too "
                        "(importance weights: the rendered posterior's moments at the recorded "
                        "chain's precision)")
    args = p.parse_args()

    names = [PARAMETER, "environment.scale"]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        capture = make_dataset(tmp, TRUTH, args.width, args.height, seed=11)
        fitted = fit(tmp / "scene.toml", capture, names,
                     FitSettings(spp=args.fit_spp, downsample=2, max_iterations=8, refinement_steps=2),
                     initial={PARAMETER: [6.0, 6.0, 6.0]})
        start = {n: {"value": fitted.summary()["parameters"][n]["value"],
                     "stderr": fitted.summary()["parameters"][n]["stderr"]} for n in names}
        steps = args.evaluations // args.walkers - 1
        runs = {}
        for reweight in (False, True):
            stages, t0 = {}, time.perf_counter()
            result = sample(tmp / "scene.toml", capture, names,
                            SampleSettings(spp=args.spp, downsample=2, walkers=args.walkers,
                                           max_steps=(args.recorded_evaluations // args.walkers - 1
                                                      if reweight else steps),
                                           predictive_draws=0, reweight=reweight),
                            chain_path=tmp / f"chain_{reweight}.h5", start=start,
                            on_stage=lambda message, st=stages: st.setdefault(message.split(" (")[0],
                                                                              time.perf_counter()))
            runs[reweight] = (result, stages, t0, time.perf_counter())
        result, stages, t0, t_end = runs[False]
        s = result.summary()
        per_eval = 2 * 1  # two fixed-seed renders of the one training view
        wall_emcee = stages["posterior predictive"] - stages["chain"]
        preparation = {"wall_s": stages["chain"] - t0,
                       "renders": s["renders"] - s["evaluations"] * per_eval,
                       "sample_wall_s": t_end - t0}

        def ess_min(summary):
            return min((e for n in names for e in summary["parameters"][n]["ess"] if e is not None),
                       default=np.nan)

        def moments(summary, key):
            return [v for n in names for v in summary["parameters"][n][key]]

        ess_emcee = ess_min(s)
        rec, rec_stages, rec_t0, rec_end = runs[True]
        rs = rec.summary()

        # The same calibrated posterior (noise model, seeds, offset, compiled scene) for the
        # independence sampler, proposing from its own Laplace approximation at the mode:
        # J^T diag(1/variance) J with the likelihood's per-pixel variance.
        t0 = time.perf_counter()
        posterior, theta = result.posterior, result.mode
        _, J = posterior.problem().residuals(theta, args.spp, posterior.seeds[0], jacobian=True)
        cov = np.linalg.inv(J.T @ (J / posterior.variance[:, None]))
        adapt = args.evaluations // 3
        run = independence_sampler(posterior, theta, cov, args.evaluations - adapt - J.shape[1],
                                   adapt_evaluations=adapt, seed=3)
        wall_ind = time.perf_counter() - t0
        chain = run.chain
        ess_ind = float(np.min(chain.shape[0] / integrated_time(chain[:, None, :], quiet=True)))
        importance = importance_check(rec, result.posterior, args.importance_points)

    rows = {
        "emcee": {"evaluations": s["evaluations"], "renders": s["evaluations"] * per_eval,
                  "wall_s": wall_emcee, "ess_min": ess_emcee, "acceptance": s["acceptance_fraction"],
                  "mean": moments(s, "mean"), "sd": moments(s, "sd")},
        # The Jacobian costs one attached render per scalar, counted as one evaluation each.
        "independence_adaptive": {"evaluations": run.evaluations + J.shape[1],
                                  "renders": (run.evaluations + J.shape[1]) * per_eval,
                                  "wall_s": wall_ind, "ess_min": ess_ind,
                                  "acceptance": run.acceptance_fraction,
                                  "mean": chain.mean(axis=0).tolist(), "sd": chain.std(axis=0).tolist()},
        # Every render of the run (preparation included): its chain renders nothing.
        "emcee_recorded": {"evaluations": rs["evaluations"], "renders": rs["renders"],
                           "wall_s": rec_stages["posterior predictive"] - rec_stages["chain"],
                           "ess_min": ess_min(rs), "acceptance": rs["acceptance_fraction"],
                           "mean": moments(rs, "mean"), "sd": moments(rs, "sd"),
                           "sample_wall_s": rec_end - rec_t0},
    }
    for row in rows.values():
        row["ess_per_s"] = row["ess_min"] / row["wall_s"]
        row["ess_per_render"] = row["ess_min"] / row["renders"]
    ratios = {k: rows["independence_adaptive"][k] / rows["emcee"][k] for k in ("ess_per_s", "ess_per_render")}
    recorded = {"ess_per_render": rows["emcee_recorded"]["ess_per_render"] / rows["emcee"]["ess_per_render"],
                "ess_per_s": rows["emcee_recorded"]["ess_per_s"] / rows["emcee"]["ess_per_s"],
                # Equal posterior: means within 0.2 sd, sds within 10 %.
                "mean_shift_in_sd": (np.abs(np.subtract(rows["emcee_recorded"]["mean"], rows["emcee"]["mean"]))
                                     / np.array(rows["emcee"]["sd"])).tolist(),
                "sd_ratio": (np.array(rows["emcee_recorded"]["sd"]) / np.array(rows["emcee"]["sd"])).tolist()}
    print(f"{'sampler':<22} {'evals':>6} {'wall s':>7} {'min ESS':>8} {'ESS/s':>7} {'ESS/render':>11} {'accept':>7}")
    for name, r in rows.items():
        print(f"{name:<22} {r['evaluations']:>6} {r['wall_s']:>7.1f} {r['ess_min']:>8.1f} "
              f"{r['ess_per_s']:>7.3f} {r['ess_per_render']:>11.4f} {r['acceptance']:>7.2f}")
    print(f"shared preparation (noise model, mode, calibration): {preparation['wall_s']:.1f} s, "
          f"{preparation['renders']} renders")
    print(f"ratio independence / emcee: ESS/s {ratios['ess_per_s']:.2f}, ESS/render "
          f"{ratios['ess_per_render']:.2f}")
    print(f"recorded / rendered emcee: ESS/render {recorded['ess_per_render']:.1f}, ESS/s "
          f"{recorded['ess_per_s']:.1f}; means apart by {np.round(recorded['mean_shift_in_sd'], 2)} sd, "
          f"sd ratios {np.round(recorded['sd_ratio'], 3)}")
    print(f"rendered posterior by importance weights on {importance['points']} recorded samples "
          f"({importance['renders']} renders): log-weight sd {importance['log_weight_sd']:.3f}, "
          f"weights' ESS {importance['weights_ess']:.0f}; means apart by "
          f"{np.round(importance['mean_shift_in_sd'], 3)} sd, sd ratios {np.round(importance['sd_ratio'], 3)}")
    report = {"truth": TRUTH.tolist(), "parameters": names, "fit": start, "mode": result.mode.tolist(),
              "render_scale": result.noise.render_scale, "preparation": preparation,
              "samplers": rows,
              "ratio_independence_over_emcee": ratios, "recorded_over_rendered_emcee": recorded,
              "rendered_by_importance": importance,
              "config": vars(args),
              "machine": platform.platform()}
    write_json(RESULTS, json.loads(json.dumps(report, default=float).replace("NaN", "null")))
    print(f"wrote {RESULTS}")


if __name__ == "__main__":
    main()
