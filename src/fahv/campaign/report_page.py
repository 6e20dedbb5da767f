"""One self-contained HTML page per campaign: its pass rates with their bounds, worst runs, figures.

`fahv report DIR` makes the campaign's report (`fahv.campaign.report.make_report`: the
pass rate of every requirement with its Clopper-Pearson bound, the certified and not
certified draws apart, the worst runs, the figures) and writes it as `DIR/report/report.html`:
the report's Markdown as HTML, every figure embedded as a PNG (`data:` URI), the page's
images counted once loaded (`fahv.runs.report_page.page`).
"""

from __future__ import annotations

import re
from pathlib import Path

import markdown

from fahv.campaign.report import make_report
from fahv.runs.report_page import embedded_png, page, write_page

#: An image of the report's Markdown, as the Markdown library writes it.
_IMG = re.compile(r'<img alt="([^"]*)" src="([^"]+)"')


def campaign_page(out_dir: str | Path) -> str:
    """The HTML page of a campaign folder (module notes).

    Parameters
    ----------
    out_dir : str or Path
        The campaign's folder (its `results/` dataset).

    Returns
    -------
    str
        The whole HTML document.

    Raises
    ------
    CampaignError
        If the folder holds no campaign dataset (`make_report`).
    """
    folder = Path(out_dir)
    make_report(folder, figures=True)
    text = (folder / "report" / "report.md").read_text()
    body = markdown.markdown(text, extensions=["tables"])

    def inline(m: re.Match) -> str:
        src = folder / "report" / m.group(2)
        return f'<img alt="{m.group(1)}" src="{embedded_png(src) if src.is_file() else m.group(2)}"'

    body = _IMG.sub(inline, body)
    return page(f"Campaign {folder.name}", body)


def write_campaign_page(out_dir: str | Path, out: str | Path | None = None) -> Path:
    """Write `campaign_page` to `out` (default `DIR/report/report.html`); returns the file.

    Raises
    ------
    CampaignError
        As `campaign_page`.
    """
    target = Path(out) if out else Path(out_dir) / "report" / "report.html"
    return write_page(target, campaign_page(out_dir))
