"""fahv inspect / export / compare on recorded runs, and the command line's handling of
bad run files (empty, corrupt, truncated, from another program, older definitions)."""

import json
import math
import re

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from fahv.cli import main
from fahv.errors import RunError
from fahv.loop.graph import STATE_FIELDS, TOPICS
from fahv.loop.simulate import simulate
from fahv.model.vehicle import ALPHA, load_vehicle
from fahv.msg import MSG_DIR
from fahv.runs.bag import bag_paths, read_run
from fahv.runs.metrics import metrics
from fahv.runs.tools import compare, export_run, field_units, summarize, topic_table
from fahv.runs.writer import RunWriter
from fahv.sil.runner import run_metadata, write_run_params
from fahv.sil.workspace import ROOT

T, N = 2.0, 100
LAYOUT = ROOT / "ros_ws" / "src" / "hsv_bringup" / "config" / "foxglove_layout.json"


def _record(design, variant, folder):
    bag = folder / f"sim_{variant}"
    with RunWriter(bag, run_metadata(design, variant, "simulate", T), 0.02) as w:
        write_run_params(design, variant, bag, bag / "params.yaml", T, 10.0)
        run = simulate(design, variant, duration=T, writer=w)
    return bag, run


@pytest.fixture(scope="module")
def runs(design, tmp_path_factory):
    folder = tmp_path_factory.mktemp("runs")
    return {v: _record(design, v, folder) for v in ("tube_mpc", "tube_mpc_no_notch")}


@pytest.fixture(scope="module")
def limits():
    return load_vehicle().limits


def _cli(capsys, *argv):
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def test_inspect_reports_topics_rates_metadata_and_the_run_metrics(runs, design, limits, capsys):
    bag, run = runs["tube_mpc"]
    s = summarize(read_run(bag), limits)
    assert s["complete"] and s["sim_time_s"] == [0.0, pytest.approx(1.98, abs=1e-12)]
    assert set(s["topics"]) == set(TOPICS)
    for name, t in s["topics"].items():
        assert (t["count"], t["type"], t["loop"]) == (N, TOPICS[name], True)
        assert t["rate_hz"] == pytest.approx(50.0, rel=1e-9)
    assert s["metadata"]["design_hash"] == design.summary["design_hash"]
    assert s["metadata"]["status"] == "complete"
    assert all(
        v == {"duplicate": 0, "out_of_order": 0, "missing": 0} for v in s["step_anomalies"].values()
    )
    # the same numbers the run printed, exactly (assert_equal treats NaN == NaN)
    np.testing.assert_equal(s["metrics"], metrics(run, limits))

    rc, out, _ = _cli(capsys, "inspect", bag)
    assert rc == 0
    assert "step anomalies: none" in out
    row = re.search(r"max \|alpha - alpha_r\| \[deg\]\s+(\S+)", out).group(1)
    # the table prints 3 decimals: equal to within half a unit of the last digit
    assert float(row) == pytest.approx(s["metrics"]["alpha_err_max_deg"], abs=5e-4)
    rc, out, _ = _cli(capsys, "inspect", bag, "--json")
    js = json.loads(out)  # strict JSON: NaN written as null
    assert js["metrics"]["theta_err_max_deg"] == s["metrics"]["theta_err_max_deg"]
    assert js["metrics"]["settling_time_h_s"] is None
    assert math.isnan(s["metrics"]["settling_time_h_s"])


def test_export_tables_have_named_columns_units_and_the_recorded_values(runs, tmp_path, capsys):
    import pyarrow.csv as pacsv
    import pyarrow.parquet as pq

    bag, run = runs["tube_mpc"]
    files = export_run(read_run(bag), tmp_path / "pq", "parquet")
    assert {f.name for f in files} >= {"hsv_state.parquet", "hsv_nominal.parquet", "columns.csv"}
    state = pq.read_table(tmp_path / "pq" / "hsv_state.parquet")
    assert state.column_names == ["k", "t", *STATE_FIELDS, "phi_a", "delta_e_a", "phi_a_rate_peak",
                                  "delta_e_a_rate_peak"]  # fmt: skip
    assert state.schema.field("delta_e_a_rate_peak").metadata[b"unit"] == b"rad/s"
    assert state.schema.field("alpha").metadata[b"unit"] == b"rad"
    assert state.schema.field("delta_e_a").metadata[b"unit"] == b"rad"
    np.testing.assert_array_equal(state.column("delta_e_a").to_numpy(), run.u_actuator[:, 1])
    assert state.schema.field("h").metadata[b"unit"] == b"ft"
    np.testing.assert_array_equal(state.column("alpha").to_numpy(), run.x[:, ALPHA])
    nom = pq.read_table(tmp_path / "pq" / "hsv_nominal.parquet")
    assert "x_r.alpha" in nom.column_names and "u_n.delta_e" in nom.column_names
    assert nom.schema.field("x_r.V").metadata[b"unit"] == b"ft/s"
    np.testing.assert_array_equal(nom.column("x_r.alpha").to_numpy(), run.x_r[:, ALPHA])

    rc, out, _ = _cli(capsys, "export", bag, "--format", "csv", "--out", tmp_path / "csv")
    assert rc == 0 and "hsv_state.csv" in out
    table = pacsv.read_csv(tmp_path / "csv" / "hsv_state.csv")
    assert table.num_rows == N
    np.testing.assert_allclose(table.column("alpha").to_numpy(), run.x[:, ALPHA], rtol=1e-15)
    cols = pacsv.read_csv(tmp_path / "csv" / "columns.csv").to_pylist()
    units = {(c["topic"], c["column"]): c["unit"] for c in cols}
    assert units[("/hsv/control_command", "delta_e")] == "rad"
    assert units[("/hsv/nominal", "h_c")] == "ft"
    assert units[("/clock", "t")] == "s"


def test_compare_gives_side_by_side_metrics_and_differences(runs, limits, capsys):
    (a, ra), (b, rb) = runs["tube_mpc"], runs["tube_mpc_no_notch"]
    sa, sb = summarize(read_run(a), limits), summarize(read_run(b), limits)
    c = compare(sa, sb, ("A", "B"))
    ma, mb = metrics(ra, limits), metrics(rb, limits)
    d = c["table"]["B - A"]
    assert (
        d["eta_1_dot_rms_after_fault"]
        == mb["eta_1_dot_rms_after_fault"] - ma["eta_1_dot_rms_after_fault"]
    )
    assert d["eta_1_dot_rms_after_fault"] != 0.0  # the notch changes the mode-1 rate
    assert d["attitude_within_0.5deg"] is None  # booleans are not subtracted
    assert c["metadata"]["variant"] == ("tube_mpc", "tube_mpc_no_notch")
    rc, out, _ = _cli(capsys, "compare", a, b)
    assert rc == 0 and "B - A" in out and "variant: A tube_mpc | B tube_mpc_no_notch" in out


def test_foxglove_layout_plots_only_existing_fields():
    layout = json.loads(LAYOUT.read_text())
    paths = [p["value"] for cfg in layout["configById"].values() for p in cfg.get("paths", [])]
    paths += [cfg["topicPath"] for cfg in layout["configById"].values() if "topicPath" in cfg]
    assert len(paths) >= 15
    for path in paths:
        topic, _, fld = path.partition(".")
        assert topic in TOPICS, path
        if fld:
            name = re.sub(r"\[\d+\]$", "", fld)
            assert name in field_units(TOPICS[topic]), path

    def ids(node):
        return [node] if isinstance(node, str) else ids(node["first"]) + ids(node["second"])

    assert sorted(ids(layout["layout"])) == sorted(layout["configById"])


def test_empty_run_is_inspected_but_has_no_metrics_or_tables(tmp_path, limits, capsys):
    with RunWriter(tmp_path / "empty", {"case": "case1", "variant": "tube_mpc"}, 0.02):
        pass
    s = summarize(read_run(tmp_path / "empty"), limits)
    assert s["metrics"] is None and "no complete step" in s["metrics_note"]
    assert all(t["count"] == 0 for t in s["topics"].values()) and s["sim_time_s"] is None
    rc, out, err = _cli(capsys, "inspect", tmp_path / "empty")
    assert rc == 0 and "metrics: no complete step" in out
    rc, out, err = _cli(capsys, "export", tmp_path / "empty")
    assert rc == 2 and "nothing to export" in err and "Traceback" not in err
    rc, out, err = _cli(capsys, "compare", tmp_path / "empty", tmp_path / "empty")
    assert rc == 2 and "no complete step" in err


def test_corrupt_missing_and_truncated_files_in_the_command_line(runs, tmp_path, capsys):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"\x00" * 100)
    for cmd in ("inspect", "export", "plot"):
        rc, out, err = _cli(capsys, cmd, bad)
        assert rc == 2 and "not an MCAP file" in err and "Traceback" not in err
    rc, out, err = _cli(capsys, "inspect", tmp_path / "missing")
    assert rc == 2 and "does not exist" in err
    _, mcap = bag_paths(runs["tube_mpc"][0])
    cut = tmp_path / "cut" / "cut.mcap"
    cut.parent.mkdir()
    data = mcap.read_bytes()
    cut.write_bytes(data[: len(data) - 3000])  # summary and footer lost
    rc, out, err = _cli(capsys, "inspect", cut)
    assert rc == 0 and "truncated" in err and "TRUNCATED" in out


def test_run_of_another_program_lists_its_topics(tmp_path, limits, capsys):
    ts = get_typestore(Stores.ROS2_JAZZY)
    with Writer(tmp_path / "other", version=9, storage_plugin=StoragePlugin.MCAP) as w:
        c = w.add_connection("/chatter", "std_msgs/msg/String", typestore=ts)
        for i in range(3):
            msg = ts.types["std_msgs/msg/String"](data=f"hello {i}")
            w.write(c, i * 10**9, ts.serialize_cdr(msg, "std_msgs/msg/String"))
    s = summarize(read_run(tmp_path / "other"), limits)
    assert s["topics"]["/chatter"] == {
        "type": "std_msgs/msg/String",
        "count": 3,
        "first_s": 0.0,
        "last_s": 2.0,
        "rate_hz": 1.0,
        "loop": False,
    }
    assert s["metrics"] is None
    rc, out, err = _cli(capsys, "inspect", tmp_path / "other")
    assert rc == 0 and "/chatter" in out and "no (not decoded)" in out


def test_run_recorded_with_an_older_definition_still_decodes(tmp_path):
    """A TubeStatus recorded before it had the RMPC counters: decoded with its own schema."""
    old = "\n".join(
        ln
        for ln in (MSG_DIR / "TubeStatus.msg").read_text().splitlines()
        if "lmi_" not in ln and "qp_" not in ln
    )
    name = TOPICS["/hsv/tube_status"]
    ts = get_typestore(Stores.ROS2_JAZZY)
    ts.register(get_types_from_msg(old, name))
    with Writer(tmp_path / "old", version=9, storage_plugin=StoragePlugin.MCAP) as w:
        c = w.add_connection("/hsv/tube_status", name, typestore=ts)
        msg = ts.types[name](
            k=0, t=0.0, law="tube_mpc", tau=1.0, level=0.25, inside=True, e=np.zeros(9)
        )
        w.write(c, 0, ts.serialize_cdr(msg, name))
    rec = read_run(tmp_path / "old")
    assert rec.records["/hsv/tube_status"][0]["level"] == 0.25
    assert "lmi_solves" not in rec.records["/hsv/tube_status"][0]
    cols, meta = topic_table(rec, "/hsv/tube_status")
    assert cols["level"][0] == 0.25 and meta["level"][0] == "-"


def test_export_rejects_an_unknown_format(runs, tmp_path):
    with pytest.raises(RunError, match="unknown export format"):
        export_run(read_run(runs["tube_mpc"][0]), tmp_path, "xlsx")


def test_simulate_overrides_node_parameters_and_names_unknown_nodes(design):
    run = simulate(design, "tube_mpc", 0.1, overrides={"notch_filter": {"enabled": False}})
    np.testing.assert_array_equal(run.q_f, run.x[:, 4])  # no filter: q' = q
    with pytest.raises(RunError, match="override for node 'bogus'"):
        simulate(design, "tube_mpc", 0.1, overrides={"bogus": {"x": 1}})


def test_paper_figures_take_the_paper_law_from_the_vertex_case(monkeypatch, tmp_path):
    """Fig. 9, 10 and 12 draw the paper's law from case1_paper (Case 1's certified design
    has no such variant), labelled with its case; a missing run is left out."""
    from fahv.runs import plots

    drawn = {}

    def fake_plot_group(group, sel, path, title):
        drawn[path.name] = [label for label, _ in sel]
        return path

    monkeypatch.setattr(plots, "plot_group", fake_plot_group)
    runs = {("case1", "tube_mpc"): 1, ("case1", "rmpc"): 2, ("case1_paper", "tube_mpc_paper"): 3,
            ("case1_paper", "tube_mpc"): 4}  # fmt: skip
    plots.paper_figures(runs, tmp_path)
    paper = plots.LABELS["tube_mpc_paper"] + " (case1_paper)"
    assert drawn["fig09_case1_trajectory.png"] == [plots.LABELS["tube_mpc"], paper,
                                                  plots.LABELS["rmpc"]]  # fmt: skip
    assert paper not in drawn["fig11_case1_flexible.png"]
    assert "fig14_case2_trajectory.png" not in drawn  # no Case 2 run


def test_the_report_page_of_a_run_holds_its_verdict_and_every_figure(runs, capsys, tmp_path,
                                                                      rendered_body):  # fmt: skip
    """`fahv report RUN`: one self-contained page, written atomically beside the run; its
    verdict table has every requirement, its 9 figures are embedded PNGs, and Chromium
    loads all 9."""
    import base64
    from html.parser import HTMLParser

    bag, _ = runs["tube_mpc"]
    rc, out, _ = _cli(capsys, "report", bag)
    page = bag / "report.html"
    assert rc == 0 and out.strip() == f"report: {page}"
    assert not list(bag.glob("*.part"))
    text = page.read_text()
    srcs = []

    class Images(HTMLParser):
        def handle_starttag(self, tag, attrs):
            if tag == "img":
                srcs.append(dict(attrs)["src"])

    Images().feed(text)
    assert len(srcs) == 9
    for src in srcs:  # every image is in the page: no file beside it
        head, data = src.split(",", 1)
        assert head == "data:image/png;base64"
        assert base64.b64decode(data)[:8] == b"\x89PNG\r\n\x1a\n"
    for key in ("completes", "attitude", "input_limits", "input_rates", "tube", "settling",
                "final_h", "final_V"):  # fmt: skip
        assert f"<td class=\"\">{key}</td>" in text
    assert "verdict: " in text and "<b>coverage:</b>" in text
    body = rendered_body(page)
    assert body["data-images"] == body["data-images-loaded"] == "9"
