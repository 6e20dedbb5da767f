"""One re-checked certificate: its name, whether it holds, its margin and its line."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class CheckResult:
    """One re-checked certificate.

    Attributes
    ----------
    name : str
        Which certificate (`model`, `tightening`, `tube RPI`, ...).
    ok : bool
        True if it holds.
    margin : float
        Distance to its bound in the check's own unit (negative: violated).
    line : str
        What was checked, the value, the bound and the margin.
    """

    name: str
    ok: bool
    margin: float
    line: str

    def text(self) -> str:
        """The printed line: `name: line  OK` or `... FAILED`."""
        return f"{self.name}: {self.line}  {'OK' if self.ok else 'FAILED'}"
