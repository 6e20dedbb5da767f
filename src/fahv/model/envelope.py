"""The flight envelope Gamma over which the design and the runs are defined (sec. 5.1)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fahv.errors import EnvelopeError


@dataclass(frozen=True)
class Envelope:
    """Flight envelope Gamma = [h_min, h_max] x [V_min, V_max] (ft, ft/s), sec. 5.1.

    Attributes
    ----------
    h_min, h_max : float
        Altitude range [ft].
    V_min, V_max : float
        Speed range [ft/s].

    Examples
    --------
    >>> env = Envelope(85000.0, 86500.0, 7700.0, 8300.0)
    >>> env.contains(85500.0, 7900.0), env.contains(87000.0, 7900.0)
    (True, False)
    >>> env.outside(np.array([84000.0, 85500.0]), np.array([7900.0, 7900.0])).tolist()
    [True, False]
    >>> env.check(87000.0, 7900.0)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
        ...
    fahv.errors.EnvelopeError: flight condition h = 87000.0 ft, V = 7900.0 ft/s lies outside ...
    """

    h_min: float
    h_max: float
    V_min: float
    V_max: float

    def contains(self, h: float, V: float, rtol: float = 1e-12) -> bool:
        """True if (h, V) lies in the closed envelope (relative tolerance `rtol`).

        Parameters
        ----------
        h : float
            Altitude [ft].
        V : float
            Speed [ft/s].
        rtol : float
            Tolerance relative to max(|h_max|, 1) and max(|V_max|, 1).

        Returns
        -------
        bool
            True inside or on the boundary.
        """
        th = rtol * max(abs(self.h_max), 1.0)
        tv = rtol * max(abs(self.V_max), 1.0)
        return (self.h_min - th <= h <= self.h_max + th) and (
            self.V_min - tv <= V <= self.V_max + tv
        )

    def outside(self, h: np.ndarray, V: np.ndarray) -> np.ndarray:
        """Element-wise True where (h [ft], V [ft/s]) lies outside the closed envelope.

        `h` and `V` broadcast together; NaN counts as inside (a non-finite state is
        reported by itself).

        Parameters
        ----------
        h : ndarray
            Altitudes [ft].
        V : ndarray
            Speeds [ft/s].

        Returns
        -------
        ndarray of bool
            Of the broadcast shape of `h` and `V`.
        """
        h, V = np.asarray(h), np.asarray(V)
        return (h < self.h_min) | (h > self.h_max) | (V < self.V_min) | (V > self.V_max)

    def describe(self, t: float, h: float, V: float) -> str:
        """The sentence naming where a run left the envelope.

        Parameters
        ----------
        t : float
            Time of the run [s].
        h : float
            Altitude there [ft].
        V : float
            Speed there [ft/s].

        Returns
        -------
        str
            "left the flight envelope at t = ... (h = ..., V = ...; envelope ...)".
        """
        return (
            f"left the flight envelope at t = {t:.2f} s (h = {h:.1f} ft, V = {V:.1f} ft/s; "
            f"envelope h in [{self.h_min:g}, {self.h_max:g}] ft, "
            f"V in [{self.V_min:g}, {self.V_max:g}] ft/s)"
        )

    def check(self, h: float, V: float) -> None:
        """Raise `EnvelopeError` naming the envelope if (h, V) lies outside it.

        Parameters
        ----------
        h : float
            Altitude [ft].
        V : float
            Speed [ft/s].

        Raises
        ------
        EnvelopeError
            If (h, V) is not finite or lies outside the closed envelope.
        """
        if not (np.isfinite(h) and np.isfinite(V)) or not self.contains(h, V):
            raise EnvelopeError(
                f"flight condition h = {h} ft, V = {V} ft/s lies outside the flight envelope "
                f"h in [{self.h_min}, {self.h_max}] ft, V in [{self.V_min}, {self.V_max}] ft/s"
            )
