"""``fahv campaign rerun --sil``: a campaign run through the ROS 2 node graph."""

import math

import pytest

from fahv.campaign import store
from fahv.campaign.engine import run_campaign
from fahv.campaign.rerun import rerun
from fahv.campaign.spec import load_campaign
from fahv.runs.bag import read_run

pytestmark = pytest.mark.ros


def test_sil_rerun_reproduces_the_campaign_row(write_campaign, tmp_path):
    c = load_campaign(write_campaign("sil", runs=2, batch_size=2, duration=3.0))
    out = tmp_path / "out"
    assert run_campaign(c, out, workers=1, progress=False, log=lambda *_: None).missing == 0
    r = rerun(out, 1, sil=True, bags=tmp_path / "bags")
    assert r.error == "" and r.recorded is not None
    rec = read_run(r.bag)
    assert rec.metadata["source"] == "sil" and rec.metadata["status"] == "complete"
    row = store.read_rows(out)[1]
    assert row["index"] == 1
    # named after the campaign run; its metadata says the run's own fault
    assert r.bag.name.startswith("sil_1_tube_mpc_rerun_sil_")
    fs = rec.records["/hsv/fault_status"][-1]
    assert rec.metadata["fault_kind"] == fs["kind"] == row["fault.kind"]
    assert float(rec.metadata["fault_t_onset"]) == fs["t_onset"] == row["fault.t_onset"]
    assert rec.metadata["run_index"] == "1" and rec.metadata["campaign"] == "sil"
    assert rec.metadata["dispersed.fault.t_onset"] == str(row["fault.t_onset"])
    for k, v in r.metrics.items():  # SIL equals simulate (the SIL tests: 1e-9)
        x = row[k]
        if isinstance(v, float) and math.isnan(v):
            assert math.isnan(x), k
        else:
            assert v == pytest.approx(x, rel=1e-9, abs=1e-12), k
