"""The search space of a clearance: a campaign's dispersions as a box of real variables.

Every value a campaign draws at random (`fahv.campaign.draws`) is a variable of the
search with the campaign's range as its bounds: the uncertain parameters' s_p in
[-1, 1], the fault's onset, loss and bias, the initial trim, the command's steps, the
servo and sensor factors. Values the campaign does not range keep the scenario's. A
choice among several fault kinds, or among the campaign's first K sensor-noise seeds, is
a variable over [0, K) read by its integer part: the optimiser moves it like any other,
and a point names one kind and one seed. Otherwise the sensor noise is held fixed at one
seed (the campaign's run 0 by default). A point maps to the values of a run in the form
`fahv.campaign.draws.draw` gives them (`SearchSpace.values`), so a searched run is a
campaign run at other values, through the same overrides and simulator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from fahv.campaign.draws import (
    HARDWARE,
    dispersed_groups,
    fault_kinds,
    point_defaults,
    run_seed,
    values_at,
)
from fahv.errors import CampaignError
from fahv.sensors.data import EXACT_STATE
from fahv.spec.schema import plant_choices

#: Unit of each variable of a point (`fahv.campaign.draws.point_defaults`' keys).
UNITS = {"fault.t_onset": "s", "fault.loss": "-", "fault.bias_deg": "deg", "initial.h0": "ft",
         "initial.V0": "ft/s", "command.dh": "ft", "command.dV": "ft/s",
         "sensors.bias_mean": "stddevs"}  # fmt: skip


@dataclass(frozen=True)
class Variable:
    """One searched value.

    Attributes
    ----------
    name : str
        Its key in a point (`s.m`, `fault.loss`, `actuators.omega_n`, ...; `noise` for
        the choice of sensor-noise seed).
    lo, hi : float
        Bounds [unit].
    unit : str
    choices : tuple
        For a choice (fault kind, noise seed): the options, the variable's integer part
        indexing them over [0, len(choices)); empty for a real value.
    """

    name: str
    lo: float
    hi: float
    unit: str = "-"
    choices: tuple = ()

    def read(self, x: float):
        """The value at x: x itself, or the choice its integer part indexes."""
        if not self.choices:
            return float(x)
        return self.choices[min(int(math.floor(x)), len(self.choices) - 1)]


@dataclass(frozen=True)
class SearchSpace:
    """A campaign's dispersion space as a box (`Variable` bounds) and its map to run values.

    Build it with `SearchSpace.of`. Attributes: `data` (validated campaign), `case`
    (its scenario's data), `variables`, `fixed` (the values every point shares: the
    sensor-noise seed when held fixed).
    """

    data: dict
    case: dict
    variables: tuple[Variable, ...]
    fixed: dict

    @classmethod
    def of(cls, data: dict, case: dict, noise_seeds: int = 0, noise_seed: int | None = None):
        """The search space of a validated campaign `data` on its scenario data `case`.

        Parameters
        ----------
        noise_seeds : int
            Search the sensor noise over the campaign's first `noise_seeds` runs' seeds
            (0: hold it fixed).
        noise_seed : int, optional
            The fixed seed of the sensor noise (default: the campaign's run 0's).

        Raises
        ------
        CampaignError
            If the campaign ranges nothing (no variable to search), naming the section.
        """
        d, seed = data["dispersions"], data["seed"]
        groups = dispersed_groups(data)
        out: list[Variable] = []
        if "uncertainty" in groups:
            out += [Variable(f"s.{p}", -1.0, 1.0) for p in d["uncertainty"]["parameters"]]
        if "fault" in groups:
            kinds = fault_kinds(data, case)
            if len(kinds) > 1:
                out.append(Variable("fault.kind", 0.0, float(len(kinds)), choices=tuple(kinds)))
            for key, name in (("onset", "fault.t_onset"), ("loss", "fault.loss"),
                              ("bias_deg", "fault.bias_deg")):  # fmt: skip
                if d["fault"][key]:
                    out.append(Variable(name, *map(float, d["fault"][key]), UNITS[name]))
        for group, keys in (("initial", ("h0", "V0")), ("command", ("dh", "dV")),
                            *((g, tuple(k)) for g, k in HARDWARE.items())):  # fmt: skip
            for k in keys:
                if group in groups and d[group][k]:
                    name = f"{group}.{k}"
                    out.append(Variable(name, *map(float, d[group][k]), UNITS.get(name, "-")))
        fixed: dict = {}
        if plant_choices(case)["measured"] != EXACT_STATE:
            if noise_seeds > 0:
                seeds = tuple(run_seed(seed, i) for i in range(int(noise_seeds)))
                out.append(Variable("noise", 0.0, float(len(seeds)), choices=seeds))
            else:
                fixed["sensor_seed"] = run_seed(seed, 0) if noise_seed is None else int(noise_seed)
        if not out:
            raise CampaignError(f"campaign {data['name']}: its dispersions range nothing to "
                                "search (dispersions: uncertainty, fault, initial, command, "
                                "actuators, sensors)")  # fmt: skip
        return cls(data, case, tuple(out), fixed)

    def within(self, name: str, hi: float) -> SearchSpace:
        """The space with variable `name`'s upper bound lowered to `hi` (absent: as it is).

        Raises
        ------
        CampaignError
            If `hi` is at or below the variable's lower bound (nothing left to search).
        """
        out = []
        for v in self.variables:
            if v.name == name and hi < v.hi:
                if hi <= v.lo:
                    raise CampaignError(f"{name}: nothing left to search below {hi:g} "
                                        f"(the campaign's range starts at {v.lo:g})")  # fmt: skip
                v = replace(v, hi=float(hi))
            out.append(v)
        return replace(self, variables=tuple(out))

    @property
    def names(self) -> list[str]:
        """Variable names in search order."""
        return [v.name for v in self.variables]

    @property
    def bounds(self) -> list[tuple[float, float]]:
        """(lo, hi) of every variable, the optimiser's box."""
        return [(v.lo, v.hi) for v in self.variables]

    def values(self, x) -> dict:
        """The run's dispersed values at the point x (d,) (`fahv.campaign.draws.draw`'s form).

        Raises
        ------
        ValueError
            If x has not one finite value per variable inside its bounds.
        """
        x = np.asarray(x, dtype=float)
        if x.shape != (len(self.variables),) or not np.all(np.isfinite(x)):
            raise ValueError(f"a point has {len(self.variables)} finite values "
                             f"({', '.join(self.names)}), got {x!r}")  # fmt: skip
        lo, hi = np.array(self.bounds).T
        if np.any(x < lo) or np.any(x > hi):
            raise ValueError(f"point {x!r} outside the search box {self.bounds}")
        groups = dispersed_groups(self.data)
        point = {k: v for k, v in point_defaults(self.data, self.case).items()
                 if k.split(".", 1)[0] in groups}  # fmt: skip
        if "fault" in groups:
            point["fault.kind"] = fault_kinds(self.data, self.case)[0]
        point.update(self.fixed)
        for v, xi in zip(self.variables, x, strict=True):
            point["sensor_seed" if v.name == "noise" else v.name] = v.read(xi)
        return values_at(self.data, self.case, point)
