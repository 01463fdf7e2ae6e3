from setuptools import find_packages, setup

package_name = 'trust_av_planner'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={package_name: ['py.typed', 'models/*.npz', 'models/*.json',
                                 'models/*.md', 'models/*.png']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools'],
    extras_require={'test': ['pytest']},  # colcon test runs pytest (setup.cfg)
    zip_safe=False,
    maintainer='trust-av maintainers',
    maintainer_email='maintainers@trust-av.invalid',
    description=('Trust-aware NMPC for the automated vehicle: the plan estimators, the planner, '
                 'ego-plant and stand-in nodes.'),
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'planner = trust_av_planner.planner_node:main',
            'ego_plant = trust_av_planner.ego_plant_node:main',
            # kept here for one release (`ros2 run trust_av_planner recorder|follower_plant`);
            # their homes are trust_av and human_driver_sim
            'recorder = trust_av.graph.recorder_node:main',
            'follower_plant = human_driver_sim.follower_plant_node:main',
        ],
        # The plan estimators, registered like any plug-in (trust_av_common.registry).
        'trust_av.predictors': [
            'ca = trust_av_planner.predictors.ca:COMPONENT',
            'cv = trust_av_planner.predictors.cv:COMPONENT',
            'gru = trust_av_planner.predictors.gru:COMPONENT',
        ],
    },
)
