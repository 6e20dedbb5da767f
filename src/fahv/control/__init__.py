"""Control laws and their nominal parts behind one interface each (`fahv.control.base`).

The registry entries of the built-in laws and nominal parts are the imports below: a
new law is its module plus one line here (and, if it brings its own nominal part, that
module and one line more). Laws, nominal parts and fault kinds kept outside the
library are *plugins*: modules named in the environment variable `FAHV_PLUGINS`
(comma-separated, importable from `PYTHONPATH`) are imported right after the
built-ins, by every process that imports this package -- `fahv` commands, campaign
workers and every node of the ROS graph alike -- so their registry entries exist
everywhere a run is built.
"""

import importlib
import os

# isort: off
from fahv.control import reference  # noqa: F401  (registry entries: governor, command)
from fahv.control.mpc import nominal_source  # noqa: F401  (registry entry: mpc)
from fahv.control import tube_mpc  # noqa: F401  (registry entries)
from fahv.control import rmpc  # noqa: F401  (registry entry)

# isort: on
from fahv.control.base import (  # noqa: E402
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
    variant_notch,
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
    "variant_notch",
]

#: Environment variable naming plugin modules (comma-separated).
PLUGINS_ENV = "FAHV_PLUGINS"


def load_plugins() -> list[str]:
    """Import the modules named in `FAHV_PLUGINS`; returns their names.

    Raises
    ------
    ImportError
        Naming the module that could not be imported and the variable.
    """
    names = [n.strip() for n in os.environ.get(PLUGINS_ENV, "").split(",") if n.strip()]
    for name in names:
        try:
            importlib.import_module(name)
        except ImportError as exc:
            raise ImportError(
                f"{PLUGINS_ENV}: plugin module '{name}' cannot be imported ({exc}); "
                "is its folder on PYTHONPATH?"
            ) from exc
    return names


load_plugins()
