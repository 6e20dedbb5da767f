"""The stored eight-state tube sets with their vertex data rebuilt (tube_set_records.py)."""

import functools
import pickle
from dataclasses import replace

import numpy as np
import pytest
from tube_set_records import load_record

from fahv.bounds.domain import SchedulingBox
from fahv.bounds.vertices import nominal_vertices
from fahv.model.trim import TrimMap
from fahv.model.vehicle import load_vehicle
from fahv.plant.uncertainty import PAPER_UNCERTAINTY

TS, N_SUB = 0.02, 5

#: The stored closed tube sets of the baseline law: the k = 5 set on the box the
#: certified design reproduces, and the certified design's own (k = 7, 16384 vertices,
#: the attitude supports bounded and the onset's jumps held).
TUBE_SETS = ("closed_tube_h_reset.npz", "cm_certified")


def rebuilt(design, name):
    """A stored tube set's record, the vehicle, the trim map, the scheduling box, the
    design scaling and the vertex data rebuilt here."""
    from fahv.model.tp_model import build_tp_model

    d = load_record(name)
    a = design.arrays
    veh = load_vehicle()
    tp = build_tp_model(veh, "cm", 4, 5, 21, 21)
    tm = TrimMap(a["trim_h"], a["trim_V"], a["trim_x"], a["trim_u"])
    box = SchedulingBox(d["lo"], d["hi"], d["other_half"])
    scale = np.concatenate([tp.state_scale, tp.input_scale])
    nv = nominal_vertices(box, veh, tm, dict(PAPER_UNCERTAINTY), float(d["rho_min"]), TS, N_SUB,
                          scale, int(d["k"]), d["w_design"], d["col_scale"])  # fmt: skip
    return d, veh, tm, box, scale, nv


@pytest.fixture(scope="session")
def stored_tube_sets(design, tmp_path_factory, worker_id):
    """``stored_tube_sets(name)``: :func:`rebuilt` of a record, built once per test run.

    Under pytest-xdist the first worker that needs a record rebuilds it and pickles it
    next to the workers' temporary folders (as the ``design`` fixture); the other waits
    on the lock and loads it, so test_one_step_bound.py and test_onset.py on different
    workers do not rebuild the same vertex data twice.
    """
    if worker_id == "master":  # not distributed
        return functools.cache(lambda name: rebuilt(design, name))
    from filelock import FileLock

    shared = tmp_path_factory.getbasetemp().parent

    @functools.cache
    def shared_rebuilt(name):
        path = shared / f"tube_set_{name.replace('.', '_')}.pickle"
        with FileLock(f"{path}.lock"):
            if path.exists():
                return pickle.loads(path.read_bytes())
            record = rebuilt(design, name)
            path.write_bytes(pickle.dumps(record, protocol=pickle.HIGHEST_PROTOCOL))
            return record

    return shared_rebuilt


@pytest.fixture(scope="session", params=TUBE_SETS)
def tube_set(stored_tube_sets, request):
    """A stored closed tube set, its scheduling box and its vertex data rebuilt here."""
    return stored_tube_sets(request.param)


@pytest.fixture(scope="session")
def tube_set_k5(stored_tube_sets):
    """The k = 5 tube set (4096 vertices), as ``tube_set``."""
    return stored_tube_sets("closed_tube_h_reset.npz")


@pytest.fixture(scope="session")
def tube_set_case1(stored_tube_sets):
    """The certified design's own tube set (16384 vertices), as ``tube_set``."""
    return stored_tube_sets("cm_certified")


@pytest.fixture(scope="session")
def tube_set_tau(stored_tube_sets):
    """The adjustable law's tube set (tau = 0.8: the vertices cover the gains tau' F_8,
    tau' in [0.8, 1]), as ``tube_set``."""
    d, veh, tm, box, scale, nv = stored_tube_sets("closed_tube_h_reset_tau.npz")
    return d, veh, tm, box, scale, replace(nv, tau=float(d["tau"]))
