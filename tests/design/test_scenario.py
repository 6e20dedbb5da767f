"""Designs apart from scenarios: a scenario runs on its stored design without designing,
is refused beyond what the design certifies, and a stale design is never used."""

import shutil
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from fahv.certificate.verified import load_or_design
from fahv.errors import DesignError, SpecError
from fahv.model.vehicle import load_vehicle
from fahv.spec.scenario import load_scenario, read_scenario_file, run_spec_data, uncertified
from fahv.spec.store import stored_design

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "offline_design" / "scenarios" / "case1_paper.yaml"


def _copy_tree(tmp_path: Path) -> Path:
    """offline_design/ (the paper's design with its stored outputs) copied to tmp_path."""
    root = tmp_path / "offline_design"
    (root / "designs").mkdir(parents=True)
    (root / "scenarios").mkdir()
    src = ROOT / "offline_design" / "designs"
    shutil.copy(src / "cm_paper.yaml", root / "designs")
    shutil.copytree(src / "cm_paper", root / "designs" / "cm_paper",
                    ignore=shutil.ignore_patterns(".verified-*"))  # fmt: skip
    return root


def _scenario(root: Path, name: str, **changes) -> Path:
    d = read_scenario_file(PAPER)  # the whole scenario, its `extends:` merged in
    d["name"] = name
    for key, value in changes.items():
        section, _, field = key.partition(".")
        if field:
            d[section][field] = value
        else:
            d[section] = value
    path = root / "scenarios" / f"{name}.yaml"
    path.write_text(yaml.safe_dump(d, sort_keys=False))
    return path


def test_a_new_scenario_runs_on_the_stored_design_without_designing(tmp_path, monkeypatch):
    root = _copy_tree(tmp_path)
    path = _scenario(root, "descent", **{"command.h_c": 85100.0, "command.V_c": 7800.0,
                                         "fault.rho_f": 0.8, "fault.t_onset": 60.0,
                                         "variants": ["tube_mpc"]})  # fmt: skip
    import fahv.design.pipeline as pipeline

    def no_design(*args, **kwargs):
        raise AssertionError("a scenario must not re-design")

    monkeypatch.setattr(pipeline, "run_design", no_design)
    t0 = time.perf_counter()
    case, design, _ = load_or_design(path, log=lambda *_: None)
    assert time.perf_counter() - t0 < 60.0  # verification included (a few seconds)
    stored = stored_design(root / "designs" / "cm_paper.yaml", vehicle=load_vehicle())[1]
    assert design.summary["design_hash"] == stored.summary["design_hash"]
    for k in ("F", "N", "K", "Q", "w_max", "A", "B"):
        np.testing.assert_array_equal(design.arrays[k], stored.arrays[k])
    assert design.case["command"]["h_c"] == 85100.0 and case["fault"]["rho_f"] == 0.8
    # x0 is the trim at the scenario's own initial point (here the design point)
    np.testing.assert_allclose(design.arrays["x0"], stored.arrays["x0"], rtol=0, atol=0)
    # the verdict was recorded for this content: the next run does not verify again
    assert list((root / "designs" / "cm_paper").glob(".verified-*"))


def test_the_baselines_ellipsoids_are_made_only_when_the_baseline_runs(tmp_path, monkeypatch):
    """A new step with rmpc among the scenario's variants: running tube_mpc alone (what
    `fahv simulate` runs by default) does not solve the baseline's ellipsoids; running
    rmpc does, once, and caches them."""
    from fahv.control import LAWS

    root = _copy_tree(tmp_path)
    path = _scenario(root, "climb", **{"command.h_c": 86000.0})
    monkeypatch.chdir(tmp_path)  # the scenario cache, .cache/scenarios/, goes here
    solved = []
    # the ellipsoids' solve itself (about half a minute) is the design's test
    # (tests/control/test_rmpc.py): here the design step's stand in for the scenario's
    stored = {k: v for k, v in stored_design(root / "designs" / "cm_paper.yaml")[1].arrays.items()
              if k.startswith("rmpc_")}  # fmt: skip
    counted = classmethod(lambda cls, ctx: solved.append(ctx.spec["command"]["h_c"]) or stored)
    monkeypatch.setattr(LAWS["rmpc"], "design", counted)
    _, design, _ = load_or_design(path, log=lambda *_: None, variants=["tube_mpc"])
    assert solved == [] and "rmpc_Q" in design.arrays  # the design step's, unused
    _, design, _ = load_or_design(path, log=lambda *_: None, variants=["rmpc"])
    assert solved == [86000.0]  # sized for the scenario's own step
    np.testing.assert_array_equal(design.arrays["rmpc_Q"], stored["rmpc_Q"])
    load_or_design(path, log=lambda *_: None, variants=["rmpc"])
    assert solved == [86000.0]  # cached


def test_a_fault_beyond_the_design_range_is_refused_or_warned(tmp_path):
    root = _copy_tree(tmp_path)
    path = _scenario(root, "big_loss", **{"fault.rho_f": 0.6})
    with pytest.raises(SpecError, match=r"below the design's fault range rho_f in \[0.76, 1\]"):
        load_or_design(path, log=lambda *_: None)
    lines = []
    load_or_design(path, log=lines.append, allow_uncertified=True)
    assert any(line.startswith("warning:") and "0.6" in line for line in lines)


def test_a_command_outside_the_envelope_is_named():
    vehicle = load_vehicle()
    sc = load_scenario(PAPER)
    _, design, _ = stored_design(sc.design_file, vehicle=vehicle)
    c = run_spec_data(PAPER)
    c["command"]["h_c"] = vehicle.envelope.h_max + 100.0
    msgs = uncertified(design, c, vehicle)
    assert len(msgs) == 1 and "command" in msgs[0] and "flight envelope" in msgs[0]
    assert msgs[0].endswith("h 85000..86500 ft, V 7700..8300 ft/s")  # the range checked
    assert uncertified(design, run_spec_data(PAPER), vehicle) == []


def test_a_variant_the_design_did_not_prepare_is_refused(tmp_path):
    root = _copy_tree(tmp_path)
    d = yaml.safe_load((root / "designs" / "cm_paper.yaml").read_text())
    d["variants"] = ["tube_mpc"]
    (root / "designs" / "cm_paper.yaml").write_text(yaml.safe_dump(d, sort_keys=False))
    path = _scenario(root, "rmpc_too", variants=["tube_mpc", "rmpc"])
    with pytest.raises(SpecError, match=r"\['rmpc'\] not prepared by design 'cm_paper'"):
        load_scenario(path)


def test_a_stale_design_is_refused_with_the_command_that_fixes_it(tmp_path):
    root = _copy_tree(tmp_path)
    dfile = root / "designs" / "cm_paper.yaml"
    dfile.write_text(dfile.read_text().replace("margin: 1.2", "margin: 1.3"))
    path = _scenario(root, "c1")
    with pytest.raises(DesignError, match=r"stale: the design file .* changed .*fahv design"):
        load_or_design(path, log=lambda *_: None)


def test_a_missing_design_names_the_command(tmp_path):
    root = _copy_tree(tmp_path)
    shutil.rmtree(root / "designs" / "cm_paper")
    with pytest.raises(DesignError, match=r"no stored design .* run `fahv design"):
        load_or_design(_scenario(root, "c1"), log=lambda *_: None)


def test_a_scenario_names_its_vehicle_file_relative_to_itself(tmp_path):
    """`vehicle:` in a scenario, a file beside it: a vehicle 3 % heavier has no stored
    design, and the refusal gives the whole command that designs for it between
    backticks, ready to paste; `--vehicle` on the command line takes precedence."""
    import re

    from fahv.model.vehicle import vehicle_file_text
    from fahv.sil.workspace import ROOT

    data = yaml.safe_load(vehicle_file_text()[0])
    data["parameters"]["m"]["value"] = 1.03 * float(data["parameters"]["m"]["value"])
    (tmp_path / "heavy.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    case1 = ROOT / "offline_design" / "scenarios" / "case1.yaml"
    path = tmp_path / "case1_heavy.yaml"
    path.write_text(f"extends: {case1}\nvehicle: heavy.yaml\n")
    assert load_scenario(path).vehicle_file == tmp_path / "heavy.yaml"
    with pytest.raises(DesignError) as info:
        load_or_design(str(path), log=lambda *_: None)
    fix = re.search(r"run `([^`]+)`$", str(info.value))
    assert fix and fix.group(1) == (f"fahv design offline_design/designs/cm_certified.yaml "
                                    f"--vehicle {tmp_path / 'heavy.yaml'}")  # fmt: skip
    data["parameters"]["m"]["value"] *= 0.97 / 1.03
    (tmp_path / "light.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    with pytest.raises(DesignError, match=r"--vehicle \S*light\.yaml`$"):  # the command line's
        load_or_design(str(path), vehicle_file=str(tmp_path / "light.yaml"), log=lambda *_: None)
