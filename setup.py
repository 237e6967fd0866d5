"""ament_python build of id_learning (colcon) and pip install (the Makefile's venv)."""

from __future__ import annotations

from glob import glob

from setuptools import find_packages, setup

PACKAGE = 'id_learning'

setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(include=[PACKAGE, f'{PACKAGE}.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', [f'resource/{PACKAGE}']),
        (f'share/{PACKAGE}', ['package.xml']),
        (f'share/{PACKAGE}/config', glob('config/*.yaml')),
        (f'share/{PACKAGE}/launch', glob('launch/*.py')),
        (f'share/{PACKAGE}/urdf', glob('urdf/*.urdf')),
        (f'share/{PACKAGE}/bags/default', glob('bags/default/*')),
    ],
    install_requires=['setuptools'],
    extras_require={'test': ['pytest', 'hypothesis']},
    zip_safe=True,
    maintainer='id_learning maintainers',
    maintainer_email='maintainers@id-learning.dev',
    description='Inverse-dynamics learning and tau_u feed-forward for industrial robots.',
    license='Apache-2.0',
    python_requires='>=3.11',
    entry_points={
        'console_scripts': [
            # Each program is imported inside Ctrl-C's handling (id_learning/entry.py).
            'id-learning = id_learning.entry:cli',
            'train = id_learning.entry:train',
            'recorder = id_learning.entry:recorder',
            'replay = id_learning.entry:replay',
            'predictor = id_learning.entry:predictor',
        ],
    },
)
