"""The generalisation benchmark's summary splits detection by what the base leaves."""

from bench.bench_generalise import _visible_line


def _row(effect, R, found, before, ceiling=2.0):
    ranking = [{'effect': effect if found else 'zero_shift', 'significant': True}]
    return {'effect': effect, 'R': R, 'ranking': ranking, 'before_percent': before,
            'ceiling_percent': ceiling}


def test_detection_is_split_at_the_absorbed_ceiling():
    rows = [_row('strain_sensitivity', 5.0, True, 10.0),    # shown, found
            _row('strain_sensitivity', 1.5, False, 3.5),    # shown (1.75x), missed
            _row('channel_delay', 1.5, False, 2.9),         # hidden (1.45x), missed
            _row('channel_delay', 1.5, True, 2.0),          # hidden, found
            _row('channel_delay', 0.5, False, 9.0),         # R below 1.5: not counted
            _row('thermal_drift', 5.0, False, 9.0)]         # outside the catalogue
    line = _visible_line(rows)
    assert 'leaves > 1.5x' in line
    shown, hidden = line.split('; where it does not: ')
    assert shown.endswith('found 1/2 (50 %)') and hidden == 'found 1/2 (50 %)'
