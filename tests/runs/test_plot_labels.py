"""Legend labels of overlaid recorded runs (``fahv plot``): one distinct label per run.

Each run is labelled with its scenario and variant from its metadata; runs of the same
scenario and variant are told apart by their folder (or .mcap file) names.
"""

import shutil

import matplotlib.pyplot as plt
import pytest

from fahv.loop.simulate import simulate
from fahv.runs.bag import bag_paths, read_run, run_result_of
from fahv.runs.plots import group_figure
from fahv.runs.plots_context import run_labels
from fahv.runs.writer import RunWriter

T = 0.2  # simulated time of each run [s]: 10 steps of 0.02 s


class _Tee:
    """Writer of one simulation into several runs."""

    def __init__(self, writers):
        self.writers = writers

    def write(self, topic, k, msg):
        for w in self.writers:
            w.write(topic, k, msg)


@pytest.fixture(scope="module")
def runs(design, tmp_path_factory):
    """Recorded runs ``{name: folder}``: three of tube_mpc (two in folders of the same
    name), one of tube_mpc_no_notch, all of source ``simulate``."""
    root = tmp_path_factory.mktemp("plot_runs")
    made = {}
    for variant, names in (("tube_mpc", ("sim_a", "x/run", "y/run")),
                           ("tube_mpc_no_notch", ("sim_b",))):  # fmt: skip
        meta = {"case": design.case["name"], "variant": variant, "source": "simulate"}
        writers = [RunWriter(root / n, meta, 0.02) for n in names]
        simulate(design, variant, duration=T, writer=_Tee(writers))
        for n, w in zip(names, writers, strict=True):
            w.close()
            made[n] = root / n
    return made


def _labels(paths):
    """Labels as ``fahv plot`` makes them: from the paths and the runs' metadata."""
    return run_labels(paths, [read_run(p).metadata for p in paths])


def _legend(paths, group="trajectory"):
    """Labels of the run lines in the first panel of a figure of ``paths``."""
    labelled = list(zip(_labels(paths), (run_result_of(read_run(p)) for p in paths), strict=True))
    fig = group_figure(group, labelled)
    try:
        return [line.get_label() for line in fig.axes[0].get_lines()]
    finally:
        plt.close(fig)


def test_runs_of_one_variant_are_told_apart_by_their_folders(runs, design):
    c = design.case["name"]
    paths = [runs["sim_a"], runs["x/run"]]
    assert _legend(paths) == [f"{c} / tube_mpc (sim_a)", f"{c} / tube_mpc (run)", "command"]
    assert _legend(paths, "attitude") == [f"{c} / tube_mpc (sim_a)", f"{c} / tube_mpc (run)"]


def test_runs_of_several_variants_are_labelled_by_scenario_and_variant(runs, design):
    c = design.case["name"]
    paths = [runs["sim_a"], runs["sim_b"]]
    assert _legend(paths, "inputs") == [f"{c} / tube_mpc", f"{c} / tube_mpc_no_notch"]


def test_runs_of_the_same_name_and_bare_files_are_told_apart(runs, design, tmp_path):
    c = design.case["name"]
    bare = tmp_path / "alone.mcap"
    shutil.copy(bag_paths(runs["sim_a"])[1], bare)
    paths = [runs["x/run"], runs["y/run"], bare, runs["sim_a"], runs["sim_a"]]
    assert _legend(paths, "flexible") == [
        f"{c} / tube_mpc (x/run)", f"{c} / tube_mpc (y/run)", f"{c} / tube_mpc (alone)",
        f"{c} / tube_mpc (sim_a) [1]", f"{c} / tube_mpc (sim_a) [2]",
    ]  # fmt: skip


def test_run_labels_need_metadata_per_run():
    with pytest.raises(ValueError, match="2 runs but 1 metadata"):
        run_labels(["a", "b"], [{"case": "case1", "variant": "tube_mpc"}])
