from setuptools import find_packages, setup

package_name = 'trust_av_autoware'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={package_name: ['py.typed']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools'],
    extras_require={'test': ['pytest']},  # colcon test runs pytest (setup.cfg)
    zip_safe=False,
    maintainer='trust-av maintainers',
    maintainer_email='maintainers@trust-av.invalid',
    description=(
        'Adapters between an Autoware stack and the trust-aware planner: kinematic state and '
        'predicted objects to distances along a lane, the planner command to Autoware Control.'
    ),
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'autoware_lane = trust_av_autoware.lane_adapter_node:main',
            'autoware_control = trust_av_autoware.control_adapter_node:main',
            'field_labels = trust_av_autoware.labels_node:main',
        ],
    },
)
