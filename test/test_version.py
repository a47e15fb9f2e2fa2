"""One version: the package, setup.py and package.xml agree."""

from pathlib import Path
import re
import xml.etree.ElementTree as ElementTree

from sensor_comp import __version__

ROOT = Path(__file__).resolve().parents[1]


def test_setup_py_and_package_xml_state_the_package_version():
    setup = re.search(r"version='([^']+)'", (ROOT / 'setup.py').read_text()).group(1)
    package = ElementTree.parse(ROOT / 'package.xml').getroot().findtext('version')
    assert setup == package == __version__
