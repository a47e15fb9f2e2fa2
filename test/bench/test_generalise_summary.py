"""The generalisation summary: detection split by what the base leaves; joint parameters; names."""

import math

import pytest

from bench.bench_generalise import (_params_each, _params_ok, _visible_line, _wrongly_named,
                                    joint_z, PARAMETER_Z)


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


def test_an_effects_parameters_are_checked_jointly_at_one_parameters_coverage():
    one = math.erf(PARAMETER_Z / math.sqrt(2))
    for k in (1, 2, 3):
        assert math.erf(joint_z(k) / math.sqrt(2)) ** k == pytest.approx(one, rel=1e-9)
    assert joint_z(1) == pytest.approx(PARAMETER_Z) and 2.4 < joint_z(3) < 2.45
    check = {'freq_khz': {'z': 2.3, 'ok': False}, 'zeta': {'z': 0.4, 'ok': True},
             'gain': {'z': 1.0, 'ok': True}}
    row = {'true': {'check': check}}
    assert _params_ok(row) and not _params_each(row)
    check['freq_khz']['z'] = 2.5
    assert not _params_ok(row)
    del check['gain']  # two parameters: 2.27 std each
    check['freq_khz']['z'] = 2.3
    assert not _params_ok(row)


def test_only_a_missing_effect_verdict_without_the_hidden_effect_is_a_wrong_name():
    row = _row('strain_sensitivity', 1.5, False, 3.0)
    assert _wrongly_named(dict(row, verdict='missing_effect', named=['channel_delay']))
    # Both added by a two-effect verdict, or told to be indistinguishable: not wrong.
    assert not _wrongly_named(dict(row, verdict='missing_effect',
                                   named=['channel_delay', 'strain_sensitivity']))
    assert not _wrongly_named(dict(row, verdict='ambiguous',
                                   named=['channel_delay', 'strain_sensitivity']))
    # Rows kept before the names were: the confidently named first entry.
    assert _wrongly_named(dict(row, verdict='missing_effect'))
    assert not _wrongly_named(dict(_row('strain_sensitivity', 1.5, True, 3.0),
                                   verdict='missing_effect'))
