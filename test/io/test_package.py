"""The entry points ``sensor_comp.io`` and ``sensor_comp.core`` export, loaded on first use."""

import importlib
import subprocess
import sys

import pytest


@pytest.mark.parametrize('package', ['sensor_comp.io', 'sensor_comp.core'])
def test_every_exported_name_resolves_to_its_module_object(package):
    module = importlib.import_module(package)
    for name in module.__all__:
        value = getattr(module, name)
        assert getattr(importlib.import_module(value.__module__), name) is value
        assert name in dir(module)
    with pytest.raises(AttributeError):
        getattr(module, 'no_such_name')


def test_importing_the_packages_imports_none_of_their_modules():
    code = ('import sys, sensor_comp.io, sensor_comp.core; '
            'print(sorted(m for m in sys.modules if m.startswith(("sensor_comp.io.", '
            '"sensor_comp.core."))))')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == '[]'
