"""
A zero shift whose decay spans several shots: the peak detector's memory in the windows.

Independent rig (:mod:`bench.independent_rig`, a simulator written apart from
``sensor_comp.sim``) whose zero shift is a leaky peak detector of ``|a_z|`` running over the
whole recording, as the compensation filter runs it: with a 134 ms decay and shots 20–40 ms
apart, a shot smaller than what the detector still holds of an earlier one adds no offset.
Windows fitted from rest predicted one for every shot (τ read as 57 ± 256 ms, the offset as
2.95 ± 4.1 Pa/g, validation fit 1.6 points below the noise-limited ceiling). Cut in two by
time, its validation recording starts while the last calibration shock still decays: what the
detector held then is read from the recording (the diagnosis said ``unexplained``).
"""

import functools

from bench.independent_rig import draw_spec, simulate
from sensor_comp.core.diagnosis.diagnose import diagnose
from sensor_comp.core.estimators import fit_percent
from sensor_comp.core.identification.identify import identify, ShotSource

#: Largest distance of the validation fit from the noise-limited ceiling, percentage points.
TOLERANCE_PP = 0.2


@functools.lru_cache(maxsize=None)
def _rig():
    spec = draw_spec(3884535365, effect='zero_shift', R=1.5, rate_range=(1e5, 3e5))
    case = simulate(spec)
    assert spec.shape['tau_ms'] > 100 and spec.fs < 3e5
    return spec, case, ShotSource.detect(case.recording)


def test_a_zero_shift_that_carries_from_shot_to_shot_is_read_within_its_deviation():
    _, case, source = _rig()
    result = identify([source], effects=['zero_shift'])
    entry = result.model.effects[0]
    for name, truth in case.truth['parameters'].items():
        value, std = entry['parameters'][name], entry['std'][name]
        assert std is not None and abs(value - truth) <= 3 * std, (name, value, std, truth)
    assert entry['std']['tau_ms'] < 0.1 * entry['parameters']['tau_ms']
    # Alternate shots validate (identify's default): the noise-limited ceiling on them.
    shots, clean = source.shots[1::2], case.clean_pressure
    ceiling = fit_percent([source.recording.pressure[s.window] - s.baseline_pa for s in shots],
                          [clean[s.window] - clean[s.baseline_window].mean() for s in shots])
    assert result.validation_fit_percent >= ceiling - TOLERANCE_PP, \
        (result.validation_fit_percent, ceiling)


def test_the_diagnosis_names_it_on_a_validation_recording_cut_while_it_decays():
    spec, case, _ = _rig()
    recording = case.recording
    half = len(spec.shots) // 2
    cut = int(spec.fs * (max(p.stop_s for p in spec.shots[half - 1].axes)
                         + spec.shots[half].z.onset_s) / 2)
    calib = ShotSource.detect(recording.slice(0, cut))
    valid = ShotSource.detect(recording.slice(cut, recording.n_samples))
    base = identify([calib], validation=[valid])
    result = diagnose([calib], [valid], base=base.model)
    assert result.verdict == 'missing_effect' and result.named == ('zero_shift',), \
        result.explanation
    assert result.leftover.consistent
    parameters = result.entry('zero_shift').parameters
    for name, truth in case.truth['parameters'].items():
        value, std = parameters[name]
        assert std is not None and abs(value - truth) <= 3 * std, (name, value, std, truth)
