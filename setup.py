"""Install sensor_comp as an ament_python package."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = 'sensor_comp'

setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*', 'bench', 'bench.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE]),
        ('share/' + PACKAGE, ['package.xml', 'README.md']),
        ('share/' + PACKAGE + '/bags', sorted(glob('bags/*.mcap') + glob('bags/*.md'))),
    ],
    install_requires=['setuptools', 'numpy', 'scipy', 'mcap', 'EMD-signal', 'matplotlib',
                      'dask[distributed]', 'pyarrow'],
    extras_require={
        'test': ['pytest', 'pytest-xdist', 'hypothesis', 'flake8', 'pydocstyle', 'rosbags',
                 'mcap-ros2-support'],
    },
    zip_safe=True,
    maintainer='sensor_comp developers',
    maintainer_email='dev@sensor-comp.invalid',
    description='Identify and compensate the acceleration-induced error of pressure sensors.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'sensor-comp = sensor_comp.cli.main:main',
            'recorder = sensor_comp.nodes.recorder:main',
            'player = sensor_comp.nodes.player:main',
            'acquisition = sensor_comp.nodes.acquisition:main',
            'identification = sensor_comp.nodes.identification:main',
            'compensation = sensor_comp.nodes.compensation:main',
        ],
    },
)
