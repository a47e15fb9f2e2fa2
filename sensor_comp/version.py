"""The package's version (setup.py and package.xml state the same: test_version)."""

__all__ = ['__version__']

__version__ = '0.1.0'
