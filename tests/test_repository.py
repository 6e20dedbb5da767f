"""The repository is self-contained: no tracked file points to documents outside it."""

import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# spelled in pieces so that this file does not match itself
NAMES = ("ARCHITECTURE", "ENVIRONMENT", "MODEL_DATA")
OUTSIDE = tuple(n + ".md" for n in NAMES) + ("../" + "shared",)


def test_no_tracked_file_cites_documents_outside_the_repository():
    files = subprocess.run(
        ["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True
    ).stdout.split()
    hits = []
    for name in files:
        path = ROOT / name
        if path.suffix in (".png", ".pdf") or not path.is_file():
            continue
        text = path.read_text(errors="ignore")
        hits += [f"{name}: {word}" for word in OUTSIDE if word in text]
    assert hits == []


def _pins():
    from packaging.utils import canonicalize_name

    pins = {}
    for line in (ROOT / "constraints.txt").read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            name, _, version = line.partition("==")
            assert version, f"constraints.txt: {line!r} is not an exact pin"
            pins[canonicalize_name(name)] = version.strip()
    return pins


def test_every_dependency_is_pinned_and_installed_at_its_pin():
    """constraints.txt (scripts/lock.sh) pins every dependency of pyproject.toml, the
    extras dev and ros included, and the environment running the tests (scripts/setup.sh
    installs with it) holds exactly those versions: a new release cannot move a result."""
    import tomllib
    from importlib.metadata import PackageNotFoundError, version

    from packaging.requirements import Requirement
    from packaging.utils import canonicalize_name

    pins = _pins()
    assert len(pins) > 200  # the ROS 2 wheels and colcon included
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    wanted = list(project["dependencies"])
    for extra in ("dev", "ros"):
        wanted += project["optional-dependencies"][extra]
    names = {canonicalize_name(Requirement(r).name) for r in wanted}
    assert sorted(names - set(pins)) == []
    for r in wanted:  # each pin satisfies pyproject.toml's own bounds
        req = Requirement(r)
        assert req.specifier.contains(pins[canonicalize_name(req.name)]), r
    moved = []
    for name, pinned in pins.items():
        try:
            installed = version(name)
        except PackageNotFoundError:
            moved.append(f"{name}: not installed")
            continue
        if installed != pinned:
            moved.append(f"{name}: {installed} installed, {pinned} pinned")
    assert moved == []


def _tracked_text_files():
    files = subprocess.run(
        ["git", "ls-files", "--cached", "--others", "--exclude-standard"],
        cwd=ROOT, capture_output=True, text=True, check=True,
    ).stdout.split()  # fmt: skip
    for name in files:
        path = ROOT / name
        if path.suffix in (".png", ".pdf", ".npz", ".mcap", ".ico") or not path.is_file():
            continue
        if name.startswith(("tests/live/package-lock", "constraints.txt")):
            continue
        yield name, path.read_text(errors="ignore")


#: Words of the development process, meaningless to a user (spelled in pieces so that
#: this file does not match itself).
PROCESS = re.compile(
    r"\b("
    + "|".join(("st" + "op", "is" + "sue", "it" + "em", "ses" + "sion", "rou" + "nd"))
    + r")[ _-]?#?\d+\b|\bte"
    + r"st_is"
    + r"sue\d+|\bla"
    + r"b note"
    + r"book\b",
    re.IGNORECASE,
)


def test_no_development_process_vocabulary_in_the_repository():
    """Code, docs, configuration and test names say what things are, not when they came."""
    hits = []
    for name, text in _tracked_text_files():
        for m in PROCESS.finditer(text + "\n" + name):
            hits.append(f"{name}: {m.group(0)!r}")
    assert hits == []


#: Modules over MODULE_LINES lines must say why in their docstring (this phrase).
MODULE_LINES = 600
REASON = "one concept, kept whole:"


def test_modules_hold_one_concept_and_stay_under_600_lines():
    long = []
    for path in sorted((ROOT / "src" / "fahv").rglob("*.py")):
        lines = path.read_text().splitlines()
        if len(lines) > MODULE_LINES and REASON not in "\n".join(lines[:40]):
            long.append(f"{path.relative_to(ROOT)}: {len(lines)} lines")
    assert long == []


def test_scripts_holds_only_setup_test_main_job_build_and_lock():
    names = sorted(p.name for p in (ROOT / "scripts").iterdir())
    assert names == ["build_ros.sh", "docs.sh", "lock.sh", "main_job.sh", "setup.sh", "test.sh"]


#: Functions longer than FUNCTION_LINES (docstring excluded) must say why (REASON).
FUNCTION_LINES = 80


def test_functions_stay_under_80_lines_or_say_why():
    import ast

    long = []
    for path in sorted((ROOT / "src" / "fahv").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                continue
            doc = ast.get_docstring(node) or ""
            n = node.end_lineno - node.lineno + 1
            if doc:
                n -= node.body[0].end_lineno - node.body[0].lineno + 1
            if n > FUNCTION_LINES and "kept whole:" not in doc:
                long.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name}: {n} lines")
    assert long == []
