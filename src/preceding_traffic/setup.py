from setuptools import find_packages, setup

package_name = 'preceding_traffic'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={package_name: ['py.typed', 'data/*.csv', 'data/*.md', 'data/*.txt',
                                 'data/training/*.csv', 'data/training/*.md']},
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
        'Preceding-traffic speed source: '
        'drive-cycle traces, validation, resampling and preview.'
    ),
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'traffic = preceding_traffic.traffic_node:main',
        ],
    },
)
