"""``abs brdf ...``: the measured-BRDF tools (materials, MERL tables, the PCA basis, measurement plans)."""

from __future__ import annotations

from pathlib import Path


def add_parser(sub) -> None:
    from abs.brdf.measured import STUDY_MATERIALS
    from abs.brdf.pca import DEFAULT_EPSILON

    p = sub.add_parser("brdf", help="measured BRDFs: list materials, export MERL tables, build the PCA basis, plan measurement directions")
    commands = p.add_subparsers(dest="brdf_command", required=True)
    merl_help = "folder of real MERL <name>.binary files (default: the neural fits in the shared data)"

    names = commands.add_parser("materials", help="list the measured materials")
    names.add_argument("--merl-dir", type=Path, help=merl_help)
    names.set_defaults(run=run_materials)

    export = commands.add_parser("export", help="write a material's table as a MERL .binary file")
    export.add_argument("material", help="material name, e.g. blue-rubber")
    export.add_argument("--out", type=Path, required=True, help="the .binary file to write")
    export.add_argument("--merl-dir", type=Path, help=merl_help)
    export.set_defaults(run=run_export)

    build = commands.add_parser("build-basis", help="build the PCA basis (.npz, docs/brdf.md)")
    build.add_argument("--out", type=Path, required=True, help="basis file to write (.npz)")
    build.add_argument("--exclude", default=",".join(STUDY_MATERIALS),
                       help="comma-separated materials held out of the basis (default: the study "
                            "materials %(default)s); '' holds out none")
    build.add_argument("--materials", help="comma-separated training materials (default: all not excluded)")
    build.add_argument("--components", type=int, default=32,
                       help="number of components K (default %(default)s; at most materials − 1)")
    build.add_argument("--epsilon", type=float, default=DEFAULT_EPSILON,
                       help="offset ε of the mapping, 1/sr (default %(default)s)")
    build.add_argument("--merl-dir", type=Path, help=merl_help)
    build.set_defaults(run=run_build)

    plan = commands.add_parser("plan-directions",
                               help="direction pairs to measure for a reconstruction from n observations")
    plan.add_argument("basis", type=Path, help="basis file (.npz) built without the materials to measure")
    plan.add_argument("-n", type=int, required=True, help="number of direction pairs")
    plan.add_argument("--out", type=Path, required=True, help="plan to write (.json)")
    plan.add_argument("--candidates", type=int, default=20_000,
                      help="random candidate pairs to choose from (default %(default)s)")
    plan.add_argument("--max-theta", type=float, default=80.0,
                      help="largest polar angle of a direction, degrees (default %(default)s)")
    plan.add_argument("--noise", type=float, default=0.0,
                      help="relative noise of the measured values (sets η; default %(default)s)")
    plan.add_argument("--seed", type=int, default=0, help="seed of the random candidates")
    plan.add_argument("--criterion", default="mapped",
                      help="what the plan minimises: mapped (log-relative error of the table) or "
                           "radiance (relative error of the cosine-weighted BRDF, what renderings "
                           "show) (default %(default)s)")
    plan.set_defaults(run=run_plan)


def _names(text: str | None) -> list[str]:
    return [n.strip() for n in (text or "").split(",") if n.strip()]


def run_materials(args) -> int:
    from abs.brdf.measured import measured_material_names

    print("\n".join(measured_material_names(args.merl_dir)))
    return 0


def run_export(args) -> int:
    from abs.brdf.measured import measured_table
    from abs.io.merl import write_merl

    _check_known([args.material], args.merl_dir, "material")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_merl(args.out, measured_table(args.material, args.merl_dir))
    print(f"wrote {args.out}")
    return 0


def _check_known(names: list[str], merl_dir: Path | None, option: str) -> list[str]:
    from abs.brdf.measured import measured_material_names
    from abs.errors import InputError

    known = measured_material_names(merl_dir)
    unknown = [n for n in names if n not in known]
    if unknown:
        raise InputError(None, option, f"unknown materials {', '.join(unknown)} "
                                       "(see `abs brdf materials`)")
    return known


def run_build(args) -> int:
    from functools import partial

    from tqdm import tqdm

    from abs.brdf.measured import measured_table
    from abs.brdf.pca import build_basis
    from abs.errors import InputError

    exclude = _names(args.exclude)
    known = _check_known(exclude, args.merl_dir, "--exclude")
    training = _names(args.materials) or known
    _check_known(training, args.merl_dir, "--materials")
    training = [n for n in training if n not in exclude]
    if not 1 <= args.components <= len(training) - 1:
        raise InputError(None, "--components", f"must be in [1, {len(training) - 1}] for "
                                               f"{len(training)} training materials")
    bar = tqdm(total=len(training), desc="tables", unit="material")
    basis = build_basis(training, partial(measured_table, binary_dir=args.merl_dir), args.components,
                        epsilon=args.epsilon, on_table=lambda name: bar.update(1))
    bar.close()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    basis.save(args.out)
    sv = basis.singular_values
    kept = float((sv[: args.components] ** 2).sum() / (sv**2).sum())
    print(f"wrote {args.out}: {args.components} components from {len(training)} materials "
          f"({100 * kept:.1f} % of the mapped variance; held out: {', '.join(exclude) or 'none'})")
    return 0


def run_plan(args) -> int:
    import json

    import numpy as np

    from abs.brdf.basis import BRDFBasis
    from abs.brdf.design import CRITERIA, plan_directions
    from abs.brdf.directions import rusinkiewicz_angles
    from abs.brdf.reconstruct import default_eta
    from abs.errors import InputError

    basis = BRDFBasis.load(args.basis)
    if basis.training_coefficients is None or basis.residual_variance is None:
        raise InputError(args.basis, "training_coefficients",
                         "this basis has no training-set statistics; rebuild it with `abs brdf build-basis`")
    if not 0 < args.max_theta <= 90:
        raise InputError(None, "--max-theta", f"must be in (0, 90] degrees, got {args.max_theta}")
    if args.criterion not in CRITERIA:
        raise InputError(None, "--criterion", f"unknown criterion {args.criterion!r}; known: {', '.join(CRITERIA)}")
    eta = default_eta(basis, args.noise)
    try:
        plan = plan_directions(basis, args.n, args.candidates, eta, args.max_theta, args.seed,
                               args.criterion)
    except ValueError as exc:
        raise InputError(None, "-n", str(exc)) from None
    theta_h, theta_d, phi_d = (np.degrees(a) for a in rusinkiewicz_angles(plan.wi, plan.wo))

    def polar(w):
        return np.degrees(np.arccos(np.clip(w[:, 2], -1, 1))), np.degrees(np.arctan2(w[:, 1], w[:, 0]))

    (theta_i, phi_i), (theta_o, phi_o) = polar(plan.wi), polar(plan.wo)
    pairs = [{"wi": plan.wi[j].round(6).tolist(), "wo": plan.wo[j].round(6).tolist(),
              "theta_i_deg": round(float(theta_i[j]), 3), "phi_i_deg": round(float(phi_i[j]), 3),
              "theta_o_deg": round(float(theta_o[j]), 3), "phi_o_deg": round(float(phi_o[j]), 3),
              "theta_h_deg": round(float(theta_h[j]), 3), "theta_d_deg": round(float(theta_d[j]), 3),
              "phi_d_deg": round(float(phi_d[j]), 3),
              "expected_rmse": round(float(plan.expected_rmse[j]), 5)}
             for j in range(args.n)]
    document = {"basis": str(args.basis), "criterion": plan.criterion, "eta": eta, "noise": args.noise,
                "candidates": args.candidates, "max_theta_deg": args.max_theta, "seed": args.seed,
                "frame": "local shading frame, z = surface normal; expected_rmse: after the first k "
                         "pairs, in the criterion's units (docs/brdf.md)",
                "pairs": pairs}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(document, indent=2))
    print(f"wrote {args.out}: {args.n} direction pairs, expected {plan.criterion} RMSE "
          f"{plan.expected_rmse[0]:.3f} after 1, {plan.expected_rmse[-1]:.3f} after {args.n}")
    return 0
