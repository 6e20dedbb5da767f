"""One coverage verdict per run: "certified", or "not certified" with its reasons.

A run is certified when its design's certificate covers everything the run asks:
`coverage` checks the run spec against the stored design and returns a
`Coverage`, whose `Coverage.text` is the line `fahv simulate` and `fahv
sil` print, the run file's metadata `coverage` holds and a campaign's report counts.

Its reasons come in two kinds. **Refused** (`Coverage.refused`): what lies beyond
the ranges the design states for its steady flight, the reasons of
`fahv.spec.scenario.uncertified` (an initial point or command outside the nominal
range or the envelope, a trim input outside the tightened input set, a loss beyond the
design's fault range, a vehicle draw beyond its parameter box); a scenario is refused
with them unless `--allow-uncertified`. **Run** (`Coverage.run_anyway`): what
the design's certificate does not claim, so no range can be stretched to hold it: a
fault kind outside the kinds it names, the onset of a loss larger than the certified
onset loss (`certificate.onset.certified_loss`), the onset of a bias (the onset
lines bound losses only), a design whose own certificate does not close.

A fault whose onset lies at or after the end of the run never acts: it adds no reason.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

from fahv.model.vehicle import load_vehicle
from fahv.spec.artefacts import Design
from fahv.spec.scenario import uncertified

#: The verdict of a run its design certifies.
CERTIFIED = "certified"
#: Prefix of the verdict of a run its design does not certify (reasons follow).
NOT_CERTIFIED = "not certified: "
#: Fault kinds a design's certificate names: no fault, a loss of effectiveness with
#: rho_f in [tube.rho_min, 1] (eq. 15), an elevator bias constant after its onset.
COVERED_KINDS = ("none", "loss_of_effectiveness", "bias")


@dataclass(frozen=True)
class Coverage:
    """What a run asks beyond its design's certificate.

    Attributes
    ----------
    refused : tuple of str
        Beyond the design's stated ranges (`fahv.spec.scenario.uncertified`): a
        scenario with such a reason is refused unless `--allow-uncertified`.
        The sentences name the range.
    run_anyway : tuple of str
        Outside what the certificate claims (fault kind, onset, an open certificate):
        such a run runs, with its verdict.
    until : float or None
        When the only reasons are the fault's onset (a loss above the certified onset
        loss, a bias): its onset time [s], before which the certificate covers the run
        (the plant has no fault yet). None otherwise.
    """

    refused: tuple[str, ...] = ()
    run_anyway: tuple[str, ...] = ()
    until: float | None = None

    @property
    def certified(self) -> bool:
        """True when the design certifies everything the run asks."""
        return not (self.refused or self.run_anyway)

    @property
    def reasons(self) -> tuple[str, ...]:
        """Every reason, the refused ones first."""
        return self.refused + self.run_anyway

    def text(self) -> str:
        """`certified` or `not certified: <reason>; <reason> ...` (stored, counted)."""
        return CERTIFIED if self.certified else NOT_CERTIFIED + "; ".join(self.reasons)

    def describe(self) -> str:
        """The coverage line a run prints: which part of the run the certificate covers.

        `certified: the certificate covers the whole run`, `certified up to the fault's
        onset at t = 100 s, not after it: <reasons>`, or `not certified: <reasons>`.
        """
        if self.certified:
            return f"{CERTIFIED}: the certificate covers the whole run"
        if self.until is not None:
            return (f"{CERTIFIED} up to the fault's onset at t = {self.until:g} s, not after "
                    f"it: {'; '.join(self.reasons)}")  # fmt: skip
        return self.text()


def is_certified(text: str | None) -> bool | None:
    """Whether a stored verdict (`Coverage.text`) is `certified`; None if absent."""
    if not text:
        return None
    return text == CERTIFIED


def percent(fraction: float) -> str:
    """A fraction as a percentage to two decimals, trailing zeros dropped (0.1 -> `10`)."""
    return f"{round(100.0 * fraction, 2):g}"


def certified_onset_loss(design: Design) -> float:
    """Largest loss whose onset the design certifies, as a fraction (0 when none is).

    `certificate.onset.certified_loss` of the design's summary (the eight-state tube's
    onset lines: 8.07 % for `cm_certified`); a design without onset lines certifies
    no onset.
    """
    onset = (design.summary.get("certificate") or {}).get("onset") or {}
    return float(onset.get("certified_loss", 0.0))


def acting_fault(fault: dict, duration: float) -> dict:
    """The fault a run meets: `fault`, or no fault when its onset is at or after the end.

    Parameters
    ----------
    fault : dict
        The run's fault: `kind`, `t_onset` [s] and the kind's parameters.
    duration : float
        Simulated time of the run [s].

    Returns
    -------
    dict
        `fault` itself, or `{"kind": "none", "t_onset": inf}`.
    """
    if fault["kind"] != "none" and float(fault.get("t_onset", math.inf)) >= duration:
        return {"kind": "none", "t_onset": math.inf}
    return fault


def fault_reasons(design: Design, fault: dict) -> list[str]:
    """Why a run's fault lies outside the certificate (kind, onset), one sentence each.

    Parameters
    ----------
    design : Design
        The stored design (its summary's onset lines).
    fault : dict
        The fault the run meets (`acting_fault`): `kind`, `t_onset` [s] and
        the kind's parameters.

    Returns
    -------
    list of str
        Empty for no fault or one the certificate covers. The steady loss is
        `fahv.spec.scenario.uncertified`'s.
    """
    kind = fault["kind"]
    if kind == "none":
        return []
    if kind not in COVERED_KINDS:
        return [f"fault kind {kind} outside the design's fault kinds ({', '.join(COVERED_KINDS)})"]
    if kind == "loss_of_effectiveness":
        loss, cert = 1.0 - float(fault["rho_f"]), certified_onset_loss(design)
        if loss > cert + 1e-12:
            return [f"onset loss {percent(loss)} % above the certified {percent(cert)} %"]
    if kind == "bias" and float(fault.get("bias_deg", 0.0)) != 0.0:
        return [
            f"onset of a {float(fault['bias_deg']):g} deg bias (the onset lines certify "
            "losses only)"
        ]
    return []


def design_reasons(design: Design) -> list[str]:
    """Why the design's own certificate does not hold: W not closed over its domain.

    `certificate.certified` (or `closed`) of the design's summary, False for the
    paper's vertex designs, whose W is exceeded over the domain or not checked there.
    """
    cert = design.summary.get("certificate") or {}
    if cert.get("certified", cert.get("closed")) is False:
        name = design.summary.get("design_name", "")
        return [f"design {name}: W is not shown to bound the disturbance over its domain"]
    return []


@functools.lru_cache(maxsize=4)
def _vehicle(path: str):
    return load_vehicle(path or None)


def coverage(design: Design, spec: dict, vehicle=None, duration: float | None = None) -> Coverage:
    """The coverage verdict of a run: what its design certifies of it.

    Parameters
    ----------
    design : Design
        The stored design, or a run's design (the stored one with a scenario's arrays).
    spec : dict
        The run spec's data (`command`, `fault`, `uncertainty`, `duration`), with
        a campaign run's dispersed values (`fahv.loop.params.case_with`).
    vehicle : fahv.model.vehicle.Vehicle, optional
        The nominal vehicle (default: the design's vehicle file).
    duration : float, optional
        Simulated time [s] (default: the run spec's).

    Returns
    -------
    Coverage

    Raises
    ------
    KeyError
        If the design lacks the arrays or summary entries a certificate records.
    """
    if vehicle is None:
        vehicle = _vehicle(design.summary.get("provenance", {}).get("vehicle_file", ""))
    d = float(spec["duration"] if duration is None else duration)
    spec = {**spec, "fault": acting_fault(spec["fault"], d)}
    refused = uncertified(design, spec, vehicle)
    own, onset = design_reasons(design), fault_reasons(design, spec["fault"])
    until = None  # before a covered kind's onset the plant has no fault yet
    if onset and not (refused or own) and spec["fault"]["kind"] in COVERED_KINDS:
        until = float(spec["fault"]["t_onset"])
    return Coverage(tuple(refused), tuple(own + onset), until)
