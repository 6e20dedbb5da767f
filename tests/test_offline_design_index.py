"""offline_design/README.md is the index `fahv index` generates from the files."""

from pathlib import Path

from fahv.cli.index import index_markdown

ROOT = Path(__file__).resolve().parents[1]


def test_the_committed_index_is_current():
    text = (ROOT / "offline_design" / "README.md").read_text()
    assert text == index_markdown(ROOT / "offline_design"), "run `fahv index --write`"


def test_the_index_lists_every_design_scenario_and_campaign():
    text = index_markdown(ROOT / "offline_design")
    for kind in ("designs", "scenarios", "campaigns"):
        for f in (ROOT / "offline_design" / kind).glob("*.yaml"):
            assert f"| `{f.stem}` |" in text
    assert "not designed" not in text  # every design is shipped with its outputs
