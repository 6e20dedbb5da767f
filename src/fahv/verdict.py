"""How a closed-loop run ends: its verdict, and the step, time and node that set it.

Every run ends with exactly one verdict of `VERDICTS`: `completed` when it flew
its whole duration, otherwise the first condition under which the loop cannot go on,
found by the node whose computation meets it. That node raises `RunEnded`
(through `fahv.lanes.Lanes`, so a campaign batch records it for that run alone);
the in-process simulator, the batch engine and the nodes of the graph turn it into the
run file's metadata (`Verdict.metadata`), the `fahv` exit status and the last
status a node publishes (`Verdict.as_dict`). The checks run inside the loop's
node cores (`fahv.loop.cores`) and the law's nominal part, once per step, so every
path meets the same verdict at the same step.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

from fahv.errors import RunError

#: The verdict of a run that flew its whole duration.
COMPLETED = "completed"
#: Every verdict, with the node that finds it and what it means.
VERDICTS = {
    COMPLETED: ("-", "the run flew its whole duration"),
    "non_finite_state": ("plant", "the vehicle's state is no longer finite"),
    "non_finite_input": ("plant", "an actuator command reaching the plant is not finite"),
    "non_finite_estimate": (
        "state_estimator",
        "the state estimate is no longer finite (a measurement that is not finite, or the "
        "filter diverged)",
    ),
    "nominal_out_of_domain": (
        "nominal_trajectory",
        "the nominal MPC's operating point (the nominal's altitude and speed) left the "
        "trim map it schedules its QP on",
    ),
    "nominal_singular": (
        "nominal_trajectory",
        "the nominal MPC's scheduling problem is singular at the nominal's operating "
        "point (trim-map Jacobian or steady-state equations)",
    ),
}
#: Metadata keys of a verdict in a run file (`Verdict.metadata`).
METADATA_KEYS = ("verdict", "verdict_node", "verdict_step", "verdict_t", "verdict_reason")


@dataclass(frozen=True)
class Verdict:
    """How one run ended.

    Attributes
    ----------
    name : str
        One of `VERDICTS`.
    node : str
        Node (or law part) that found it; `-` for `completed`.
    step : int
        Steps the run flew in full (the step at which it ended; the run's length for
        `completed`).
    t : float
        Simulated time of that step, `step * Ts` [s].
    reason : str
        What was found, with the values that show it.
    """

    name: str
    node: str
    step: int
    t: float
    reason: str = ""

    def __post_init__(self) -> None:
        if self.name not in VERDICTS:
            raise ValueError(f"verdict must be one of {sorted(VERDICTS)}, got {self.name!r}")

    @property
    def completed(self) -> bool:
        """True for `completed`."""
        return self.name == COMPLETED

    def text(self) -> str:
        """One line: `<name> at t = <t> s (step <k>, <node>): <reason>`."""
        if self.completed:
            return f"{COMPLETED} at t = {self.t:.2f} s ({self.step} steps)"
        return f"{self.name} at t = {self.t:.2f} s (step {self.step}, {self.node}): {self.reason}"

    def as_dict(self) -> dict:
        """The fields as a JSON-able dict (a node's last status carries it)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> Verdict:
        """The verdict of `as_dict`.

        Parameters
        ----------
        d : dict
            `name`, `node`, `step`, `t` and optionally `reason`.

        Returns
        -------
        Verdict

        Raises
        ------
        ValueError
            If a key is missing or the name is not a verdict.
        """
        try:
            return cls(str(d["name"]), str(d["node"]), int(d["step"]), float(d["t"]),
                       str(d.get("reason", "")))  # fmt: skip
        except (KeyError, TypeError) as exc:
            raise ValueError(f"verdict {d!r}: missing or malformed field ({exc})") from None

    def metadata(self) -> dict[str, str]:
        """The run-file metadata of the verdict (`METADATA_KEYS`)."""
        values = (self.name, self.node, self.step, f"{self.t:.6g}", self.reason)
        return {k: str(v) for k, v in zip(METADATA_KEYS, values, strict=True)}

    @classmethod
    def from_metadata(cls, meta: dict) -> Verdict | None:
        """The verdict stored in a run's metadata (None for a run file without one).

        Parameters
        ----------
        meta : dict
            Run metadata (string values).

        Returns
        -------
        Verdict or None
        """
        if "verdict" not in meta:
            return None
        return cls(meta["verdict"], meta.get("verdict_node", "-"),
                   int(meta.get("verdict_step", 0)), float(meta.get("verdict_t", "nan")),
                   meta.get("verdict_reason", ""))  # fmt: skip

    @property
    def status(self) -> str:
        """The run file's `status`: `complete`, or `ended: <name>`."""
        return "complete" if self.completed else f"ended: {self.name}"


def completed(n_steps: int, Ts: float) -> Verdict:
    """The verdict of a run that flew its `n_steps` steps of `Ts` [s]."""
    return Verdict(COMPLETED, "-", int(n_steps), n_steps * Ts)


class RunEnded(RunError):
    """A run ended with a verdict other than `completed` (`Verdict`).

    Raised by the node core that finds it; the message is `Verdict.text`.

    Parameters
    ----------
    name : str
        One of `VERDICTS` (not `completed`).
    node : str
        The node (or law part) that found it.
    step : int
        Step at which the run ended.
    t : float
        Simulated time of that step [s].
    reason : str
        What was found, with its values.

    Attributes
    ----------
    verdict : Verdict
    partial : fahv.loop.simulate.RunResult or None
        What the run flew before `step` (set by the simulator and the batch engine).

    Raises
    ------
    ValueError
        If `name` is not a verdict, or is `completed`.
    """

    def __init__(self, name: str, node: str, step: int, t: float, reason: str) -> None:
        if name == COMPLETED:
            raise ValueError("a run that completed did not end early: no RunEnded")
        self.verdict = Verdict(name, node, int(step), float(t), reason)
        self.partial = None
        super().__init__(self.verdict.text())

    @classmethod
    def of(cls, verdict: Verdict) -> RunEnded:
        """The exception of a verdict (a node that learns it from a peer)."""
        return cls(verdict.name, verdict.node, verdict.step, verdict.t, verdict.reason)
