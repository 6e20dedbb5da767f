import functools
from pathlib import Path

import numpy as np
import pytest
import yaml

from fahv.campaign.spec import campaign_spec, load_campaign
from fahv.cli import main
from fahv.config.spec import markdown
from fahv.errors import CampaignError

ROOT = Path(__file__).resolve().parents[2]


PAPER = ROOT / "studies" / "paper_design" / "campaigns"


@pytest.fixture(scope="module")
def write_campaign(request, make_case, tmp_path_factory):
    """``write_campaign(name, **changes)`` as in tests/campaign/conftest.py (its `BASE`
    campaign with the changes), beside the quick case's design file and scenario only.

    Loading and checking a campaign file reads its scenario and the scenario's design file,
    never the designed arrays: the files here validate without the quick design (half a
    minute of LMIs) that running a campaign needs.
    """
    import json

    from fahv.spec.scenario import design_part
    from fahv.spec.schema import SCENARIO_KEYS

    conftest = request.config.pluginmanager.get_plugin(str(Path(__file__).with_name(
        "conftest.py")))  # fmt: skip
    folder = tmp_path_factory.mktemp("mc_files")
    case = make_case()  # the case the quick design is made of (tests/conftest.py)
    c = json.loads(json.dumps(case.data))
    for sub in ("designs", "scenarios"):
        (folder / sub).mkdir()
    dpart = json.loads(json.dumps(design_part(case).data))
    (folder / "designs" / "quick.yaml").write_text(
        yaml.safe_dump({**dpart, "name": "quick"}, sort_keys=False))  # fmt: skip
    scenario = {k: c[k] for k in SCENARIO_KEYS if k in c}
    (folder / "scenarios" / "quick.yaml").write_text(
        yaml.safe_dump({**scenario, "design": "quick"}, sort_keys=False))  # fmt: skip

    return functools.partial(conftest.campaign_file, folder)


@pytest.mark.parametrize(
    "path, scenario",
    [(ROOT / "offline_design" / "campaigns" / "case1.yaml", "case1"),
     (ROOT / "offline_design" / "campaigns" / "envelope.yaml", "case1"),
     (PAPER / "case1_paper.yaml", "case1_paper"), (PAPER / "paired.yaml", "case1_paper"),
     (ROOT / "offline_design" / "campaigns" / "case2.yaml", "case2")],
    ids=lambda v: v.name if isinstance(v, Path) else v,
)  # fmt: skip
def test_shipped_campaign_files_validate(path, scenario):
    c = load_campaign(path)
    assert c.run_spec.name == scenario
    assert c.duration == 300.0
    assert set(c["variants"]) <= set(c.run_spec["variants"])


def test_a_campaign_runs_around_another_scenario():
    """--scenario: the same dispersions around another scenario (and its design)."""
    c = load_campaign(ROOT / "offline_design" / "campaigns" / "case1.yaml", scenario="case1_paper")
    assert c.run_spec.name == "case1_paper" and c.run_spec["tube"]["form"] == "vertices"
    base = load_campaign(ROOT / "offline_design" / "campaigns" / "case1.yaml")
    assert c["dispersions"] == base["dispersions"] and c.content_hash() != base.content_hash()


def test_the_paper_design_campaign_draws_losses_beyond_its_range():
    c = load_campaign(PAPER / "case1_paper.yaml")
    assert c["runs"] == 1000
    f = c["dispersions"]["fault"]
    assert f["kinds"] == ["loss_of_effectiveness"] and f["loss"] == [0.0, 0.3]
    assert f["onset"] == [30.0, 200.0]
    assert c["dispersions"]["uncertainty"] == {
        "method": "uniform", "scale": 1.0,
        "parameters": ["m", "I_yy", "S", "z_T", "c_bar", "c_e", "beta_1", "beta_3", "beta_5",
                       "beta_7"],
    }  # fmt: skip
    assert any("fault range" in w for w in c.warnings)


def _edit(write_campaign, tmp_name, edit):
    path = write_campaign(tmp_name)
    data = yaml.safe_load(path.read_text())
    edit(data)
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.parametrize(
    ("edit", "key", "words"),
    [
        (lambda d: d["dispersions"]["fault"].update(lost=[0, 1]), "dispersions.fault.lost",
         "unknown key"),
        (lambda d: d.update(sed=3), "sed", "unknown key"),
        (lambda d: d["dispersions"]["fault"].update(loss=[0.0, 1.2]), "dispersions.fault.loss",
         "must be in [0, 1)"),
        (lambda d: d["dispersions"]["fault"].update(onset=[5.0, 1.0]), "dispersions.fault.onset",
         "low <= high"),
        (lambda d: d["dispersions"]["uncertainty"].update(scale=1.5),
         "dispersions.uncertainty.scale", "must be in [0, 1]"),
        (lambda d: d["dispersions"]["uncertainty"].update(method="sobol"),
         "dispersions.uncertainty.method", "must be one of"),
        (lambda d: d["dispersions"]["command"].update(dh=[0.0, 2000.0]),
         "dispersions.command.dh", "flight envelope"),
        (lambda d: d["dispersions"]["initial"].update(V0=[7000.0, 7900.0]),
         "dispersions.initial.V0", "flight envelope"),
        (lambda d: d.update(variants=["tube_mpc", "nope"]), "variants", "must be one of"),
        (lambda d: d.update(runs=0), "runs", "must be in [1, 1e+06]"),
        (lambda d: d.pop("seed"), "seed", "missing key"),
        (lambda d: d.update(scenario="nope.yaml"), "scenario", "does not load"),
        # a servo or a sensor that is not physical, before any run
        (lambda d: d["dispersions"].update(actuators={"omega_n": [0.0, 1.2]}),
         "dispersions.actuators.omega_n", "must be in (0, 100]"),
        (lambda d: d["dispersions"].update(actuators={"zeta": [-0.1, 1.0]}),
         "dispersions.actuators.zeta", "must be in [0, 100]"),
        (lambda d: d["dispersions"].update(actuators={"rate_limit": [1.1, 0.9]}),
         "dispersions.actuators.rate_limit", "low <= high"),
        (lambda d: d["dispersions"].update(sensors={"stddev": [-1.0, 1.0]}),
         "dispersions.sensors.stddev", "must be in [0, 100]"),
        # servos and sensors dispersed on a loop that has neither (case1: the paper's)
        (lambda d: d["dispersions"].update(actuators={"omega_n": [0.9, 1.1]}),
         "dispersions.actuators.omega_n", "flies ideal actuators"),
        (lambda d: d["dispersions"].update(sensors={"stddev": [0.9, 1.1]}),
         "dispersions.sensors.stddev", "reads the exact state"),
    ],
)  # fmt: skip
def test_bad_campaign_files_fail_naming_the_key(write_campaign, edit, key, words):
    path = _edit(write_campaign, "bad", edit)
    with pytest.raises(CampaignError) as exc:
        load_campaign(path)
    msg = str(exc.value)
    assert f"'{key}'" in msg and words in msg and str(path) in msg


def test_fault_kind_without_size_fails_naming_the_key(write_campaign):
    path = _edit(write_campaign, "nobias",
                 lambda d: d["dispersions"]["fault"].pop("bias_deg"))  # fmt: skip
    with pytest.raises(CampaignError, match=r"'dispersions.fault.bias_deg' is needed"):
        load_campaign(path)


def test_cli_names_the_key_and_exits_2(write_campaign, capsys):
    path = _edit(write_campaign, "cli", lambda d: d["dispersions"]["fault"].update(loss=[0, 2]))
    assert main(["campaign", str(path), "--out", str(path.parent / "never")]) == 2
    err = capsys.readouterr().err
    assert "'dispersions.fault.loss'" in err and "must be in [0, 1)" in err
    assert not (path.parent / "never").exists()


def test_docs_key_table_is_the_declaration():
    text = (ROOT / "docs" / "reference" / "configuration.md").read_text()
    table = text.split("<!-- campaign-keys -->\n")[1].split("\n<!-- /campaign-keys -->")[0]
    assert table == markdown(campaign_spec())


def test_fault_onsets_beyond_the_run_are_warned(write_campaign, capsys, monkeypatch):
    """Onsets drawn after the run's end are warned (those runs have no fault)."""
    assert load_campaign(write_campaign("onset_ok")).warnings == []  # onset [1, 4], 6 s runs
    c = load_campaign(
        write_campaign(
            "onset_late",
            duration=6.0,
            fault={"kinds": ["loss_of_effectiveness"], "loss": [0.0, 0.24], "onset": [2.0, 10.0]},
        )
    )
    [w] = c.warnings
    assert "dispersions.fault.onset [2, 10] s reaches beyond the run's duration 6 s" in w
    assert "50 % of the runs end before their fault" in w  # (10 - 6) / (10 - 2)
    # the case's own onset (100 s) with 6 s runs and no dispersed onset
    c = load_campaign(write_campaign("case_onset", fault={"kinds": ["loss_of_effectiveness"]}))
    assert c.warnings and "the scenario's fault onset 100 s" in c.warnings[0]
    assert "100 % of the runs" in c.warnings[0]
    # the command prints it before it starts
    import fahv.cli.campaign as cli

    def stop(*args, **kwargs):
        raise CampaignError("stopped by the test")

    monkeypatch.setattr(cli, "run_campaign", stop)
    assert main(["campaign", str(c.path), "--out", str(c.path.parent / "w")]) == 2
    err = capsys.readouterr().err
    assert err.index("warning: ") < err.index("stopped by the test")


def test_the_nominal_range_warning_uses_the_campaigns_vehicle(tmp_path):
    """A campaign run with another vehicle file runs that vehicle's design: the range it
    warns about is the nominal range over that vehicle's envelope, not the packaged
    vehicle's: 85005..86495 ft for the packaged vehicle, 85005..86995 ft for one that
    flies up to 87000 ft."""
    from importlib import resources

    from fahv.model.vehicle import load_vehicle

    text = resources.files("fahv.data").joinpath("vehicle_parker2007.yaml").read_text()
    text = text.replace("h: {min: 85000.0, max: 86500.0,", "h: {min: 85000.0, max: 87000.0,")
    (tmp_path / "wide.yaml").write_text(text)
    wide = load_vehicle(tmp_path / "wide.yaml")
    assert wide.envelope.h_max == 87000.0
    path = ROOT / "offline_design" / "campaigns" / "envelope.yaml"
    [h_c] = [w for w in load_campaign(path).warnings if "commanded h_c" in w]
    assert "[85000, 86500] ft" in h_c and "[85005, 86495] ft" in h_c
    [h_c] = [w for w in load_campaign(path, vehicle=wide).warnings if "commanded h_c" in w]
    assert "[85000, 86500] ft" in h_c and "[85005, 86995] ft" in h_c


def test_the_hardware_campaign_disperses_the_servos_and_sensors_on_the_same_draws():
    """Each run its own servo and sensor factors, within the file's ranges, to the plant;
    its vehicle, fault and noise seed those of the same run of case1_implementable_1000."""
    from fahv.campaign.draws import draw, overrides
    from fahv.certificate.verified import load_or_design

    folder = ROOT / "offline_design" / "campaigns"
    c = load_campaign(ROOT / "studies" / "hardware_tolerances" / "campaigns"
                      / "case1_implementable_hardware.yaml")  # fmt: skip
    plain = load_campaign(folder / "case1_implementable_1000.yaml")
    for i in (0, 7, 999):
        same = draw(plain.data, plain.run_spec.data, i)
        assert {k: v for k, v in draw(c.data, c.run_spec.data, i).items() if k in same} == same
    d = c["dispersions"]
    assert d["actuators"] == {"omega_n": [0.8, 1.2], "zeta": [0.8, 1.2], "rate_limit": [0.9, 1.1]}
    assert d["sensors"]["stddev"] == [0.8, 1.25] and d["sensors"]["bias_mean"] == [-0.5, 0.5]
    values = [draw(c.data, c.run_spec.data, i) for i in range(50)]
    omega = np.array([v["actuators.omega_n"] for v in values])
    assert 0.8 <= omega.min() < 0.9 and 1.1 < omega.max() <= 1.2
    assert all(v["sensors.bias_stddev"] == 1.0 for v in values)  # not dispersed
    _, design, _ = load_or_design(c.run_spec.path, log=lambda *_: None, allow_uncertified=True,
                                  variants=["tube_mpc"])  # fmt: skip
    plant = overrides(values[0], design, "tube_mpc")["plant"]
    assert plant["servo_omega_n_factor"] == values[0]["actuators.omega_n"]
    assert plant["sensor_bias_mean_shift"] == values[0]["sensors.bias_mean"]
    assert plant["sensor_seed"] == values[0]["sensor_seed"]


def test_a_copied_campaign_file_runs_sized_from_the_command_line(tmp_path, monkeypatch, capsys):
    """A shipped campaign copied elsewhere finds its scenario by name, started from another
    folder too (the project's scenarios); --runs and --duration size it without editing
    it, into a folder named with its size."""
    from fahv.cli import campaign as cli
    from fahv.sil.workspace import ROOT

    copy = tmp_path / "elsewhere" / "case1.yaml"
    copy.parent.mkdir()
    copy.write_text((ROOT / "offline_design" / "campaigns" / "case1.yaml").read_text())
    seen = {}

    def capture(campaign, out, **_):
        seen.update(campaign=campaign, out=out)
        raise CampaignError("stopped by the test")

    monkeypatch.setattr(cli, "run_campaign", capture)
    monkeypatch.chdir(copy.parent)  # no offline_design/ here
    assert main(["campaign", str(copy), "--runs", "20", "--duration", "60"]) == 2
    c = seen["campaign"]
    assert (c.data["runs"], c.data["duration"]) == (20, 60.0)
    assert Path(c.run_spec.path).resolve() == (ROOT / "offline_design" / "scenarios"
                                               / "case1.yaml").resolve()  # fmt: skip
    assert seen["out"].name == "case1-20runs-60s"
    assert "campaign case1: 20 draws x 1 variant(s), runs of 60 s" in capsys.readouterr().err
    with pytest.raises(CampaignError, match="'runs' must be in"):
        load_campaign(copy, runs=0)
