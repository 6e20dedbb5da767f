"""The campaign folder and its Parquet dataset.

Layout of `DIR` (`campaigns/<name>/` by default):

    campaign.json          campaign and case content, their hash, code version, start time
    design/                the design every run used (artefacts of fahv.design)
    results/part-G-B.parquet       one file per finished batch: one row per run
    trajectories/part-G-B.parquet  decimated histories of the same runs (report figures)
    report/                report.md and the PNG figures

`results/` is one Parquet dataset (`pyarrow.dataset.dataset(DIR / "results")`
reads it whole). Each file is written to a temporary name and renamed into place when
complete, so an interrupted campaign holds only complete batches, and the rows of a
run index appear once. `G` counts the sessions (the first run and each
`--resume`), `B` the batch within the session.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

RESULTS = "results"
TRAJECTORIES = "trajectories"
MANIFEST = "campaign.json"


def write_part(out_dir: Path, sub: str, name: str, rows: list[dict]) -> Path | None:
    """Write `rows` as `out_dir/sub/name.parquet` atomically (None when no rows).

    Rows may hold different keys (a failed run has no metrics): the columns are their
    union, absent values null.
    """
    if not rows:
        return None
    d = Path(out_dir) / sub
    d.mkdir(parents=True, exist_ok=True)
    keys = list(dict.fromkeys(k for r in rows for k in r))
    table = pa.Table.from_pylist([{k: r.get(k) for k in keys} for r in rows])
    path = d / f"{name}.parquet"
    tmp = d / f".{name}.parquet.tmp"
    pq.write_table(table, tmp)
    os.replace(tmp, path)
    return path


def read_table(out_dir: Path, sub: str = RESULTS) -> pa.Table | None:
    """Every complete part of `out_dir/sub` as one table (None if there is none).

    Columns are unified across parts (a column missing in a part is null there).
    """
    d = Path(out_dir) / sub
    files = sorted(d.glob("part-*.parquet")) if d.is_dir() else []
    if not files:
        return None
    tables = [pq.read_table(f) for f in files]
    return pa.concat_tables(tables, promote_options="permissive")


def read_rows(out_dir: Path, sub: str = RESULTS) -> list[dict]:
    """Rows of the dataset as dicts, sorted by (variant, index)."""
    t = read_table(out_dir, sub)
    rows = [] if t is None else t.to_pylist()
    return sorted(rows, key=lambda r: (r["variant"], r["index"]))


def done_keys(out_dir: Path) -> set[tuple[int, str]]:
    """(index, variant) of every run already in the dataset."""
    t = read_table(out_dir, RESULTS)
    if t is None:
        return set()
    idx = t.column("index").to_pylist()
    var = t.column("variant").to_pylist()
    return set(zip(idx, var, strict=True))


def next_session(out_dir: Path) -> int:
    """Number of the next session (1 + the highest G of the part files)."""
    d = Path(out_dir) / RESULTS
    gens = [int(f.name.split("-")[1]) for f in d.glob("part-*.parquet")] if d.is_dir() else []
    return max(gens, default=0) + 1


def read_manifest(out_dir: Path) -> dict | None:
    """`campaign.json` of a campaign folder (None if absent)."""
    p = Path(out_dir) / MANIFEST
    return json.loads(p.read_text()) if p.is_file() else None


def write_manifest(out_dir: Path, manifest: dict) -> None:
    """Write `campaign.json` atomically."""
    p = Path(out_dir) / MANIFEST
    tmp = p.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(manifest, indent=2, default=str))
    os.replace(tmp, p)
