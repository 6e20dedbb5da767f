"""A minimal stand-in for the `ros2` command, for machines without ros2cli.

The ROS 2 Jazzy wheels this project installs from PyPI do not include ros2cli, so
there is no `ros2` command after `source ros_ws/install/setup.bash`. This module
provides the few verbs the project's users need, with the same syntax as ros2cli:

`ros2 run PACKAGE EXECUTABLE [ARGS ...]`
    Finds `<prefix>/lib/PACKAGE/EXECUTABLE` through the ament index (the prefix of
    PACKAGE on `AMENT_PREFIX_PATH`, as ros2run does) and replaces this process with
    it, so `--ros-args ...` and signals reach the node unchanged.
`ros2 pkg executables [PACKAGE]`
    The executables of a package (or of every package), as `PACKAGE EXECUTABLE`.
`ros2 bag info RUN`
    `fahv inspect RUN`: topics, counts, metadata, anomalies and metrics of a run.
`ros2 topic list [-t]` and `ros2 topic echo TOPIC [--once]`
    Through rclpy, in the domain of `ROS_DOMAIN_ID`.

Where a real ros2cli is importable, `ros2` hands over to it unchanged (and the
package installs `bin/ros2` only when ros2cli is absent at build time).
"""

from __future__ import annotations

import argparse
import array
import importlib
import importlib.util
import os
import sys
import time

from ament_index_python.packages import (
    PackageNotFoundError,
    get_package_prefix,
    get_packages_with_prefixes,
)


def executables(package: str) -> list[str]:
    """Executables installed by `package` (sorted file names in `<prefix>/lib/<pkg>`).

    Raises
    ------
    PackageNotFoundError
        If the ament index does not know the package.
    """
    folder = os.path.join(get_package_prefix(package), "lib", package)
    if not os.path.isdir(folder):
        return []
    return sorted(
        f
        for f in os.listdir(folder)
        if os.path.isfile(os.path.join(folder, f)) and os.access(os.path.join(folder, f), os.X_OK)
    )


def executable_path(package: str, executable: str) -> str:
    """Path of `executable` of `package`, found through the ament index.

    Raises
    ------
    LookupError
        Naming the package or the executable (with the package's executables) when
        either is not found.
    """
    try:
        prefix = get_package_prefix(package)
    except (PackageNotFoundError, ValueError):
        raise LookupError(f"Package '{package}' not found") from None
    path = os.path.join(prefix, "lib", package, executable)
    if not (os.path.isfile(path) and os.access(path, os.X_OK)):
        have = ", ".join(executables(package)) or "none"
        raise LookupError(f"No executable '{executable}' in package '{package}' (it has: {have})")
    return path


def cmd_run(args) -> int:
    """`ros2 run`: replace this process with the node executable."""
    try:
        path = executable_path(args.package, args.executable)
    except LookupError as exc:
        print(exc, file=sys.stderr)
        return 1
    os.execv(path, [path, *args.argv])
    return 1  # not reached


def cmd_pkg_executables(args) -> int:
    """`ros2 pkg executables`: `PACKAGE EXECUTABLE` lines."""
    packages = [args.package] if args.package else sorted(get_packages_with_prefixes())
    for pkg in packages:
        try:
            for exe in executables(pkg):
                print(pkg, exe)
        except (PackageNotFoundError, ValueError):
            print(f"Package '{pkg}' not found", file=sys.stderr)
            return 1
    return 0


def cmd_bag_info(args) -> int:
    """`ros2 bag info RUN`: `fahv inspect RUN`."""
    from fahv.cli import main as fahv_main

    return fahv_main(["inspect", args.bag_path])


#: topics every rclpy node (this one too) publishes: seeing only these means no peer yet
OWN_TOPICS = frozenset({"/rosout", "/parameter_events"})
#: discovery of `list` goes on until the topic set has not changed for this long [s]
SETTLE_S = 1.0


def _discover(
    node, spin_time: float, want: str | None = None, longest: float | None = None
) -> dict[str, list[str]]:
    """Topic names and types seen by `node` through DDS discovery.

    With `want` (`echo`): spins until that topic is seen or `spin_time` [s] has
    passed. Without it (`list`): spins at least `spin_time`, then on while the topic
    set still changes (until it has been the same for `SETTLE_S`) or while no peer's
    topic has been seen yet, `longest` [s] at most. A loaded host can answer a new
    participant's discovery late (Fast DDS repeats its announcements every few seconds),
    and a fixed short window then lists an empty graph.
    """
    import rclpy

    t0 = time.monotonic()
    longest = spin_time if longest is None else max(longest, spin_time)
    seen: dict[str, list[str]] = {}
    changed = t0
    while (now := time.monotonic()) - t0 < longest:
        rclpy.spin_once(node, timeout_sec=0.05)
        topics = dict(node.get_topic_names_and_types())
        if want is not None:
            if want in topics:
                return topics
            if now - t0 >= spin_time:
                return topics
            continue
        if topics.keys() != seen.keys():
            seen, changed = topics, now
        if now - t0 >= spin_time and now - changed >= SETTLE_S and set(seen) - OWN_TOPICS:
            break
    return dict(node.get_topic_names_and_types())


def to_plain(msg):
    """A ROS message as plain Python data (dicts, lists, numbers, strings) for YAML."""
    if hasattr(msg, "get_fields_and_field_types"):
        return {f: to_plain(getattr(msg, f)) for f in msg.get_fields_and_field_types()}
    if isinstance(msg, array.array | list | tuple):
        return [to_plain(v) for v in msg]
    if hasattr(msg, "tolist"):  # numpy arrays and scalars
        return msg.tolist()
    return msg


def message_class(type_name: str):
    """Message class of `pkg/msg/Name` (the workspace must be sourced).

    Raises
    ------
    LookupError
        If the type cannot be imported.
    """
    pkg, _, name = type_name.split("/")
    try:
        return getattr(importlib.import_module(f"{pkg}.msg"), name)
    except (ImportError, AttributeError):
        raise LookupError(f"message type {type_name} not found (workspace sourced?)") from None


def cmd_topic(args) -> int:
    """`ros2 topic list` and `ros2 topic echo` through rclpy."""
    import rclpy
    import yaml
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    rclpy.init()
    node = rclpy.create_node(f"ros2_standin_{os.getpid()}", start_parameter_services=False)
    try:
        if args.verb == "list":
            topics = _discover(node, args.spin_time, None, args.longest)
        else:
            topics = _discover(node, args.wait, args.topic)
        if args.verb == "list":
            for name, types in sorted(topics.items()):
                print(f"{name} [{', '.join(types)}]" if args.show_types else name)
            return 0
        if args.topic not in topics:
            print(f"topic {args.topic} not found (after {args.wait:g} s)", file=sys.stderr)
            return 1
        cls = message_class(topics[args.topic][0])
        got = []
        qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        node.create_subscription(cls, args.topic, got.append, qos)
        while rclpy.ok():
            rclpy.spin_once(node, timeout_sec=0.1)
            while got:
                sys.stdout.write(yaml.safe_dump(to_plain(got.pop(0)), sort_keys=False) + "---\n")
                sys.stdout.flush()
                if args.once:
                    return 0
    except LookupError as exc:
        print(exc, file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 0
    finally:
        node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0


def build_parser() -> argparse.ArgumentParser:
    """Parser of the stand-in: `run`, `pkg executables`, `bag info`, `topic`."""
    ap = argparse.ArgumentParser(
        prog="ros2",
        description="minimal ros2 stand-in of the fahv workspace (no ros2cli on this machine)",
    )
    sub = ap.add_subparsers(dest="command", required=True)
    p = sub.add_parser("run", help="run a package's executable (found through the ament index)")
    p.add_argument("package")
    p.add_argument("executable")
    p.add_argument("argv", nargs=argparse.REMAINDER, help="arguments, e.g. --ros-args ...")
    p.set_defaults(func=cmd_run)
    pkg = sub.add_parser("pkg", help="package information").add_subparsers(dest="verb")
    pkg.required = True
    p = pkg.add_parser("executables", help="executables of a package (or of all)")
    p.add_argument("package", nargs="?")
    p.set_defaults(func=cmd_pkg_executables)
    bag = sub.add_parser("bag", help="recorded runs").add_subparsers(dest="verb")
    bag.required = True
    p = bag.add_parser("info", help="fahv inspect of a run (folder or .mcap)")
    p.add_argument("bag_path")
    p.set_defaults(func=cmd_bag_info)
    topic = sub.add_parser("topic", help="topics of the running graph").add_subparsers(dest="verb")
    topic.required = True
    p = topic.add_parser("list", help="topics seen in ROS_DOMAIN_ID")
    p.add_argument("-t", "--show-types", action="store_true")
    p.add_argument(
        "-s", "--spin-time", type=float, default=2.0,
        help="least discovery time [s]; discovery goes on while topics still appear",
    )  # fmt: skip
    p.add_argument(
        "--longest", type=float, default=10.0,
        help="longest discovery time [s] (reached when no other node is seen)",
    )  # fmt: skip
    p.set_defaults(func=cmd_topic)
    p = topic.add_parser("echo", help="print the messages of a topic as YAML")
    p.add_argument("topic")
    p.add_argument("--once", action="store_true", help="print one message and exit")
    p.add_argument("--wait", type=float, default=10.0, help="longest wait for the topic [s]")
    p.set_defaults(func=cmd_topic)
    return ap


def main(argv: list[str] | None = None) -> int:
    """Entry point `ros2`: ros2cli if it is installed, else this stand-in."""
    if importlib.util.find_spec("ros2cli") is not None:  # a real ROS 2 install
        from ros2cli.cli import main as ros2cli_main

        return ros2cli_main()
    args = build_parser().parse_args(argv)
    return args.func(args)


def run() -> None:
    """Console script `ros2` (`lib/hsv_bringup/ros2`, called by `bin/ros2`)."""
    sys.exit(main())
