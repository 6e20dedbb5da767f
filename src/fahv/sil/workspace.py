"""The colcon workspace ros_ws/: build on source change, and its environment."""

from __future__ import annotations

import hashlib
import subprocess
import sys
from pathlib import Path

from fahv.errors import RunError

#: Repository root (the library is installed in editable mode from it).
ROOT = Path(__file__).resolve().parents[3]


WS = ROOT / "ros_ws"


PACKAGES = ("hsv_interfaces", "hsv_common", "hsv_plant", "hsv_ctrl", "hsv_bringup")


def sources_hash(ws: Path = WS) -> str:
    """SHA-256 over every source file of `ws/src` (message files included).

    The packages are installed as copies (no `--symlink-install`), so a changed
    node or message needs a rebuild; `workspace_built` compares this hash
    with the one the last build recorded.
    """
    h = hashlib.sha256()
    for f in sorted((ws / "src").rglob("*")):
        if f.is_file() and "__pycache__" not in f.parts:
            h.update(str(f.relative_to(ws)).encode() + b"\0" + f.read_bytes() + b"\0")
    return h.hexdigest()


def write_build_stamp(ws: Path = WS) -> None:
    """Record `sources_hash` after a successful build (`scripts/build_ros.sh`)."""
    (ws / "install" / ".fahv_sources").write_text(sources_hash(ws))


def workspace_built(ws: Path = WS) -> bool:
    """True if every hsv package is installed in `ws/install` from the current sources."""
    stamp = ws / "install" / ".fahv_sources"
    return (
        (ws / "install" / "setup.bash").is_file()
        and all((ws / "install" / p / "share" / p / "package.xml").is_file() for p in PACKAGES)
        and stamp.is_file()
        and stamp.read_text() == sources_hash(ws)
    )


def ensure_built(ws: Path = WS, log=print) -> None:
    """Build the workspace with colcon if a package is missing or its sources changed.

    Raises
    ------
    RunError
        If the build fails (the colcon output is shown).
    """
    if workspace_built(ws):
        return
    log(f"building {ws} (colcon) ...")
    r = subprocess.run(
        ["bash", str(ROOT / "scripts" / "build_ros.sh")], capture_output=True, text=True
    )
    if r.returncode != 0 or not workspace_built(ws):
        raise RunError(f"colcon build of {ws} failed:\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}")


def ros_env(ws: Path = WS) -> dict:
    """Environment of `source ws/install/setup.bash` with this venv first on PATH.

    Raises
    ------
    RunError
        If sourcing fails.
    """
    venv_bin = str(Path(sys.executable).parent)
    script = f'export PATH="{venv_bin}:$PATH"; source "{ws}/install/setup.bash" && env -0'
    r = subprocess.run(["bash", "-c", script], capture_output=True)
    if r.returncode != 0:
        raise RunError(f"sourcing {ws}/install/setup.bash failed: {r.stderr.decode()[-2000:]}")
    env = dict(item.split("=", 1) for item in r.stdout.decode().split("\0") if "=" in item)
    return env
