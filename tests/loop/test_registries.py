"""A law with its own nominal part, and a fault kind, registered outside the library.

Nothing in the library is edited: the plugin module ``plugin_law`` (beside this file)
holds a nominal part, a law and a fault kind, each one class and one registry call.
The law runs through ``simulate``, the batch engine and the ROS graph (which imports
the plugin through FAHV_PLUGINS).
"""

import copy
import importlib
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from fahv.control import LAWS, NOMINAL_SOURCES, VARIANTS, load_plugins
from fahv.control.base import unregister_law
from fahv.errors import SpecError
from fahv.loop.batch import simulate_batch
from fahv.loop.params import node_parameters, specs
from fahv.loop.simulate import simulate
from fahv.plant.faults import FAULTS
from fahv.spec.files import spec_file

HERE = Path(__file__).resolve().parent


@pytest.fixture
def registered(monkeypatch):
    monkeypatch.syspath_prepend(str(HERE))
    monkeypatch.setenv("FAHV_PLUGINS", "plugin_law")
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(HERE), os.environ.get("PYTHONPATH", "")]))
    sys.modules.pop("plugin_law", None)
    assert load_plugins() == ["plugin_law"]
    yield importlib.import_module("plugin_law")
    unregister_law("half_feedback")
    NOMINAL_SOURCES.unregister("hold_start")
    FAULTS.unregister("elevator_scale")


@pytest.fixture
def dummy(registered, raw, design):
    d = copy.deepcopy(raw)
    d["disturbance"]["samples"] = 40
    d["variants"] = ["tube_mpc_paper", "half_feedback"]
    d["half_feedback"] = {"gain": 0.5}
    d["fault"] = {"kind": "elevator_scale", "t_onset": 1.0, "factor": 0.95}
    case = spec_file(d, "dummy.yaml")
    # the design's arrays do not depend on these choices: reuse them with the new case
    return type(design)(case.data, design.arrays, design.summary)


def test_plugin_law_and_fault_run_through_simulate_and_the_batch(dummy, design):
    assert "half_feedback" in LAWS and "half_feedback" in VARIANTS
    assert "gain" in [f.name for f in specs()["tube_mpc"]]
    assert "hold_scale" in [f.name for f in specs()["nominal_trajectory"]]
    p = node_parameters(dummy, "half_feedback")
    assert p["tube_mpc"]["law"] == "half_feedback" and p["tube_mpc"]["gain"] == 0.5
    assert p["nominal_trajectory"]["nominal"] == "hold_start"
    assert p["fault_injector"] == {**p["fault_injector"], "kind": "elevator_scale", "factor": 0.95}
    run = simulate(dummy, "half_feedback", duration=2.0)
    after = run.t >= 1.0
    # the fault scales the applied elevator by exactly 0.95 from its onset
    np.testing.assert_allclose(run.u_applied[after, 1], 0.95 * run.u[after, 1], rtol=1e-15)
    np.testing.assert_array_equal(run.u_applied[~after], run.u[~after])
    # the held trim and half the ancillary feedback at step 0
    e0 = run.x[0] - run.x_r[0] - run.x_n[0][:9]
    u0 = run.x_r[0] * 0  # x_n = 0: u = u_r(start) + 0.5 F e
    assert np.all(run.x_n == 0.0) and np.all(run.h_g == dummy.case["command"]["h0"])
    F = design.arrays["F"]
    ref = simulate(dummy, "half_feedback", duration=0.02, overrides={"tube_mpc": {"gain": 1.0}})
    np.testing.assert_allclose(ref.u[0] - run.u[0], 0.5 * F @ e0 + u0[:2], rtol=1e-9, atol=1e-15)
    # the batch engine gives every run the bits of simulate
    ovs = [None, {"fault_injector": {"factor": 0.5}}]
    for ov, res in zip(ovs, simulate_batch(dummy, "half_feedback", ovs, 2.0), strict=True):
        alone = simulate(dummy, "half_feedback", 2.0, overrides=ov)
        np.testing.assert_array_equal(alone.x, res.x)
        np.testing.assert_array_equal(alone.u_applied, res.u_applied)


@pytest.mark.ros
def test_plugin_law_runs_through_the_graph(dummy, tmp_path):
    from fahv.runs.bag import read_run, run_result_of
    from fahv.sil.runner import run_sil

    res = run_sil(dummy, "half_feedback", duration=1.5, out_dir=tmp_path, quiet=True,
                  log=lambda *_: None)  # fmt: skip
    assert res.returncode == 0
    run = run_result_of(read_run(res.bag))
    ref = simulate(dummy, "half_feedback", duration=1.5)
    np.testing.assert_array_equal(run.x, ref.x)
    np.testing.assert_array_equal(run.u_applied, ref.u_applied)


def test_unknown_law_or_fault_names_the_registry(raw):
    d = copy.deepcopy(raw)
    d["fault"]["kind"] = "elevator_scale"
    with pytest.raises(SpecError, match="'fault.kind': unknown actuator fault kind "
                       "'elevator_scale'; must be one of .*FAHV_PLUGINS"):  # fmt: skip
        spec_file(d, "x.yaml")
    # a plugin's kind with its parameter, the plugin not imported: the kind is named,
    # not the parameter it brings
    d["fault"] = {"kind": "elevator_travel", "t_onset": 50.0, "travel_deg": 12.1}
    with pytest.raises(SpecError, match="unknown actuator fault kind 'elevator_travel'"):
        spec_file(d, "x.yaml")


def test_a_law_must_name_a_registered_nominal_part():
    from fahv.control.base import ControlLaw, register_law
    from fahv.errors import ConfigError

    class NoNominal(ControlLaw):
        """A law without a nominal part."""

        name = "no_nominal"

    with pytest.raises(ConfigError, match="must name its nominal part"):
        register_law(NoNominal)
    assert "no_nominal" not in LAWS


def test_a_bad_plugin_module_is_named(monkeypatch):
    monkeypatch.setenv("FAHV_PLUGINS", "no_such_plugin_module")
    with pytest.raises(ImportError, match="'no_such_plugin_module' cannot be imported"):
        load_plugins()
