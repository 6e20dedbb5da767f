"""ament_python package hsv_bringup."""

import importlib.util

from setuptools import setup

# `ros2` stand-in (bin/ros2 -> lib/hsv_bringup/ros2) only where no ros2cli is installed:
# on a full ROS 2 install the real command must not be shadowed by this workspace.
STANDIN = [("bin", ["bin/ros2"])] if importlib.util.find_spec("ros2cli") is None else []

setup(
    name="hsv_bringup",
    version="0.1.0",
    packages=["hsv_bringup"],
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/hsv_bringup"]),
        ("share/hsv_bringup", ["package.xml"]),
        ("share/hsv_bringup/config", ["config/foxglove_layout.json"]),
        *STANDIN,
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="fahv maintainers",
    maintainer_email="maintainers@fahv.example.org",
    description="MCAP recorder, replay and the SIL runner of the flexible hypersonic vehicle graph.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "recorder = hsv_bringup.recorder:run",
            "replay = hsv_bringup.replay:run",
            "sil = hsv_bringup.sil:run",
            "loop = hsv_bringup.composed:run",
            "ros2 = hsv_bringup.ros2_standin:run",
        ],
    },
)
