"""ament_python package hsv_ctrl."""

from setuptools import setup

setup(
    name="hsv_ctrl",
    version="0.1.0",
    packages=["hsv_ctrl"],
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/hsv_ctrl"]),
        ("share/hsv_ctrl", ["package.xml"]),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="fahv maintainers",
    maintainer_email="maintainers@fahv.example.org",
    description="State estimator, notch filter, nominal trajectory, Tube-MPC (and RMPC baseline) nodes of Yang et al. 2022.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "state_estimator = hsv_ctrl.state_estimator:run",
            "notch_filter = hsv_ctrl.notch_filter:run",
            "nominal_trajectory = hsv_ctrl.nominal_trajectory:run",
            "tube_mpc = hsv_ctrl.tube_mpc:run",
            "rmpc = hsv_ctrl.tube_mpc:run_rmpc",
        ],
    },
)
