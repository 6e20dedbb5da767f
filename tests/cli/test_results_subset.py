"""`fahv results --check/--write-reference` on some of the reference's cases: the cases
run are checked (the others are named, not failed), and writing a reference replaces
only the cases run. The designs and runs are stubbed: this tests the bookkeeping."""

import json
from types import SimpleNamespace

import pytest

from fahv.cli import main


@pytest.fixture
def stub_cases(monkeypatch):
    """Case files a.yaml and b.yaml whose one variant has a settling time of 10 / 20 s."""
    import fahv.cli.run as run
    import fahv.runs.results as results

    values = {"a": 10.0, "b": 20.0}

    class Case(dict):
        def __init__(self, name):
            super().__init__(variants=["tube_mpc"])
            self.name = name

    monkeypatch.setattr(
        run, "load_or_design",
        lambda path, _o, _v, allow_uncertified=False: (Case(path.removesuffix(".yaml")),
                              SimpleNamespace(summary={"design_hash": "x"},
                                              name=path.removesuffix(".yaml")),
                              SimpleNamespace(limits=None)),
    )  # fmt: skip

    def run_case(design, variants, limits, log):
        return {"tube_mpc": {"settling_time_h_s": values[design.name]}}

    monkeypatch.setattr(results, "run_case", run_case)
    monkeypatch.setattr(results, "markdown_table", lambda res: "table")
    return values


def test_a_subset_is_checked_and_written_without_losing_the_other_cases(
    stub_cases, tmp_path, capsys
):
    ref = tmp_path / "ref.json"
    assert main(["results", "--cases", "a.yaml", "b.yaml", "--write-reference", str(ref)]) == 0
    assert set(json.loads(ref.read_text())) == {"a", "b"}
    capsys.readouterr()
    # only a is run: a is checked, b is named as not run, and the check passes
    assert main(["results", "--cases", "a.yaml", "--check", str(ref)]) == 0
    out = capsys.readouterr().out
    assert "not run, not checked: b" in out and "within the tolerances (a)" in out
    # a changes by more than one step: the check fails and names it
    stub_cases["a"] = 10.5
    assert main(["results", "--cases", "a.yaml", "--check", str(ref)]) == 1
    assert "differs: a tube_mpc settling_time_h_s" in capsys.readouterr().out
    # writing a alone replaces a and keeps b
    assert main(["results", "--cases", "a.yaml", "--write-reference", str(ref)]) == 0
    assert "kept from it, not run: b" in capsys.readouterr().out
    got = json.loads(ref.read_text())
    assert got["a"]["tube_mpc"]["settling_time_h_s"] == 10.5
    assert got["b"]["tube_mpc"]["settling_time_h_s"] == 20.0
    assert not list(tmp_path.glob("*.part"))
    # no case of the reference run: an error, not a pass
    other = tmp_path / "other.json"
    other.write_text(json.dumps({"c": {"tube_mpc": {"settling_time_h_s": 1.0}}}))
    assert main(["results", "--cases", "a.yaml", "--check", str(other)]) == 1
    assert "none of the cases run is in the reference" in capsys.readouterr().err
