"""HTML pieces of the fit report: tables from ``fit.json``'s summary, figures, view sections.

Every function returns a string of HTML; the page is self-contained (inline CSS, no script) and
refers to its figures by relative file name, so the report folder can be moved or archived as
a whole. Missing optional values show as an em dash.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from html import escape

import numpy as np

from abs.report.data import as_vector

__all__ = ["format_number", "html_table", "metrics_table", "parameter_table", "figure", "view_section", "section", "page"]

_MISSING = "—"

_STYLE = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 70em; padding: 0 1em;
       color: #222; }
table { border-collapse: collapse; margin: 0.5em 0 1.5em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: right; }
th:first-child, td:first-child { text-align: left; }
thead th { background: #f2f2f2; }
figure { margin: 1em 0; }
img { max-width: 100%; height: auto; }
.tag { font-size: 0.7em; padding: 0.1em 0.5em; border-radius: 0.3em; vertical-align: middle;
       background: #dde8f5; }
.holdout .tag { background: #f5c26b; }
"""


def format_number(value: object, spec: str = ".4g") -> str:
    """``value`` formatted with ``spec``, or a dash when it is missing or NaN."""
    if value is None or not np.isfinite(float(value)):
        return _MISSING
    return format(float(value), spec)


def _integer(value: object) -> str:
    """A count with thousands separators, or a dash when it is missing."""
    return _MISSING if value is None else f"{int(value):,}"


def _row(cells: Iterable[str], header: bool = False) -> str:
    tag = "th" if header else "td"
    return "<tr>" + "".join(f"<{tag}>{c}</{tag}>" for c in cells) + "</tr>"


def html_table(header: list[str], rows: Iterable[Iterable[str]]) -> str:
    head = _row((escape(h) for h in header), header=True)
    body = "\n".join(_row(r) for r in rows)
    return f"<table>\n<thead>{head}</thead>\n<tbody>\n{body}\n</tbody>\n</table>"


def metrics_table(summary: Mapping) -> str:
    """Image agreement before/after the fit and the cost of the fit.

    Parameters
    ----------
    summary : mapping
        ``fit.json``: optional ``train_rmse``, ``holdout_rmse``, ``train_ssim``,
        ``holdout_ssim`` (each ``{"before": x, "after": y}``), ``renders``,
        ``samples_rendered``, ``wall_s``, ``iterations``, ``method``.

    Returns
    -------
    str
        Two tables: RMSE (photograph's radiance units) and SSIM per view set, then the run.
    """
    agreement = []
    for key, label, spec in (("train_rmse", "RMSE, training views", ".4g"),
                             ("holdout_rmse", "RMSE, holdout views", ".4g"),
                             ("train_ssim", "SSIM, training views", ".4f"),
                             ("holdout_ssim", "SSIM, holdout views", ".4f")):
        pair = summary.get(key) or {}
        agreement.append([label, format_number(pair.get("before"), spec), format_number(pair.get("after"), spec)])
    run = [["method", escape(str(summary.get("method") or _MISSING))],
           ["iterations", _integer(summary.get("iterations"))],
           ["renders", _integer(summary.get("renders"))],
           ["samples rendered", _integer(summary.get("samples_rendered"))],
           ["wall time (s)", format_number(summary.get("wall_s"), ".1f")]]
    return (html_table(["metric", "before fit", "after fit"], agreement) + "\n"
            + html_table(["run", ""], run))


def parameter_table(parameters: Mapping[str, Mapping]) -> str:
    """One row per parameter component: initial, fitted ± standard error, truth and error.

    Parameters
    ----------
    parameters : mapping
        ``fit.json``'s ``parameters``: name → dict with ``value`` and optional ``stderr``,
        ``unit``, ``initial``, ``truth`` (scalars or per-component lists; ``None`` = unknown).

    Returns
    -------
    str
        A table; the truth, error (fitted − truth) and error/stderr columns appear only when
        some parameter has a true value (synthetic captures).
    """
    with_truth = any(p.get("truth") is not None for p in parameters.values())
    header = ["parameter", "unit", "initial", "fitted ± stderr"]
    if with_truth:
        header += ["truth", "error", "error / stderr"]
    rows = []
    for name, info in parameters.items():
        value = as_vector(info.get("value"))
        n = value.size
        stderr, initial, truth = (np.broadcast_to(as_vector(info.get(k)), (n,))
                                  for k in ("stderr", "initial", "truth"))
        for i in range(n):
            label = escape(name if n == 1 else f"{name}[{i}]")
            fitted = format_number(value[i])
            if np.isfinite(stderr[i]):
                fitted += f" ± {format_number(stderr[i], '.2g')}"
            row = [label, escape(info.get("unit") or ""), format_number(initial[i]), fitted]
            if with_truth:
                error = value[i] - truth[i]
                row += [format_number(truth[i]), format_number(error, "+.3g"),
                        format_number(error / stderr[i] if stderr[i] > 0 else np.nan, "+.2f")]
            rows.append(row)
    return html_table(header, rows)


def starts_table(starts: Mapping) -> str:
    """One row per short fit of several starts (``fit.json``'s ``starts``): where it started,
    where it ended (first component of each parameter), its mean two-seed objective, and which
    one the fit started from."""
    rows = []
    for k, tried in enumerate(starts["tried"]):
        rows.append([", ".join(f"{escape(n)} {format_number(v[0])}" for n, v in tried["start"].items()),
                     ", ".join(f"{escape(n)} {format_number(as_vector(v)[0])}"
                               for n, v in tried["end"].items()),
                     format_number(tried["objective"]), "chosen" if k == starts["chosen"] else ""])
    return html_table(["start", "end", "objective (mean of fresh seed pairs)", ""], rows)


def figure(src: str, caption: str) -> str:
    """An image file (relative name) with a caption, which is also its alternative text."""
    text = escape(caption)
    return (f'<figure><img src="{escape(src)}" alt="{text}">'
            f"<figcaption>{text}</figcaption></figure>")


def view_section(name: str, holdout: bool, src: str, rmse_before: float,
                 rmse_after: float) -> str:
    """One view: its name tagged "holdout" or "train", its RMSE, and its figure.

    Parameters
    ----------
    name : str
        View name.
    holdout : bool
        Whether the view was left out of the fit.
    src : str
        Relative file name of the view's figure.
    rmse_before, rmse_after : float
        The view's RMSE with the initial and the fitted parameters (radiance units).
    """
    kind = "holdout" if holdout else "train"
    return (f'<section class="view {kind}">\n'
            f'<h3>{escape(name)} <span class="tag">{kind}</span></h3>\n'
            f"<p>RMSE {format_number(rmse_before)} before the fit, {format_number(rmse_after)} after."
            f"{' Not used by the fit.' if holdout else ''}</p>\n"
            + figure(src, f"{name} ({kind}): photograph, rendering and log10 error, "
                          "before (top) and after (bottom) the fit")
            + "\n</section>")


def section(title: str, *content: str) -> str:
    """A titled section holding the given HTML pieces."""
    return f"<section>\n<h2>{escape(title)}</h2>\n" + "\n".join(content) + "\n</section>"


def page(title: str, *sections: str) -> str:
    """The whole self-contained HTML document."""
    return (f'<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
            f"<title>{escape(title)}</title>\n<style>{_STYLE}</style>\n</head>\n<body>\n"
            f"<h1>{escape(title)}</h1>\n" + "\n".join(sections) + "\n</body>\n</html>\n")
