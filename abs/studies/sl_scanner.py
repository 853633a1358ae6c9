"""The structured-light variational study (the seed paper "A Variational Study on BRDF
Reconstruction in a Structured Light Scanner", Nielsen, Stets et al. 2017), as independent tasks.

A task is one (material, tessellation, error type, error level): it renders the scan with the
material's true table (:mod:`~abs.studies.sl_capture`), then, for each repetition, perturbs the
scanner's estimate (:mod:`~abs.studies.sl_noise`), collects BRDF samples
(:mod:`~abs.studies.sl_sampling`), reconstructs the full table from the PCA basis
(:func:`abs.brdf.reconstruct.reconstruct`, η from the basis' training statistics) and scores it
(:mod:`~abs.studies.sl_scoring`). Tasks without error (Table 1) run once and also score the best
Lambertian fit to the same samples, a baseline the basis must beat.

Tasks and results are plain dicts (JSON-ready, picklable), so they run in local processes or on a
Dask cluster (:mod:`abs.pools`) and are checkpointed one file each by the caller.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from abs.brdf.measured import STUDY_MATERIALS
from abs.runs.identity import digest
from abs.studies.sl_noise import NOISE_TYPES

__all__ = [
    "LUMINANCE",
    "PROFILE_ANGLES_DEG",
    "PROFILE_INCIDENCE_DEG",
    "StudyConfig",
    "in_plane_profile",
    "run_task",
    "study_tasks",
    "task_id",
]

PROFILE_INCIDENCE_DEG = 45.0
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
"""Rec. 709 luminance weights of linear R, G, B (the profiles are plotted as luminance)."""
PROFILE_ANGLES_DEG = np.arange(-85.0, 85.5, 1.0)
"""Outgoing angles of the in-plane profile, degrees; positive on the mirror side."""


@dataclass(frozen=True)
class StudyConfig:
    """Everything that defines the study's numbers (recorded in ``study.json``).

    Attributes
    ----------
    basis : str
        PCA basis file (``abs brdf build-basis``), held-out materials excluded.
    materials : tuple of str
        Materials scanned (names of :func:`abs.brdf.measured.measured_table`).
    tessellations : tuple of int
        Icosphere subdivisions of Table 1.
    noise_tessellation : int
        Subdivision used in the error study (Table 2).
    noise : dict
        Error type -> levels (units of :data:`~abs.studies.sl_noise.NOISE_TYPES`).
    repetitions : int
        Random realisations per error level.
    width, height, spp : int
        Scanner images: pixels and positions per pixel.
    score_size, score_spp : int
        Score rendering: pixels per side and samples per pixel.
    environment : str
        Environment map of the score (relative to the shared data folder, or absolute).
    steps : int
        Turntable steps over 180 degrees.
    seed : int
        Master seed.
    merl_dir : str, optional
        Folder of real MERL ``.binary`` files (else the neural fits).
    """

    basis: str
    materials: tuple[str, ...] = STUDY_MATERIALS
    tessellations: tuple[int, ...] = (1, 3, 5)
    noise_tessellation: int = 5
    noise: dict = field(default_factory=lambda: {k: list(v.levels) for k, v in NOISE_TYPES.items()})
    repetitions: int = 30
    width: int = 640
    height: int = 480
    spp: int = 4
    score_size: int = 128
    score_spp: int = 64
    environment: str = "polyhaven_hdri_1k/royal_esplanade_1k.hdr"
    steps: int = 10
    seed: int = 0
    merl_dir: str | None = None

    def to_dict(self) -> dict:
        d = asdict(self)
        d["materials"], d["tessellations"] = list(self.materials), list(self.tessellations)
        return d


def task_id(task: dict) -> str:
    """A file-name-safe name of a task, e.g. ``blue-rubber_t5_normal_tilt_10``."""
    level = "" if task["noise"] is None else f"_{task['noise']}_{task['level']:g}"
    return f"{task['material']}_t{task['tessellation']}{level or '_none'}"


def study_tasks(config: StudyConfig) -> list[dict]:
    """Table 1 tasks (no error, every tessellation) then Table 2 tasks (every error level)."""
    common = {k: v for k, v in config.to_dict().items()
              if k not in ("materials", "tessellations", "noise", "noise_tessellation")}
    tasks = []
    for material in config.materials:
        for t in config.tessellations:
            tasks.append({**common, "material": material, "tessellation": t, "noise": None,
                          "level": 0.0, "repetitions": 1})
    for material in config.materials:
        for noise, levels in config.noise.items():
            for level in levels:
                tasks.append({**common, "material": material, "tessellation": config.noise_tessellation,
                              "noise": noise, "level": float(level)})
    return tasks


def task_digest(task: dict) -> str:
    """Hash of everything a task's result depends on (resume refuses a stale result)."""
    return digest(task)


def in_plane_profile(table: np.ndarray, incidence_deg: float = PROFILE_INCIDENCE_DEG,
                     angles_deg: np.ndarray = PROFILE_ANGLES_DEG) -> np.ndarray:
    """BRDF along the plane of incidence (nearest table entries), 1/sr.

    Light at ``incidence_deg`` from the normal; the viewer at each of ``angles_deg`` in the same
    plane, positive angles on the mirror side. Returns (3, len(angles)) R, G, B.
    """
    from abs.brdf.directions import merl_entries

    ti, to = np.deg2rad(incidence_deg), np.deg2rad(np.asarray(angles_deg, float))
    wi = np.broadcast_to([np.sin(ti), 0.0, np.cos(ti)], (len(to), 3))
    wo = np.stack([-np.sin(to), np.zeros_like(to), np.cos(to)], axis=1)
    return np.asarray(table, np.float64).reshape(-1)[merl_entries(wi, wo)].T


# -- worker side --------------------------------------------------------------------------------
_BASES: dict[str, object] = {}


def _basis(path: str):
    """The basis of a file, loaded once per worker process."""
    from abs.brdf.basis import BRDFBasis

    if path not in _BASES:
        _BASES[path] = BRDFBasis.load(path)
    return _BASES[path]


def _seed(task: dict) -> np.random.SeedSequence:
    return np.random.SeedSequence([task["seed"], int(task_digest({"id": task_id(task)}), 16)])


def run_task(task: dict) -> dict:
    """Run one task (see the module docstring); returns a JSON-ready result.

    Result keys: ``id``, ``digest``, ``samples`` (per repetition), ``delta_e_mean`` and
    ``delta_e_sd`` (per repetition: mean and sd of CIEDE2000 over the sphere's pixels),
    ``profile_mean``/``profile_sd`` (3 x angles, over repetitions), the same for luminance
    (``profile_luminance_mean``/``_sd``), ``profile_truth``, and for
    error-free tasks the Lambertian baseline's ``lambert_delta_e_mean``/``_sd``.
    """
    import abs.render  # noqa: F401  (selects the Mitsuba variant in a fresh worker)
    from abs.brdf.directions import merl_entries
    from abs.brdf.measured import measured_table
    from abs.brdf.reconstruct import reconstruct
    from abs.studies.sl_capture import render_scan
    from abs.studies.sl_noise import ScanEstimate, perturb
    from abs.studies.sl_rig import default_rig, icosphere
    from abs.studies.sl_sampling import brdf_samples
    from abs.studies.sl_scoring import Scorer, ScoreSettings

    truth = measured_table(task["material"], task["merl_dir"])
    rig = default_rig(task["width"], task["height"], task["steps"])
    mesh = icosphere(task["tessellation"])
    images = render_scan(rig, mesh, truth, spp=task["spp"], seed=task["seed"])
    scorer = Scorer.from_shared(truth, ScoreSettings(task["score_size"], task["score_spp"], task["seed"],
                                                     task["environment"]))
    basis = _basis(task["basis"])
    exact = ScanEstimate(mesh, rig.light_position, rig.light_intensity)
    rng = np.random.default_rng(_seed(task))
    result: dict = {"id": task_id(task), "digest": task_digest(task), "samples": [],
                    "delta_e_mean": [], "delta_e_sd": []}
    profiles = []
    for _ in range(task["repetitions"]):
        estimate = exact if task["noise"] is None else perturb(exact, task["noise"], task["level"], rng)
        samples = brdf_samples(images, rig, estimate)
        result["samples"].append(samples.count)
        if samples.count == 0:  # nothing observed: the reconstruction is undefined
            result["delta_e_mean"].append(None)
            result["delta_e_sd"].append(None)
            continue
        entries = merl_entries(samples.wi, samples.wo)
        table = reconstruct(basis, entries, samples.f)
        score = scorer.score(table)
        result["delta_e_mean"].append(score["mean"])
        result["delta_e_sd"].append(score["sd"])
        profiles.append(in_plane_profile(table))
        if task["noise"] is None:
            # Best Lambertian BRDF for the same samples (per-channel median: robust to highlights).
            lambert = np.broadcast_to(np.median(samples.f, axis=0)[:, None, None, None],
                                      truth.shape).astype(np.float32)
            base = scorer.score(lambert)
            result["lambert_delta_e_mean"], result["lambert_delta_e_sd"] = base["mean"], base["sd"]
    if profiles:
        stack = np.asarray(profiles)
        result["profile_mean"] = stack.mean(axis=0).tolist()
        result["profile_sd"] = stack.std(axis=0).tolist()
        luminance = np.tensordot(stack, LUMINANCE, axes=([1], [0]))
        result["profile_luminance_mean"] = luminance.mean(axis=0).tolist()
        result["profile_luminance_sd"] = luminance.std(axis=0).tolist()
    result["profile_truth"] = in_plane_profile(truth).tolist()
    return result
