"""`extends:`: a scenario or campaign file that states only how it differs from another
merges and validates exactly like the whole file; its errors name it; every study file of
`studies/` loads and each study scenario flies."""

from pathlib import Path

import pytest
import yaml

from fahv.campaign.spec import load_campaign
from fahv.certificate.verified import load_or_design
from fahv.config.extends import merged
from fahv.errors import CampaignError, SpecError
from fahv.loop.simulate import simulate
from fahv.sil.workspace import ROOT
from fahv.spec.scenario import load_scenario

SCENARIOS = ROOT / "offline_design" / "scenarios"
STUDIES = ROOT / "studies"


def write(path: Path, data: dict) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def test_an_extending_scenario_is_the_whole_file_it_stands_for(tmp_path):
    """case1_implementable with the nominal's estimate at 5 s and a bias instead of the loss:
    the extending file's run spec equals that of the edited whole file, key for key."""
    whole = yaml.safe_load((SCENARIOS / "case1_implementable.yaml").read_text())
    whole["name"] = "edited"
    whole["estimator"]["nominal_est_tau"] = 5.0
    whole["fault"] = {"kind": "bias", "t_onset": 50.0, "bias_deg": 1.0}
    a = load_scenario(write(tmp_path / "scenarios" / "whole.yaml", whole)).run_spec.data
    ext = {"extends": str(SCENARIOS / "case1_implementable.yaml"), "name": "edited",
           "estimator": {"nominal_est_tau": 5.0},
           "fault": {"kind": "bias", "t_onset": 50.0, "bias_deg": 1.0}}  # fmt: skip
    b = load_scenario(write(tmp_path / "scenarios" / "ext.yaml", ext)).run_spec.data
    assert a == b
    assert b["fault"] == {"kind": "bias", "t_onset": 50.0, "bias_deg": 1.0}  # no rho_f left


def test_a_base_by_name_a_chain_and_the_file_name_as_default_name(tmp_path):
    first = write(tmp_path / "scenarios" / "first.yaml",
                  {"extends": "case1", "duration": 60.0})  # fmt: skip
    second = write(tmp_path / "scenarios" / "second.yaml",
                   {"extends": "first", "fault": {"rho_f": 0.95}})  # fmt: skip
    s = load_scenario(second)
    assert s.data["name"] == "second" and s.data["duration"] == 60.0
    assert s.data["fault"]["rho_f"] == 0.95 and s.data["fault"]["t_onset"] == 100.0
    assert load_scenario(first).data["fault"]["rho_f"] == 0.9


@pytest.mark.parametrize("extra, match", [
    ({"fault": {"rho_f": 1.5}}, r"ext\.yaml: key 'fault\.rho_f' must be in"),
    ({"nonsense": 1}, r"ext\.yaml: unknown key 'nonsense'"),
    ({"extends": 3}, r"key 'extends' must be a file name or path, got 3"),
    ({"extends": "no_such_scenario"}, r"key 'extends': no file 'no_such_scenario' \(looked for"),
])  # fmt: skip
def test_errors_name_the_extending_file_and_the_key(tmp_path, extra, match):
    data = {"extends": "case1", **extra}
    with pytest.raises(SpecError, match=match):
        load_scenario(write(tmp_path / "scenarios" / "ext.yaml", data))


def test_a_cycle_is_refused_naming_the_files(tmp_path):
    write(tmp_path / "scenarios" / "a.yaml", {"extends": "b"})
    write(tmp_path / "scenarios" / "b.yaml", {"extends": "a"})
    with pytest.raises(SpecError, match=r"key 'extends' makes a cycle: .*a\.yaml -> .*b\.yaml"
                                        r" -> .*a\.yaml"):  # fmt: skip
        load_scenario(tmp_path / "scenarios" / "a.yaml")


def test_an_extending_campaign_turns_a_dispersion_off_with_an_empty_range(tmp_path):
    base = ROOT / "offline_design" / "campaigns" / "case2.yaml"
    path = write(tmp_path / "campaigns" / "calm.yaml",
                 {"extends": str(base), "runs": 5,
                  "dispersions": {"command": {"dh": [], "dV": []}}})  # fmt: skip
    c = load_campaign(path)
    whole = load_campaign(base)
    assert c.data["runs"] == 5 and c.name == "calm"
    assert c.data["dispersions"]["command"] == {"dh": [], "dV": []}
    assert c.data["dispersions"]["fault"] == whole.data["dispersions"]["fault"]
    assert c.run_spec.data == whole.run_spec.data  # the base's scenario, by its own path
    with pytest.raises(CampaignError, match="calm.yaml: key 'runs' must be in"):
        load_campaign(write(path, {"extends": str(base), "runs": 0}))


def test_merging_replaces_a_section_of_another_kind_and_merges_one_of_the_same():
    base = {"fault": {"kind": "loss", "rho_f": 0.9, "t_onset": 100.0}, "variants": ["a", "b"]}
    assert merged(base, {"fault": {"t_onset": 5.0}})["fault"] == {
        "kind": "loss", "rho_f": 0.9, "t_onset": 5.0}
    assert merged(base, {"fault": {"kind": "stuck", "t_onset": 5.0}})["fault"] == {
        "kind": "stuck", "t_onset": 5.0}
    assert merged(base, {"variants": ["c"]})["variants"] == ["c"]  # a list replaces


STUDY_SCENARIOS = sorted(STUDIES.rglob("scenarios/*.yaml"))
STUDY_CAMPAIGNS = sorted(STUDIES.rglob("campaigns/*.yaml"))


def test_every_study_file_is_short_and_extends_a_product_file():
    assert len(list((ROOT / "offline_design" / "scenarios").glob("*.yaml"))) <= 6
    assert len(list((ROOT / "offline_design" / "campaigns").glob("*.yaml"))) <= 4
    assert len(STUDY_SCENARIOS) >= 7 and len(STUDY_CAMPAIGNS) >= 7
    for path in STUDY_SCENARIOS + STUDY_CAMPAIGNS:
        lines = path.read_text().splitlines()
        assert len(lines) <= 15, path
        assert lines[0].startswith("extends: "), path


@pytest.mark.parametrize("path", STUDY_CAMPAIGNS, ids=lambda p: p.stem)
def test_every_study_campaign_loads(path):
    c = load_campaign(path)
    assert c.name == path.stem and c.data["runs"] >= 1


@pytest.mark.parametrize("path", STUDY_SCENARIOS, ids=lambda p: p.stem)
def test_every_study_scenario_flies(path):
    """Each study scenario on its shipped design, its first variant, ten steps."""
    spec, design, _ = load_or_design(str(path), log=lambda *_: None, allow_uncertified=True,
                                     variants=None)  # fmt: skip
    variant = spec["variants"][0]
    run = simulate(design, variant, 0.2)
    assert run.t.size == 10 and spec.name == path.stem


def test_an_extending_design_file_is_the_whole_file_it_stands_for(tmp_path):
    """A design file that extends the certified design by name validates as the merged
    file would, with its own entries in place; an estimate section gets its defaults, and
    a bad value in it is refused naming the extending file and the key."""
    from fahv.spec.files import load_design_file, spec_file
    from fahv.spec.schema import design_spec

    base = ROOT / "offline_design" / "designs" / "cm_certified.yaml"
    text = ("extends: " + str(base) + "\nname: cm_on_estimate\ntube: {tau: 0.5}\n"
            "estimate: {probability: 0.95}\n")  # fmt: skip
    (tmp_path / "d.yaml").write_text(text)
    got = load_design_file(tmp_path / "d.yaml")
    whole = yaml.safe_load(base.read_text())
    whole["name"], whole["tube"]["tau"] = "cm_on_estimate", 0.5
    whole["estimate"] = {"probability": 0.95}
    assert got.data == spec_file(whole, "whole", design_spec()).data
    assert got.data["estimate"]["duration"] == 300.0
    assert got.data["estimate"]["tau_candidates"] == [] and got.data["estimate"]["claims"] == [
        "attitude", "elevator_rate"]
    assert got.data["eight_state"]["attitude"] == 0.4  # the base's, untouched
    (tmp_path / "bad.yaml").write_text(text.replace("0.95", "1.5"))
    with pytest.raises(SpecError, match=r"bad\.yaml.*estimate\.probability"):
        load_design_file(tmp_path / "bad.yaml")
