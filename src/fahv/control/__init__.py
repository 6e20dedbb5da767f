"""Control laws and their nominal parts behind one interface each (:mod:`fahv.control.base`).

The registry entries of the built-in laws and nominal parts are the imports below: a
new law is its module plus one line here (and, if it brings its own nominal part, that
module and one line more).
"""

# isort: off
from fahv.control import reference  # noqa: F401  (registry entries: governor, command)
from fahv.control import nominal_mpc  # noqa: F401  (registry entry: mpc)
from fahv.control import tube_mpc  # noqa: F401  (registry entries)
from fahv.control import rmpc  # noqa: F401  (registry entry)

# isort: on
from fahv.control.base import (
    LAWS,
    NOMINAL_SOURCES,
    VARIANTS,
    ControlLaw,
    LawStep,
    NominalSource,
    Variant,
    law_of,
    register_law,
    register_nominal,
)

__all__ = [
    "LAWS",
    "NOMINAL_SOURCES",
    "VARIANTS",
    "ControlLaw",
    "LawStep",
    "NominalSource",
    "Variant",
    "law_of",
    "register_law",
    "register_nominal",
]
