"""`extends:` for configuration files: a file that states only how it differs from another.

A scenario or campaign file may begin with `extends: BASE`; its other entries override
the base's, and the result is validated as a whole file would be (the same errors, naming
the extending file). BASE is a path relative to the extending file, or a name looked up
as `<name>.yaml` in the places its loader gives (a scenario's name in
`offline_design/scenarios/`). A base may extend another; a cycle is an error.

Merging (`merged`), entry by entry:

- a mapping merges into the base's mapping, key by key, recursively;
- a mapping that sets `kind` to another value than the base's replaces the base's
  mapping whole: another fault or command kind takes other keys, and a key of the base's
  kind left behind would be refused (`fahv.config.spec.validate`);
- anything else (a number, a string, a list) replaces the base's value.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

#: The key that names a file's base.
EXTENDS = "extends"


def merged(base: Mapping, override: Mapping) -> dict:
    """The base's entries with the override's (module notes), as a new dict.

    Examples
    --------
    >>> merged({"fault": {"kind": "loss", "rho_f": 0.9}, "duration": 300.0},
    ...        {"fault": {"rho_f": 0.8}, "duration": 60.0})
    {'fault': {'kind': 'loss', 'rho_f': 0.8}, 'duration': 60.0}
    >>> merged({"fault": {"kind": "loss", "rho_f": 0.9}}, {"fault": {"kind": "bias",
    ...        "bias_deg": 1.0}})
    {'fault': {'kind': 'bias', 'bias_deg': 1.0}}
    """
    out = dict(base)
    for key, value in override.items():
        old = out.get(key)
        other_kind = isinstance(value, Mapping) and "kind" in value and isinstance(
            old, Mapping) and old.get("kind") != value["kind"]
        if isinstance(value, Mapping) and isinstance(old, Mapping) and not other_kind:
            out[key] = merged(old, value)
        else:
            out[key] = dict(value) if isinstance(value, Mapping) else value
    return out


def resolve_extends(data: Any, path: Path, read: Callable[[Path], Any],
                    find: Callable[[str, Path], list[Path]], error: type,
                    path_keys: tuple[str, ...] = ()) -> Any:  # fmt: skip
    """A file's content with its `extends:` chain merged in (unchanged without one).

    Parameters
    ----------
    data : any
        The file's parsed YAML (a mapping to extend; anything else is returned as is, for
        the validation to refuse).
    path : Path
        The file, for relative bases and messages.
    read : callable
        `read(path) -> data`: parses a base file (raising `error` if it is missing or not
        YAML).
    find : callable
        `find(name, folder) -> [Path, ...]`: where a base given by name is looked for, in
        order, from the folder of the file that names it.
    error : type
        The exception raised (a `fahv.errors.ConfigError` subclass).
    path_keys : tuple of str
        Top-level keys whose value may be a path relative to its file (a campaign's
        `scenario`, a scenario's `design` given as a `.yaml` path): a base's such path is
        made absolute from the base's own folder, so it resolves from the file that names
        it.

    Returns
    -------
    any
        The merged mapping, without `extends` (the extending file's `name` defaults to
        its file name when neither it nor a base sets one).

    Raises
    ------
    error
        If `extends` is not a string, names no file, or the chain has a cycle (naming
        the files).
    """
    chain = [Path(path).resolve()]
    layers = []
    while isinstance(data, Mapping) and EXTENDS in data:
        base = data[EXTENDS]
        here = chain[-1]
        if not isinstance(base, str) or not base:
            raise error(f"{here}: key '{EXTENDS}' must be a file name or path, got {base!r}")
        layers.append({k: v for k, v in data.items() if k != EXTENDS})
        base_path = _base_file(base, here, find, error)
        if base_path in chain:
            cycle = " -> ".join(str(p) for p in [*chain, base_path])
            raise error(f"{chain[0]}: key '{EXTENDS}' makes a cycle: {cycle}")
        chain.append(base_path)
        data = _rebased(read(base_path), base_path.parent, path_keys)
    if not layers:
        return data
    if not isinstance(data, Mapping):
        return data
    out = dict(data)
    for layer in reversed(layers):
        out = merged(out, layer)
    if "name" not in layers[0]:  # an extending file is its own scenario or campaign
        out["name"] = Path(path).stem
    return out


def _base_file(base: str, here: Path, find, error) -> Path:
    """The file `extends: base` names, from the file `here` that names it."""
    if base.endswith((".yaml", ".yml")):
        tries = [here.parent / base]
    else:
        tries = find(base, here.parent)
    for t in tries:
        if t.is_file():
            return t.resolve()
    raise error(f"{here}: key '{EXTENDS}': no file {base!r} (looked for "
                + ", ".join(str(t) for t in tries) + ")")  # fmt: skip


def _rebased(data: Any, folder: Path, path_keys: tuple[str, ...]) -> Any:
    """`data` with the relative `.yaml` paths of `path_keys` made absolute from `folder`."""
    if not isinstance(data, Mapping):
        return data
    out = dict(data)
    for key in path_keys:
        v = out.get(key)
        if isinstance(v, str) and v.endswith((".yaml", ".yml")) and not Path(v).is_absolute():
            out[key] = str((folder / v).resolve())
    return out
