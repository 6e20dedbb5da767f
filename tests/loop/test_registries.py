"""A law and a fault kind registered from a test run through `simulate` untouched.

Nothing in the library is edited: the dummy law is one class and one
``register_law`` call, the dummy fault one class and one ``register_fault`` call.
"""

import copy

import numpy as np
import pytest

from fahv.config import Field, Section
from fahv.control import LAWS, VARIANTS
from fahv.control.base import ControlLaw, register_law, unregister_law
from fahv.control.tube_mpc import TubeMPC
from fahv.design.case import case_from_mapping
from fahv.errors import CaseError
from fahv.loop.params import node_parameters, specs
from fahv.loop.simulate import simulate
from fahv.model.vehicle import DELTA_E
from fahv.plant.faults import FAULTS, FaultKind, register_fault


class HalfFeedback(ControlLaw):
    """Eq. (36) with half the ancillary gain: u = u_r + u_n + 0.5 F e (a test law)."""

    name = "half_feedback"
    section = Section(
        "half_feedback",
        (Field("gain", "float", "fraction of F applied", lo=0.0, hi=1.0),),
        when=lambda r: "half_feedback" in r.get("variants", ()),
        when_text="a variant uses half_feedback",
    )
    parameters = (
        Field("gain", "float", "fraction of F", lo=0.0, hi=1.0,
              when=lambda p: p.get("law") == "half_feedback", when_text="law is half_feedback"),
    )  # fmt: skip

    def __init__(self, p):
        super().__init__(p)
        self.tube = TubeMPC(p["F"], p["N"], 1.0)
        self.gain = p["gain"]

    @classmethod
    def node_values(cls, arrays, case):
        return {"gain": case["half_feedback"]["gain"]}

    def step(self, k, x, ref):
        e = self.tube.error(x, ref)
        u = ref.u_r + ref.u_n + self.gain * self.tube.F @ e
        return u, {"e": e, "level": self.tube.tube_level(e)}


class ElevatorScale(FaultKind):
    """From onset the elevator command is scaled by ``factor`` (a test fault)."""

    name = "elevator_scale"
    parameters = (Field("factor", "float", "elevator scale", lo=0.0, hi=1.0),)

    def apply(self, u, held):
        u[DELTA_E] *= self.params["factor"]
        return u


@pytest.fixture
def registered():
    register_law(HalfFeedback)
    register_fault(ElevatorScale)
    yield
    unregister_law("half_feedback")
    FAULTS.unregister("elevator_scale")


def test_dummy_law_and_fault_run_through_simulate(registered, raw, design):
    assert "half_feedback" in LAWS and "half_feedback" in VARIANTS
    assert "gain" in [f.name for f in specs()["tube_mpc"]]
    d = copy.deepcopy(raw)
    d["disturbance"]["samples"] = 40
    d["variants"] = ["tube_mpc_paper", "half_feedback"]
    d["half_feedback"] = {"gain": 0.5}
    d["fault"] = {"kind": "elevator_scale", "t_onset": 1.0, "factor": 0.95}
    case = case_from_mapping(d, "dummy.yaml")
    # the design's arrays do not depend on these choices: reuse them with the new case
    dummy = type(design)(case.data, design.arrays, design.summary)
    p = node_parameters(dummy, "half_feedback")
    assert p["tube_mpc"]["law"] == "half_feedback" and p["tube_mpc"]["gain"] == 0.5
    assert p["fault_injector"] == {**p["fault_injector"], "kind": "elevator_scale", "factor": 0.95}
    run = simulate(dummy, "half_feedback", duration=2.0)
    ref = simulate(dummy, "tube_mpc_paper", duration=2.0)  # same governor nominal
    after = run.t >= 1.0
    # the fault scales the applied elevator by exactly 0.95 from its onset
    np.testing.assert_allclose(run.u_applied[after, 1], 0.95 * run.u[after, 1], rtol=1e-15)
    np.testing.assert_array_equal(run.u_applied[~after], run.u[~after])
    # half the ancillary feedback at step 0 (same state and reference in both runs)
    e0 = run.x[0] - run.x_r[0] - run.x_n[0][:9]
    F = design.arrays["F"]
    np.testing.assert_allclose(run.u[0] - ref.u[0], -0.5 * F @ e0, rtol=1e-9, atol=1e-15)


def test_unknown_law_or_fault_names_the_registry(raw):
    d = copy.deepcopy(raw)
    d["fault"]["kind"] = "elevator_scale"
    with pytest.raises(CaseError, match="'fault.kind' must be one of"):
        case_from_mapping(d, "x.yaml")
