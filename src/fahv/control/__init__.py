"""Control laws behind one interface (:class:`fahv.control.base.ControlLaw`).

The registry entries of the built-in laws are the imports below: a new law is its
module plus one line here.
"""

# isort: off
from fahv.control import tube_mpc  # noqa: F401  (registry entry)
from fahv.control import rmpc  # noqa: F401  (registry entry)

# isort: on
from fahv.control.base import LAWS, VARIANTS, ControlLaw, Variant, law_of, register_law

__all__ = ["LAWS", "VARIANTS", "ControlLaw", "Variant", "law_of", "register_law"]
