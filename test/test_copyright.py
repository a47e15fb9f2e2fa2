"""License headers: ament_copyright, where installed (it is not on PyPI)."""

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.linter
def test_copyright():
    main = pytest.importorskip('ament_copyright.main').main
    rc = main(argv=[str(ROOT / 'sensor_comp'), str(ROOT / 'test')])
    assert rc == 0, 'Found errors'
