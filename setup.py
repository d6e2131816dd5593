"""ament_python package swarm_ros; also a plain pip-installable Python package."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "swarm_ros"

setup(
    name=PACKAGE,
    version="0.1.0",
    description="Self-organized shape formation in large robot swarms (ROS 2 Jazzy)",
    license="Apache-2.0",
    python_requires=">=3.11",
    packages=find_packages(include=[PACKAGE, f"{PACKAGE}.*"]),
    # numba's cache of the kernels, if scripts/setup.sh filled it in this tree: numba keys a cached kernel by its
    # source's contents, so the installed copy loads it instead of compiling again (swarm_ros/core/kernels.py)
    package_data={
        f"{PACKAGE}.{sub}": ["__pycache__/*.nbi", "__pycache__/*.nbc", "__pycache__/swarm_ros-kernels-*.compiled"]
        for sub in ("core", "core.darr_niazi", "core.rubenstein", "protocol.rubenstein")
    },
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/shapes", sorted(glob("shapes/*.txt"))),
        (f"share/{PACKAGE}/shapes/3d", sorted(glob("shapes/3d/*.txt"))),
        (f"share/{PACKAGE}/config", sorted(glob("config/*.yaml") + glob("config/*.xml"))),
        (f"share/{PACKAGE}/launch", sorted(glob("launch/*.launch.py"))),
        (f"share/{PACKAGE}/rviz", sorted(glob("rviz/*.rviz"))),
        (
            f"share/{PACKAGE}/config/experiments",
            sorted(glob("config/experiments/*.yaml") + glob("config/experiments/*.csv")),
        ),
    ],
    install_requires=[
        "numpy>=2.0,<2.5",
        "numba>=0.61",
        "scipy>=1.13",
        "connected-components-3d>=3.12",
        "trimesh>=4.0",  # 3D shapes from meshes (core/voxels.py)
        "matplotlib>=3.8",
        "pillow>=10",
        "PyYAML>=6",
        "tqdm>=4.66",
        "setproctitle>=1.3",  # a forked node shows its own command in ps (app/forking.py)
        "rerun-sdk>=0.41,<0.42",
        "rosbags>=0.11,<0.12",
        "mcap>=1.6",  # reading a killed monitor's unfinished bag (ros/bag_writer.py)
        "dask[distributed]>=2024.1",
        "distributed>=2024.1",  # imported directly too: a LocalCluster worker plugin (app/dask_workers.py)
    ],
    extras_require={
        "test": ["pytest>=8", "pytest-xdist>=3.5", "hypothesis>=6.100", "pytest-cov>=7", "mcap-ros2-support>=0.6"]
    },
    # `ros2 run swarm_ros <node>` finds the node scripts in lib/swarm_ros (setup.cfg) after colcon build.
    entry_points={
        "console_scripts": [
            "swarm-ros = swarm_ros.app.main:entry",
            "world = swarm_ros.app.main:world",
            "world_shard = swarm_ros.app.main:world_shard",
            "robot_batch = swarm_ros.app.main:robot_batch",
            "monitor = swarm_ros.app.main:monitor",
        ]
    },
    zip_safe=False,
)
