"""
The identification workflow on simulated rig data with a known truth (issue 3).

The rig simulator gives the sensor's linear response (fn = 5 kHz, ζ = 0.05,
S = 1.4e-4 MPa/g, no hidden effect) plus white pressure noise of 0.5 % of the largest
induced peak, and hands back the clean induced pressure. The best any model can do on the
validation windows is the *noise-limited ceiling*: the fit of that clean pressure against the
measurement over the same windows, baselines removed as :func:`segments` removes them. An
unbiased estimator (output error) must land within :data:`TOLERANCE_PP` of it, and its
continuous-time view must match the simulator's sensor.

Shot windows hold 2 ms of pre-trigger and 5 ms after the pulse: the sensor's ringing decays
by e⁻⁵ in 5/(ζω) = 3.2 ms. The delay is given as ``nk = 1`` where the delay search is not the
point: the simulator has no channel delay, and a sampled continuous second-order system
driven by a first-order-hold input has its numerator on lags 0..2, which ``nb = 2, nk = 1``
captures (the delay search finds ``nk = 1`` too; the ``'auto'`` test runs it).
"""

import functools
import hashlib

import numpy as np
import pytest
from scipy import signal

from sensor_comp.bundled import bundled_bag
from sensor_comp.core.estimators import fit_percent, IdentError
from sensor_comp.core.estimators.selection import EARLIER
from sensor_comp.core.identification.identify import identify, ShotSource
from sensor_comp.core.shots.detection import ShotError
from sensor_comp.core.shots.windows import EARLY_S
from sensor_comp.io.bag_reader import read_recording
from sensor_comp.io.bag_writer import write_recording
from sensor_comp.sim import random_shots, RigConfig, simulate, TABLE2
from sensor_comp.streams import Recording

#: Largest distance of an unbiased fit from the noise-limited ceiling, percentage points.
TOLERANCE_PP = 0.5
#: Relative tolerances on the identified physics against the simulator's sensor.
SENSITIVITY_REL, FN_REL, ZETA_REL = 0.02, 0.05, 0.30
#: How far ARX must fall below OE (and GLS rise above ARX) on every seed: twice the
#: tolerance an unbiased fit gets around the ceiling, so the ordering cannot come from
#: estimator scatter (OE lands within hundredths of a point of the ceiling).
BIAS_MARGIN_PP = 2 * TOLERANCE_PP
#: Shot windows (see the module docstring).
DETECT = {'pre_ms': 2.0, 'post_ms': 5.0}
#: Table-2 pulses shorter than this (the 1963 g and 2185 g shots) leave ringing well above
#: the noise (see test_simulated_sensor_rings_above_the_noise).
SHORT_PULSE_S = 1.0e-3
RATES = (1e6, 200e3)


@functools.lru_cache(maxsize=None)
def rig(fs: float, seed: int = 0, shots=TABLE2):
    """Return a simulated run and its detected shots (cached: shared by the fixtures)."""
    sim = simulate(RigConfig(shots=shots, fs=fs, seed=seed, pre_trigger_s=0.005,
                             post_shot_s=0.01))
    return sim, ShotSource.detect(sim.recording, **DETECT)


def identify_one(source, *, structure='oe', denoise=False, **options):
    """Identify one structure (output error by default), delay 1, EMD only when asked."""
    return identify([source], structure=structure, delay=1, denoise=denoise, **options)


def ceiling(validation, induced):
    """
    Return the fit of the clean induced pressure against the measurement.

    Over the validation windows of each source (one clean ``induced`` array per source),
    baselines removed as the workflow removes them: the mean of each shot's pre-trigger.
    """
    ys, clean = [], []
    for source, truth in zip(validation, induced, strict=True):
        for shot in source.shots:
            ys.append(source.recording.pressure[shot.window] - shot.baseline_pa)
            clean.append(truth[shot.window] - np.mean(truth[shot.baseline_window]))
    return fit_percent(ys, clean)


def recomputed_fit(ident):
    """
    Return the model's validation fit, simulated here with ``scipy.signal.lfilter``.

    Against the pressure as measured (never denoised) over the validation windows, from
    rest at each window start.
    """
    model = ident.model
    num = np.concatenate([np.zeros(model.nk), model.b[0]])
    ys, yhats = [], []
    for source in ident.validation:
        for shot in source.shots:
            u = source.recording.axial[shot.window] - shot.baseline_acceleration[2]
            ys.append(source.recording.pressure[shot.window] - shot.baseline_pa)
            yhats.append(signal.lfilter(num, model.a, u))
    return fit_percent(ys, yhats)


def check_against_truth(ident, sim, induced=None):
    """Assert the validation fit is at the ceiling and the physics match the sensor."""
    best = ceiling(ident.validation, induced or [sim.induced])
    assert ident.validation_fit_percent == pytest.approx(recomputed_fit(ident), abs=1e-6)
    assert abs(ident.validation_fit_percent - best) <= TOLERANCE_PP, \
        f'validation fit {ident.validation_fit_percent:.3f} %, ceiling {best:.3f} %'
    view = ident.model.continuous()
    sensor = sim.config.sensor
    assert not view.overdamped
    assert view.sensitivity_MPa_per_g == pytest.approx(sensor.sensitivity_mpa_per_g,
                                                       rel=SENSITIVITY_REL)
    assert view.natural_frequency_hz == pytest.approx(sensor.fn_hz, rel=FN_REL)
    assert view.damping_ratio == pytest.approx(sensor.zeta, rel=ZETA_REL)


def shot_indices(sources):
    """Return the shot indices of every source, in order."""
    return [shot.index for source in sources for shot in source.shots]


@pytest.fixture(scope='module', params=RATES, ids=('1MSps', '200kSps'))
def run(request):
    """Return the Table-2 run at each sample rate and its shots."""
    return rig(request.param)


@pytest.fixture(scope='module')
def oe(run):
    """Return the output-error identification of the Table-2 run."""
    return identify_one(run[1])


def test_simulated_sensor_rings_above_the_noise(run):
    # The fn and ζ criteria need ringing above the noise. After a pulse ends the anvil is
    # at rest, so the clean induced pressure there is the sensor's free ringing alone:
    # after the short (< 1 ms) Table-2 pulses it must stand well above the noise σ.
    sim, _ = run
    fs = sim.recording.fs
    short = [t for t in sim.touches if t.shot.width_s < SHORT_PULSE_S]
    assert short
    for touch in short:
        first = int(np.ceil(touch.end_s * fs))
        free = sim.induced[first:first + round(1e-3 * fs)]
        assert np.max(np.abs(free)) > 10 * sim.pressure_noise_pa


def test_output_error_reaches_the_noise_ceiling_and_the_true_sensor(run, oe):
    sim, source = run
    assert len(source.shots) == len(TABLE2)
    check_against_truth(oe, sim)
    assert oe.model.structure == 'oe'
    assert oe.excluded == () and oe.denoising == ()


def test_auto_structure_reaches_the_noise_ceiling_and_the_true_sensor(run):
    sim, source = run
    ident = identify([source], structure='auto', denoise=False)
    check_against_truth(ident, sim)
    assert ident.selection is not None
    assert ident.model.structure == 'oe'


def test_auto_chooses_the_structure_on_the_pulses_and_their_ringing(run):
    """The orders are chosen up to EARLY_S after each pulse; delay and model on whole windows."""
    sim, source = run
    long = rig(sim.recording.fs, 4)[0].recording  # 15 ms after each pulse: a long rest
    long_source = ShotSource.detect(long, pre_ms=2.0, post_ms=15.0)
    ident = identify([long_source], structure='auto', denoise=False)
    fs = long.fs
    shots = [shot for s in ident.calibration for shot in s.shots]
    whole = sum(shot.stop - shot.start for shot in shots)
    early = sum(min(shot.stop, shot.end + round(EARLY_S * fs)) - shot.start for shot in shots)
    assert early < 0.8 * whole
    assert ident.selection.estimate.n_samples == early
    assert ident.model.fit['n_samples'] == whole
    assert f'up to {1e3 * EARLY_S:g} ms after its pulse' in ident.model.fit['selection']
    # The delays tried are read on the whole windows: the one found there, EARLIER below
    # it to one above.
    nk = ident.delay.nk
    assert {c.nk for c in ident.selection.candidates} == set(range(max(nk - EARLIER, 0),
                                                                   nk + 2))
    assert ident.model.a.size - 1 == 2  # the simulated sensor's two poles


@pytest.mark.parametrize('fs', RATES, ids=('1MSps', '200kSps'))
def test_arx_is_biased_and_gls_removes_the_bias_on_every_seed(fs):
    for seed in (1, 2, 3):
        _, source = rig(fs, seed)
        fits = {structure: identify_one(source, structure=structure).validation_fit_percent
                for structure in ('oe', 'arx', 'gls')}
        assert fits['arx'] < fits['oe'] - BIAS_MARGIN_PP, (seed, fits)
        assert fits['gls'] > fits['arx'] + BIAS_MARGIN_PP, (seed, fits)


def test_one_recording_validates_on_other_shots_than_it_fits(run, oe):
    _, source = run
    calibration, validation = shot_indices(oe.calibration), shot_indices(oe.validation)
    assert calibration and validation
    assert not set(calibration) & set(validation)
    assert sorted(calibration + validation) == shot_indices([source])
    assert all(s.recording is source.recording for s in oe.calibration + oe.validation)
    assert [row.index for c in oe.comparisons for row in c.shots] == validation
    assert oe.model.fit['calibration_shots'] == len(calibration)
    assert oe.model.fit['validation_shots'] == len(validation)
    assert oe.model.provenance == ()  # in-memory data: nothing to hash


def test_a_validation_recording_supplies_every_validation_shot():
    sim, calibration = rig(1e6)
    other, validation = rig(1e6, 7, random_shots(4, seed=7))
    ident = identify_one(calibration, validation=[validation])
    assert [s.recording for s in ident.validation] == [validation.recording]
    assert ident.validation[0].shots == validation.shots
    assert ident.calibration[0].shots == calibration.shots  # nothing held out
    assert [row.index for row in ident.comparisons[0].shots] == shot_indices([validation])
    check_against_truth(ident, sim, [other.induced])


def test_emd_denoising_keeps_the_fit_at_the_noise_ceiling(run, oe):
    sim, source = run
    ident = identify_one(source, denoise=True)
    # EMD denoises the calibration windows only; validation is on the measured pressure
    # (recomputed_fit in check_against_truth), so denoising cannot flatter the fit.
    check_against_truth(ident, sim)
    assert len(ident.denoising) == len(shot_indices(ident.calibration))
    assert ident.model.fit['emd_denoised'] is True
    assert oe.model.fit['emd_denoised'] is False
    # The calibration fit is reported against the measured pressure too: OE is unbiased by
    # white noise, so fitting the denoised target moves it by far less than the 0.5 pp
    # tolerance of the ceiling criterion.
    assert abs(ident.model.fit['calibration_fit_percent']
               - oe.model.fit['calibration_fit_percent']) < 0.1


def test_a_clipped_shot_is_left_out_with_a_message():
    sim, _ = rig(1e6)
    fs = sim.recording.fs
    peaks = np.array([np.max(sim.induced[int(t.onset_s * fs):int((t.end_s + 1e-3) * fs)])
                      for t in sim.touches])
    largest, second = np.argsort(peaks)[::-1][:2]
    level = (peaks[largest] + peaks[second]) / 2
    # Only the largest shot reaches the clipping level, with the noise far from deciding.
    assert peaks[largest] - level > 5 * sim.pressure_noise_pa
    rec = sim.recording
    clipped = Recording(fs=fs, t0_ns=rec.t0_ns, pressure=np.minimum(rec.pressure, level),
                        acceleration=rec.acceleration, frame_id=rec.frame_id,
                        metadata=rec.metadata)
    source = ShotSource.detect(clipped, **DETECT)
    ident = identify_one(source)
    assert len(ident.excluded) == 1
    assert f'shot {largest} ' in ident.excluded[0] and 'clipped' in ident.excluded[0]
    used = shot_indices(ident.calibration) + shot_indices(ident.validation)
    assert sorted(used) == [i for i in range(len(TABLE2)) if i != largest]
    check_against_truth(ident, sim)


def test_mixed_sample_rates_are_refused():
    _, fast = rig(1e6)
    _, slow = rig(200e3)
    with pytest.raises(IdentError, match='sample rates'):
        identify_one(fast, validation=[slow])
    with pytest.raises(IdentError, match='sample rates'):
        identify([fast, slow], structure='oe', delay=1, denoise=False)


def test_an_unknown_structure_is_refused():
    _, source = rig(1e6)
    with pytest.raises(IdentError, match="'bj'.*oe"):
        identify([source], structure='bj', denoise=False)


@pytest.mark.parametrize('role', ('calibration', 'validation'))
def test_a_recording_without_shots_is_refused_naming_it(role):
    _, source = rig(1e6)
    rng = np.random.default_rng(0)
    n = 50_000
    noise = Recording(fs=1e6, t0_ns=0, pressure=rng.standard_normal(n),
                      acceleration=rng.standard_normal((3, n)))
    # Noise alone stays below the 8 σ threshold.
    with pytest.raises(ShotError, match='^quiet.mcap: no shot found'):
        ShotSource.detect(noise, path='quiet.mcap', **DETECT)
    quiet = ShotSource(noise, (), 'quiet.mcap')
    calibration, validation = ([quiet], []) if role == 'calibration' else ([source], [quiet])
    # The documented error for "no usable shots" names the file and what to check.
    with pytest.raises(IdentError, match=f'no usable {role} shot.*quiet.mcap'):
        identify(calibration, validation=validation, structure='oe', delay=1, denoise=False)


def test_provenance_holds_the_sha256_of_each_bag(tmp_path):
    paths = {'calibration': tmp_path / 'calibration.mcap',
             'validation': tmp_path / 'validation.mcap'}
    runs = {'calibration': rig(1e6)[0], 'validation': rig(1e6, 5, random_shots(3, seed=5))[0]}
    sources = {}
    for role, path in paths.items():
        write_recording(path, runs[role].recording)
        sources[role] = ShotSource.detect(read_recording(path), path=str(path), **DETECT)
    ident = identify_one(sources['calibration'], validation=[sources['validation']])
    provenance = ident.model.provenance
    assert sorted(s.path for s in provenance) == sorted(str(p) for p in paths.values())
    for entry in provenance:
        role = 'calibration' if entry.path == str(paths['calibration']) else 'validation'
        assert entry.sha256 == hashlib.sha256(paths[role].read_bytes()).hexdigest()
        assert {shot['role'] for shot in entry.shots} == {role}
        assert [shot['index'] for shot in entry.shots] == shot_indices([sources[role]])
    check_against_truth(ident, runs['calibration'], [runs['validation'].induced])


def test_the_delay_search_is_not_led_off_by_a_misleading_start():
    """
    The search keeps the lower of its own start and the base fit's start (bundled case f).

    Case f's base lacks the amplifier high-pass, so its fit at nk = 1 is an overdamped
    pair; started from it, the search fell into nk = 18 (validation fit 83 %, worst peak
    residual 27 %) where its own start finds nk = 0 (95.4 %, 7.1 %).
    """
    sources = [ShotSource.detect(read_recording(bundled_bag(f'case_f_{role}.mcap')))
               for role in ('calib', 'valid')]
    ident = identify(sources[:1], validation=sources[1:], structure='oe', orders=(2, 2))
    assert ident.delay.nk <= 2
    assert ident.comparisons[0].fit_percent > 94.0


def test_the_grid_reaches_back_to_a_response_that_leads_its_input():
    """
    A delay read with one coefficient comes late where the response leads (base strain).

    An independent rig (``bench.independent_rig``; seed 19's case 56: 186 kS/s, the sensor's
    55 kHz mode beyond the 37 kHz anti-alias corner, strain at R = 5) reads nk = 3; the grid
    chose nk = 2 from ±1 and left 11.9 noise ceilings at the worst validation peak, where
    nk = 0, 3 below, leaves 2.0.
    """
    from bench.bench_generalise import _ceiling, _split
    from bench.independent_rig import draw_spec, simulate as simulate_rig
    spec = draw_spec(2592649607, effect='strain_sensitivity', R=5.0, rate_range=(1e5, 3e5))
    case = simulate_rig(spec)
    (calib, valid), cut = _split(case, via_csv=False, folder=None)
    ident = identify([calib], validation=[valid])
    assert ident.delay.nk - ident.model.nk >= 2
    low = max(ident.delay.nk - EARLIER, 0)
    assert f'delays nk={low}..{ident.delay.nk + 1} tried' in ident.model.fit['selection']
    ceiling = _ceiling(case, cut, ident.validation)
    assert ident.model.fit['validation_peak_residual_percent'] < 3.0 * ceiling
