from glob import glob

from setuptools import find_packages, setup

package_name = 'trust_av_planner'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={package_name: ['py.typed', 'models/*.npz', 'models/*.json',
                                 'models/*.md', 'models/*.png',
                                 'drive/web/*']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        # the Foxglove layout, kept in the package (the repository's config/ links here);
        # the params files are trust_monitor's (share/trust_monitor/config)
        ('share/' + package_name + '/config', sorted(glob(package_name + '/config/*.json'))),
    ],
    install_requires=['setuptools'],
    extras_require={'ray': ['ray==2.60.0'], 'test': ['pytest']},
    zip_safe=False,
    maintainer='trust-av maintainers',
    maintainer_email='maintainers@trust-av.invalid',
    description='Trust-aware NMPC for the automated vehicle, in-process simulator and CLI.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'trust-av = trust_av_planner.cli.main:main',
            'planner = trust_av_planner.planner_node:main',
            'ego_plant = trust_av_planner.ego_plant_node:main',
            'recorder = trust_av_planner.graph.recorder_node:main',
            'follower_plant = trust_av_planner.drive.follower_node:main',
        ],
        # The plan estimators, registered like any plug-in (trust_monitor.common.registry).
        'trust_av.predictors': [
            'ca = trust_av_planner.predictors.ca:COMPONENT',
            'cv = trust_av_planner.predictors.cv:COMPONENT',
            'gru = trust_av_planner.predictors.gru:COMPONENT',
        ],
    },
)
