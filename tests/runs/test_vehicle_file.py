"""--vehicle FILE reaches the design (provenance, hash), the plant node and the metrics."""

import re
from importlib import resources

import numpy as np
import pytest

from fahv.design.pipeline import run_design
from fahv.loop.simulate import simulate
from fahv.model.vehicle import load_vehicle
from fahv.runs.bag import read_run, run_result_of
from fahv.runs.judged import run_vehicle
from fahv.sil.runner import run_sil
from fahv.spec.artefacts import load_design, save_design, stale_reason
from fahv.spec.files import spec_file

T = 1.0


@pytest.fixture(scope="module")
def heavy(tmp_path_factory):
    """The packaged vehicle file with the mass per unit span 5 % higher (300 -> 315)."""
    text = resources.files("fahv.data").joinpath("vehicle_parker2007.yaml").read_text()
    new, n = re.subn(r"(\n  m:\s+\{value: )300\.0,", r"\g<1>315.0,", text)
    assert n == 1
    path = tmp_path_factory.mktemp("vehicle") / "heavy.yaml"
    path.write_text(new)
    return path


@pytest.fixture(scope="module")
def heavy_design(make_case, heavy, raw):
    """Case 1 designed for the heavy vehicle (one of the tube LMI's contraction factors)."""
    tube = {**raw["tube"], "lam": raw["tube"]["lam"][1:2]}
    return run_design(make_case(tube=tube), load_vehicle(heavy), log=lambda *_: None)


def test_vehicle_changes_design_hash_and_provenance(design, heavy_design, heavy, tmp_path):
    assert heavy_design.summary["design_hash"] != design.summary["design_hash"]
    prov = heavy_design.summary["provenance"]
    assert prov["vehicle_file"] == str(heavy.resolve())
    assert prov["vehicle_hash"] != design.summary["provenance"]["vehicle_hash"]
    assert design.summary["provenance"]["vehicle_file"] == ""  # the packaged file
    # a saved design is stale for another vehicle and for a changed design part, not for
    # a changed scenario
    from fahv.spec.scenario import design_part

    save_design(design, tmp_path / "d")
    back = load_design(tmp_path / "d")
    c = design_part(spec_file(design.case, "quick.yaml"))
    assert stale_reason(back, c, load_vehicle()) is None
    assert stale_reason(back, c, load_vehicle(heavy)) == (
        "the vehicle file changed since the design was made"
    )
    longer = design_part(spec_file({**design.case, "duration": 299.0}, "quick.yaml"))
    assert stale_reason(back, longer, load_vehicle()) is None  # a scenario key
    margin = {**design.case["disturbance"], "margin": 1.3}
    c2 = design_part(spec_file({**design.case, "disturbance": margin}, "quick.yaml"))
    assert stale_reason(back, c2, load_vehicle()) == (
        "the design file quick.yaml changed since the design was made"
    )


def test_vehicle_changes_the_simulated_trajectory(design, heavy_design):
    a = simulate(design, "tube_mpc", duration=T)
    b = simulate(heavy_design, "tube_mpc", duration=T)
    assert a.x.shape == b.x.shape
    assert np.abs(b.x[-1, :2] - a.x[-1, :2]).max() > 1e-3  # h, V differ at 1 s
    assert heavy_design.summary["plant_params"]["m"] != design.summary["plant_params"]["m"]


@pytest.mark.ros
def test_vehicle_reaches_the_plant_node(heavy_design, heavy, tmp_path):
    res = run_sil(heavy_design, "tube_mpc", duration=T, out_dir=tmp_path, quiet=True)
    assert res.returncode == 0
    rec = read_run(res.bag)
    assert rec.metadata["vehicle_file"] == str(heavy.resolve())
    assert run_vehicle(rec).source_file == str(heavy.resolve())
    run = run_result_of(rec)
    ref = simulate(heavy_design, "tube_mpc", duration=T)
    np.testing.assert_allclose(run.x, ref.x, rtol=1e-12, atol=0)
