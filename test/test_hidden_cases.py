"""
Acceptance tests of the diagnosis loop on the bundled hidden-effect bag pairs.

For every pair ``bags/case_<x>_calib.mcap`` / ``case_<x>_valid.mcap`` (the case table and
its answers are in ``hidden_cases.py``), as a user would do it: detect the shots, identify
the base model on the calibration bag (output error, orders (2, 2), one sample of delay, no
EMD), and diagnose it with the validation bag. Then:

- the hidden effect ranks first and the verdict is ``missing_effect``; the clean pair is
  ``adequate``; with two hidden effects both rank in the top two;
- adding the effect (the ranked entry's extended model, fitted on calibration shots and
  scored on validation shots; with two effects, the second round of the loop: the model
  with the first effect diagnosed again) lowers the worst validation peak residual of the
  identified base model by at least 60 % and brings the validation fit within one point
  of the noise-limited ceiling (the diagnosis's own base, with an exact sensor numerator,
  may already hold part of that fall);
- the recovered physical parameters are within 15 % of the simulator's truth.

The ceiling is the fit of the simulator's own clean pressure (induced plus disturbance, run
again from the case's settings) to the measured pressure over the same validation windows,
baselines removed as :func:`~sensor_comp.core.shots.detection.segments` removes them: what a
perfect model scores given the noise.
"""

from dataclasses import dataclass
import functools
import importlib.util
from pathlib import Path
import sys

import numpy as np
import pytest

from sensor_comp.cli.main import build_parser
from sensor_comp.cli.simulate import build_config
from sensor_comp.core.diagnosis.diagnose import Diagnosis, diagnose
from sensor_comp.core.effects import EFFECTS
from sensor_comp.core.estimators import fit_percent
from sensor_comp.core.identification.identify import identify, ShotSource
from sensor_comp.core.shots.detection import segments
from sensor_comp.io.bag_reader import read_recording
from sensor_comp.sim import simulate


def _load_cases():
    """Import ``hidden_cases.py`` by path (test modules cannot import each other)."""
    path = Path(__file__).with_name('hidden_cases.py')
    spec = importlib.util.spec_from_file_location('hidden_cases', path)
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault(spec.name, module)  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


CASES = _load_cases()
#: Least fraction of the worst validation peak residual the missing effect removes.
PEAK_REDUCTION = 0.6
#: Largest distance of the extended model's validation fit below the ceiling, points.
CEILING_POINTS = 1.0
#: Largest relative error of a recovered physical parameter.
PARAMETER_TOLERANCE = 0.15

SINGLE = [c for c in CASES.CASES if len(c.effects) == 1]
PAIRS = [c for c in CASES.CASES if len(c.effects) == 2]
CLEAN = [c for c in CASES.CASES if not c.effects]


def _ids(case) -> str:
    return f'case_{case.name}'


@dataclass(frozen=True)
class Outcome:
    """
    What the loop gives on one pair.

    Attributes:
        diagnosis: The diagnosis of the base model.
        extended: By effect id, the ranked entry that adds it: to the base model; with
            two hidden effects, the second to the base model with the first (both in).
        ceiling: Validation fit of the simulator's clean pressure, %.
        base_peak: Worst validation peak residual of the identified base model, %.

    """

    diagnosis: Diagnosis
    extended: dict
    ceiling: float
    base_peak: float


def _source(case, role: str) -> ShotSource:
    path = CASES.BAGS / case.bag(role)
    if not path.is_file():
        pytest.fail(f'{path} is missing: run python test/hidden_cases.py')
    return ShotSource.detect(read_recording(path), path=str(path))


def _ceiling(case, valid: ShotSource) -> float:
    """Return the noise-limited validation fit (the simulator's clean pressure), %."""
    args = build_parser().parse_args(['simulate', '-o', case.bag('valid'), *case.argv('valid')])
    config = build_config(args)
    sim = simulate(config)
    # Same run, other library versions or CPU: the refined-grid recursion of N steps may
    # differ by up to N float64 round-offs of the peak (measured: 1e5 eps; a wrong run
    # differs by the noise, 1e-3 of the peak).
    steps = config.oversample * sim.recording.pressure.size
    peak = np.abs(valid.recording.pressure).max()
    np.testing.assert_allclose(
        sim.recording.pressure, valid.recording.pressure, rtol=0,
        atol=steps * np.finfo(float).eps * peak,
        err_msg=f'{case.bag("valid")} is not the run its case describes: regenerate the bags')
    clean = sim.induced + sim.disturbance
    measured = [y for _, y in segments(valid.recording, valid.shots)]
    model = [clean[s.window] - clean[s.baseline_window].mean() for s in valid.shots]
    return fit_percent(measured, model)


@functools.cache
def outcome(name: str) -> Outcome:
    """Run the loop on case ``name`` once for all the tests."""
    case = next(c for c in CASES.CASES if c.name == name)
    calib, valid = _source(case, 'calib'), _source(case, 'valid')
    base = identify([calib], validation=[valid], structure='oe', orders=(2, 2), delay=1,
                    denoise=False).model
    diagnosis = diagnose([calib], [valid], base=base)
    extended = {}
    if len(case.effects) == 1:
        extended[case.effect_ids[0]] = diagnosis.entry(case.effect_ids[0])
    elif len(case.effects) == 2:
        # The loop's second round: add the better-ranked effect, diagnose again.
        position = {r.effect: i for i, r in enumerate(diagnosis.ranking)}
        first, second = sorted(case.effect_ids, key=lambda e: position.get(e, len(position)))
        again = diagnose([calib], [valid], base=diagnosis.entry(first).fit.model(),
                         candidates=[second])
        extended[second] = again.entry(second)
    return Outcome(diagnosis, extended, _ceiling(case, valid),
                   base.fit['validation_peak_residual_percent'])


@pytest.mark.parametrize('case', CLEAN, ids=_ids)
def test_clean_pair_is_adequate(case):
    result = outcome(case.name)
    diagnosis = result.diagnosis
    assert diagnosis.verdict == 'adequate', diagnosis.summary()
    assert not diagnosis.significant
    # Nothing is missing: the base model is at the noise ceiling already.
    assert diagnosis.fit_percent >= result.ceiling - CEILING_POINTS


@pytest.mark.parametrize('case', SINGLE, ids=_ids)
def test_hidden_effect_ranks_first(case):
    diagnosis = outcome(case.name).diagnosis
    if diagnosis.verdict == 'ambiguous':  # a form outside the catalogue fits as well (a³)
        assert diagnosis.named == case.effect_ids[:1], diagnosis.summary()
        assert diagnosis.alternatives and diagnosis.alternatives[0] not in EFFECTS
    else:
        assert diagnosis.verdict == 'missing_effect', diagnosis.summary()
    best = diagnosis.ranking[0]
    assert best.effect == case.effect_ids[0], [(r.effect, r.score) for r in diagnosis.ranking]
    assert best.significant


@pytest.mark.parametrize('case', PAIRS, ids=_ids)
def test_both_hidden_effects_rank_in_the_top_two(case):
    diagnosis = outcome(case.name).diagnosis
    assert diagnosis.verdict == 'missing_effect', diagnosis.summary()
    top = diagnosis.ranking[:2]
    assert {r.effect for r in top} == set(case.effect_ids), [
        (r.effect, r.score) for r in diagnosis.ranking]
    assert all(r.significant for r in top)
    # After adding the first, the second is still missing beyond noise.
    (entry,) = outcome(case.name).extended.values()
    assert entry.significant


@pytest.mark.parametrize('case', SINGLE + PAIRS, ids=_ids)
def test_adding_the_effect_removes_the_peak_residual(case):
    result = outcome(case.name)
    before = result.base_peak
    for entry in result.extended.values():
        reduction = 1 - entry.peak_residual_percent / before
        assert reduction >= PEAK_REDUCTION, (
            f'{entry.effect}: worst validation peak residual {before:.2f} % -> '
            f'{entry.peak_residual_percent:.2f} % ({100 * reduction:.0f} % less)')


@pytest.mark.parametrize('case', SINGLE + PAIRS, ids=_ids)
def test_adding_the_effect_reaches_the_noise_ceiling(case):
    result = outcome(case.name)
    for entry in result.extended.values():
        assert entry.fit_percent >= result.ceiling - CEILING_POINTS, (
            f'{entry.effect}: validation fit {entry.fit_percent:.2f} %, ceiling '
            f'{result.ceiling:.2f} % (base model {result.diagnosis.fit_percent:.2f} %)')


@pytest.mark.parametrize('case', SINGLE + PAIRS, ids=_ids)
def test_physical_parameters_are_recovered(case):
    (entry,) = outcome(case.name).extended.values()
    for effect_id, truth in case.truth().items():
        fitted = entry.fit.parameters(effect_id)
        for name, value in truth.items():
            estimate = fitted[name][0]
            assert abs(estimate - value) <= PARAMETER_TOLERANCE * abs(value), (
                f'{effect_id}.{name}: recovered {estimate:.4g}, truth {value:.4g}')


def test_the_tutorial_base_of_case_f_is_diagnosed_as_missing_the_high_pass():
    """
    The README tutorial: case f identified with EMD and orders 2 2, then diagnosed.

    The high-pass candidate on the diagnosis's base (numerator lags 0..2) stayed in an
    overdamped basin and left 4.3× the noise: a false ``partly_explained``. Fitted as well
    as ``identify --effect`` fits it, it leaves a residual within the noise band.
    """
    case = next(c for c in CASES.CASES if c.name == 'f')
    calib, valid = _source(case, 'calib'), _source(case, 'valid')
    base = identify([calib], validation=[valid], structure='oe', orders=(2, 2)).model
    diagnosis = diagnose([calib], [valid], base=base)
    assert diagnosis.verdict == 'missing_effect', diagnosis.summary()
    assert diagnosis.named == ('amplifier_highpass',)
    assert diagnosis.leftover.consistent, diagnosis.leftover.describe()
    tau, std = diagnosis.entry('amplifier_highpass').parameters['tau_ms']
    assert abs(tau - 8.0) <= 2 * std, (tau, std)
