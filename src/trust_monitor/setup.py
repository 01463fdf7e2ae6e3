from setuptools import find_packages, setup

package_name = 'trust_monitor'

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
        'Explicability score, performance level and trust '
        'dynamics of the human follower (Ozkan & Ma, eqs. 8-11).'
    ),
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'trust-monitor-estimate = trust_monitor.estimate:main',
            'monitor = trust_monitor.monitor_node:main',
        ],
        # The trust models (trust_monitor.model_interface); a plug-in package adds its own
        # to this group the same way (docs/concepts/trust-models.md).
        'trust_av.trust_models': [
            'paper = trust_monitor.shipped_models:PAPER',
            'asymmetric = trust_monitor.shipped_models:ASYMMETRIC',
            'beta_bernoulli = trust_monitor.shipped_models:BETA_BERNOULLI',
            'optimo = trust_monitor.shipped_models:OPTIMO',
        ],
    },
)
