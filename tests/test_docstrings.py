"""Every public function and class of the model and synthesis layers documents its interface.

numpydoc's own validation (``numpydoc.validate.validate``) over the public functions,
classes and methods of every module of ``fahv.model``, ``fahv.synthesis`` and
``fahv.estimation``, with the
rules that matter here:

- PR01: a parameter is not documented;
- PR02: a documented parameter does not exist;
- RT01: a function that returns a value has no Returns section.

A summary line of its own (SS01-SS06), an extended summary (ES01), examples (EX01) and
the like are not required. A dataclass documents its fields, which are its constructor's
parameters, under Attributes: there they count as documented (PR01), and a field the
section names that the class does not have is reported as PR02.
"""

import dataclasses
import importlib
import inspect
import pkgutil

import numpydoc.validate
from numpydoc.docscrape import NumpyDocString

import fahv.estimation
import fahv.model
import fahv.synthesis

PACKAGES = (fahv.model, fahv.synthesis, fahv.estimation)
RULES = ("PR01", "PR02", "RT01")


def _modules():
    for package in PACKAGES:
        yield package
        for info in pkgutil.walk_packages(package.__path__, package.__name__ + "."):
            yield importlib.import_module(info.name)


def _public_objects():
    """(import path, object) of every public function, class and method of the layers."""
    for module in _modules():
        for name, obj in vars(module).items():
            if name.startswith("_") or getattr(obj, "__module__", None) != module.__name__:
                continue  # private, or imported from elsewhere (checked where it is defined)
            if not (inspect.isfunction(obj) or inspect.isclass(obj)):
                continue
            path = f"{module.__name__}.{name}"
            yield path, obj
            if inspect.isclass(obj):
                for attr, member in vars(obj).items():
                    if not attr.startswith("_") and (
                        inspect.isfunction(member) or isinstance(member, staticmethod | classmethod)
                    ):
                        yield f"{path}.{attr}", member


def _names(section) -> set[str]:
    """The names of a numpydoc section's entries ("h, V : float" names h and V)."""
    return {n.strip().lstrip("*") for item in section for n in item.name.split(",") if n.strip()}


def _dataclass_fields_errors(obj) -> list[tuple[str, str]]:
    """PR01 / PR02 of a dataclass whose fields are documented under Attributes."""
    doc = NumpyDocString(inspect.getdoc(obj) or "")
    documented = _names(doc["Parameters"]) | _names(doc["Attributes"])
    fields = {f.name for f in dataclasses.fields(obj) if f.init}
    errors = []
    if fields - documented:
        errors.append(("PR01", f"Fields {sorted(fields - documented)} not documented"))
    unknown = _names(doc["Attributes"]) - {f.name for f in dataclasses.fields(obj)}
    unknown -= {name for name, _ in inspect.getmembers(obj)}  # properties may be listed too
    if unknown:
        errors.append(("PR02", f"Unknown fields {sorted(unknown)} documented"))
    return errors


def _failures() -> list[str]:
    failures = []
    for path, obj in _public_objects():
        if inspect.isclass(obj) and dataclasses.is_dataclass(obj):
            errors = _dataclass_fields_errors(obj)
        else:
            errors = numpydoc.validate.validate(path)["errors"]
        failures += [f"{path}: {code} {message}" for code, message in errors if code in RULES]
    return failures


def test_the_layers_have_public_functions_and_classes():
    paths = [path for path, _ in _public_objects()]
    assert len(paths) > 90
    assert "fahv.model.trim.trim" in paths and "fahv.synthesis.feedback.design_tube" in paths


def test_every_public_docstring_names_its_parameters_and_returns():
    failures = _failures()
    assert failures == [], f"{len(failures)} docstring failure(s):\n" + "\n".join(failures)
