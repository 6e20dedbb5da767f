"""The configuration language: ranges, defaults, conditional keys, flat parameters."""

import math

import numpy as np
import pytest

from fahv.config import Check, Field, Registry, Section, validate
from fahv.config.spec import markdown, validate_flat
from fahv.errors import ConfigError

SPEC = Section(
    "",
    (
        Field("Ts", "float", "period", unit="s", lo=0.0, hi=0.1, lo_open=True),
        Field("n", "int", "count", lo=1, default=3),
        Field("mode", "str", "mode", choices=("a", "b")),
        Section(
            "extra",
            (Field("gain", "float", "gain", lo=0.0),),
            when=lambda r: r["mode"] == "b",
            when_text="mode is b",
        ),
        Section("knobs", (Field("seed", "int", "seed", default=0),)),
    ),
    checks=(Check("n", lambda r: r["n"] * r["Ts"] <= 1.0, "must satisfy n Ts <= 1 s"),),
)


def test_defaults_filled_and_reported():
    v = validate(SPEC, {"Ts": 0.02, "mode": "a"}, "f.yaml")
    assert v.values == {"Ts": 0.02, "n": 3, "mode": "a", "knobs": {"seed": 0}}
    assert v.defaults_used == {"n": 3, "knobs.seed": 0}


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"Ts": 0.0, "mode": "a"}, r"f.yaml: key 'Ts' must be in \(0, 0.1\] s, got 0.0"),
        ({"Ts": 0.2, "mode": "a"}, r"key 'Ts' must be in \(0, 0.1\]"),
        ({"Ts": math.nan, "mode": "a"}, "key 'Ts' must be finite"),
        ({"mode": "a"}, "missing key 'Ts'"),
        ({"Ts": 0.02, "mode": "c"}, r"key 'mode' must be one of \('a', 'b'\)"),
        ({"Ts": 0.02, "mode": "a", "x": 1}, "unknown key 'x'"),
        ({"Ts": 0.02, "mode": "b"}, r"missing section 'extra' \(required when mode is b\)"),
        ({"Ts": 0.02, "mode": "b", "extra": {"gain": -1.0}}, "key 'extra.gain' must be in"),
        ({"Ts": 0.02, "mode": "a", "knobs": {"sed": 1}}, "unknown key 'knobs.sed'"),
        ({"Ts": 0.02, "mode": "a", "n": True}, "key 'n' must be int"),
        ({"Ts": 0.1, "mode": "a", "n": 20}, "key 'n' must satisfy n Ts <= 1 s, got 20"),
    ],
)
def test_errors_name_file_and_dotted_key(data, message):
    with pytest.raises(ConfigError, match=message):
        validate(SPEC, data, "f.yaml")


def test_conditional_section_accepted_when_unused():
    v = validate(SPEC, {"Ts": 0.02, "mode": "a", "extra": {"gain": 2.0}}, "f.yaml")
    assert v.values["extra"] == {"gain": 2.0}


def test_flat_parameters_and_matrices():
    fields = (
        Field("Ts", "float", "period", lo=0.0, hi=0.1, lo_open=True),
        Field("F", "matrix", "gain"),
        Field("k", "int", "only for law x", when=lambda p: p.get("law") == "x"),
    )
    out = validate_flat(fields, {"Ts": 0.02, "F": [1.0, 2.0, 3.0, 4.0], "F_shape": [2, 2]}, "node")
    np.testing.assert_array_equal(out["F"], [[1.0, 2.0], [3.0, 4.0]])
    assert "k" not in out
    with pytest.raises(ConfigError, match="node: parameter 'F' has a non-finite value at index 1"):
        validate_flat(fields, {"Ts": 0.02, "F": [1.0, math.inf], "F_shape": [2]}, "node")
    with pytest.raises(ConfigError, match="node: parameter 'k' is missing"):
        validate_flat(fields, {"Ts": 0.02, "F": [1.0], "F_shape": [1], "law": "x"}, "node")


def test_markdown_table_lists_every_key():
    text = markdown(SPEC)
    for key in ("`Ts`", "`n`", "`extra.gain`", "`knobs.seed`"):
        assert key in text
    assert "required when mode is b" in text


def test_registry():
    r = Registry("thing")
    r.register("a", 1)
    with pytest.raises(ConfigError, match="thing 'a' is registered already"):
        r.register("a", 2)
    with pytest.raises(ConfigError, match="unknown thing 'b'; registered: a"):
        r["b"]
    assert r.names() == ("a",)
