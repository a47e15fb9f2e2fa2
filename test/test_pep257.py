"""Docstring style: pep257 with ament's convention."""

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.linter
def test_pep257():
    main = pytest.importorskip('ament_pep257.main').main
    # ament's convention, except the two numpy-only rules (D406, D407) that demand a dashed
    # underline under 'Returns'/'Raises': our docstrings use Google sections ('Returns:').
    paths = [str(ROOT / p) for p in ('sensor_comp', 'test', 'bench', 'setup.py')]
    rc = main(argv=['--add-ignore', 'D406', 'D407', '--'] + paths)
    assert rc == 0, 'Found code style errors / warnings'
