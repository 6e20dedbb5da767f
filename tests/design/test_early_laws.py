"""Offline parts started on the design's Dask cluster as soon as the model is made."""

from types import SimpleNamespace

import numpy as np
import pytest

from fahv.control.base import ControlLaw, register_law, unregister_law
from fahv.control.reference import CommandReference
from fahv.design.stages import early_laws_stage, model_arrays, offline_part
from fahv.model.vehicle import load_vehicle


class ModelOnlyLaw(ControlLaw):
    """A law whose offline part reads the model's arrays alone (tests)."""

    name = "model_only_test"
    node = "rmpc"
    nominal = CommandReference
    has_tube = False
    model_only = True

    @classmethod
    def design(cls, ctx):
        """One array from the trim map, the design point and the input room; one line."""
        a = ctx.arrays
        ctx.log(f"model-only part: h0 {ctx.spec['command']['h0']:.0f} ft")
        return {"model_only_sum": np.array(a["trim_x"].sum() + a["x0"].sum() + a["u_room"].sum())}


@pytest.fixture
def model_only_law():
    register_law(ModelOnlyLaw)
    yield ModelOnlyLaw
    unregister_law(ModelOnlyLaw.name)


def _model():
    """The parts of a DesignModel the early stage reads, with a 2 x 3 trim grid."""
    rng = np.random.default_rng(3)
    trim = SimpleNamespace(h_grid=np.array([85e3, 86e3]),
                           V_grid=np.array([7.7e3, 8e3, 8.3e3]),
                           x_r=rng.normal(size=(2, 3, 9)),
                           u_r=rng.normal(size=(2, 3, 2)))  # fmt: skip
    return SimpleNamespace(step={"h0": 85e3, "V0": 7.85e3, "h_c": 86e3, "V_c": 7.95e3},
                           trim=trim, x_start=rng.normal(size=9))  # fmt: skip


def test_without_a_client_nothing_starts_early(model_only_law):
    early = early_laws_stage({"variants": ["model_only_test"]}, load_vehicle(), _model())
    assert early.parts == {}


def test_a_model_only_part_runs_on_the_cluster_as_in_process(model_only_law):
    from distributed import Client

    veh, model = load_vehicle(), _model()
    spec = {"variants": ["tube_mpc", "model_only_test"]}
    with Client(processes=False, n_workers=1, threads_per_worker=1, dashboard_address=None):
        early = early_laws_stage(spec, veh, model)
        assert set(early.parts) == {"model_only_test"}  # tube_mpc's part needs the tube
        made, lines = early.parts["model_only_test"].result(timeout=60)
    here, here_lines = offline_part(ModelOnlyLaw, {**spec, "command": model.step}, veh,
                                    model_arrays(model, veh))  # fmt: skip
    assert lines == here_lines == ["model-only part: h0 85000 ft"]
    np.testing.assert_array_equal(made["model_only_sum"], here["model_only_sum"])
    room = veh.limits.u_max - veh.limits.u_min  # a positive room on both inputs
    assert np.all(model_arrays(model, veh)["u_room"] > 0) and np.all(room > 0)
    expected = model.trim.x_r.sum() + model.x_start.sum() + model_arrays(model, veh)["u_room"].sum()
    assert float(made["model_only_sum"]) == pytest.approx(expected, rel=1e-15)
