"""Configuration: the one declaration language (fields, sections), YAML, registries.

`fahv.config.faults` is the base of the fault kinds (actuator and sensor): their
per-lane onset and parameters and their registry.

The bottom layer of fahv with `fahv.synthesis`: no vehicle, no control law.
"""

from fahv.config.registry import Registry
from fahv.config.spec import REQUIRED, Check, Field, Section, Validated, validate

__all__ = ["REQUIRED", "Check", "Field", "Registry", "Section", "Validated", "validate"]
