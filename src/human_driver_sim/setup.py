from setuptools import find_packages, setup

package_name = 'human_driver_sim'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={package_name: ['py.typed', 'models/*.yaml']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools'],
    extras_require={'test': ['pytest']},  # colcon test runs pytest (setup.cfg)
    zip_safe=False,
    maintainer='trust-av maintainers',
    maintainer_email='maintainers@trust-av.invalid',
    description='IRL-style MPC model of the human driver following the AV (Ozkan & Ma, eq. 13).',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'driver = human_driver_sim.driver_node:main',
            'follower_plant = human_driver_sim.follower_plant_node:main',
        ],
        # The follower models, registered like any plug-in (trust_av_common.registry).
        'trust_av.drivers': [
            'idm = human_driver_sim.idm:COMPONENT',
            'mpc = human_driver_sim.driver_mpc:COMPONENT',
        ],
    },
)
