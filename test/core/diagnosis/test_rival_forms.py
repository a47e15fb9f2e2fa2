"""
An effect whose extension only passes for another form is not named (rival probes).

A cubic drive ``a + κ a³`` (outside the catalogue) is fitted almost to the noise by the
catalogue's ``a|a|`` nonlinearity: over a pulse the two shapes differ by a few per cent of
their energy. The cubic probe explains that much more of the base residual and of what the
``a|a|`` fit leaves, so the diagnosis says ``unexplained`` and why, while an ``a|a|`` rig is
still found first. Where the two probes take the base residual within the practical share
of each other, neither form is the reading: ``ambiguous``, ``a|a|`` first. An accelerometer
resonance passes for a second mode exactly (and for base
strain below its frequency), which the acceleration's own ringing tells apart
(``Effect.confounded``). The rigs come from :mod:`bench.independent_rig` (the
generalisation benchmark's seed-1 cases 29, 43 and 87, and seed 4's cases 9 and 97, at
0.1-0.3 MS/s), seed 3's case 17 and seed 6's case 132.
"""

from types import SimpleNamespace

import pytest
from scipy import stats

from bench.independent_rig import draw_spec, simulate
from sensor_comp.core.diagnosis.diagnose import diagnose
from sensor_comp.core.diagnosis.findings import AMPLITUDE_ALPHA
from sensor_comp.core.diagnosis.noise_floor import PRACTICAL_SHARE
from sensor_comp.core.diagnosis.rival_forms import untold_form
from sensor_comp.core.diagnosis.scoring import unresolved_amplitude
from sensor_comp.core.effects import get_effect
from sensor_comp.core.effects.base import RIVAL_MARGIN, RIVAL_SHARE
from sensor_comp.core.identification.identify import ShotSource

NONLINEAR = 'nonlinear_sensitivity'
BAND = (1e5, 3e5)


def _halves(effect, seed, R=1.5, rate_range=BAND):
    case = simulate(draw_spec(seed, effect=effect, R=R, rate_range=rate_range))
    return case.truth, [ShotSource.detect(r) for r in case.halves()[1]]


def _analysis(own: float, cube: float):
    probe = SimpleNamespace
    return SimpleNamespace(probes={'abs_square': probe(fraction=0.5, statistic=own),
                                   'cube': probe(fraction=0.5, statistic=cube)})


def test_a_rival_must_beat_the_own_probe_by_the_margin_and_the_share():
    effect = get_effect(NONLINEAR)
    own = 1e4
    edge = (1 + RIVAL_SHARE) * own + RIVAL_MARGIN
    assert effect.rival(_analysis(own, edge - 1.0)) is None
    why = effect.rival(_analysis(own, edge + 1.0))
    assert why is not None and 'cubic' in why
    # Without the analysis (or without the effect's own probe) nothing is doubted.
    assert effect.rival(None) is None
    assert get_effect('mains_hum').rival(_analysis(own, 10 * own)) is None


def test_a_form_is_read_only_when_it_beats_its_rival_by_the_practical_share():
    # A cubic drive at R = 1.5 and 1 MS/s (seed 21, rig 99): G·(a|a|) and G·a³ took 31255
    # and 33123 noise variances of the base residual over 133171 samples, within the
    # practical share (6659) of each other, and the a|a| fit left only noise.
    effect, samples = get_effect(NONLINEAR), 133171
    assert untold_form(effect, _analysis(31255.0, 33123.0), samples=samples).name == 'cube'
    edge = PRACTICAL_SHARE * samples
    assert untold_form(effect, _analysis(1e4 + edge - 1.0, 1e4), samples=samples) is not None
    assert untold_form(effect, _analysis(1e4 + edge + 1.0, 1e4), samples=samples) is None
    assert untold_form(effect, None, samples=samples) is None
    # A form searched over a grid may hold its rival's (a drift with a short rise is a jump).
    zero_shift = get_effect('zero_shift')
    grids = SimpleNamespace(probes={zero_shift.probes[0].name: SimpleNamespace(statistic=1.0),
                                    zero_shift.rivals[0].name: SimpleNamespace(statistic=9.0)})
    assert untold_form(zero_shift, grids, samples=samples) is None


@pytest.mark.slow
def test_a_cubic_drive_is_unexplained_not_a_sensitivity_changing_with_load():
    truth, (calibration, validation) = _halves('cubic_nonlinearity', 1179198021)
    result = diagnose([calibration], [validation])
    assert result.verdict == 'unexplained'
    entry = next(r for r in result.ranking if r.effect == NONLINEAR)
    assert not entry.significant and 'cubic' in entry.evidence
    assert 'still explains' in entry.evidence  # in what the a|a| fit leaves, too
    probes = result.analyses[0].probes
    # The cubic form explains more than the a|a| one by more than the forms' own difference.
    assert probes['cube'].statistic > (1 + RIVAL_SHARE) * probes['abs_square'].statistic


def _found_first_form_untold(result):
    """Assert a|a| is found first, its fit leaving noise, and its form not told from a³."""
    top = result.ranking[0]
    assert result.verdict == 'ambiguous' and top.effect == NONLINEAR and top.significant
    assert result.named == (NONLINEAR,) and 'cubic drive' in result.alternatives[0]
    assert top.leftover.consistent
    return top


@pytest.mark.slow
def test_a_sensitivity_changing_with_load_is_found_first_though_its_form_is_untold():
    # The base residual took 84987 noise variances of G·(a|a|) and 85403 of G·a³: within
    # the practical share the shots do not tell the forms apart (a cubic drive alike).
    truth, (calibration, validation) = _halves(NONLINEAR, 3390017097)
    result = diagnose([calibration], [validation])
    top = _found_first_form_untold(result)
    value, std = top.parameters['beta_per_g']
    assert abs(value - truth['parameters']['beta_per_g']) <= 3 * std


@pytest.mark.slow
def test_a_strong_sensitivity_change_at_a_low_rate_is_found_despite_the_rival():
    # a|a| at R = 5 and 187 kS/s (seed-1 case 87): the base residual's misfit makes G·a³
    # explain more than G·(a|a|), but what the a|a| fit leaves holds nothing of a cubic drive.
    # While the base's mode could sit below 1 kHz the fit left 1.3x the noise and the verdict
    # was partly_explained; with the sensor's mode held at 1 kHz or more it leaves the noise.
    # A cubic drive's a|a| fit leaves nothing of G·a³ either: the form stays untold.
    truth, (calibration, validation) = _halves(NONLINEAR, 2978456523, R=5.0)
    result = diagnose([calibration], [validation])
    top = _found_first_form_untold(result)
    assert 'does not follow that form' in top.evidence
    value, std = top.parameters['beta_per_g']
    assert abs(value - truth['parameters']['beta_per_g']) <= 3 * std


@pytest.mark.slow
def test_a_rival_the_fit_leaves_nothing_of_does_not_unfind_the_effect():
    # a|a| at R = 5 and 695 kS/s (seed-3 case 17): the base residual's misfit makes G·a³
    # explain more of it than G·(a|a|) by more than the margin, but what the a|a| fit leaves
    # holds nothing of a cubic drive: the rival is judged there and the effect is named.
    truth, (calibration, validation) = _halves(NONLINEAR, 2815252342, R=5.0,
                                               rate_range=(3e5, 1e6))
    result = diagnose([calibration], [validation])
    probes = result.analyses[0].probes
    own, cube = probes['abs_square'].statistic, probes['cube'].statistic
    assert cube > (1 + RIVAL_SHARE) * own + RIVAL_MARGIN  # the old rule would unname it
    top = _found_first_form_untold(result)
    assert 'does not follow that form' in top.evidence
    value, std = top.parameters['beta_per_g']
    assert abs(value - truth['parameters']['beta_per_g']) <= 3 * std


@pytest.mark.slow
def test_an_accelerometer_resonance_is_not_named_a_second_mode():
    # A 26.4 kHz mode in the accelerometer channel only (fraction 0.23, R = 1.5, 153 kS/s;
    # seed-4 case 97): the pressure predicted from the measured acceleration has exactly
    # the second-mode form (a mode at 30.1 kHz, gain -0.39), which the diagnosis named. Its
    # zero pair sits where the acceleration rings after the pulses and the pressure does not.
    truth, (calibration, validation) = _halves('accel_resonance', 1784411294)
    result = diagnose([calibration], [validation])
    entry = next(r for r in result.ranking if r.effect == 'second_resonance')
    assert not entry.significant and 'accelerometer' in entry.evidence, entry.evidence
    assert f"cancels {truth['parameters']['freq_khz']:.3g} kHz" in entry.evidence
    assert 'second_resonance' not in result.significant


@pytest.mark.slow
def test_a_second_mode_beside_an_anvil_ringing_is_still_named():
    # A 9.95 kHz mount mode at gain -0.014 beside a 10.1 kHz anvil ringing (R = 1.5,
    # 270 kS/s; seed-4 case 9): the acceleration rings near the fit's zeros, but the
    # pressure follows that ringing. Base strain left only noise too while its derivative
    # was half a sample late (ambiguous); with the zero-lag one the mode is named alone.
    truth, (calibration, validation) = _halves('second_resonance', 3813740144)
    result = diagnose([calibration], [validation])
    top = result.ranking[0]
    assert result.verdict == 'missing_effect' and top.effect == 'second_resonance', \
        result.explanation
    assert result.named == ('second_resonance',)
    value, std = top.parameters['freq_khz']
    assert abs(value - truth['parameters']['freq_khz']) <= 3 * std


@pytest.mark.slow
def test_an_accelerometer_resonance_above_the_pulses_is_not_named_strain():
    # A 27.3 kHz mode in the accelerometer channel only (R = 1.5, 327 kS/s; seed-6 case
    # 132): below it the pressure predicted from the measured acceleration gains a leading
    # derivative term, which the diagnosis named base strain with confidence. Not counted:
    # the accelerometer's ringing explains it, or (first, since the strain term owns the
    # lead that pays back a pair damped at the bound) its coefficient is not told from zero.
    truth, (calibration, validation) = _halves('accel_resonance', 2489710441,
                                               rate_range=(3e5, 1e6))
    result = diagnose([calibration], [validation])
    entry = next(r for r in result.ranking if r.effect == 'strain_sensitivity')
    assert not entry.significant, entry.evidence
    assert ('accelerometer' in entry.evidence
            or 'not told apart from zero' in entry.evidence), entry.evidence
    assert not result.significant, result.explanation


@pytest.mark.slow
def test_a_small_lead_beside_a_base_that_leaves_noise_is_not_named():
    # A 58 kHz mode in the accelerometer channel only, far above a 20.1 kHz anti-alias
    # corner (R = 1.5, 201 kS/s; seed-21 case 97): the base leaves only noise, and a strain
    # term of 0.071 ± 0.034 Pa/(g/ms) removed 18 % of it with p = 0 and was named with
    # confidence. Corrected for the accelerometer noise it reads 0.071 ± 0.022 and leaves
    # no less beyond its own noise floor than the free-numerator base: not named.
    _, (calibration, validation) = _halves('accel_resonance', 2882586782,
                                           rate_range=(1e5, 3e5))
    result = diagnose([calibration], [validation])
    entry = result.entry('strain_sensitivity')
    assert result.base_leftover.consistent
    assert not entry.significant, entry.evidence
    assert result.verdict == 'adequate', result.explanation


def test_an_amplitude_meets_the_family_wise_level():
    # Eight candidates share a 5 % false-alarm level: |z| above norm.isf(0.05 / 16) = 2.73.
    ctx = SimpleNamespace(amplitude_alpha=AMPLITUDE_ALPHA / 8)
    effect = get_effect('strain_sensitivity')
    level = float(stats.norm.isf(AMPLITUDE_ALPHA / 16))
    assert level == pytest.approx(2.73, abs=0.005)

    def doubt(z):
        return unresolved_amplitude(effect, {effect.amplitude: (z * 0.02, 0.02)}, ctx)

    assert 'not told apart from zero beside the other candidates' in doubt(0.99 * level)
    assert doubt(-0.99 * level) is not None
    assert doubt(1.01 * level) is None and doubt(-1.01 * level) is None
    # An effect without an amplitude, or an amplitude without a deviation, is left to the
    # effect's own checks.
    assert get_effect('amplifier_highpass').amplitude is None
    assert unresolved_amplitude(get_effect('amplifier_highpass'), {'tau_ms': (8.0, 0.01)},
                                ctx) is None
    assert unresolved_amplitude(effect, {effect.amplitude: (0.01, None)}, ctx) is None


@pytest.mark.slow
def test_a_structure_change_does_not_carry_a_name_its_amplitude_cannot():
    # A 59.6 kHz accelerometer-only resonance at 416 kS/s (R = 1.5; seed-21 case 27): the
    # strain candidate's own free-numerator channel took 55 % of the residual with a
    # coefficient of -0.055 ± 0.027 Pa/(g/ms) (|z| 2.05) and was named with confidence.
    _, (calibration, validation) = _halves('accel_resonance', 366403,
                                           rate_range=(3e5, 1e6))
    result = diagnose([calibration], [validation])
    strain = result.entry('strain_sensitivity')
    assert not strain.significant, strain.evidence
    assert 'strain_sensitivity' not in result.named, result.explanation
