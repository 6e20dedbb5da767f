"""Configuration: the one declaration language (fields, sections), YAML, registries.

The bottom layer of fahv with `fahv.synthesis`: no vehicle, no control law.
"""

from fahv.config.registry import Registry
from fahv.config.spec import REQUIRED, Check, Field, Section, Validated, validate

__all__ = ["REQUIRED", "Check", "Field", "Registry", "Section", "Validated", "validate"]
