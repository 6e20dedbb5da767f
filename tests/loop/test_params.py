"""Node parameters: the checks every node runs at start-up, and the variants."""

import copy
import math

import numpy as np
import pytest

from fahv.errors import ParameterError
from fahv.loop.cores import build_core
from fahv.loop.params import node_parameters, validate
from fahv.msg import VehicleState


@pytest.fixture(scope="module")
def params(design):
    return node_parameters(design)


def test_every_node_validates(params):
    for node, values in params.items():
        out = validate(node, values)
        assert out["Ts"] == 0.02
    assert validate("tube_mpc", params["tube_mpc"])["F"].shape == (2, 9)


@pytest.mark.parametrize(
    ("node", "key", "value", "message"),
    [
        ("tube_mpc", "F_shape", [2, 8], "parameter 'F' has 18 values, but 'F_shape' = \\[2, 8\\]"),
        ("tube_mpc", "N_shape", [3, 3], "parameter 'N'"),
        ("tube_mpc", "tau", 1.5, r"parameter 'tau' must be in \(0, 1\], got 1.5"),
        ("tube_mpc", "law", "pid", "parameter 'law': unknown control law 'pid'; must be one of"),
        ("notch_filter", "omega_z", "fast", "parameter 'omega_z' must be float"),
        ("fault_injector", "rho_f", None, "parameter 'rho_f' is missing"),
        ("plant", "x0_shape", [8], "parameter 'x0' has 9 values"),
        ("nominal_trajectory", "K_shape", [9, 2], "parameter 'K' has shape \\(9, 2\\)"),
    ],
)
def test_bad_parameter_names_the_key(params, node, key, value, message):
    bad = copy.deepcopy(params[node])
    bad[key] = value
    with pytest.raises(ParameterError, match=message):
        validate(node, bad)


def test_nan_in_a_matrix_is_rejected(params):
    bad = copy.deepcopy(params["tube_mpc"])
    bad["F"][3] = math.nan
    with pytest.raises(ParameterError, match="parameter 'F' has a non-finite value at index 3"):
        build_core("tube_mpc", bad)


def test_variants(design):
    no_notch = node_parameters(design, "tube_mpc_no_notch")
    assert no_notch["notch_filter"]["enabled"] is False
    state = VehicleState.of(0, 0.0, np.array([[85500.0, 7900.0, 0.02, 0.02, 0.25, 0, 0, 0, 0]]))
    assert build_core("notch_filter", no_notch["notch_filter"]).on_state(state).q_f[0] == 0.25
    notch2 = node_parameters(design, "tube_mpc_notch2")["notch_filter"]
    assert notch2["omega_z"] == pytest.approx(design.arrays["omega_flex"][1], rel=1e-12)
    with pytest.raises(ParameterError, match="variant 'pid'"):
        node_parameters(design, "pid")


def test_rmpc_variant_parameters(paper_scenario_design):
    design = paper_scenario_design
    rmpc = node_parameters(design, "rmpc")
    assert "rmpc" in rmpc and "tube_mpc" not in rmpc
    assert rmpc["nominal_trajectory"]["nominal"] == "command"
    N = design.case["rmpc"]["ellipsoids"]  # the off-line RMPC: ellipsoids and gains
    assert N == 9
    assert np.asarray(rmpc["rmpc"]["rmpc_P"]).size == N * 81
    assert np.asarray(rmpc["rmpc"]["rmpc_K"]).size == N * 18


def test_a_variant_runs_the_gain_designed_for_its_notch_loop(design):
    """``F_<variant>`` in the design (eight_state.notch_gain: designed) replaces F for that
    variant's controller only; the other variants keep the tube's F."""
    import dataclasses

    from fahv.spec.artefacts import variant_gain_key

    first, *others = design.case["variants"]
    own = 1.5 * np.asarray(design.arrays["F"])
    with_gain = dataclasses.replace(design, arrays={**design.arrays, variant_gain_key(first): own})
    p = node_parameters(with_gain, first)
    node = next(n for n in p if "F" in p[n])
    np.testing.assert_array_equal(validate(node, p[node])["F"], own)
    for v in others:
        q = node_parameters(with_gain, v)
        for n in q:
            if "F" in q[n]:
                np.testing.assert_array_equal(validate(n, q[n])["F"], design.arrays["F"])
    assert others, "the test design has one variant: nothing shows the other variants keep F"
