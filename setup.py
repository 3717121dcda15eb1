"""ament_python package definition (see package.xml for the ROS metadata)."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "transparency_ros"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*"]),
    package_data={PACKAGE: ["py.typed"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", sorted(glob("config/*.yaml"))),
    ],
    install_requires=["setuptools"],
    zip_safe=False,
    maintainer="transparency_ros maintainers",
    maintainer_email="maintainers@transparency-ros.invalid",
    description="Proprioceptive contact detection with transparent actuators (ROS 2 Jazzy).",
    license="Apache-2.0",
    python_requires=">=3.10",
    extras_require={"test": ["pytest", "hypothesis"]},
    entry_points={
        "console_scripts": [
            "transparency = transparency_ros.cli:main",
            "actuator_driver = transparency_ros.ros.actuator_driver:main",
            "contact_estimator = transparency_ros.ros.contact_estimator:main",
            "feel_cage_behavior = transparency_ros.ros.feel_cage_behavior:main",
            "bag_replay = transparency_ros.ros.bag_replay:main",
        ],
    },
)
