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
