"""ament_python package ema_sim; also installs with pip (see README)."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "ema_sim"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(include=["ema_sim", "ema_sim.*", "ema_msgs_py", "ema_msgs_py.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", sorted(glob("config/*.yaml"))),
        (f"share/{PACKAGE}/launch", sorted(glob("launch/*.launch.py"))),
        (f"share/{PACKAGE}/rosdep", ["rosdep/ema_sim.yaml"]),
        (f"share/{PACKAGE}/ema_msgs_py", ["ema_msgs_py/README.md"]),
    ],
    python_requires=">=3.10",
    install_requires=[
        "numpy>=1.26",
        "scipy>=1.11",
        "numba>=0.59",
        "control>=0.10",
        "rosbags>=0.10",
        "mcap>=1.1",
        "matplotlib>=3.8",
        "PyYAML>=6",
        "threadpoolctl>=3",
        "jsonschema>=4.18",
    ],
    zip_safe=True,
    maintainer="ema_sim maintainers",
    maintainer_email="ema-sim@example.org",
    description="X-43A electromechanical actuator emulation: models, ROS 2 nodes, analysis, identification.",
    license="Apache-2.0",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [
            "ema = ema_sim.cli:entry",
            "emac = ema_sim.nodes.emac:main",
            "testenv = ema_sim.nodes.testenv:main",
            "maneuver = ema_sim.nodes.maneuver:main",
            "simclock = ema_sim.nodes.clock:main",
            "fmu_bridge = ema_sim.nodes.bridge:main",
            "fmu = ema_sim.nodes.fmu:main",
            "ema_container = ema_sim.nodes.container:main",
            "ema_monitor = ema_sim.nodes.monitor:main",
        ],
    },
)
