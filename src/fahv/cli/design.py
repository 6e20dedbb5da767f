"""`fahv design` (synthesis of a design file) and `fahv verify` (its re-check)."""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

from fahv.certificate.verify import record_pass, require_verified, verify
from fahv.cli.common import add_vehicle_option, progress, vehicle_of
from fahv.errors import DesignError, SpecError
from fahv.spec.artefacts import load_design, save_design
from fahv.spec.files import load_design_file, read_yaml_file
from fahv.spec.scenario import load_scenario
from fahv.spec.schema import OPTIONAL_SECTIONS, SCENARIO_KEYS
from fahv.spec.store import design_dir, stored_design


def design_and_store(spec, vehicle, out_dir: Path, log=print, cold: bool = False):
    """Design a design file (`spec`) for `vehicle` and store it with its certificate lines.

    Writes `design.npz` (the certified arrays), `warm_starts.npz`, `design.json` and
    `certificate.txt` (every line the design printed) into `out_dir` atomically. A
    progress line names the stage at least every 10 s, with the time left estimated from
    the stage times of the design `out_dir` held before
    (`fahv.design.stage_clock.StageClock`). The LMIs' constraint generation starts from
    the active sets that design stored (its warm starts,
    `fahv.spec.artefacts.Design.warm_starts`), unless
    `cold` (`previous` of `fahv.design.pipeline.run_design`). A design whose
    arrays and inputs are those of the stored one leaves its files as they are (its
    design hash is its content, `fahv.spec.artefacts.save_design`): the stored
    code version and stage times stay, and the latter still estimate the next design.

    Returns
    -------
    fahv.spec.artefacts.Design

    Raises
    ------
    DesignError
        If a certificate fails (nothing is written then).
    """
    warnings.filterwarnings("ignore", message="Solution may be inaccurate")
    lines: list[str] = []
    t0 = time.monotonic()

    def both(line: str) -> None:
        lines.append(line)
        log(f"[{time.monotonic() - t0:6.0f} s] {line}")

    def bar(it):
        return progress(it, desc="sample W", leave=False)

    # here: `fahv verify` (this module's other command) loads neither cvxpy nor Dask
    from fahv.design.pipeline import run_design
    from fahv.design.stage_clock import StageClock

    previous = _previous_design(out_dir)
    times = None if previous is None else previous.summary.get("stage_times_s")
    start = None if cold or previous is None else previous.warm_starts
    with StageClock(times) as clock:
        design = run_design(spec, vehicle, progress=bar, log=both, clock=clock, previous=start)
    design.summary["design_time_s"] = round(time.monotonic() - t0, 1)  # not in the hash
    design.summary["stage_times_s"] = clock.times  # not in the hash: the next estimate
    if previous is not None and previous.content_hash() == design.content_hash():
        log(f"design hash {design.summary['design_hash']}: the stored design's arrays from the "
            "same inputs; its files are kept, with the code and the times that made them")
    save_design(design, out_dir, {"certificate.txt": "\n".join(lines) + "\n"})
    return design


def _previous_design(folder: Path):
    """The design stored in `folder` (None if none is, or it does not load)."""
    try:
        return load_design(folder)
    except DesignError:
        return None


def cmd_design(args) -> int:
    """Offline synthesis of a design file: print every certificate, write the artefacts."""
    spec = load_design_file(args.design)
    vehicle = vehicle_of(args)
    out = design_dir(spec.path, spec.name, args.out, vehicle)
    # the workers start while the first stages run in this process
    from fahv.cluster import dask_client

    client, cluster = dask_client(args.scheduler, args.workers)
    try:
        design = design_and_store(spec, vehicle, out, cold=args.cold)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    prov = design.summary["provenance"]
    print(
        f"design hash {design.summary['design_hash']} (design file {prov['design_file_hash']}, "
        f"vehicle {prov['vehicle_file'] or 'packaged'} {prov['vehicle_hash']}, code "
        f"{prov['code_hash']}); artefacts written to {out}/"
    )
    return 0


def resolve_design_file(path: str | Path) -> Path:
    """The design file of `path`: a design file, a scenario file, or a design name.

    Raises
    ------
    SpecError
        If `path` is none of them.
    """
    p = Path(path)
    if not p.suffix:  # a name
        for d in (Path("offline_design") / "designs", Path("offline_design") / "scenarios"):
            if (d / f"{p}.yaml").is_file():
                p = d / f"{p}.yaml"
                break
        else:
            raise SpecError(f"no design or scenario named {path!r} in offline_design/")
    data = read_yaml_file(p, "design or scenario file")
    if not isinstance(data, dict) or "design_step" in data:
        return p
    # a scenario names its design or extends another scenario; a design file that extends
    # another has an entry no scenario has (its estimate, tube, mpc, ...)
    own = set(data) - {"extends", "name", "description"}
    if "design" in data or ("extends" in data and own <= {*SCENARIO_KEYS, *OPTIONAL_SECTIONS,
                                                          "vehicle"}):
        return load_scenario(p).design_file
    return p


def cmd_verify(args) -> int:
    """Re-check every certificate of a stored design; exit 1 naming what fails."""
    vehicle = vehicle_of(args)
    design_file = resolve_design_file(args.design)
    _, design, folder = stored_design(design_file, args.design_dir, vehicle)
    print(f"design {design.summary.get('design_name', folder.name)} ({folder}), hash "
          f"{design.summary['design_hash']}")  # fmt: skip
    t0 = time.monotonic()
    try:
        results = verify(design, vehicle, only=args.only)
    except ValueError as exc:
        print(f"fahv verify: --only: {exc}", file=sys.stderr)
        return 2
    try:
        require_verified(results, str(folder))
    except DesignError as exc:
        print(f"fahv verify: {exc}", file=sys.stderr)
        return 1
    if args.only is None:  # the runs of this design reuse a whole pass, never a part
        record_pass(design, vehicle, folder, results)
    what = ("certificates hold" if args.only is None
            else f"lines of the chosen checks ({', '.join(args.only)}) hold")  # fmt: skip
    print(f"verified: {len(results)} {what} ({time.monotonic() - t0:.1f} s)")
    return 0


def add_parsers(sub) -> None:
    """Add the parsers of this command group."""
    p = sub.add_parser("design", help="offline synthesis of a design file: certified artefacts")
    p.add_argument("design", help="design file, e.g. offline_design/designs/cm_certified.yaml")
    p.add_argument(
        "--out",
        default=None,
        help="artefact folder (default: beside the design file, named after it)",
    )
    p.add_argument(
        "--cold",
        action="store_true",
        help="start the LMIs' constraint generation from scratch, not from the active sets "
        "the design stored in the artefact folder holds (the same certificate, found slower)",
    )
    p.add_argument(
        "--scheduler",
        default=None,
        help="address of an existing Dask scheduler for the invariant ellipsoids checked with "
        "the tube (default: a LocalCluster of one worker process per core)",
    )
    p.add_argument(
        "--workers",
        type=int,
        default=None,
        help="worker processes of the LocalCluster (default: the cores)",
    )
    add_vehicle_option(p)
    p.set_defaults(func=cmd_design)
    p = sub.add_parser("verify", help="re-check every certificate of a stored design")
    p.add_argument("design", help="design or scenario: a file, or a name in offline_design/")
    p.add_argument("--design-dir", default=None, help="artefact folder of the stored design")
    p.add_argument("--only", action="append", default=None, metavar="CHECK",
                   help="re-check only this certificate (repeatable), e.g. 'model' after a "
                   "change of BLAS; an unknown name lists the design's checks. A partial "
                   "re-check is not recorded as a pass")  # fmt: skip
    add_vehicle_option(p)
    p.set_defaults(func=cmd_verify)
