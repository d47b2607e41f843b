from glob import glob

from setuptools import find_packages, setup

package_name = 'quad_sim'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={package_name: ['config/*.yaml']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob(package_name + '/config/*.yaml')),
    ],
    # the same as the root pyproject.toml's for this package (pip install .); package.xml names them by rosdep key
    install_requires=['setuptools', 'numpy>=1.26.4', 'PyYAML>=6.0', 'numba>=0.68.1'],
    zip_safe=True,
    maintainer='NNIT2FSMC flight stack maintainers',
    maintainer_email='maintainers@nnit2fsmc.invalid',
    description='Simulator node for the quadrotor model of the NNIT2FSMC paper (eq. 1 and 2, section IV disturbances, RK4).',
    license='Apache-2.0',
    extras_require={'test': ['pytest']},
    entry_points={'console_scripts': [
        'quad_sim = quad_sim.sim_node:main',
        'px4_bridge = quad_sim.px4_node:main',
    ]},
)
