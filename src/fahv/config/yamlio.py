"""YAML reading with YAML 1.2 number syntax (`5.0e5` is a float, not a string).

PyYAML implements YAML 1.1, whose float pattern needs a sign in the exponent and
a dot in the mantissa; vehicle and case files written by people use `5.0e5` and
`1e-3`. The resolver below is the one documented in the PyYAML issue tracker for
this case, restricted to the safe loader.
"""

from __future__ import annotations

import re
from typing import Any

import yaml


class _Loader(yaml.SafeLoader):
    """Safe loader that resolves YAML 1.2 floats."""


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(
        r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
        |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
        |\.[0-9_]+(?:[eE][-+]?[0-9]+)?
        |[-+]?\.(?:inf|Inf|INF)
        |\.(?:nan|NaN|NAN))$""",
        re.X,
    ),
    list("-+0123456789."),
)


def load_yaml(text: str) -> Any:
    """Parse YAML text with the safe loader and YAML 1.2 floats.

    Raises
    ------
    yaml.YAMLError
        If the text is not valid YAML.
    """
    return yaml.load(text, Loader=_Loader)  # noqa: S506 - _Loader derives from SafeLoader
