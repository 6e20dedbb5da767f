"""A control law with its own nominal part, and a fault kind, outside the library (a plugin).

Imported through ``FAHV_PLUGINS=plugin_law`` (with this folder on ``PYTHONPATH``) by
the test process and by every node of the graph; nothing in the library names it.
The nominal part holds the initial trim (x_n = 0, no governor); the law applies a
fraction ``gain`` of the ancillary feedback F: u = u_r + u_n + gain F e.
"""

import numpy as np

from fahv.config import Field, Section
from fahv.control.base import ControlLaw, LawStep, NominalSource, register_law, register_nominal
from fahv.control.reference import mv, quad, trim_map_of
from fahv.model.vehicle import DELTA_E
from fahv.msg import NominalTrajectory
from fahv.plant.faults import FaultKind, register_fault


@register_nominal
class HoldStart(NominalSource):
    """Nominal part that holds the trim of the initial point: x_r, u_r fixed, x_n = 0."""

    name = "hold_start"
    parameters = (
        Field("hold_scale", "float", "factor on the held trim input (1: the trim)", lo=0.5,
              hi=1.5, default=1.0),
    )  # fmt: skip

    def __init__(self, p, runs, lanes):
        super().__init__(p, runs, lanes)
        tm = trim_map_of(p)
        h0 = np.array([r["command.h0"] for r in runs])
        V0 = np.array([r["command.V0"] for r in runs])
        self.h0, self.V0 = h0, V0
        self.x_r, self.u_r = tm.at(h0, V0)
        self.u_r = self.u_r * p["hold_scale"]

    @classmethod
    def node_values(cls, arrays, case):
        return {"hold_scale": 1.0}

    def output(self, k, t, x, u_prev):
        B = self.h0.size
        z = np.zeros(B, dtype=np.int64)
        n = self.x_r.shape[1]
        return NominalTrajectory(
            k, t, self.h0.copy(), self.V0.copy(), self.h0.copy(), self.V0.copy(),
            self.x_r.copy(), self.u_r.copy(), np.zeros((B, n)), np.zeros((B, 2)),
            np.zeros(B), z, z, z, np.zeros((B, 2)), z,
        )  # fmt: skip


class HalfFeedback(ControlLaw):
    """Eq. (36) with a fraction of the ancillary gain: u = u_r + u_n + gain F e (a test law)."""

    name = "half_feedback"
    nominal = HoldStart
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

    def __init__(self, p, n_runs=1):
        super().__init__(p, n_runs)
        self.F, self.N_inv, self.gain = p["F"], np.linalg.inv(p["N"]), p["gain"]

    @classmethod
    def node_values(cls, arrays, case):
        return {"gain": case["half_feedback"]["gain"]}

    def step(self, k, x, ref, lanes):
        e = np.ascontiguousarray(x - ref.x_r - ref.x_n)
        u = (ref.u_r + ref.u_n) + mv(self.gain * self.F, e)
        return LawStep(u, e, quad(e, self.N_inv), np.zeros(e.shape[0], dtype=np.int64))


register_law(HalfFeedback)


@register_fault
class ElevatorScale(FaultKind):
    """From onset the elevator command is scaled by ``factor`` (a test fault)."""

    name = "elevator_scale"
    parameters = (Field("factor", "float", "elevator scale", lo=0.0, hi=1.0),)

    def apply(self, u, held, lanes):
        u[:, DELTA_E] *= self.params["factor"][lanes]
        return u
