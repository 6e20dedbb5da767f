"""The code hash of a design's provenance covers every package the design code imports."""

from pathlib import Path

import grimp

import fahv
from fahv.spec.artefacts import DESIGN_PACKAGES

ROOT = Path(fahv.__file__).resolve().parent
#: Imported, but no number of a design depends on it: the loop messages (the control laws'
#: online part names their types).
NOT_HASHED = {"msg"}


def test_the_code_hash_covers_every_package_the_design_and_its_verification_import():
    """A change in any package the pipeline or the verification imports (directly or not)
    must move the code hash, so that a cached verdict is not reused for other code."""
    graph = grimp.build_graph("fahv")
    reached = set()
    for start in ("fahv.design.pipeline", "fahv.certificate.verify", "fahv.certificate.verified"):
        reached |= graph.find_upstream_modules(start) | {start}
    packages = {m.split(".")[1] for m in reached if m.count(".") >= 1}
    packages = {p for p in packages if (ROOT / p / "__init__.py").is_file()}
    assert sorted(packages - set(DESIGN_PACKAGES) - NOT_HASHED) == []
    assert all((ROOT / p / "__init__.py").is_file() for p in DESIGN_PACKAGES)
