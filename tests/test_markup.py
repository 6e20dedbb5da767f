"""Docstrings and help texts are Markdown: no reStructuredText a reader would see as is.

The documentation site renders docstrings as Markdown (mkdocstrings) and `fahv --help`
prints them as written, so a Sphinx role (`:func:` before a code span), a doubled
backtick or a literal-block marker (`::` ending a line) shows literally in both. The
site's build fails on any left in a rendered page (docs/hooks/generated.py,
`on_page_content`); this test reads the sources and every `--help`.
"""

import argparse
import re
from pathlib import Path

from fahv.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
ROLE = re.compile(r":(?:py:)?(?:func|class|mod|meth|attr|data|exc|obj|const|ref):`")
#: a role, a doubled backtick (not a fence's three), a literal-block marker
LEFTOVERS = (ROLE, re.compile(r"(?<!`)``(?!`)"), re.compile(r"\S::$", re.M),
             re.compile(r"^\s*::\s*$", re.M))


def _helps():
    """(prog, help text) of `fahv` and of every subcommand, nested ones included."""
    out = []

    def walk(parser: argparse.ArgumentParser) -> None:
        out.append((parser.prog, parser.format_help()))
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for sub in dict.fromkeys(action.choices.values()):
                    walk(sub)

    walk(build_parser())
    return out


def test_no_help_text_shows_restructuredtext():
    helps = _helps()
    assert len(helps) >= 18  # fahv and its subcommands
    bad = [(prog, m.group(0)) for prog, text in helps for pat in LEFTOVERS
           for m in pat.finditer(text)]  # fmt: skip
    assert bad == []


def test_no_source_docstring_holds_a_sphinx_role_or_a_literal_block_marker():
    files = [p for d in ("src", "ros_ws/src", "benchmarks", "docs")
             for p in (ROOT / d).rglob("*") if p.suffix in (".py", ".md")]  # fmt: skip
    assert len(files) > 100
    bad = [f"{p.relative_to(ROOT)}:{p.read_text().count(chr(10), 0, m.start()) + 1}: {m.group(0)}"
           for p in files for pat in LEFTOVERS for m in pat.finditer(p.read_text())]  # fmt: skip
    assert bad == []
