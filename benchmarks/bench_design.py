"""Wall time of `fahv design`: an earlier commit beside today's, and how it scales.

The machine's speed varies between hours and machines of the same kind, so the figures
that mean something are those timed back to back in one session. Three designs of the
same design file, each in its own process:

- `before`: an earlier commit, checked out into a temporary git worktree and run with
  its own sources on the same virtual environment (its design file as it named it then);
- `cold`: today's code from scratch (`fahv design --cold` into an empty folder: no
  earlier design and no stored active set, as for a user's new vehicle);
- `warm`: today's code into a folder holding the shipped design, whose stored active
  sets start the LMIs' constraint generation (what re-making a design costs).

Then the scaling table (`--scaling`): the closure of the eight-state tube set (the
tube LMI by constraint generation, W_8's bound and the exact all-vertex level) on the
certified design's own vertex data with k = 3, 5, 7, 9 parameter directions (1024 to
65 536 vertices), and the invariant-ellipsoid LMI (the certificate of a fixed loop, as a
joint error of estimate and tube is certified) on systems of 8, 12, 16 and 24 states:
the eight-state closed loop on 1024 of its vertices with first-order lags appended (the
place of actuator, sensor and estimator states).

Usage:

    .venv/bin/python benchmarks/bench_design.py [--design offline_design/designs/cm_certified.yaml]
        [--before c5ab016 --before-file offline_design/designs/cm_certified.yaml]
        [--scaling] [--only-scaling] [--keep DIR] [--smoke]

`--smoke` runs the scaling code at a tiny size and no design: two of the ten
parameters varied (4 corners and 4 interior vehicles), no parameter direction (128
vertices: the box's 64 corners at both ends of rho_f), one closure iteration, and the
invariant-ellipsoid LMI on 8 and 10 states over 16 vertices of one direction: seconds,
its figures mean nothing.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
#: The smoke run's vertex data: two uncertain parameters, four interior vehicles.
SMOKE = {"params": 2, "interior": 4}
#: The arrays a design certifies (compared between the runs).
CERTIFIED = ("A", "B", "w_max", "F", "N", "K", "Q", "u_lo", "u_hi", "trim_x", "trim_u")


def run_design(src: Path, cwd: Path, design_file: str, out: Path, *extra: str) -> float:
    """Run `fahv design design_file --out out` with the sources in `src`; wall seconds."""
    env = {**os.environ, "PYTHONPATH": str(src), "OPENBLAS_NUM_THREADS": "1"}
    code = "import sys; from fahv.cli import main; sys.exit(main(sys.argv[1:]))"
    t0 = time.perf_counter()
    res = subprocess.run([sys.executable, "-c", code, "design", design_file, "--out", str(out),
                          *extra], cwd=cwd, env=env, capture_output=True, text=True)  # fmt: skip
    wall = time.perf_counter() - t0
    if res.returncode != 0:
        sys.exit(f"design of {design_file} in {cwd} failed:\n{res.stderr[-3000:]}")
    return wall


def compare(a_dir: Path, b_dir: Path) -> str:
    """Largest relative difference of each certified array between two design folders."""
    with np.load(a_dir / "design.npz") as a, np.load(b_dir / "design.npz") as b:
        out = []
        for k in CERTIFIED:
            if k in a and k in b and a[k].shape == b[k].shape:
                d = np.max(np.abs(a[k] - b[k])) / max(np.max(np.abs(b[k])), 1e-300)
                out.append(f"{k} {d:.1e}")
    return ", ".join(out)


def designs(args, tmp: Path) -> None:
    """Time the earlier commit's design, today's from scratch and today's warm."""
    times = {}
    if args.before:
        tree = tmp / "before"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree),
                        args.before], check=True, capture_output=True)  # fmt: skip
        try:
            times["before"] = run_design(tree / "src", tree, args.before_file, tmp / "b")
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)],
                           capture_output=True)  # fmt: skip
        print(f"before ({args.before}, {args.before_file}): {times['before']:.1f} s wall",
              flush=True)  # fmt: skip
    times["cold"] = run_design(ROOT / "src", ROOT, args.design, tmp / "cold", "--cold")
    print(f"after, cold (working tree, {args.design}, from scratch): {times['cold']:.1f} s wall",
          flush=True)  # fmt: skip
    shipped = ROOT / Path(args.design).with_suffix("")
    shutil.copytree(shipped, tmp / "warm")
    times["warm"] = run_design(ROOT / "src", ROOT, args.design, tmp / "warm")
    print(f"after, warm (working tree, from the shipped design's active sets): "
          f"{times['warm']:.1f} s wall", flush=True)  # fmt: skip
    if "before" in times:
        for k in ("cold", "warm"):
            print(f"ratio {k} / before: {times[k] / times['before']:.2f}; certified arrays, "
                  f"largest relative difference: {compare(tmp / k, tmp / 'b')}")  # fmt: skip
    if args.keep is not None:
        shutil.copytree(tmp / "warm", args.keep, dirs_exist_ok=True)


def _vertex_data(design_file: Path, k: int, params: int | None = None, interior: int = 256):
    """The eight-state vertex data of a design file with k parameter directions.

    `params`: only the first `params` uncertain parameters varied (the smoke run's
    size; None: all ten), `interior` vehicles inside their box besides the corners.
    """
    from fahv.bounds.domain import nominal_box
    from fahv.bounds.vertices import nominal_vertices
    from fahv.model.trim import trim_map
    from fahv.model.vehicle import load_vehicle
    from fahv.plant.uncertainty import PAPER_UNCERTAINTY
    from fahv.spec.artefacts import load_design
    from fahv.spec.files import load_design_file

    c = load_design_file(design_file).data
    d = load_design(design_file.with_suffix(""))
    veh = load_vehicle()
    nominal, box = nominal_box(c["eight_state"], veh.envelope)
    tm = trim_map(veh, *c["trim_grid"], "cm")
    unc = {n: v * c["uncertainty"]["scale"] for n, v in PAPER_UNCERTAINTY.items()}
    unc = dict(list(unc.items())[:params])
    a = d.arrays
    scale = np.concatenate([a["Dx"], a["Du"]])
    nv = nominal_vertices(box, veh, tm, unc, float(c["tube"]["rho_min"]), c["Ts"],
                          c["plant_substeps"], scale, k, a["w_max"],
                          np.asarray(d.summary["certificate"]["col_scale"]),
                          interior=interior)  # fmt: skip
    return c, d, nv, nominal


def vertex_scaling(design_file: Path, ks, onset: bool = True, smoke: bool = False) -> None:
    """The closure of the tube set against the number of vertices (k directions).

    `onset`: Z_8 holds the onset's first jumps (66 560 plant steps to sample them), as
    the design does; the smoke run leaves them out. `smoke`: the tiny vertex data of
    `SMOKE` and one closure iteration.
    """
    from fahv.design.tube_set_design import _contain, _state_max
    from fahv.model.trim import trim_map
    from fahv.model.vehicle import load_vehicle
    from fahv.plant.uncertainty import PAPER_UNCERTAINTY
    from fahv.tube.closure import close_tube_set

    print("closure of the eight-state tube set (tube LMI by constraint generation from "
          "scratch, W_8's bound, exact all-vertex level):")  # fmt: skip
    print(f"  {'vertices':>9} {'closure [s]':>12} {'blocks held':>12}")
    for k in ks:
        c, d, nv, nominal = _vertex_data(design_file, k, **(SMOKE if smoke else {}))
        s, a = c["eight_state"], d.arrays
        veh = load_vehicle()
        unc = {n: v * c["uncertainty"]["scale"] for n, v in PAPER_UNCERTAINTY.items()}
        tm = trim_map(veh, *c["trim_grid"], "cm")
        contain = (_contain(c, nv.box, veh, tm, unc, float(c["tube"]["rho_min"]), lambda _: None)
                   if onset else None)  # fmt: skip
        iterations = 1 if smoke else s["iterations"]
        t0 = time.perf_counter()
        try:
            ts = close_tube_set(nv, nominal, s["w0"] * a["w_max"][1:], a["Dx"], a["Du"],
                                np.asarray(d.summary["tube"]["row_room"]), s["lam"],
                                c["mpc"]["M"], grow=s["grow"], iterations=iterations,
                                w_ref=a["w_max"], state_max=_state_max(c, lambda _: None),
                                contain=contain, log=lambda _: None)  # fmt: skip
            held = str(len(ts.active_set.vertices))
        except Exception as exc:  # a size at which the tube set does not close: say so
            held = f"not closed: {str(exc)[:60]}"
        print(f"  {nv.n_vertices:>9} {time.perf_counter() - t0:>12.1f} {held:>12}", flush=True)


def _augmented(Acl, extra: int, a: float = 0.8):
    """Closed-loop vertices (R, n, n) with `extra` states appended: first-order lags.

    Lag j follows the plant's state j mod n (x+ = a x + (1 - a) e_j): the place of the
    actuator, sensor and estimator states of an output-feedback design. Block lower
    triangular, so every vertex keeps its own eigenvalues and gains a at each lag.
    """
    R, n, _ = Acl.shape
    Aa = np.zeros((R, n + extra, n + extra))
    Aa[:, :n, :n] = Acl
    for j in range(extra):
        Aa[:, n + j, n + j] = a
        Aa[:, n + j, j % n] = 1.0 - a
    return Aa


def state_scaling(dims, R: int, smoke: bool = False) -> None:
    """The invariant-ellipsoid LMI against the state dimension (augmented closed loops).

    The eight-state tube set's closed loop A_8 + B_8 F_8 (the shipped F_8 and W_8) on R
    of its vertices, with lags appended up to each dimension; the smallest ellipsoid RPI
    for W_8 whose projection lies in Z_8 (`fahv.synthesis.invariant_ellipsoid.
    invariant_ellipsoid`: constraint generation from scratch, the exact all-vertex level
    at every pass), the LMI a joint error of estimate and tube is certified with.
    `smoke`: the vertices drawn from the tiny vertex data of `SMOKE` (k = 1).
    """
    from fahv.spec.artefacts import load_design
    from fahv.synthesis.invariant_ellipsoid import invariant_ellipsoid
    from fahv.synthesis.rpi_level import vertex_levels

    design_file = ROOT / "offline_design/designs/cm_certified.yaml"
    _, d, nv, _ = _vertex_data(design_file, 1, **SMOKE) if smoke else _vertex_data(design_file, 3)
    A, B = nv.vertices()
    rng = np.random.default_rng(0)
    idx = rng.choice(A.shape[0], min(R, A.shape[0]), replace=False)
    cert = load_design(design_file.with_suffix("")).summary["certificate"]
    F_8 = np.asarray(d.arrays["F"])[:, 1:]
    N_8 = np.asarray(d.arrays["N"])[1:, 1:]
    w8 = np.asarray(cert["W_8"])
    Acl8 = A[idx, 1:, 1:] + B[idx, 1:, :] @ F_8
    tightening = np.sqrt(np.einsum("ij,jk,ik->i", F_8, N_8, F_8))
    print(f"invariant ellipsoid (constraint generation from scratch) on {len(idx)} vertices "
          "against the state dimension (the eight-state closed loop with first-order lags):")
    print(f"  {'states':>7} {'LMI [s]':>9} {'blocks held':>12} {'exact level':>12}")
    for n in dims:
        Aa = _augmented(Acl8, n - 8)
        w = np.r_[w8, np.zeros(n - 8)]
        K = np.hstack([F_8, np.zeros((2, n - 8))])
        D = np.r_[np.sqrt(np.diag(N_8)), np.full(n - 8, np.sqrt(N_8.diagonal().mean()))]
        t0 = time.perf_counter()
        ell = invariant_ellipsoid(Aa, w8, D, N_8, K, 10.0 * tightening,
                                  lambda P, Aa=Aa, w=w: vertex_levels(Aa, P, w), 0.995)  # fmt: skip
        wall = time.perf_counter() - t0
        level = f"{vertex_levels(Aa, ell.P, w).max():.6f}" if ell.found else "none found"
        print(f"  {n:>7} {wall:>9.1f} {ell.n_blocks:>12} {level:>12}", flush=True)


def main() -> int:
    """Time the designs (unless --only-scaling), then the scaling tables if asked."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--design", default="offline_design/designs/cm_certified.yaml")
    ap.add_argument("--before", default="c5ab016",
                    help="earlier commit (default: the release before the faster synthesis; "
                         "'': skip it)")  # fmt: skip
    ap.add_argument("--before-file", default="offline_design/designs/cm_certified.yaml",
                    help="the design's file as the earlier commit named it")  # fmt: skip
    ap.add_argument("--keep", type=Path, default=None,
                    help="copy today's warm design folder here (e.g. to ship it)")  # fmt: skip
    ap.add_argument("--scaling", action="store_true", help="print the scaling tables too")
    ap.add_argument("--only-scaling", action="store_true", help="the scaling tables alone")
    ap.add_argument("--smoke", action="store_true",
                    help="the scaling code at a tiny size, no design (CI)")  # fmt: skip
    args = ap.parse_args()
    warnings.filterwarnings("ignore", message="Solution may be inaccurate")
    design_file = ROOT / args.design
    if args.smoke:
        print("smoke: the scaling code at a tiny size, no design (the figures mean nothing)")
        vertex_scaling(design_file, (0,), onset=False, smoke=True)
        state_scaling((8, 10), 16, smoke=True)
        return 0
    if not args.only_scaling:
        with tempfile.TemporaryDirectory() as tmp:
            designs(args, Path(tmp))
    if args.scaling or args.only_scaling:
        vertex_scaling(design_file, (3, 5, 7, 9))
        state_scaling((8, 12, 16, 24), 1024)
    return 0


if __name__ == "__main__":
    sys.exit(main())
