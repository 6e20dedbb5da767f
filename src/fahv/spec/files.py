"""Reading and validating design files, scenario files and run specs.

A validated file is a `SpecFile`: its path, its content with every default filled
in, and the defaults it relied on. `spec_file` validates a mapping against a
schema of `fahv.spec.schema` (the run spec's by default), `load_design_file`
reads a design file; a scenario file and the run spec it forms are read by
`fahv.spec.scenario.load_scenario`. Every failure is a
`fahv.errors.SpecError` naming the file and the dotted key.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fahv.config import Section, validate
from fahv.config.extends import resolve_extends
from fahv.config.yamlio import load_yaml
from fahv.errors import SpecError
from fahv.spec.schema import design_spec, run_spec


@dataclass(frozen=True)
class SpecFile:
    """A validated design file, scenario file or run spec, with the file it came from.

    Attributes
    ----------
    path : Path
        File it was read from (for a run spec: its scenario file).
    data : dict
        Validated content, defaults filled in (see `fahv.spec.schema`).
    defaults_used : dict
        `{dotted key: value}` of every default the file relied on.
    """

    path: Path
    data: dict
    defaults_used: dict = field(default_factory=dict)

    def __getitem__(self, key: str) -> Any:
        """Top-level entry of the content."""
        return self.data[key]

    @property
    def name(self) -> str:
        """Name of the design or the scenario (artefact folders and run files)."""
        return self.data["name"]

    def content_hash(self) -> str:
        """sha256 of the validated content (defaults included), first 16 hex characters."""
        text = json.dumps(self.data, sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()[:16]


def spec_file(data: Any, path: str = "<mapping>", spec: Section | None = None) -> SpecFile:
    """Validate a mapping against `spec` (`fahv.spec.schema.run_spec` by default).

    Raises
    ------
    SpecError
        Naming the file, the dotted key and the value at fault.
    """
    v = validate(run_spec() if spec is None else spec, data, path, SpecError)
    return SpecFile(Path(path), v.values, v.defaults_used)


def read_yaml_file(path: str | Path, what: str, error: type = SpecError) -> Any:
    """The YAML content of a file.

    Raises
    ------
    error
        `SpecError` by default (a campaign file's: `CampaignError`): if the file is
        missing or is not YAML (naming the file, `what` it should be, the YAML error's
        line).
    """
    p = Path(path)
    if not p.is_file():
        raise error(f"{what} not found: {p}")
    try:
        return load_yaml(p.read_text())
    except Exception as exc:  # yaml errors carry the line number
        raise error(f"{p}: not a valid YAML file: {exc}") from None


def load_design_file(path: str | Path) -> SpecFile:
    """Read and validate a design file (`fahv.spec.schema.design_spec`).

    A design file may begin with `extends: BASE` (`fahv.config.extends`): a design that
    differs from another in a few entries (the design for the loop on the estimate from
    the exact state's). A base given by name is `<name>.yaml` beside the file, then in
    `offline_design/designs/` of the working folder.

    Raises
    ------
    SpecError
        If the file or a base is missing or is not YAML, `extends` makes a cycle, or the
        merged file does not validate (naming the key).
    """
    def find(name: str, folder: Path) -> list[Path]:
        return [folder / f"{name}.yaml", Path("offline_design") / "designs" / f"{name}.yaml"]

    data = resolve_extends(read_yaml_file(path, "design file"), Path(path),
                           lambda p: read_yaml_file(p, "design file"), find, SpecError)
    return spec_file(data, str(path), design_spec())
