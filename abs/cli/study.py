"""``abs study sl-scanner --out DIR``: the structured-light variational study (docs/sl-study.md);
``abs study sl-paper --study study.json``: its tables beside the paper's published ones."""

from __future__ import annotations

from pathlib import Path


def add_parser(sub) -> None:
    p = sub.add_parser("study", help="simulation studies")
    studies = p.add_subparsers(dest="study", required=True)
    sl = studies.add_parser("sl-scanner", help="BRDF reconstruction in a simulated structured-light "
                                               "scanner: Tables 1 and 2, profile plots")
    sl.add_argument("--out", type=Path, required=True, help="output folder (rerun to resume)")
    sl.add_argument("--basis", type=Path, help="PCA basis (.npz) without the study materials; default: "
                                               "built into OUT/basis.npz (abs brdf build-basis)")
    sl.add_argument("--materials", help="comma-separated materials (default: the paper's four)")
    sl.add_argument("--tessellations", default="1,3,5", help="icosphere subdivisions of Table 1")
    sl.add_argument("--noise-tessellation", type=int, default=5, help="subdivision of the error study")
    sl.add_argument("--noise", help="comma-separated error types (default: all: vertex_position, "
                                    "normal_tilt, light_position, light_intensity); '' for none")
    sl.add_argument("--repetitions", type=int, default=30)
    sl.add_argument("--width", type=int, default=640, help="scanner image width, pixels")
    sl.add_argument("--height", type=int, default=480, help="scanner image height, pixels")
    sl.add_argument("--spp", type=int, default=4, help="scanner image positions per pixel")
    sl.add_argument("--score-size", type=int, default=128, help="score rendering size, pixels")
    sl.add_argument("--score-spp", type=int, default=64, help="score rendering samples per pixel")
    sl.add_argument("--environment", help="environment map of the score (default: shared "
                                          "polyhaven_hdri_1k/royal_esplanade_1k.hdr)")
    sl.add_argument("--merl-dir", type=Path, help="folder of real MERL .binary files")
    sl.add_argument("--workers", type=int, default=1, help="local worker processes")
    sl.add_argument("--scheduler", help="Dask scheduler address (tcp://host:8786): run tasks there")
    sl.add_argument("--seed", type=int, default=0)
    sl.add_argument("--paper-tables", type=Path, help="the paper's published tables (Markdown) to put "
                                                      "beside abs's; default: ../shared/docs/"
                                                      "sl-study-paper-tables.md when present")
    sl.set_defaults(run=run)
    paper = studies.add_parser("sl-paper", help="an existing study's tables beside the paper's "
                                                "published ones (Markdown)")
    paper.add_argument("--study", type=Path, required=True, help="study.json of `abs study sl-scanner`")
    paper.add_argument("--paper-tables", type=Path, help="default: ../shared/docs/sl-study-paper-tables.md")
    paper.add_argument("--out", type=Path, help="Markdown file to write (default: print)")
    paper.set_defaults(run=run_paper)


def _paper_tables(path: Path | None) -> Path | None:
    """The published tables' file: an explicit one must exist; the default may be absent."""
    from abs.errors import InputError
    from abs.studies.sl_paper import default_paper_tables_path

    if path is not None and not path.is_file():
        raise InputError(path, "--paper-tables", "file not found")
    return path or default_paper_tables_path()


def run_paper(args) -> int:
    from abs.errors import InputError, read_json
    from abs.studies.sl_paper import read_paper_tables
    from abs.studies.sl_report import paper_markdown

    summary = read_json(args.study, what="study summary (study.json)", field="--study")
    if not isinstance(summary.get("table1"), dict) \
            or not isinstance(summary.get("table2"), dict):
        raise InputError(args.study, "table1", "not a study.json (needs the objects table1 and table2)")
    path = _paper_tables(args.paper_tables)
    text = paper_markdown(summary, read_paper_tables(path) if path.is_file() else None, missing=str(path))
    if args.out is None:
        print(text)
    else:
        args.out.write_text(text + "\n")
        print(f"wrote {args.out}")
    return 0


def _list(text: str | None) -> list[str] | None:
    return None if text is None else [x.strip() for x in text.split(",") if x.strip()]


def _default_basis(out: Path, exclude: list[str], merl_dir: Path | None) -> Path:
    """OUT/basis.npz, built once from every measured material except ``exclude``."""
    path = out / "basis.npz"
    if path.is_file():
        return path
    from tqdm import tqdm

    from abs.brdf.measured import measured_material_names, measured_table
    from abs.brdf.pca import build_basis

    names = [n for n in measured_material_names(merl_dir) if n not in exclude]
    bar = tqdm(total=len(names), desc="basis tables", unit="material")
    basis = build_basis(names, lambda n: measured_table(n, merl_dir), min(32, len(names) - 1),
                        on_table=lambda _: bar.update(1))
    bar.close()
    out.mkdir(parents=True, exist_ok=True)
    basis.save(path)
    return path


def run(args) -> int:
    from tqdm import tqdm

    from abs.brdf.measured import STUDY_MATERIALS, measured_material_names
    from abs.errors import InputError
    from abs.studies.sl_noise import NOISE_TYPES
    from abs.studies.sl_scanner import StudyConfig
    from abs.studies.sl_scoring import DEFAULT_ENVIRONMENT
    from abs.studies.sl_study import run_study

    materials = _list(args.materials) or list(STUDY_MATERIALS)
    known = measured_material_names(args.merl_dir)
    unknown = [m for m in materials if m not in known]
    if unknown:
        raise InputError(None, "--materials", f"unknown materials {', '.join(unknown)} (see `abs brdf materials`)")
    noises = list(NOISE_TYPES) if args.noise is None else _list(args.noise)
    bad = [n for n in noises if n not in NOISE_TYPES]
    if bad:
        raise InputError(None, "--noise", f"unknown error types {', '.join(bad)}; known: {', '.join(NOISE_TYPES)}")
    try:
        tessellations = tuple(int(t) for t in _list(args.tessellations))
    except ValueError:
        raise InputError(None, "--tessellations", f"expected integers, got {args.tessellations!r}") from None
    for name, value in (("--repetitions", args.repetitions), ("--width", args.width), ("--height", args.height),
                        ("--spp", args.spp), ("--score-size", args.score_size), ("--score-spp", args.score_spp)):
        if value < 1:
            raise InputError(None, name, f"must be >= 1, got {value}")
    paper_tables = _paper_tables(args.paper_tables)
    basis = args.basis or _default_basis(args.out, materials, args.merl_dir)
    if not Path(basis).is_file():
        raise InputError(basis, "", "basis file not found (make one with `abs brdf build-basis`)")
    from abs.brdf.basis import BRDFBasis

    held = BRDFBasis.load(basis).materials
    leaked = sorted(set(materials) & set(held.tolist())) if held is not None else []
    if leaked:
        raise InputError(basis, "materials", f"the basis was trained on the studied {', '.join(leaked)}: "
                                             "build it with --exclude (the study holds them out)")
    config = StudyConfig(
        basis=str(Path(basis).resolve()), materials=tuple(materials), tessellations=tessellations,
        noise_tessellation=args.noise_tessellation, noise={n: list(NOISE_TYPES[n].levels) for n in noises},
        repetitions=args.repetitions, width=args.width, height=args.height, spp=args.spp,
        score_size=args.score_size, score_spp=args.score_spp,
        environment=args.environment or DEFAULT_ENVIRONMENT, seed=args.seed,
        merl_dir=str(args.merl_dir) if args.merl_dir else None)
    bar = tqdm(desc="study tasks", unit="task")

    def progress(_: str, finished: int, to_run: int) -> None:
        bar.total = to_run
        bar.update(finished - bar.n)

    summary = run_study(config, args.out, workers=args.workers, scheduler=args.scheduler, on_result=progress,
                        paper_tables=paper_tables)
    bar.close()
    print(f"wrote {args.out / 'study.json'}, table1.md, table2.md, paper_comparison.md, report.html "
          f"({summary['runtime_s']:.0f} s, {summary['tasks_run']} tasks run)")
    return 0
