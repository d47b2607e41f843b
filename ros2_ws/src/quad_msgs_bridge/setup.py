from glob import glob

from setuptools import find_packages, setup

package_name = 'quad_msgs_bridge'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={package_name: ['config/*.yaml', 'config/vehicles/*.yaml']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob(package_name + '/config/*.yaml')),
        ('share/' + package_name + '/config/vehicles', glob(package_name + '/config/vehicles/*.yaml')),
    ],
    # the same as the root pyproject.toml's (pip install .); package.xml names them by rosdep key
    install_requires=['setuptools', 'numpy>=1.26.4', 'PyYAML>=6.0', 'numba>=0.68.1', 'rosbags>=0.11.9,<0.12', 'mcap>=1.6.0,<2',
                      'mcap-ros2-support>=0.6.0', 'zstandard>=0.25.0'],
    zip_safe=True,
    maintainer='NNIT2FSMC flight stack maintainers',
    maintainer_email='maintainers@nnit2fsmc.invalid',
    description="The NNIT2FSMC stack's contract: topic names, QoS, frames, message and numpy conversions, the vehicle description, MCAP bag writing, reading and review.",
    license='Apache-2.0',
    extras_require={'test': ['pytest'], 'plots': ['matplotlib>=3.11.2']},
    entry_points={'console_scripts': [
        'record = quad_msgs_bridge.bag.recorder_node:main',
        'review = quad_msgs_bridge.review.command:main',
        'recover = quad_msgs_bridge.bag.recover:recover_main',
        'merge = quad_msgs_bridge.bag.merge:merge_main',
        'rosbag2_qos = quad_msgs_bridge.bag.metadata:qos_overrides_main',
    ]},
)
