"""Version of the fahv library and of the code a result was made with."""

from __future__ import annotations

import subprocess
from pathlib import Path

from fahv import __version__

__all__ = ["__version__", "code_version"]


def code_version() -> str:
    """`fahv <version>` plus the git commit (`+dirty` when modified), if in a repository."""
    v = f"fahv {__version__}"
    try:
        here = Path(__file__).resolve().parent
        rev = subprocess.run(
            ["git", "describe", "--always", "--dirty"],
            cwd=here,
            capture_output=True,
            text=True,
            timeout=5,
            check=True,
        ).stdout.strip()
        return f"{v} ({rev})" if rev else v
    except (OSError, subprocess.SubprocessError):
        return v
