"""ament_python package hsv_common."""

from setuptools import setup

setup(
    name="hsv_common",
    version="0.1.0",
    packages=["hsv_common"],
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/hsv_common"]),
        ("share/hsv_common", ["package.xml"]),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="fahv maintainers",
    maintainer_email="maintainers@fahv.example.org",
    description="Lockstep, parameter and message plumbing shared by the hsv_* nodes of the flexible hypersonic vehicle SIL graph.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [],
    },
)
