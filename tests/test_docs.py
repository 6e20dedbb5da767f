"""The README and the documentation site: a guide of a few screens, product documentation.

The site itself is built, strict, by scripts/docs.sh; these checks are the ones a build
does not make: the README's length and links, the vocabulary of every page, every page in
the nav, and an API page for every part of the library.
"""

import re
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"

#: Words of how the project was made rather than of what it is.
PROCESS_WORDS = (
    re.compile(r"\b(stop|issue|item|session)\s+\d+", re.IGNORECASE),
    re.compile(r"lab" + r" notebook", re.IGNORECASE),
    re.compile(r"^#{1,6}\s.*\b(19|20)\d\d-\d\d", re.MULTILINE),
    re.compile(r"\b(19|20)\d\d-\d\d-\d\d\b"),
)


def _pages() -> list[Path]:
    """Every Markdown page of the site (docs/hooks/ holds code and docs/evidence/ what
    commands wrote for the pages to show, not pages)."""
    return sorted(p for p in DOCS.rglob("*.md")
                  if not {"hooks", "evidence"} & set(p.relative_to(DOCS).parts))  # fmt: skip


def _nav_pages(entries) -> list[str]:
    found = []
    for entry in entries:
        if isinstance(entry, str):
            found.append(entry)
        elif isinstance(entry, dict):
            for value in entry.values():
                found += _nav_pages(value) if isinstance(value, list) else [value]
    return found


def _nav() -> list[str]:
    return _nav_pages(yaml.safe_load((ROOT / "mkdocs.yml").read_text())["nav"])


def test_readme_is_a_guide_of_at_most_150_lines_of_100_characters():
    """A newcomer reads it in five minutes: figures and evidence live in the docs."""
    lines = (ROOT / "README.md").read_text().splitlines()
    assert len(lines) <= 150, f"README.md has {len(lines)} lines"
    long = [i + 1 for i, line in enumerate(lines) if len(line) > 100]
    assert long == [], f"README.md lines over 100 characters: {long}"


def test_readme_links_resolve():
    text = (ROOT / "README.md").read_text()
    targets = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text)
    assert targets, "the README links to the documentation"
    missing = [t for t in targets if "://" not in t and not (ROOT / t).exists()]
    assert missing == []


def test_no_development_process_vocabulary():
    found = []
    for path in [ROOT / "README.md", *_pages()]:
        text = path.read_text()
        for pattern in PROCESS_WORDS:
            for m in pattern.finditer(text):
                line = text.count("\n", 0, m.start()) + 1
                found.append(f"{path.relative_to(ROOT)}:{line}: {m.group(0)!r}")
    assert found == []


def test_every_page_is_in_the_nav_and_every_nav_entry_is_a_page():
    pages = {p.relative_to(DOCS).as_posix() for p in _pages()}
    nav = set(_nav())
    assert sorted(pages - nav) == [], "pages missing from the nav of mkdocs.yml"
    assert sorted(nav - pages) == [], "nav entries without a page"


def test_every_part_of_the_library_has_an_api_page():
    src = ROOT / "src" / "fahv"
    parts = {p.name for p in src.iterdir() if (p / "__init__.py").exists()}
    parts |= {p.stem for p in src.glob("*.py") if p.stem != "__init__"}
    api = "\n".join(p.read_text() for p in (DOCS / "reference" / "api").glob("*.md"))
    documented = set(re.findall(r"^::: fahv\.(\w+)", api, re.MULTILINE))
    assert sorted(parts - documented) == []
    assert sorted(documented - parts) == []
    assert re.search(r"^::: fahv_studies$", api, re.MULTILINE)  # the studies' package


def _verdict_cells(lines: list[str]) -> dict[str, list[str]]:
    """Requirement -> its last four cells (value, limit, margin, verdict) of a verdict table."""
    rows = {}
    for line in lines:
        cells = re.split(r"\s{2,}", line.strip())
        if len(cells) >= 5 and cells[-1] in ("PASS", "FAIL", "n/a"):
            rows[cells[0]] = cells[-4:]
    return rows


def test_the_readmes_verdict_example_is_the_generated_table():
    """The README's excerpt of Case 1's verdict table has the numbers of the table the
    command wrote into the runs guide (`fahv simulate ... case1.yaml`, marker
    case1-verdict, checked current by the docs build), row for row, and its last line."""
    guide = (DOCS / "guide" / "runs.md").read_text()
    generated = guide.split("<!-- case1-verdict -->\n", 1)[1].split("<!-- /case1-verdict -->")[0]
    readme = (ROOT / "README.md").read_text()
    excerpt = readme.split("    requirement  measured", 1)[1].split("\n\n", 1)[0].splitlines()
    ours, theirs = _verdict_cells(excerpt), _verdict_cells(generated.splitlines())
    assert ours and all(theirs[k] == cells for k, cells in ours.items()), (ours, theirs)
    assert excerpt[-1].strip() == generated.rstrip().splitlines()[-1].strip()


def test_every_evidence_file_a_page_shows_is_shown_as_it_is():
    """A page's `evidence:` markers (docs/hooks/generated.py) hold the files a command wrote,
    unedited (headings two levels down); a hand edit of either side fails here, and the
    site's strict build fails the same way."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("generated", DOCS / "hooks" / "generated.py")
    hook = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hook)
    shown = [(page, m) for page in _pages() for m in hook.MARKER.finditer(page.read_text())
             if m.group(1).startswith(hook.EVIDENCE)]  # fmt: skip
    assert shown, "the results pages show evidence files"
    for page, m in shown:
        path = ROOT / m.group(1)[len(hook.EVIDENCE):]
        assert path.is_file(), f"{page.name}: {path} is missing"
        assert m.group(2).strip("\n") == hook.evidence(m.group(1)[len(hook.EVIDENCE):]), (
            f"{page.name}: {path.name} differs from the page; run docs/hooks/generated.py")
    assert hook.evidence(m.group(1)[len(hook.EVIDENCE):]).startswith("### "), "demoted"
