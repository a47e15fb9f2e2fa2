"""
The base model without effects, fitted as an effect's fit is (``identify._corrected_base``).

Independent rigs of the generalisation benchmark. Seed 39's case 39 (1.26 MS/s, a
58.17 kHz sensor with ζ 0.021, a strain term at R = 0.5, below the noise): fitted to the
EMD-denoised pressure the base read ζ 0.041 and left 2.9 noise ceilings at the worst
validation peak (the sensor's ringing at every pulse onset); refitted to the measured
pressure and corrected for the accelerometer's noise it must leave no more than the
benchmark's 1.5 noise ceilings and read the damping within 25 %. Where the corrected fit
leaves the held-out shots more energy than least squares (a sensor mode the shots barely
excite), least squares stay. Extra poles the held-out shots refuse give way to two. A
structure other than output error is left as fitted.
"""

import math

import numpy as np
import pytest

from bench.independent_rig import draw_spec, simulate as simulate_rig
from sensor_comp.core.estimators.metrics import fit_percent
from sensor_comp.core.estimators.polynomials import resonances
from sensor_comp.core.identification.identify import _thinned, identify, ShotSource
from sensor_comp.sim import RigConfig, simulate, TABLE2

#: Criterion 4 of the generalisation benchmark: the worst peak within this many ceilings.
CEILINGS = 1.5


def rig(seed: int, effect: str, ratio: float, rates: tuple[float, float]):
    """Return the rig's spec, its identification (calibration: first half) and ceilings."""
    spec = draw_spec(seed, effect=effect, R=ratio, rate_range=rates)
    case = simulate_rig(spec)
    cut, (calibration, validation) = case.halves()
    result = identify([ShotSource.detect(calibration)],
                      validation=[ShotSource.detect(validation)])
    return spec, result, ceilings(case, cut, validation)


def ceilings(case, cut: int, validation) -> tuple[float, float]:
    """
    Return what a perfect model fed the measured acceleration leaves on ``validation``.

    Its worst peak residual (%) and its fit (%), windows and baselines as the comparison's.
    """
    source = ShotSource.detect(validation)
    span = slice(cut, cut + validation.n_samples)
    noise = validation.pressure - case.clean_pressure[span] - case.accel_noise_pressure[span]
    measured = [validation.pressure[s.window] - s.baseline_pa for s in source.shots]
    left = [noise[s.window] - np.mean(noise[s.baseline_window]) for s in source.shots]
    peak = max(100 * float(np.max(np.abs(r)) / np.max(np.abs(y)))
               for y, r in zip(measured, left))
    return peak, float(fit_percent(measured, [y - r for y, r in zip(measured, left)]))


def assert_the_sensor_at_the_ceiling(spec, result, ceiling: float) -> None:
    """Assert the worst peak within the criterion and the sensor's mode read (3 %, 25 %)."""
    peak = result.model.fit['validation_peak_residual_percent']
    assert peak <= CEILINGS * ceiling, (peak, ceiling, result.explanation)
    [(hz, zeta)] = [(f, z) for f, z in resonances(result.model.a, spec.fs)
                    if abs(f - spec.fn_hz) < 0.05 * spec.fn_hz]
    assert hz == pytest.approx(spec.fn_hz, rel=0.03)
    assert zeta == pytest.approx(spec.zeta, rel=0.25), (zeta, spec.zeta)


@pytest.mark.slow
def test_the_base_refitted_and_corrected_reaches_the_ceiling():
    spec, result, (ceiling, _) = rig(4168394101, 'strain_sensitivity', 0.5, (1e6, 2e6))
    assert 'then fitted to the measured pressure' in result.explanation
    assert 'then corrected for the accelerometer\'s noise' in result.explanation
    assert_the_sensor_at_the_ceiling(spec, result, ceiling)


@pytest.mark.slow
def test_two_poles_replace_extra_ones_the_held_out_shots_refuse():
    # Seed 39's case 101 (391 kS/s, a 38.6 kHz sensor with ζ 0.083 behind a 39.1 kHz
    # anti-alias corner, an accelerometer resonance at 59.8 kHz at R = 5): the selection
    # chose four poles, whose corrected fit kept ζ 0.093 and left 2.85 noise ceilings at
    # the worst peak; two poles, corrected, read ζ 0.082 and left 0.7.
    spec, result, (ceiling, _) = rig(910560367, 'accel_resonance', 5.0, (300e3, 1e6))
    assert 'then two poles (the sensor\'s own mode) instead of the nf=4' in result.explanation
    assert result.model.orders['na'] == 2
    assert_the_sensor_at_the_ceiling(spec, result, ceiling)


def test_least_squares_stay_where_the_correction_leaves_more_energy():
    # Seed 2 (207 kS/s, a 32.5 kHz sensor behind a 4-pole anti-alias filter, the mode
    # excited 0.9 times above the accelerometer noise): corrected, ζ 0.091 → 0.034 (truth
    # 0.041), the held-out fit fell from 94.07 % to 93.69 %, 13 % more energy.
    _, result, (_, fit) = rig(2, 'amplifier_highpass', 0.5, (100e3, 2e6))
    assert 'then not corrected for the accelerometer\'s noise' in result.explanation, \
        result.explanation
    # Damped against the accelerometer noise, least squares predict the held-out shots
    # better than the sensor itself would.
    assert result.validation_fit_percent >= fit, (result.validation_fit_percent, fit)


def test_an_equation_error_base_is_left_as_fitted():
    sim = simulate(RigConfig(shots=TABLE2[:6], fs=200e3, seed=3))
    source = ShotSource.detect(sim.recording)
    result = identify([source], structure='arx', orders=(2, 3), delay=0, denoise=False)
    assert 'corrected for the accelerometer' not in result.explanation
    assert result.model.structure == 'arx'
    assert 'base_nf' not in result.model.fit


def test_thinning_keeps_every_kth_shot_within_the_budget():
    sim = simulate(RigConfig(shots=TABLE2[:6], fs=200e3, seed=3))
    source = ShotSource.detect(sim.recording)
    parts = [ShotSource(source.recording, source.shots[:4]),
             ShotSource(source.recording, source.shots[4:])]
    sizes = [s.stop - s.start for s in source.shots]
    thinned, kept = _thinned(parts, math.ceil(sum(sizes) / 2))  # every second shot
    assert kept == [0, 2, 4]
    assert [s.shots for s in thinned] == [source.shots[0:3:2], source.shots[4:5]]
    whole, every = _thinned(parts, sum(sizes))
    assert every == list(range(len(sizes)))
    assert [s.shots for s in whole] == [p.shots for p in parts]
