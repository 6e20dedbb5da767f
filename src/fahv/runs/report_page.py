"""One self-contained HTML page per run: its verdict, coverage, metadata, metrics, figures.

`fahv report RUN` writes `RUN/report.html`: the overall verdict and the verdict table
against the requirements the run was flown with (`fahv.runs.judged`), the coverage line,
the run's metadata and metrics, and every figure `fahv plot` draws
(`fahv.runs.figures`), each embedded as a PNG (`data:` URI), so the page is one file that
can be mailed or archived beside the run. The page counts its images once loaded and
writes the count into `<body data-images-loaded>`: a browser test reads it. A campaign's
page is `fahv.campaign.report_page`, with the same parts (`page`, `embedded_png`).
"""

from __future__ import annotations

import base64
import html
import io
from pathlib import Path

from fahv.runs.bag import read_run
from fahv.runs.figures import run_figures
from fahv.runs.judged import run_judgements, run_limits
from fahv.runs.plots import plt
from fahv.runs.plots_context import plotted_run, run_labels
from fahv.runs.tools import METRIC_ROWS, summarize
from fahv.spec.requirements import overall, overall_line, verdict_rows

#: The page's style: plain, readable, printable.
STYLE = """
body { font-family: sans-serif; max-width: 1100px; margin: 2em auto; color: #222; }
table { border-collapse: collapse; margin: 0.5em 0 1.5em; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: left; }
td.num { text-align: right; font-family: monospace; }
.PASS { color: #176b2c; font-weight: bold; } .FAIL { color: #b00020; font-weight: bold; }
.verdict { font-size: 1.4em; padding: 0.4em 0.8em; border: 2px solid; display: inline-block; }
figure { margin: 1.5em 0; } figure img { max-width: 100%; }
"""
#: Counts the images that loaded (non-zero natural width) into <body data-images-loaded>.
COUNT_IMAGES = """
window.addEventListener("load", function () {
  var n = 0; var imgs = document.images;
  for (var i = 0; i < imgs.length; i++) { if (imgs[i].complete && imgs[i].naturalWidth > 0) n++; }
  document.body.setAttribute("data-images-loaded", String(n));
  document.body.setAttribute("data-images", String(imgs.length));
});
"""


def embedded_png(fig_or_path) -> str:
    """A figure (closed afterwards) or a PNG file as a `data:image/png;base64,...` URI."""
    if isinstance(fig_or_path, str | Path):
        data = Path(fig_or_path).read_bytes()
    else:
        buf = io.BytesIO()
        fig_or_path.savefig(buf, format="png", dpi=100)
        plt.close(fig_or_path)
        data = buf.getvalue()
    return "data:image/png;base64," + base64.b64encode(data).decode("ascii")


def page(title: str, body: str) -> str:
    """A whole HTML document: `title`, the style, `body` and the image counter."""
    return (f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>{html.escape(title)}</title><style>{STYLE}</style></head>\n"
            f"<body>\n{body}\n<script>{COUNT_IMAGES}</script>\n</body></html>\n")  # fmt: skip


def table(header: list[str], rows: list[list[str]], numeric: set[int] = frozenset()) -> str:
    """An HTML table; cells are escaped, the columns in `numeric` right-aligned."""
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join(
        "<tr>" + "".join(f"<td class=\"{_cell_class(i, c, numeric)}\">{html.escape(c)}</td>"
                         for i, c in enumerate(r)) + "</tr>"
        for r in rows
    )  # fmt: skip
    return f"<table><tr>{head}</tr>{body}</table>"


def _cell_class(i: int, cell: str, numeric) -> str:
    """A cell's class: a verdict word its own (coloured), a numeric column `num`."""
    if cell in ("PASS", "FAIL"):
        return cell
    return "num" if i in numeric else ""


def run_page(path: str | Path) -> str:
    """The HTML page of one recorded run (module notes).

    Parameters
    ----------
    path : str or Path
        The run folder or its `.mcap`.

    Returns
    -------
    str
        The whole HTML document.

    Raises
    ------
    RunError
        If the run cannot be read (`fahv.runs.bag.read_run`).
    FahvError
        If it holds no complete step (nothing to judge or draw).
    """
    rec = read_run(path)
    md = rec.metadata
    s = summarize(rec, run_limits(rec))
    (label,) = run_labels([path], [md])
    parts = [f"<h1>Run {html.escape(Path(s['file']).parent.name)}</h1>"]
    judged = run_judgements(md, s["metrics"])
    if judged is None:
        parts.append(f"<p class=\"FAIL\">No metrics: {html.escape(s['metrics_note'])}</p>")
    else:
        word = "PASS" if overall(judged) else "FAIL"
        parts.append(f"<p class=\"verdict {word}\">{html.escape(overall_line(judged))}</p>")
        parts.append("<h2>Requirements</h2>" + table(
            ["requirement", "measured", "value", "limit", "margin", "verdict"],
            [list(r) for r in verdict_rows(judged)], {2, 3, 4}))  # fmt: skip
    parts.append(f"<p><b>coverage:</b> {html.escape(md.get('coverage', 'not recorded'))}</p>")
    parts.append("<h2>Run</h2>" + table(["key", "value"], [[k, str(v)] for k, v in md.items()]))
    if s["metrics"] is not None:
        rows = [[lab, fmt.format(s["metrics"][k])] for k, lab, fmt in METRIC_ROWS
                if s["metrics"].get(k) is not None]  # fmt: skip
        parts.append(f"<h2>Metrics ({html.escape(s['metrics_note'])})</h2>"
                     + table(["metric", label], rows, {1}))  # fmt: skip
        parts.append("<h2>Figures</h2>")
        for name, fig in run_figures([plotted_run(rec, label)]):
            parts.append(f"<figure><img alt=\"{name}\" src=\"{embedded_png(fig)}\">"
                         f"<figcaption>{name}</figcaption></figure>")  # fmt: skip
    return page(f"Run {Path(s['file']).parent.name}", "\n".join(parts))


def write_run_page(path: str | Path, out: str | Path | None = None) -> Path:
    """Write `run_page` to `out` (default `<run folder>/report.html`); returns the file.

    Raises
    ------
    RunError, FahvError
        As `run_page`.
    """
    from fahv.runs.bag import bag_paths

    folder, _ = bag_paths(path)
    return write_page(Path(out) if out else folder / "report.html", run_page(path))


def write_page(target: Path, text: str) -> Path:
    """Write a page whole or not at all (a `.part` file renamed over it); returns `target`."""
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = target.with_suffix(".html.part")
    tmp.write_text(text)
    tmp.replace(target)
    return target
