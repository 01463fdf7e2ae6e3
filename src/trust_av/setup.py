from glob import glob

from setuptools import find_packages, setup

package_name = 'trust_av'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    # the drive page and the library it draws with (every file under drive/web)
    package_data={package_name: ['py.typed', 'drive/web/*', 'drive/web/vendor/*',
                                 'drive/web/vendor/konva/*']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        # the Foxglove layout, kept in the package (the repository's config/ links here)
        ('share/' + package_name + '/config', sorted(glob(package_name + '/config/*.json'))),
    ],
    install_requires=['setuptools'],
    extras_require={'ray': ['ray==2.60.0'], 'test': ['pytest']},
    zip_safe=False,
    maintainer='trust-av maintainers',
    maintainer_email='maintainers@trust-av.invalid',
    description=(
        'The trust-av application: the trust-av command line, the node-graph orchestrator '
        'and recorder, the in-process closed loop, the studies and the driver-in-the-loop drive.'
    ),
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'trust-av = trust_av.cli.main:main',
            'recorder = trust_av.graph.recorder_node:main',
        ],
    },
)
