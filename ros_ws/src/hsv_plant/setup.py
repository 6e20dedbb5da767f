"""ament_python package hsv_plant."""

from setuptools import setup

setup(
    name="hsv_plant",
    version="0.1.0",
    packages=["hsv_plant"],
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/hsv_plant"]),
        ("share/hsv_plant", ["package.xml"]),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="fahv maintainers",
    maintainer_email="maintainers@fahv.example.org",
    description="Plant (nonlinear coupling model of the flexible hypersonic vehicle) and fault-injector nodes.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "plant = hsv_plant.plant:run",
            "fault_injector = hsv_plant.fault_injector:run",
        ],
    },
)
