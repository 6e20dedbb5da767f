"""ROS parameters of the nodes, generated from the library's configuration fields.

Every node declares its parameters from `fahv.config.Field` declarations
(`fahv.loop.params.specs` for the loop nodes, `fahv.sil.tool_nodes` for the
recorder and the replay): typed, with a description (unit, range, equation) and the
numeric range in the descriptor, and validates them once with
`fahv.config.spec.validate_flat`. A bad value raises
`fahv.errors.ParameterError` naming the node and the key (exit status 2).
"""

from __future__ import annotations

import array
import json

import rclpy
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.node import Node
from rclpy.parameter import Parameter

from fahv.config import Field
from fahv.config.spec import validate_flat
from fahv.errors import ParameterError
from fahv.loop.graph import DEFAULT_GRAPH

_ROS_TYPE = {
    "float": Parameter.Type.DOUBLE,
    "int": Parameter.Type.INTEGER,
    "str": Parameter.Type.STRING,
    "bool": Parameter.Type.BOOL,
    "floats": Parameter.Type.DOUBLE_ARRAY,
    "ints": Parameter.Type.INTEGER_ARRAY,
    "strs": Parameter.Type.STRING_ARRAY,
    "matrix": Parameter.Type.DOUBLE_ARRAY,
}


def descriptor(f: Field) -> ParameterDescriptor:
    """ROS parameter descriptor of a config field.

    Description with unit, range and equation; the numeric range when both ends are
    finite.
    """
    desc = ParameterDescriptor(description=f.doc())
    if f.lo is not None and f.hi is not None:
        if f.type == "float":
            desc.floating_point_range = [
                FloatingPointRange(from_value=float(f.lo), to_value=float(f.hi))
            ]
        elif f.type == "int":
            desc.integer_range = [IntegerRange(from_value=int(f.lo), to_value=int(f.hi))]
    return desc


def declare_parameters(node: Node, fields) -> dict:
    """Declare typed parameters from config fields; return their raw values.

    Matrices are declared as a double array plus `<name>_shape`. A parameter the
    parameter file does not set is None (absent: its default or "missing" is decided
    by `fahv.config.spec.validate_flat`, the one validation). String arrays drop
    empty strings (`[""]` stands for an empty list, since a YAML `[]` has no
    parameter type).

    Raises
    ------
    ParameterError
        Naming the key, for a value of the wrong type in the file or outside the
        declared range.
    """
    values = {}
    for f in fields:
        decls = [(f.name, _ROS_TYPE[f.type], descriptor(f))]
        if f.type == "matrix":
            shape = ParameterDescriptor(description=f"shape of {f.name}")
            decls.append((f"{f.name}_shape", Parameter.Type.INTEGER_ARRAY, shape))
        for name, typ, desc in decls:
            try:
                node.declare_parameter(name, typ, desc)
                values[name] = node.get_parameter(name).value
            except rclpy.exceptions.ParameterUninitializedException:
                values[name] = None
            except (
                rclpy.exceptions.InvalidParameterTypeException,
                rclpy.exceptions.InvalidParameterValueException,
            ) as exc:
                raise ParameterError(
                    f"{node.get_name()}: parameter '{name}' is invalid: {exc}"
                ) from None
    for key, v in values.items():
        if isinstance(v, array.array | list):
            v = [x for x in v if x != ""] if _is_str_list(v) else list(v)
            values[key] = v if v or key.endswith("_shape") else None
    return values


def _is_str_list(v) -> bool:
    return isinstance(v, list) and bool(v) and isinstance(v[0], str)


def declare_validated(node: Node, fields) -> dict:
    """Declare config fields as parameters and validate them (the one validation).

    Raises
    ------
    ParameterError
        Naming the node and the key.
    """
    return validate_flat(fields, declare_parameters(node, fields), node.get_name(), ParameterError)


def declare_graph(node: Node) -> tuple[list[str], str]:
    """Parameters every node of a graph shares: `graph_nodes` and `run_id`.

    `graph_nodes` lists the nodes of the running graph (readiness, the start of
    step 0, the names of missing peers); `run_id` tells this graph's nodes from
    another graph's in the same ROS domain ("" when the parameter file sets none).

    Returns
    -------
    (list of str, str)
    """
    node.declare_parameter(
        "graph_nodes",
        DEFAULT_GRAPH,
        ParameterDescriptor(description="nodes of the running graph (readiness check)"),
    )
    node.declare_parameter(
        "run_id",
        "",
        ParameterDescriptor(description="id shared by the nodes of one graph (fahv sil: run name)"),
    )
    graph = list(node.get_parameter("graph_nodes").value)
    return graph, str(node.get_parameter("run_id").value)


def run_metadata_param(node_name: str, text: str) -> dict:
    """Parameter `metadata_json` as a dict, with `code_version` filled in.

    Raises
    ------
    ParameterError
        If it is not a JSON object.
    """
    from fahv.version import code_version

    try:
        meta = json.loads(text)
    except ValueError:
        meta = None
    if not isinstance(meta, dict):
        raise ParameterError(f"{node_name}: parameter 'metadata_json' is not a JSON object")
    meta.setdefault("code_version", code_version())
    return meta
