"""The code hash of a design's provenance covers every package the design code imports;
the design hash is the design's content (inputs and arrays), not the code that made it."""

from pathlib import Path

import grimp
import numpy as np

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


def _small_design(code_hash="aaaa", time_s=1.0, F=(1.0, 2.0)):
    """A design of two arrays, made by code `code_hash` in `time_s` seconds."""
    from fahv.spec.artefacts import Design

    prov = {"design_file": "d.yaml", "design_file_hash": "1234", "vehicle_file": "",
            "vehicle_hash": "5678", "code_version": "0.1.0", "code_hash": code_hash,
            "blas_threads": "1"}  # fmt: skip
    d = Design(
        {"name": "d", "Ts": 0.02},
        {"F": np.array([F]), "N": np.eye(2)},
        {"code_version": "0.1.0", "provenance": prov, "design_time_s": time_s,
         "stage_times_s": {"model": time_s}},
    )  # fmt: skip
    d.summary["design_hash"] = d.content_hash()
    return d


def test_the_design_hash_is_the_content_not_the_code():
    """The arrays and the inputs' hashes make the design hash; the code version and hash,
    the paths and the times do not."""
    a = _small_design()
    assert _small_design(code_hash="bbbb", time_s=9.0).content_hash() == a.content_hash()
    other = _small_design()
    other.summary["provenance"].update(code_version="0.2.0", design_file="/elsewhere/d.yaml")
    assert other.content_hash() == a.content_hash()
    assert _small_design(F=(1.0, 2.0000000001)).content_hash() != a.content_hash()
    for key in ("design_file_hash", "vehicle_hash"):  # another design file or vehicle
        changed = _small_design()
        changed.summary["provenance"][key] = "9999"
        assert changed.content_hash() != a.content_hash(), key
    assert a.content_hash() == "2130a97a495b9b6b"


def test_resaving_the_same_content_leaves_the_files_byte_identical(tmp_path):
    """A design re-made by other code into the same arrays: design.npz, design.json and
    the certificate lines stay byte for byte, with the stored code hash and stage times
    (the next design's estimate); another array rewrites them."""
    from fahv.spec.artefacts import load_design, save_design

    out = tmp_path / "d"
    save_design(_small_design(), out, {"certificate.txt": "lines\n"})
    files = {p.name: p.read_bytes() for p in out.iterdir()}
    again = _small_design(code_hash="bbbb", time_s=9.0)
    save_design(again, out, {"certificate.txt": "lines\n"})
    assert {p.name: p.read_bytes() for p in out.iterdir()} == files
    assert again.summary["provenance"]["code_hash"] == "aaaa"  # the stored one, kept
    assert load_design(out).summary["stage_times_s"] == {"model": 1.0}
    save_design(_small_design(code_hash="bbbb", time_s=9.0, F=(3.0, 2.0)), out)
    stored = load_design(out)
    assert stored.summary["provenance"]["code_hash"] == "bbbb"
    assert stored.summary["stage_times_s"] == {"model": 9.0}
    assert (out / "design.npz").read_bytes() != files["design.npz"]


def test_a_design_stored_with_the_earlier_hash_still_loads(tmp_path):
    """Designs and campaign folders stored before the hash left the code out load as
    they are (their hash over the whole provenance is accepted)."""
    from fahv.spec.artefacts import load_design, save_design

    d = _small_design()
    legacy = d.legacy_hashes()[1]
    d.summary["design_hash"] = legacy
    assert legacy != d.content_hash()
    save_design(d, tmp_path / "old")
    assert load_design(tmp_path / "old").summary["design_hash"] == legacy


def _warm(d, closure=(3, 7), guess=2.0):
    """`d` with warm starts: a closure's active vertices and the baseline's first guess."""
    d.warm_starts = {"closure_vertices": np.array(closure), "rmpc_guess_Q": guess * np.eye(2),
                     "ellipsoid_vertices_steady_0.995": np.array([1, 5])}  # fmt: skip
    return d


def test_warm_starts_are_stored_apart_and_outside_the_hash(tmp_path):
    """Re-making a design from other warm starts into the same certified arrays keeps its
    hash and its stored files; the warm starts are in warm_starts.npz, not design.npz, and
    load back as `warm_starts`; another certified array moves the hash."""
    from fahv.spec.artefacts import load_design, save_design

    d = _warm(_small_design())
    assert d.content_hash() == _small_design().content_hash()
    assert _warm(_small_design(), closure=(1, 2), guess=5.0).content_hash() == d.content_hash()
    save_design(d, tmp_path / "d")
    with np.load(tmp_path / "d" / "design.npz") as z:
        assert sorted(z.files) == ["F", "N"]
    with np.load(tmp_path / "d" / "warm_starts.npz") as z:
        assert sorted(z.files) == sorted(d.warm_starts)
    back = load_design(tmp_path / "d")
    assert sorted(back.arrays) == ["F", "N"] and back.content_hash() == d.content_hash()
    assert np.array_equal(back.warm_starts["closure_vertices"], [3, 7])
    files = {f.name: f.read_bytes() for f in (tmp_path / "d").iterdir()}
    save_design(_warm(_small_design(), closure=(1, 2)), tmp_path / "d")  # same content
    assert {f.name: f.read_bytes() for f in (tmp_path / "d").iterdir()} == files


def test_a_design_stored_with_its_warm_starts_inside_loads_split(tmp_path):
    """A design.npz of the earlier layout (warm starts beside the certified arrays, the
    hash over both) loads: the warm starts apart, the hash accepted."""
    from fahv.spec.artefacts import _json_text, load_design

    d = _warm(_small_design())
    every = d.legacy_hashes()[0]
    assert every != d.content_hash()
    d.summary["design_hash"] = every
    (tmp_path / "old").mkdir()
    np.savez(tmp_path / "old" / "design.npz", **d.arrays, **d.warm_starts)
    (tmp_path / "old" / "design.json").write_text(_json_text(d))
    back = load_design(tmp_path / "old")
    assert sorted(back.arrays) == ["F", "N"]
    assert sorted(back.warm_starts) == sorted(d.warm_starts)
    assert back.summary["design_hash"] == every


def test_remaking_a_design_into_the_same_arrays_keeps_its_files(tmp_path, monkeypatch):
    """`fahv design` (design_and_store) on a folder that holds the same design: the
    stage clock gets the stored stage times, and no file changes."""
    import fahv.cli.design as cli_design
    import fahv.design.pipeline as pipeline

    out = tmp_path / "d"
    seen = []

    def fake_design(spec, vehicle, progress=None, log=print, clock=None, previous=None):
        seen.append(dict(clock.previous))
        clock.stage("model")
        return _small_design(code_hash=f"code{len(seen)}")

    monkeypatch.setattr(pipeline, "run_design", fake_design)
    lines = []
    cli_design.design_and_store(None, None, out, log=lines.append)
    files = {p.name: p.read_bytes() for p in out.iterdir()}
    cli_design.design_and_store(None, None, out, log=lines.append)
    assert {p.name: p.read_bytes() for p in out.iterdir()} == files
    assert seen[0] == {} and list(seen[1]) == ["model"]  # the stored stage times
    assert lines[-1].startswith("design hash 2130a97a495b9b6b: the stored design's arrays")
