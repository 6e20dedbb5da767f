"""The figures of ``fahv plot``: time window, requirement bands, limits, fault onset, spectra.

Synthetic runs (a few hundred steps of known signals) check what each figure draws
against the values it must draw; one short recorded Case 1 run of each notch setting
checks the command line end to end (labels from the metadata, the files written).
"""

import dataclasses
import math

import matplotlib.pyplot as plt
import numpy as np
import pytest

from fahv.cli import main
from fahv.errors import FahvError
from fahv.loop.simulate import RunResult
from fahv.model.vehicle import ETA1_DOT, IQ, H, V, load_vehicle
from fahv.runs.bag import read_run
from fahv.runs.metrics import ATTITUDE_BOUND_DEG, SETTLE_TOL
from fahv.runs.plots_context import (
    PlottedRun,
    clip_run,
    clip_runs,
    fault_onset,
    plotted_run,
    run_labels,
)
from fahv.runs.plots_frequency import SPECTRUM_PANELS, psd, spectra_figure
from fahv.runs.plots_time import (
    error_figure,
    estimate_figure,
    input_figure,
    input_rate_figure,
    mark_onsets,
    tube_figure,
)

TS, N = 0.02, 2000  # 40 s of 0.02 s steps
W1 = 19.05  # flexible mode 1 / notch frequency [rad/s]


def _run(slope=0.5) -> RunResult:
    """A synthetic run: h, V 100 ft, 20 ft/s below the command and decaying, eta_1_dot a
    sine at W1, q a sine at 3 rad/s, Phi a ramp of ``slope`` [1/s], tube level < 1."""
    t = np.arange(N) * TS
    x = np.zeros((N, 9))
    x[:, H] = 86100.0 - 100.0 * np.exp(-t / 5.0)
    x[:, V] = 8150.0 - 20.0 * np.exp(-t / 5.0)
    x[:, IQ] = 0.01 * np.sin(3.0 * t)
    x[:, ETA1_DOT] = 0.2 * np.sin(W1 * t)
    u = np.stack([0.2 + slope * t, np.full(N, 0.2)], axis=1)
    return RunResult(
        t=t, x=x, q_f=x[:, IQ].copy(), x_r=np.zeros((N, 9)), x_n=np.zeros((N, 9)), u=u,
        u_applied=u.copy(), h_c=np.full(N, 86100.0), V_c=np.full(N, 8150.0),
        h_g=np.full(N, 86100.0), V_g=np.full(N, 8150.0), tube_level=0.1 + 0.0 * t,
        fault_active=t >= 10.0, lmi_counts=np.zeros(1, int),
    )  # fmt: skip


def _plotted(label="case1 / tube_mpc", **kw) -> PlottedRun:
    return PlottedRun(
        label=label, run=_run(), limits=load_vehicle().limits,
        u_lo=np.array([0.05, -0.46]), u_hi=np.array([1.45, 0.46]), omega_z=W1,
        omega_flex=np.array([W1, 49.1]), t_onset=10.0, **kw,
    )  # fmt: skip


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


def _hlines(ax) -> set[float]:
    """y of the horizontal lines of an axis (constant ydata)."""
    return {float(ln.get_ydata()[0]) for ln in ax.get_lines()
            if len(set(np.atleast_1d(ln.get_ydata()))) == 1}  # fmt: skip


def test_the_time_window_clips_every_step_array_to_t0_t1():
    run = _run()
    cut = clip_run(run, 5.0, 12.5)
    assert cut.t[0] >= 5.0 and cut.t[-1] <= 12.5
    assert cut.t[0] - 5.0 < TS and 12.5 - cut.t[-1] < TS  # nothing inside lost
    for f in ("x", "u", "u_applied", "q_f", "tube_level", "fault_active", "h_c"):
        assert getattr(cut, f).shape[0] == cut.t.size
    np.testing.assert_array_equal(cut.x, run.x[(run.t >= 5.0) & (run.t <= 12.5)])
    assert cut.lmi_counts.shape == (1,)  # counts over the run are kept
    (p,) = clip_runs([_plotted()], None, 3.0)
    assert p.run.t[0] == 0.0 and p.run.t[-1] <= 3.0 and p.t_onset == 10.0
    with pytest.raises(FahvError, match="no step in the time window"):
        clip_run(run, 100.0, 200.0)
    with pytest.raises(FahvError, match="t1 is before t0"):
        clip_run(run, 5.0, 1.0)


def test_error_bands_are_the_requirement_constants():
    fig = error_figure([_plotted()])
    axes = np.array(fig.axes).reshape(4, 2)
    bounds = (SETTLE_TOL["h"], SETTLE_TOL["V"], ATTITUDE_BOUND_DEG, ATTITUDE_BOUND_DEG)
    assert bounds == (10.0, 2.0, 0.5, 0.5)
    for row, b in zip(axes, bounds, strict=True):
        for ax in row:
            assert {-b, b} <= _hlines(ax)
            (band,) = ax.patches
            y0, y1 = band.get_y(), band.get_y() + band.get_height()  # data units
            assert (y0, y1) == pytest.approx((-b, b), abs=1e-12)
        assert row[1].get_ylim() == pytest.approx((-3 * b, 3 * b))
    h_err = axes[0, 0].get_lines()[2].get_ydata()  # after the two band edges
    assert h_err[0] == pytest.approx(-100.0, abs=1e-9)  # h - h_c in ft


def test_inputs_show_the_actuator_and_the_tightened_limits_in_their_units():
    p = _plotted()
    fig = input_figure([p])
    phi, de = fig.axes[0], fig.axes[2]  # left column
    lim = p.limits
    assert {lim.Phi_min, lim.Phi_max, 0.05, 1.45} <= _hlines(phi)
    expected = {math.degrees(v) for v in (lim.delta_e_min, lim.delta_e_max, -0.46, 0.46)}
    assert {round(v, 9) for v in expected} <= {round(v, 9) for v in _hlines(de)}


def test_input_rates_are_finite_differences_of_the_command():
    """The command (before the fault injector), not the applied input: a stuck elevator
    applies 0 while the command ramps; ideal actuators draw no rate limit and say so."""
    run = _run(slope=0.5)
    run = dataclasses.replace(run, u_applied=np.zeros_like(run.u))
    fig = input_rate_figure([dataclasses.replace(_plotted(), run=run)])
    line = fig.axes[0].get_lines()[0]
    assert line.get_xdata()[0] == pytest.approx(TS)  # at the later step of each difference
    np.testing.assert_allclose(line.get_ydata(), 0.5, atol=1e-9)  # dPhi/dt [1/s]
    np.testing.assert_allclose(fig.axes[1].get_lines()[0].get_ydata(), 0.0, atol=1e-9)
    assert "ideal actuators (no rate limit): case1 / tube_mpc" in fig.axes[1].texts[0].get_text()


def test_input_rates_draw_the_servo_and_its_own_rate_limit():
    """With servos (the position lags the command) the servo's position rate is drawn
    beside the command's, and the elevator's rate limit at the vehicle file's 100 deg/s
    times the run's factor: 50 deg/s with a factor of 0.5."""
    run = _run(slope=0.5)
    lag = np.vstack([run.u[:1], run.u[:-1] * 0.9])
    run = dataclasses.replace(run, u_actuator=lag)
    half = load_vehicle().limits.with_rate_factor(0.5)
    fig = input_rate_figure([dataclasses.replace(_plotted(), run=run, limits=half)])
    labels = [ln.get_label() for ln in fig.axes[1].get_lines()]
    assert labels[:2] == ["case1 / tube_mpc: command", "case1 / tube_mpc: servo position"]
    assert {round(v, 6) for v in _hlines(fig.axes[1])} >= {50.0, -50.0}
    assert "case1 / tube_mpc: rate limit 50" in labels


def test_the_estimate_figure_draws_x_hat_less_x_in_the_panels_units():
    """An estimate 2 ft high in h and 0.01 deg in theta is drawn as 2 and 0.01; a run
    without an estimate (the exact state) as zero."""
    run = _run()
    x_hat = run.x.copy()
    x_hat[:, H] += 2.0
    x_hat[:, 3] += math.radians(0.01)
    estimated = dataclasses.replace(_plotted(), run=dataclasses.replace(run, x_hat=x_hat))
    fig = estimate_figure([estimated, _plotted("exact")])
    h, exact = fig.axes[0].get_lines()[:2]
    np.testing.assert_allclose(h.get_ydata(), 2.0, atol=1e-9)
    np.testing.assert_allclose(exact.get_ydata(), 0.0, atol=0)
    np.testing.assert_allclose(fig.axes[3].get_lines()[0].get_ydata(), 0.01, atol=1e-9)


def test_the_fault_onset_is_drawn_at_t_onset_on_every_panel():
    runs = [_plotted()]
    for fig in (error_figure(runs), input_figure(runs), tube_figure(runs)):
        assert mark_onsets(fig, runs) == [10.0]
        for ax in fig.axes:
            xs = [ln.get_xdata() for ln in ax.get_lines()]
            assert any(len(x) == 2 and x[0] == x[1] == 10.0 for x in xs)
        legend = [t.get_text() for t in fig.axes[0].get_legend().texts]
        assert "fault onset of case1 / tube_mpc, t = 10 s" in legend  # each run its own
    clipped = clip_runs(runs, 0.0, 5.0)  # onset outside the window: no line
    assert mark_onsets(error_figure(clipped), clipped) == []
    assert fault_onset({"fault_kind": "loss_of_effectiveness", "fault_t_onset": "100.0"}) == 100.0
    assert fault_onset({"fault_kind": "none", "fault_t_onset": "100.0"}) is None


def test_tube_level_axis_holds_the_boundary_of_z_at_1():
    fig = tube_figure([_plotted()])
    ax = fig.axes[0]
    assert ax.get_yscale() == "log" and 1.0 in _hlines(ax)
    assert ax.get_ylim()[0] < 0.1 < 1.0 < ax.get_ylim()[1]
    assert "e' N^-1 e" in fig.texts[0].get_text()  # the suptitle


def test_psd_peak_of_eta_1_dot_is_at_the_mode_frequency_within_a_bin():
    run = _run()
    omega, S = psd(SPECTRUM_PANELS[2][1](run), TS)
    step = omega[1] - omega[0]
    assert step == pytest.approx(2 * math.pi / (1024 * TS))
    assert abs(omega[np.argmax(S)] - W1) <= step
    assert omega[-1] == pytest.approx(math.pi / TS)
    # the density integrates to the variance (0.2^2 / 2)
    assert np.sum(S) * step == pytest.approx(0.02, rel=0.05)


def test_spectra_mark_the_notch_and_the_modes_and_the_ratio_of_q_prime_to_q():
    runs = [
        _plotted(),
        _plotted(
            "case1 / tube_mpc_no_notch",
        ),
    ]
    runs[1].omega_z = None
    fig = spectra_figure(runs, after_transient=False)
    assert len(fig.axes) == 4
    for ax in fig.axes:
        vlines = {
            float(ln.get_xdata()[0]) for ln in ax.get_lines() if len(set(ln.get_xdata())) == 1
        }
        assert {W1, 49.1} <= vlines
    ratio = fig.axes[-1].get_lines()[0].get_ydata()  # q_f = q here: 0 dB
    np.testing.assert_allclose(ratio, 0.0, atol=1e-9)
    labels = [t.get_text() for t in fig.axes[0].get_legend().texts]
    assert labels[:2] == ["case1 / tube_mpc (0-40 s)", "case1 / tube_mpc_no_notch (0-40 s)"]
    assert "notch omega_z = 19.05 rad/s" in labels


def test_legend_labels_are_scenario_and_variant_from_the_metadata(tmp_path):
    meta = [{"case": "case1", "variant": "tube_mpc"}, {"case": "case1", "variant": "rmpc"}]
    assert run_labels(["a", "b"], meta) == ["case1 / tube_mpc", "case1 / rmpc"]
    same = [meta[0], meta[0], meta[0]]
    paths = [tmp_path / "x" / "run", tmp_path / "y" / "run", tmp_path / "z.mcap"]
    assert run_labels(paths, same) == [
        "case1 / tube_mpc (x/run)", "case1 / tube_mpc (y/run)", "case1 / tube_mpc (z)",
    ]  # fmt: skip
    assert run_labels(["a", "a"], same[:2]) == ["case1 / tube_mpc [1]", "case1 / tube_mpc [2]"]
    with pytest.raises(ValueError, match="2 runs but 1 metadata"):
        run_labels(["a", "b"], meta[:1])


def test_fahv_plot_of_recorded_runs_with_and_without_the_notch(tmp_path, capsys, monkeypatch):
    """Two recorded runs of 0.2 s (10 steps); the figures are drawn, not rendered."""
    import fahv.cli.inspect as inspect_cli

    bags = tmp_path / "bags"
    rc = main(["simulate", "offline_design/scenarios/case1.yaml", "--duration", "0.2",
               "--variant", "tube_mpc", "tube_mpc_no_notch", "--out", str(bags)])  # fmt: skip
    assert rc == 0
    paths = sorted(bags.iterdir(), key=lambda p: "no_notch" in p.name)
    rec = read_run(paths[0])
    run = plotted_run(rec, "x")
    assert run.omega_z == pytest.approx(W1) and run.t_onset == 100.0
    assert run.omega_flex.shape == (2,) and np.all(run.u_lo < run.u_hi)
    drawn = {}

    def keep(fig, path):
        drawn[path.stem] = fig
        return path

    monkeypatch.setattr(inspect_cli, "save_figure", keep)
    capsys.readouterr()
    rc = main(["plot", *map(str, paths), "--out", str(tmp_path), "--t0", "0.04", "--t1", "0.14"])
    assert rc == 0
    assert set(drawn) == {"trajectory", "attitude", "flexible", "errors", "inputs",
                          "input_rates", "tube", "estimate", "spectra"}  # fmt: skip
    legend = [t.get_text() for t in drawn["errors"].axes[0].get_legend().texts]
    assert legend == ["case1 / tube_mpc", "case1 / tube_mpc_no_notch"]  # from the metadata
    t = drawn["errors"].axes[0].get_lines()[-1].get_xdata()
    assert t[0] == pytest.approx(0.04) and t[-1] == pytest.approx(0.14)  # the window
    notch = [t.get_text() for t in drawn["spectra"].axes[0].get_legend().texts]
    assert "notch omega_z = 19.05 rad/s" in notch  # the notch run's only
    assert main(["plot", str(paths[0]), "--t0", "5", "--t1", "6"]) == 2
    assert "no step in the time window" in capsys.readouterr().err
