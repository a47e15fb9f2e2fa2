"""The verdict from ranked candidates, on stand-in entries (no fits)."""

from dataclasses import replace
from types import SimpleNamespace

import pytest

from sensor_comp.core.diagnosis import verdict
from sensor_comp.core.diagnosis.findings import Diagnosis, Ranked
from sensor_comp.core.diagnosis.verdict import verdict_of


def _ranked(effect, score, *, consistent, significant=True):
    """Return a ranking entry whose leftover is (or is not) consistent with the noise."""
    ratio = 1.02 if consistent else 3.0
    left = SimpleNamespace(consistent=consistent, energy_ratio=ratio, excess=ratio - 1.0,
                           noise_variance=1.0, peak_above=False,
                           describe=lambda: '1.02× the noise energy')
    return Ranked(effect=effect, title=effect.replace('_', ' '), score=score, parameters={},
                  evidence='', significant=significant, statistic=100.0, test='chi2',
                  p_value=1e-9, fit_percent=99.0, peak_residual_percent=1.0, units={},
                  explained=5.0, excess_share=0.9, relevant=significant, leftover=left)


def _entry(effect, explained, excess, *, significant=True, relevant=None):
    """Return a consistent ranking entry that removes ``explained`` and leaves ``excess``."""
    left = SimpleNamespace(consistent=True, energy_ratio=1.0 + excess, excess=excess,
                           noise_variance=1.0, peak_above=False,
                           describe=lambda: 'about the noise energy')
    return replace(_ranked(effect, explained / 10, consistent=True, significant=significant),
                   explained=explained, leftover=left,
                   relevant=significant if relevant is None else relevant)


@pytest.mark.parametrize('second_consistent, expected', [(True, 'ambiguous'),
                                                         (False, 'missing_effect')])
def test_two_effects_that_each_leave_only_noise_are_ambiguous(second_consistent, expected):
    # An accelerometer resonance (outside the catalogue) of seed 21 was named as base strain
    # although a second mode left only noise too: no single name is then the answer.
    ranked = [_ranked('strain_sensitivity', 0.132, consistent=True),
              _ranked('second_resonance', 0.130, consistent=second_consistent),
              _ranked('zero_shift', 0.002, consistent=True, significant=False)]
    ctx = SimpleNamespace(samples=1000, sse=1200.0, allowance=lambda: 0.06)
    found, explanation, named, left, _, _ = verdict_of(ranked, ctx, ranked[0].leftover)
    assert found == expected and left is ranked[0].leftover
    if expected == 'ambiguous':
        assert named == ('strain_sensitivity', 'second_resonance')
        assert explanation.startswith('ambiguous: strain sensitivity (strain_sensitivity)')
        assert 'cannot tell it from strain_sensitivity' in explanation
    else:
        assert named == ('strain_sensitivity',) and 'cannot tell' not in explanation


@pytest.mark.parametrize('strain_excess, expected', [
    (-0.014, 'ambiguous'), (0.020, 'ambiguous'), (0.045, 'missing_effect')])
def test_a_rival_that_leaves_as_little_beyond_its_own_floor_is_alike(strain_excess, expected):
    # Seed 35 rig 83 (1.48 MS/s, strain -16.7 Pa/(g/ms) at R = 1.5): a 62 µs delay removed
    # 3.3 noise energies, the strain 1.6 (it passes more accelerometer noise), yet the strain
    # left 0.986 of its own noise floor against the delay's 1.020: it was named the delay.
    # Leaving more beyond its floor, even within the margin, it is told apart by the energy.
    ranked = [_entry('channel_delay', 3.3, 0.020),
              _entry('strain_sensitivity', 1.6, strain_excess)]
    ctx = SimpleNamespace(samples=1000, sse=1200.0, allowance=lambda: 0.06)
    found, explanation, named, _, _, _ = verdict_of(ranked, ctx, ranked[0].leftover)
    assert found == expected
    if expected == 'ambiguous':
        assert named == ('channel_delay', 'strain_sensitivity')
        assert 'cannot tell it from channel_delay' in explanation
    else:
        assert named == ('channel_delay',)


@pytest.mark.parametrize('excess, relevant, expected', [
    (0.046, True, 'ambiguous'), (0.080, True, 'missing_effect'),
    (0.046, False, 'missing_effect')])
def test_a_counted_candidate_short_of_a_name_that_leaves_less_is_alike(excess, relevant,
                                                                       expected):
    # Seed 37 rig 106 (667 kS/s, a 24.8 kHz second mode at R = 0.5): a strain removed 8 % of
    # the residual energy and left 1.075 of its floor; the second mode, read 24.83 ± 0.03 kHz
    # and beyond noise, was short of a name by its share of the base's excess (its floor is
    # higher), yet left 1.046 of it: the strain alone was named.
    ranked = [_entry('strain_sensitivity', 0.9, 0.075),
              _entry('second_resonance', 0.1, excess, significant=False, relevant=relevant)]
    ctx = SimpleNamespace(samples=1000, sse=1200.0, allowance=lambda: 0.06)
    found, _, named, _, _, _ = verdict_of(ranked, ctx, ranked[0].leftover)
    assert found == expected
    assert named == (('strain_sensitivity', 'second_resonance') if expected == 'ambiguous'
                     else ('strain_sensitivity',))


def test_a_form_outside_the_catalogue_that_passes_for_the_best_makes_it_ambiguous():
    # A cubic drive (seed 21, rig 99) was named nonlinear sensitivity: its a|a| fit left only
    # noise, and on the base residual G·a³ explained as much as G·(a|a|).
    best = replace(_ranked('nonlinear_sensitivity', 0.716, consistent=True),
                   untold='G·a³ (a cubic drive)')
    ranked = [best, _ranked('zero_shift', 0.03, consistent=False, significant=False)]
    ctx = SimpleNamespace(samples=1000, sse=1200.0, allowance=lambda: 0.06)
    found, explanation, named, left, _, _ = verdict_of(ranked, ctx, best.leftover)
    assert found == 'ambiguous' and named == ('nonlinear_sensitivity',)
    assert "do not tell its form from nonlinear_sensitivity's" in explanation
    fields = dict.fromkeys(('ranking', 'skipped', 'base', 'base_effects', 'fit_percent',
                            'peak_residual_percent', 'noise_sigma_pa', 'energy_ratio',
                            'energy_tolerance', 'consistent_with_noise'))
    diagnosis = Diagnosis(**dict(fields, verdict=found, ranking=tuple(ranked), named=named))
    assert diagnosis.alternatives == ('G·a³ (a cubic drive)',)
    assert diagnosis.named_words == 'nonlinear_sensitivity or G·a³ (a cubic drive)'
    # Named as the answer, the same entry's form is not in doubt.
    assert replace(diagnosis, verdict='missing_effect').alternatives == ()


def test_a_partly_explained_verdict_names_what_removes_as_much(monkeypatch):
    # Seed 25's rig 88 (a 20.4 kHz second mode) was partly explained by strain, which
    # removed 0.674 noise energies against the mode's 0.645, and the mode was not mentioned.
    monkeypatch.setattr(verdict, '_second', lambda best, others, ctx: None)
    best = replace(_ranked('strain_sensitivity', 0.423, consistent=False), explained=0.674)
    rival = replace(_ranked('second_resonance', 0.404, consistent=False), explained=0.645)
    far = replace(_ranked('zero_shift', 0.30, consistent=False), explained=0.674 - 0.051)
    ctx = SimpleNamespace(samples=1000, sse=1200.0, allowance=lambda: 0.06)
    found, explanation, named, *_ = verdict_of([best, rival, far], ctx, best.leftover)
    assert found == 'partly_explained' and named == ('strain_sensitivity',)
    assert ('. Second resonance (second_resonance, 40.4 %, leaving 3.00× the noise energy) '
            'removes as much') in explanation
    assert 'zero_shift' not in explanation
    found, explanation, *_ = verdict_of([best, far], ctx, best.leftover)
    assert found == 'partly_explained' and 'as much' not in explanation


def test_a_cause_outside_the_catalogue_needs_an_improvement_beyond_noise():
    ctx = SimpleNamespace(alpha=1e-3 / 8)
    why = 'the fit cancels 19.2 kHz where the measured acceleration rings'
    chance = replace(_ranked('second_resonance', 0.02, consistent=True, significant=False),
                     p_value=0.01, outside=why)
    assert verdict._outside([chance], ctx) is None  # an improvement chance gives finds nothing
    beyond = replace(chance, p_value=1e-12)
    plain = replace(beyond, effect='strain_sensitivity', outside=None)
    assert verdict._outside([plain], ctx) is None  # beyond noise, but in the catalogue's form
    found = verdict._outside([plain, beyond], ctx)
    assert found.startswith('second resonance (second_resonance) improves it beyond noise '
                            '(p = 1e-12, 5.000 noise energies)') and found.endswith(why)
