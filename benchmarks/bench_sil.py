"""Real-time factor of the SIL node graph: the working tree against an earlier commit.

Both trees run the same scenario, each from the ROS 2 parameter file its own library
makes of it (`fahv sil SCENARIO --duration D --write-params`, so that a tree whose
nodes take other parameters still runs), each with its own nodes, runner and library:
the commit is exported with `git archive` (the repository is not touched), its
workspace built with its own `scripts/build_ros.sh` and its `src` put first on
`PYTHONPATH`. The runs alternate (new, old, then old, new, ...) so that
the load of other processes on the machine falls on both alike. The wall time is that
of the `sil` runner process, as `fahv sil` measures it (start-up, the steps, the
teardown); the real-time factor is the simulated time over it. Prints every run, the
median of each tree and their ratio. Unless `--no-compose`, the working tree also runs
with its loop nodes composed in one process (`sil --compose`, named `composed`), in the
same alternation.

Run: .venv/bin/python benchmarks/bench_sil.py [--commit HEAD] [-n 3] [--duration 60]
     [--scenario offline_design/scenarios/case1.yaml] [--allow-uncertified] [--no-compose]
     [--smoke]
A commit whose nodes refuse its own file shows as failed runs (exit status 1, the
node's reason printed).

`--smoke` skips the earlier commit (nothing exported or built) and runs the working
tree's graph once for 2 s simulated: CI's check that the benchmark still runs (its
figures mean nothing). It needs the built workspace, as every SIL run.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

from fahv.sil.workspace import ROOT, WS, ensure_built, ros_env

#: Environment variables of the nodes that the benchmark does not pass on (each tree
#: runs with its own defaults).
NODE_SWITCHES = ("HSV_EXECUTOR", "HSV_PARAM_SERVICES")
#: Name of the working tree's runs with the loop nodes composed in one process.
COMPOSED_TREE = "composed"
#: --smoke: runs of the working tree and simulated time [s].
SMOKE_RUNS, SMOKE_DURATION = 1, 2.0


def export_commit(commit: str, cache: Path) -> tuple[Path, str]:
    """The tree of `commit` under `cache/<sha>`, its workspace built (reused if there).

    Raises
    ------
    subprocess.CalledProcessError
        If the commit is unknown or its workspace does not build.
    """
    sha = subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "--verify", f"{commit}^{{commit}}"],
        capture_output=True, text=True, check=True,
    ).stdout.strip()  # fmt: skip
    tree = cache / sha[:12]
    if not (tree / "ros_ws" / "install" / "setup.bash").is_file():
        shutil.rmtree(tree, ignore_errors=True)
        tree.mkdir(parents=True)
        archive = subprocess.run(
            ["git", "-C", str(ROOT), "archive", sha], capture_output=True, check=True
        ).stdout
        subprocess.run(["tar", "-x", "-C", str(tree)], input=archive, check=True)
        (tree / ".venv").symlink_to(ROOT / ".venv")
        print(f"building the workspace of {sha[:12]} in {tree} ...", flush=True)
        env = {**os.environ, "PYTHONPATH": str(tree / "src")}
        subprocess.run(
            ["bash", str(tree / "scripts" / "build_ros.sh")], env=env, check=True,
            stdout=subprocess.DEVNULL,
        )  # fmt: skip
    return tree, sha[:12]


def tree_env(ws: Path, src: Path | None) -> dict:
    """Environment of a sourced workspace, with `src` first on PYTHONPATH."""
    env = {k: v for k, v in os.environ.items() if k not in NODE_SWITCHES}
    if src is not None:
        env["PYTHONPATH"] = os.pathsep.join(p for p in (str(src), env.get("PYTHONPATH")) if p)
    venv_bin = Path(sys.executable).parent
    script = f'export PATH="{venv_bin}:$PATH"; source "{ws}/install/setup.bash" && env -0'
    out = subprocess.run(["bash", "-c", script], env=env, capture_output=True, check=True).stdout
    return dict(item.split("=", 1) for item in out.decode().split("\0") if "=" in item)


def write_params(
    root: Path, env: dict, scenario: str, duration: float, path: Path, extra: tuple = ()
) -> dict:
    """The run's parameter file, made by the tree at `root` (`fahv sil --write-params`).

    `extra`: further options of `fahv sil` (`--allow-uncertified`).

    Raises
    ------
    SystemExit
        If the tree's `fahv sil` fails (its output printed).
    """
    cmd = [sys.executable, "-c", "import sys; from fahv.cli import main; sys.exit(main())",
           "sil", scenario, "--duration", str(duration), "--write-params", str(path),
           *extra]  # fmt: skip
    r = subprocess.run(cmd, cwd=root, env=env, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"bench_sil: fahv sil --write-params in {root} failed:\n{r.stdout}{r.stderr}")
    return yaml.safe_load(path.read_text())


def run_once(
    content: dict, ws: Path, env: dict, work: Path, extra: tuple = ()
) -> tuple[int, float, str]:
    """One run of a workspace's `sil` runner (`extra`: its further options).

    Returns (exit status, wall time [s], error tail).
    """
    work.mkdir(parents=True)
    c = yaml.safe_load(yaml.safe_dump(content))
    c["recorder"]["ros__parameters"].update(bag=str(work / "run"), params_file="")
    c["/**"]["ros__parameters"]["run_id"] = work.name
    params = work / "params.yaml"
    params.write_text(yaml.safe_dump(c, sort_keys=False))
    exe = ws / "install" / "hsv_bringup" / "lib" / "hsv_bringup" / "sil"
    cmd = [str(exe), "--params-file", str(params), "--log-dir", str(work / "logs"), "--quiet",
           *extra]  # fmt: skip
    t0 = time.monotonic()
    r = subprocess.run(cmd, env=env, capture_output=True, text=True)
    wall = time.monotonic() - t0
    return r.returncode, wall, "" if r.returncode == 0 else r.stderr[-1500:]


def main() -> None:
    """Alternate runs of both trees; print each run, the medians and their ratio."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="offline_design/scenarios/case1.yaml")
    ap.add_argument("--commit", default="HEAD", help="earlier commit to compare with")
    ap.add_argument("--duration", type=float, default=60.0, help="simulated time [s]")
    ap.add_argument("-n", type=int, default=3, help="runs of each tree")
    ap.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir()) / "fahv_bench_sil")
    ap.add_argument("--keep", action="store_true", help="keep the run folders")
    ap.add_argument("--allow-uncertified", action="store_true",
                    help="run a scenario beyond what its design certifies (fahv sil's option)")
    ap.add_argument("--no-compose", action="store_true",
                    help="leave out the working tree's graph with its loop nodes composed in "
                    "one process (`sil --compose`)")  # fmt: skip
    ap.add_argument("--smoke", action="store_true",
                    help="no earlier commit, one short run of the working tree (CI: the "
                    "benchmark still runs)")  # fmt: skip
    args = ap.parse_args()

    ensure_built()
    trees = {"working tree": (WS, ros_env())}
    roots = {"working tree": ROOT}
    sha = None
    if args.smoke:
        args.n, args.duration = SMOKE_RUNS, SMOKE_DURATION
        print(f"smoke: earlier commit {args.commit} skipped (not exported, not built); the "
              "working tree's graph only (the figures mean nothing)")  # fmt: skip
    else:
        base, sha = export_commit(args.commit, args.cache)
        trees[sha] = (base / "ros_ws", tree_env(base / "ros_ws", base / "src"))
        roots[sha] = base
    work = Path(tempfile.mkdtemp(prefix="bench_sil_"))
    if not args.no_compose:  # the same tree and parameter file, the loop in one process
        trees[COMPOSED_TREE], roots[COMPOSED_TREE] = trees["working tree"], ROOT
    allow = ("--allow-uncertified",) if args.allow_uncertified else ()
    content = {
        name: write_params(roots[name], env, args.scenario, args.duration,
                           work / f"params_{i}.yaml", allow)
        for i, (name, (_, env)) in enumerate(trees.items())
    }  # fmt: skip
    for _, env in trees.values():
        for k in NODE_SWITCHES:
            env.pop(k, None)
    rtf: dict[str, list[float]] = {name: [] for name in trees}
    print(f"{args.scenario}, {args.duration:g} s simulated, {args.n} run(s) each"
          + (", alternating" if len(trees) > 1 else ""))  # fmt: skip
    for i in range(args.n):
        order = list(trees) if i % 2 == 0 else list(trees)[::-1]
        for name in order:
            ws, env = trees[name]
            extra = ("--compose",) if name == COMPOSED_TREE else ()
            rc, wall, err = run_once(content[name], ws, env,
                                     work / f"{i}_{name.replace(' ', '_')}", extra)  # fmt: skip
            rtf[name].append(args.duration / wall if rc == 0 else float("nan"))
            print(f"  run {i + 1} {name:>12s}: wall {wall:6.2f} s, real-time factor "
                  f"{rtf[name][-1]:5.2f}" + ("" if rc == 0 else f"  FAILED (exit {rc})"),
                  flush=True)  # fmt: skip
            if err:
                print("    " + err.strip().replace("\n", "\n    "), flush=True)
    med = {n: statistics.median([x for x in v if x == x] or [float("nan")]) for n, v in rtf.items()}
    for name, v in rtf.items():
        runs = ", ".join(f"{x:.2f}" for x in v)
        print(f"{name:>12s}: median real-time factor {med[name]:.2f}  ({runs})")
    if sha is not None:
        for name in [n for n in med if n != sha]:
            print(f"ratio {name} / {sha}: {med[name] / med[sha]:.2f}")
    if not args.keep:
        shutil.rmtree(work, ignore_errors=True)
    if any(x != x for x in rtf["working tree"] + rtf.get(COMPOSED_TREE, [])):
        sys.exit("bench_sil: a run of the working tree failed")


if __name__ == "__main__":
    main()
