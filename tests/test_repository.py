"""The repository is self-contained: no tracked file points to documents outside it."""

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
