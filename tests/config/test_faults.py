"""The base of the fault kinds: lanes, parameter checks naming the kind, stack, registry."""

import math
import re

import numpy as np
import pytest

from fahv.config import Field
from fahv.config.faults import FaultRegistry, LaneFault
from fahv.errors import ConfigError

KINDS: FaultRegistry = FaultRegistry("test fault kind")


@KINDS.add
class Gain(LaneFault):
    """A test kind: a required gain and an optional offset."""

    name = "gain"
    what = "test fault kind"
    parameters = (
        Field("k", "float", "gain"),
        Field("offset", "float", "offset", default=0.5),
    )

    def __init__(self, t_onset=math.inf, tag="a", **params) -> None:
        self.tag = tag
        super().__init__(t_onset, **params)
        self.check("k", self.params["k"] > 0.0, "> 0")

    def shared(self):
        return {"tag": self.tag}


def test_lanes_defaults_and_scalars_for_every_lane():
    f = Gain([1.0, 2.0, 3.0], k=2.0)
    assert f.lanes == 3 and f.kind == "gain"
    np.testing.assert_array_equal(f.params["k"], [2.0, 2.0, 2.0])
    np.testing.assert_array_equal(f.params["offset"], [0.5, 0.5, 0.5])
    np.testing.assert_array_equal(f.active(2.0), [True, True, False])
    s = Gain.stack([f, Gain(4.0, tag="a", k=3.0, offset=1.0)])
    assert s.tag == "a" and s.lanes == 4
    np.testing.assert_array_equal(s.params["k"], [2.0, 2.0, 2.0, 3.0])
    np.testing.assert_array_equal(s.t_onset, [1.0, 2.0, 3.0, 4.0])


def test_errors_name_the_kind_and_the_parameter():
    cases = [
        (lambda: Gain(1.0), "test fault kind 'gain' needs parameter(s) ['k']"),
        (lambda: Gain([1.0, 2.0], k=[1.0, 2.0, 3.0]), "parameters ['k'] do not have 2 lanes"),
        (lambda: Gain(1.0, k="x"), "'gain': parameter 'k' must be a number"),
        (lambda: Gain([1.0, 2.0], k=[1.0, -1.0]), "parameter 'k' must be > 0, got [1.0, -1.0]"),
        (lambda: KINDS.make("melted", 0.0, {}), "unknown test fault kind 'melted'"),
    ]
    for make, text in cases:
        with pytest.raises(ConfigError, match=re.escape(text)):
            make()


def test_the_registry_makes_faults_and_declares_their_parameters():
    f = KINDS.make("gain", 1.0, {"k": 2.0, "other": 1.0}, tag="b")
    assert isinstance(f, Gain) and f.tag == "b"
    fields = KINDS.fields(lambda root: root.get("kind"))
    assert [g.name for g in fields] == ["k", "offset"]
    assert fields[0].when({"kind": "gain"}) and not fields[0].when({"kind": "none"})
    assert fields[0].when_text == "kind is gain"
