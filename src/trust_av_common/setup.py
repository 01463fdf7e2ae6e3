from glob import glob

from setuptools import find_packages, setup

package_name = 'trust_av_common'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={package_name: ['py.typed']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        # the shipped params files and the graph's Fast DDS profile, kept in the package
        # (the repository's config/ links here)
        ('share/' + package_name + '/config', sorted(glob(package_name + '/config/*.yaml')
                                                     + glob(package_name + '/config/*.xml'))),
    ],
    install_requires=['setuptools'],
    extras_require={'test': ['pytest']},  # colcon test runs pytest (setup.cfg)
    zip_safe=False,
    maintainer='trust-av maintainers',
    maintainer_email='maintainers@trust-av.invalid',
    description=(
        'The shared floor of the trust-av packages: parameters, registry, topics, output '
        'files, errors (pure), and the rclpy helpers of every node.'
    ),
    license='Apache-2.0',
)
