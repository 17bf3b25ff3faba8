"""Install cog_id_ros: as an ament_python package under colcon, or with pip into a venv."""
from glob import glob
import os

from setuptools import find_packages, setup

PACKAGE = 'cog_id_ros'
#: every file of config/, not only its parameter files: a config may refer to another file
#: by a path relative to itself (crank_rocker_urdf.yaml's urdf_file: crank_rocker.urdf), and
#: an installed config whose file was left behind cannot be loaded
CONFIG_FILES = sorted(path for path in glob('config/*') if os.path.isfile(path))

setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*', 'bench']),
    # the C every compiled kernel module starts with (core/native/emitter.py reads it)
    package_data={PACKAGE + '.core.native': ['kernels_prelude.c', 'kernels_simulation.c']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE]),
        ('share/' + PACKAGE, ['package.xml']),
        ('share/' + PACKAGE + '/config', CONFIG_FILES),
    ],
    install_requires=['setuptools', 'numpy', 'scipy', 'PyYAML'],
    zip_safe=True,
    maintainer='cog_id_ros developers',
    maintainer_email='dev@cog-id-ros.invalid',
    description='Closed-link inverse dynamics by per-link COG Jacobians, as a ROS 2 node',
    license='Apache-2.0',
    python_requires='>=3.10',
    entry_points={
        'console_scripts': [
            'cog_id_node = cog_id_ros.ros.main:main',
            'cog_sim_node = cog_id_ros.ros.sim_main:main',
            'cog_transmission_node = cog_id_ros.ros.main:transmission_main',
            'cog_id_torques = cog_id_ros.offline.cli:main',
            'cog_id_player = cog_id_ros.ros.player:main',
            'cog_id_demo = cog_id_ros.demos.table:main',
            'cog_id_inspect = cog_id_ros.offline.inspect:main',
            'cog_id_simulate = cog_id_ros.offline.simulate:main',
        ],
    },
)
