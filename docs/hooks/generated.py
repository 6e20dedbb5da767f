"""Generated parts of the documentation site: an MkDocs hook, and the command that writes them.

Two kinds of generated content:

- **Tables written into their pages** between `<!-- NAME -->` and `<!-- /NAME -->`
  (the key tables of design, scenario and campaign files, the node table, the registry
  tables). The tests read them from the page; the site build checks that each equals what
  the code generates now and fails naming the command that rewrites them:

      .venv/bin/python docs/hooks/generated.py

- **Evidence files** between `<!-- evidence:PATH -->` and `<!-- /evidence:PATH -->`: a
  Markdown file a command wrote (e.g. `fahv campaign compare A B --write PATH`, kept
  beside the study it supports), shown with its headings two levels down; the build
  checks that the page holds the file as it is, and the command above rewrites it.

- **The command-line reference**, made at build time from the `fahv` argument parser
  where a page holds `<!-- fahv-cli -->`; nothing of it is stored.

The hook also tells apart two kinds of message of the API reference build that are not
defects of the pages (see `NOT_CROSS_REFERENCES` and `KNOWN_DOCSTRING_NOTES`)
and logs them as information, so that every other warning still fails the strict build.
"""

from __future__ import annotations

import argparse
import logging
import os
import re
import sys
from importlib import import_module
from pathlib import Path

DOCS = Path(__file__).resolve().parents[1]

#: Marker name -> (module, function returning the Markdown table, its arguments: paths
#: relative to the repository's root).
TABLES = {
    "design-keys": ("fahv.spec.schema", "design_spec"),
    "scenario-keys": ("fahv.spec.schema", "scenario_spec"),
    "campaign-keys": ("fahv.campaign.spec", "campaign_spec"),
    "node-table": ("fahv.loop.graph", "markdown_table"),
    "registry-tables": ("fahv.loop.graph", "registry_tables"),
    "margins-table": ("fahv.cli.margins", "docs_table"),
    "case1-verdict": ("fahv.cli.run", "docs_verdict_table"),
    "cases-table": ("fahv.runs.results", "reference_table", "tests/data/results_reference.json"),
    "case2-cm-table": ("fahv.runs.results", "reference_table",
                       "studies/case2_on_cm/results_reference.json"),
}
#: Specs whose table is `fahv.config.spec.markdown(spec())`; the others return Markdown.
SPECS = {"design-keys", "scenario-keys", "campaign-keys"}

CLI_MARKER = "<!-- fahv-cli -->"
MARKER = re.compile(r"<!-- ([a-z0-9-]+(?::[\w./-]+)?) -->\n(.*?)<!-- /\1 -->", re.DOTALL)
#: A marker's prefix for an evidence file (its path relative to the repository's root).
EVIDENCE = "evidence:"

#: An autorefs target holding ", " is a bracketed list in a docstring (units such as
#: `[ft, ft/s]` after `[h, V]`, an index such as `[:, c_i]`), which Markdown reads as
#: a reference link `[a] [b]`; an identifier never holds ", ".
NOT_CROSS_REFERENCES = re.compile(r"Could not find cross-reference target '[^']*, [^']*'")

#: (source file, word) of docstrings whose closing paragraph follows the Parameters
#: section without a heading, so that the numpydoc parser reads its first word as a
#: parameter (reported for a "Notes" heading in src/).
KNOWN_DOCSTRING_NOTES: tuple = ()

log = logging.getLogger("mkdocs.hooks.generated")

#: What reStructuredText markup would leave in a rendered page: a Sphinx role (its name
#: before a code span) or a literal-block marker ending a paragraph. Docstrings and pages
#: are Markdown, which the site and `--help` both show as written.
RST_LEFTOVERS = re.compile(
    r":(?:py:)?(?:func|class|mod|meth|attr|data|exc|obj|const|ref):(?:`|<code>)|\w::</p>"
)


def evidence(path: str) -> str:
    """An evidence file's Markdown as a page shows it: its headings two levels down.

    Raises
    ------
    FileNotFoundError
        If the file is missing (named by the page's marker).
    """
    text = (DOCS.parent / path).read_text()
    return re.sub(r"^(#+) ", lambda m: "#" * min(len(m.group(1)) + 2, 6) + " ", text,
                  flags=re.M).strip("\n")  # fmt: skip


def generated(name: str) -> bool:
    """Whether the marker `name` is one the code fills (a table or an evidence file)."""
    return name in TABLES or name.startswith(EVIDENCE)


def table(name: str) -> str:
    """The Markdown the code generates for the marker `name`."""
    if name.startswith(EVIDENCE):
        return evidence(name[len(EVIDENCE):])
    module, function, *args = TABLES[name]
    made = getattr(import_module(module), function)(*(str(DOCS.parent / a) for a in args))
    if name in SPECS:
        from fahv.config.spec import markdown

        made = markdown(made)
    return made.strip("\n")


def rewrite(text: str) -> str:
    """`text` with every marked table replaced by the one the code generates."""

    def fresh(m: re.Match) -> str:
        name = m.group(1)
        if not generated(name):
            return m.group(0)
        return f"<!-- {name} -->\n{table(name)}\n<!-- /{name} -->"

    return MARKER.sub(fresh, text)


def stale_tables(text: str) -> list[str]:
    """Names of the marked tables of `text` that differ from the code's."""
    return [
        m.group(1)
        for m in MARKER.finditer(text)
        if generated(m.group(1)) and m.group(2).strip("\n") != table(m.group(1))
    ]


def cli_reference() -> str:
    """The help of `fahv` and of every subcommand, one section each."""
    os.environ["COLUMNS"] = "100"  # argparse wraps at the terminal width
    from fahv.cli import build_parser

    parts: list[str] = []

    def walk(parser: argparse.ArgumentParser, level: int) -> None:
        parts.append(f"{'#' * level} `{parser.prog}`\n\n```text\n{parser.format_help()}```\n")
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for sub in dict.fromkeys(action.choices.values()):
                    walk(sub, min(level + 1, 4))

    walk(build_parser(), 2)
    return "\n".join(parts)


class _Demote(logging.Filter):
    """Log the messages that are not page defects (module docstring) as information."""

    def filter(self, record: logging.LogRecord) -> bool:
        text = record.getMessage()
        known = NOT_CROSS_REFERENCES.search(text) or any(
            path in text and f"'{word}'" in text for path, word in KNOWN_DOCSTRING_NOTES
        )
        if known and record.levelno == logging.WARNING:
            record.levelno, record.levelname = logging.INFO, "INFO"
        return True


for _name in ("mkdocs.plugins.griffe", "mkdocs.plugins.mkdocs_autorefs._internal.plugin"):
    logging.getLogger(_name).addFilter(_Demote())


def on_page_markdown(markdown: str, page, **kwargs) -> str:
    """MkDocs event: check the marked tables of a page, expand the CLI reference."""
    stale = stale_tables(markdown)
    if stale:
        log.warning(
            "%s: generated table(s) %s differ from the code; rewrite them with "
            "`.venv/bin/python docs/hooks/generated.py`",
            page.file.src_path,
            ", ".join(stale),
        )
    if CLI_MARKER in markdown:
        markdown = markdown.replace(CLI_MARKER, cli_reference())
    return markdown


def on_page_content(html: str, page, **kwargs) -> str:
    """MkDocs event: fail the strict build on reStructuredText left in a rendered page."""
    found = sorted({m.group(0) for m in RST_LEFTOVERS.finditer(html)})
    if found:
        log.warning("%s: reStructuredText markup in the rendered page (%s); docstrings and "
                    "pages are Markdown", page.file.src_path, ", ".join(found[:5]))  # fmt: skip
    return html


def main() -> int:
    """Rewrite every marked table under docs/ from the code; print what changed."""
    changed = 0
    for path in sorted(DOCS.rglob("*.md")):
        text = path.read_text()
        new = rewrite(text)
        if new != text:
            path.write_text(new)
            changed += 1
            print(f"rewrote {path.relative_to(DOCS.parent)}")
    print(f"{changed} page(s) rewritten")
    return 0


if __name__ == "__main__":
    sys.exit(main())
