"""Design artefacts: the certified arrays of one design, their provenance, saving and loading.

A design records where it came from (`provenance`): the design file and its
content hash, the vehicle data file and its hash, and the version and hash of the library
code that made it. Its identity, the design hash (`Design.content_hash`), is its
content: the design file's data, the inputs' hashes and the certified arrays. The code
that made it is provenance, not identity, so a design re-made with other code into the
same arrays is the same design, and `save_design` leaves its stored files as they are.
Where its LMI solves started (the active vertices and points of constraint generation, the
baseline's first guess: `Design.warm_starts`) is stored apart, in `warm_starts.npz`, and is
not part of the hash: a design re-made from other warm starts into the same certified
arrays keeps its hash.
`stale_reason` compares a stored design with its design file and vehicle, so a
design whose inputs changed is refused (with the command that re-makes it), never used.
Whether the current code still certifies a stored design is what `fahv verify`
re-checks (`fahv.certificate.verify`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fahv.errors import DesignError
from fahv.model.vehicle import VehicleParams


@dataclass
class Design:
    """Artefacts of one design (unscaled units unless stated).

    Attributes
    ----------
    case : dict
        The validated design file data; for a run, the scenario's case
        (`fahv.spec.scenario.scenario_design`).
    arrays : dict[str, ndarray]
        `A`, `B` (R, n, n/m) discrete nominal vertices; `h_grid`, `V_grid`,
        `W_h`, `W_V` TP weighting functions; `Dx`, `Du` scales; `w_max` (n,)
        W; `F` (2, n), `N` (n, n) tube; `K` (2, n), `Q` (n, n) nominal;
        `u_room`, `u_n_max` (2,); `trim_h`, `trim_V`, `trim_x` (Nh, NV, n),
        `trim_u` (Nh, NV, 2); `rmpc_A`, `rmpc_B` (DM vertices), `rmpc_Q`,
        `rmpc_P`, `rmpc_K`, `rmpc_gamma`, `rmpc_z`, `rmpc_Ds`, `rmpc_d` (the
        RMPC's nested ellipsoids, gains, cost bounds, design states, scales, step);
        `omega_flex` (2,) flexible-mode frequencies at the initial trim [rad/s];
        `F_<variant>` (2, n), a gain designed for that variant's loop through the notch
        (`variant_gain_key`), which the variant runs in place of `F`. What is certified
        (and hashed); no warm start (`is_warm_start`).
    summary : dict
        Scalars: certificates, W breakdown, plant parameters, hash.
    warm_starts : dict[str, ndarray]
        Where the LMI solves of the design started, for the next design of the same
        file (`previous` of `fahv.design.pipeline.run_design`): `closure_vertices`,
        `closure_points`, `ellipsoid_vertices_<loop>`, `rmpc_guess_Q`,
        `rmpc_guess_gamma`. They change how fast a design runs, not what it certifies.
    """

    case: dict
    arrays: dict = field(default_factory=dict)
    summary: dict = field(default_factory=dict)
    warm_starts: dict = field(default_factory=dict)

    @property
    def n_x(self) -> int:
        """Design-model state dimension (9 or 11)."""
        return self.arrays["A"].shape[1]

    def content_hash(self) -> str:
        """The design hash: sha256 over its content (16 hex characters).

        The design data (`case`), the hashes of its inputs (the provenance's
        `HASHED_PROVENANCE`: design file, vehicle data) and every certified array
        (name, shape, bytes). The code version and hash, the paths, the design's times
        and the warm starts are not hashed: they say how it was made.
        """
        return self._hash(self._inputs(), self.arrays)

    def legacy_hashes(self) -> tuple[str, str]:
        """The design hash as designs stored before the current rules computed it.

        Over the certified arrays and the warm starts together (designs stored before
        the warm starts were stored apart), and that over the whole provenance (code
        version and hash, paths, BLAS threads: before the hash left the code out).
        `load_design` accepts a design stored with either.
        """
        every = {**self.arrays, **self.warm_starts}
        return (self._hash(self._inputs(), every),
                self._hash(self.summary.get("provenance", {}), every))  # fmt: skip

    def _inputs(self) -> dict:
        prov = self.summary.get("provenance", {})
        return {k: prov.get(k) for k in HASHED_PROVENANCE}

    def _hash(self, provenance: dict, arrays: dict) -> str:
        h = hashlib.sha256(json.dumps(self.case, sort_keys=True, default=str).encode())
        h.update(json.dumps(provenance, sort_keys=True).encode())
        for k in sorted(arrays):
            a = np.ascontiguousarray(arrays[k])
            h.update(k.encode())
            h.update(str(a.shape).encode())
            h.update(a.tobytes())
        return h.hexdigest()[:16]

    def plant_params(self, vehicle) -> VehicleParams:
        """The perturbed parameter set of the simulated vehicle (summary['plant_params'])."""
        return dataclasses.replace(vehicle.params, **self.summary["plant_params"])


#: Names of the warm-start arrays (`Design.warm_starts`), and prefixes of such names.
WARM_START_KEYS = ("closure_vertices", "closure_points", "estimate_pairs")
WARM_START_PREFIXES = ("ellipsoid_vertices_", "rmpc_guess_")


def is_warm_start(name: str) -> bool:
    """Whether the array `name` says where a solve started (`Design.warm_starts`)."""
    return name in WARM_START_KEYS or name.startswith(WARM_START_PREFIXES)


def split_warm_starts(arrays: dict) -> tuple[dict, dict]:
    """`arrays` split into (certified arrays, warm starts), by `is_warm_start`."""
    warm = {k: v for k, v in arrays.items() if is_warm_start(k)}
    return {k: v for k, v in arrays.items() if k not in warm}, warm


#: Provenance entries the design hash covers: the contents of the design's inputs.
HASHED_PROVENANCE = ("design_file_hash", "vehicle_hash")
#: Summary entries that say how a design was made (the code, the paths, the times), not
#: what it is: a design saved over a stored one of the same content keeps the stored ones.
MAKING_KEYS = ("code_version", "provenance", "design_time_s", "stage_times_s")


def _json_text(design: Design) -> str:
    return json.dumps({"case": design.case, "summary": design.summary}, indent=2, default=list)


def _stored_same(out: Path, design: Design) -> Design | None:
    """The design stored in `out` if its content hash is `design`'s, else None."""
    try:
        stored = load_design(out)
    except DesignError:
        return None
    return stored if stored.content_hash() == design.content_hash() else None


def _write_if_changed(path: Path, text: str) -> None:
    """Write `text` to `path` (a temporary file renamed) unless it holds it already."""
    try:
        if path.read_text() == text:
            return
    except OSError:
        pass
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def save_design(design: Design, out_dir: str | Path, extra: dict | None = None) -> Path:
    """Write `design.npz`, `warm_starts.npz`, `design.json`, `extra` into out_dir atomically.

    `extra` maps file names to text (the design adds its certificate lines).

    The files are written to a temporary sibling folder that replaces `out_dir` only
    when all of them are complete, so a failure never leaves half an artefact set.

    `design.npz` holds the certified arrays, `warm_starts.npz` the warm starts (none: no
    file). When `out_dir` already holds a design of the same content (its design hash,
    `Design.content_hash`), the stored files stay: the arrays are not written,
    `design.summary` takes the stored `MAKING_KEYS` (the code, paths and times
    that made the stored design), and `design.json` and the `extra` files are
    rewritten only where their text changed. A design re-made into the same arrays from
    the same inputs so leaves its files byte for byte as they were.
    Returns out_dir.
    """
    out = Path(out_dir)
    stored = _stored_same(out, design)
    if stored is not None:
        design.summary.update({k: stored.summary[k] for k in MAKING_KEYS if k in stored.summary})
        _write_if_changed(out / "design.json", _json_text(design))
        for name, text in (extra or {}).items():
            _write_if_changed(out / name, text)
        return out
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        np.savez(tmp / "design.npz", **design.arrays)
        if design.warm_starts:
            np.savez(tmp / WARM_STARTS_FILE, **design.warm_starts)
        (tmp / "design.json").write_text(_json_text(design))
        for name, text in (extra or {}).items():
            (tmp / name).write_text(text)
        if out.exists():
            shutil.rmtree(out)
        os.replace(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out


def load_design(out_dir: str | Path) -> Design:
    """Read the artefacts written by `save_design`.

    The stored hash is checked against the content (`Design.content_hash`, or one of
    `Design.legacy_hashes` for a design stored before the current rules). A design stored
    with its warm starts inside `design.npz` (before they were stored apart) is read
    into the same `Design`.

    Raises
    ------
    DesignError
        If a file is missing or the content hash does not match.
    """
    out = Path(out_dir)
    try:
        meta = json.loads((out / "design.json").read_text())
        with np.load(out / "design.npz") as z:
            arrays = {k: z[k] for k in z.files}
        if (out / WARM_STARTS_FILE).exists():
            with np.load(out / WARM_STARTS_FILE) as z:
                arrays.update({k: z[k] for k in z.files})
    except (OSError, ValueError, KeyError) as exc:
        raise DesignError(f"design artefacts in {out} are missing or unreadable: {exc}") from None
    certified, warm = split_warm_starts(arrays)
    design = Design(meta["case"], certified, meta["summary"], warm)
    # a run's design (a stored design with a scenario's arrays) keeps the stored design's
    # hash as its identity and records its own content's beside it
    expected = meta["summary"].get("content_hash", meta["summary"].get("design_hash"))
    if expected not in (design.content_hash(), *design.legacy_hashes()):
        raise DesignError(f"design artefacts in {out} do not match their hash: re-run fahv design")
    return design


#: File of a stored design's warm starts, beside `design.npz` (`save_design`).
WARM_STARTS_FILE = "warm_starts.npz"


#: Library packages a design depends on (their source is hashed into the provenance).
DESIGN_PACKAGES = ("config", "synthesis", "model", "plant", "sensors", "control", "estimation",
                   "spec", "bounds", "tube", "stochastic", "onset", "certificate",
                   "design")  # fmt: skip


def save_arrays(arrays: dict, path: str | Path) -> Path:
    """Write `{name: array}` to `path` (.npz) atomically (a temporary file renamed)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=".npz", dir=path.parent)
    os.close(fd)
    try:
        np.savez(tmp, **arrays)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def load_arrays(path: str | Path) -> dict:
    """The arrays of a .npz file written by `save_arrays`.

    Raises
    ------
    DesignError
        If the file is missing or unreadable (naming it).
    """
    try:
        with np.load(path) as z:
            return {k: z[k] for k in z.files}
    except (OSError, ValueError) as exc:
        raise DesignError(f"{path}: missing or unreadable arrays: {exc}") from None


def code_hash() -> str:
    """sha256 over the source of the packages a design depends on (16 hex characters)."""
    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for pkg in DESIGN_PACKAGES:
        for f in sorted((root / pkg).rglob("*.py")):
            h.update(str(f.relative_to(root)).encode() + b"\0" + f.read_bytes())
    return h.hexdigest()[:16]


def provenance(case, vehicle) -> dict:
    """Where a design comes from: design file and hash, vehicle file and hash, code.

    Parameters
    ----------
    case : fahv.spec.files.SpecFile
        The validated design file.
    vehicle : fahv.model.vehicle.Vehicle
        The vehicle the design is made for (its `source_file` is recorded).
    """
    from fahv.version import __version__

    vfile = "" if vehicle.packaged else str(Path(vehicle.source_file).resolve())
    return {
        "design_file": str(case.path),
        "design_file_hash": case.content_hash(),
        "vehicle_file": vfile,
        "vehicle_name": vehicle.name,
        "vehicle_hash": vehicle.data_hash,
        "code_version": __version__,
        "code_hash": code_hash(),
        "blas_threads": os.environ.get("OPENBLAS_NUM_THREADS", ""),
    }


def stale_reason(design: Design, case, vehicle) -> str | None:
    """Why a stored design does not belong to (design file, vehicle); None if it does.

    Compares the design file's content hash and the vehicle file's hash with those in the
    design's provenance. A change of the library code is not a reason by itself: `fahv
    verify` re-checks every certificate of the stored arrays with the current code.

    Parameters
    ----------
    design : Design
    case : fahv.spec.files.SpecFile
        The validated design file.
    vehicle : fahv.model.vehicle.Vehicle
    """
    old = design.summary.get("provenance")
    if not old:
        return "the design has no provenance record"
    if old.get("design_file_hash") != case.content_hash():
        return f"the design file {case.path} changed since the design was made"
    if old.get("vehicle_hash") != vehicle.data_hash:
        return "the vehicle file changed since the design was made"
    return None


def variant_gain_key(variant: str) -> str:
    """Array name of the gain a variant runs in place of `F` (`F_<variant>`), if designed.

    Written by the design for a variant whose loop through the notch has its own certified
    gain (`eight_state.notch_gain: designed`); read by
    `fahv.loop.params.node_parameters`. Raises nothing.
    """
    return f"F_{variant}"
