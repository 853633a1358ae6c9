"""Running the structured-light study into a folder: resume, checkpoints, tables, report.

Folder layout::

    study.json        config, rig, Table 1 and Table 2 (JSON), runtime
    table1.md         Table 1 (paper layout) in Markdown
    table2.md         Table 2
    paper_comparison.md      the paper's published tables beside abs's, cell by cell (or a note
                             saying the file of published tables was not found)
    profile_<material>.png   45-degree in-plane profiles with ±2 sd bands
    report.html       both tables and the figures
    results/<task>.json      one file per finished task (the checkpoint: a rerun skips them)
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path

from abs.pools import worker_pool
from abs.runs.files import write_json
from abs.studies.sl_paper import default_paper_tables_path, read_paper_tables
from abs.studies.sl_rig import default_rig
from abs.studies.sl_scanner import (
    StudyConfig,
    run_task,
    study_tasks,
    task_digest,
    task_id,
)
from abs.studies.sl_tables import markdown_table1, markdown_table2, table1, table2

__all__ = ["run_study"]


def _load_done(folder: Path, tasks: list[dict]) -> dict[str, dict]:
    """Results already on disk whose digest matches their task (stale ones are recomputed)."""
    done = {}
    for task in tasks:
        path = folder / f"{task_id(task)}.json"
        if not path.is_file():
            continue
        try:
            result = json.loads(path.read_text())
        except json.JSONDecodeError:
            continue  # an interrupted write (write_json renames, so this is rare): recompute
        if result.get("digest") == task_digest(task):
            done[result["id"]] = result
    return done


def run_study(config: StudyConfig, out: str | Path, workers: int = 1, scheduler: str | None = None,
              on_result: Callable[[str, int, int], None] | None = None,
              paper_tables: str | Path | None = None) -> dict:
    """Run (or resume) the study and write its folder (see the module docstring).

    Parameters
    ----------
    config : StudyConfig
        The study.
    out : str or Path
        Output folder.
    workers : int
        Local worker processes (ignored with ``scheduler``).
    scheduler : str, optional
        Dask scheduler address.
    on_result : callable, optional
        Called as ``on_result(task_id, finished, to_run)`` after each task this call runs
        (progress reporting; tasks resumed from ``results/`` are not counted).
    paper_tables : str or Path, optional
        The paper's published tables (:mod:`abs.studies.sl_paper`); default
        ``../shared/docs/sl-study-paper-tables.md``. When the file does not exist the report says
        so and shows abs's tables alone; a malformed file is an InputError.

    Returns
    -------
    dict
        The summary written to ``study.json``.
    """
    out = Path(out)
    # Read (and check) the published tables before the long run, not after it.
    paper_path = Path(paper_tables) if paper_tables is not None else default_paper_tables_path()
    paper = read_paper_tables(paper_path) if paper_path.is_file() else None
    results_dir = out / "results"
    results_dir.mkdir(parents=True, exist_ok=True)
    tasks = study_tasks(config)
    start = time.perf_counter()
    results = _load_done(results_dir, tasks)
    todo = [t for t in tasks if task_id(t) not in results]
    if todo:  # a finished study reruns without starting workers or reaching a scheduler
        with worker_pool(workers, scheduler) as pool:
            for finished, (task, result) in enumerate(pool.as_completed(run_task, todo), start=1):
                write_json(results_dir / f"{task_id(task)}.json", result)
                results[result["id"]] = result
                if on_result is not None:
                    on_result(result["id"], finished, len(todo))
    keyed = [{**t, "id": task_id(t)} for t in tasks]
    summary = {
        "config": config.to_dict(),
        "rig": default_rig(config.width, config.height, config.steps).describe(),
        "table1": table1(results, keyed),
        "table2": table2(results, keyed),
        "runtime_s": time.perf_counter() - start,
        "tasks_run": len(todo),
    }
    write_json(out / "study.json", summary)
    (out / "table1.md").write_text(markdown_table1(summary["table1"]) + "\n")
    (out / "table2.md").write_text(markdown_table2(summary["table2"]) + "\n")
    from abs.studies.sl_report import paper_markdown, plot_profiles, write_html

    paper_text = paper_markdown(summary, paper, missing=str(paper_path))
    (out / "paper_comparison.md").write_text(paper_text + "\n")
    figures = [plot_profiles(out / f"profile_{m}.png", m, results, keyed) for m in config.materials]
    write_html(out / "report.html", summary, figures, paper_text)
    return summary
