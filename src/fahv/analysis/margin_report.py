"""The margin table of a design (`fahv.analysis.margin_study.MarginStudy`), as text.

`margin_table` lays out one row per loop break, notch setting and point (the
design point, the worst case over the LPV vertices, the parameter box corner of the
most unstable airframe) as plain text or Markdown; `notch_summary` answers what
the notch buys at omega_1 and costs at crossover, against the requirement
`REQUIREMENT` (6 dB gain margin and 45 deg phase margin, both directions).
"""

from __future__ import annotations

import math

from fahv.analysis.margins import LoopMargins

#: The usual flight-control requirement on the lowest-frequency modes: gain margin
#: +-6 dB and phase margin +-45 deg (MIL-F-9490D, sec. 3.1.3.6.1, Table I).
REQUIREMENT = {"gain_db": 6.0, "phase_deg": 45.0}

#: Columns: header, unit.
COLUMNS = (
    ("break", ""),
    ("notch", ""),
    ("point", ""),
    ("GM+", "dB"),
    ("GM-", "dB"),
    ("PM", "deg"),
    ("w_c", "rad/s"),
    ("delay", "ms"),
    ("DM gain", "dB"),
    ("DM phase", "deg"),
    ("|L(w_1)|", "dB"),
)


def _num(x: float, digits: int = 1) -> str:
    """A number for the table: inf as "inf", nan as "-"."""
    if math.isnan(x):
        return "-"
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return f"{x:.{digits}f}"


def row_cells(r: LoopMargins) -> list[str]:
    """The cells of one row (strings, in the order of `COLUMNS`).

    Parameters
    ----------
    r : LoopMargins

    Returns
    -------
    list of str
        An unstable closed loop gives its spectral radius in place of the margins.
    """
    head = [r.break_at, r.notch, r.point]
    if not r.stable:
        return head + [f"unstable (rho = {r.rho:.4f})"] + [""] * 6 + [_num(r.gain_w1_db)]
    return head + [_num(r.gm_up_db), _num(r.gm_down_db), _num(r.pm_deg), _num(r.w_c, 2),
                   _num(r.delay_ms), _num(r.dm_gain_db), _num(r.dm_phase_deg),
                   _num(r.gain_w1_db)]  # fmt: skip


def margin_table(rows: list[LoopMargins], markdown: bool = False) -> str:
    """The rows as an aligned text table, or a Markdown table.

    Parameters
    ----------
    rows : list of LoopMargins
    markdown : bool

    Returns
    -------
    str
        Header and one line per row, no trailing newline.
    """
    head = [f"{h} [{u}]" if u else h for h, u in COLUMNS]
    cells = [row_cells(r) for r in rows]
    if markdown:
        head = [h.replace("|", "\\|") for h in head]  # |L(w_1)| inside a Markdown cell
        lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        return "\n".join(lines + ["| " + " | ".join(c) + " |" for c in cells])
    widths = [max(len(x) for x in col) for col in zip(head, *cells, strict=True)]
    fmt = "  ".join(f"{{:<{w}}}" for w in widths)
    return "\n".join(fmt.format(*c).rstrip() for c in [head, *cells])


def _at(rows, break_at, notch, point="design point"):
    """The row of a break, notch setting and point (None if absent)."""
    return next((r for r in rows if (r.break_at, r.notch, r.point) == (break_at, notch, point)),
                None)  # fmt: skip


def meets(r: LoopMargins) -> bool:
    """True if a stable loop meets `REQUIREMENT` (GM+ >= 6 dB, GM- <= -6 dB, |PM| >= 45).

    Parameters
    ----------
    r : LoopMargins

    Returns
    -------
    bool
    """
    g, p = REQUIREMENT["gain_db"], REQUIREMENT["phase_deg"]
    return r.stable and r.gm_up_db >= g and r.gm_down_db <= -g and abs(r.pm_deg) >= p


def notch_summary(rows: list[LoopMargins], notch: str = "omega_1") -> list[str]:
    """What the notch buys at omega_1 and costs at crossover, at the design point, per break.

    Parameters
    ----------
    rows : list of LoopMargins
        Rows holding the design point of `notch` and of "off".
    notch : str
        The notch setting compared with "off".

    Returns
    -------
    list of str
        One sentence per break that has both rows.
    """
    out = []
    for b in ("delta_e", "q"):
        on, off = _at(rows, b, notch), _at(rows, b, "off")
        if on is None or off is None or not (on.stable and off.stable):
            continue
        out.append(
            f"break at {b}: |L(w_1)| {_num(off.gain_w1_db)} dB without the notch, "
            f"{_num(on.gain_w1_db)} dB with it ({_num(on.gain_w1_db - off.gain_w1_db)} dB); "
            f"phase margin {_num(off.pm_deg)} -> {_num(on.pm_deg)} deg, gain margin "
            f"{_num(off.gm_up_db)} -> {_num(on.gm_up_db)} dB up, {_num(off.gm_down_db)} -> "
            f"{_num(on.gm_down_db)} dB down; 6 dB / 45 deg met: "
            f"{'yes' if meets(off) else 'no'} -> {'yes' if meets(on) else 'no'}"
        )
    return out
