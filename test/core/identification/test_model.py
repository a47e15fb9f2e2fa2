"""
The model file and its physics view, against an exactly discretised continuous truth.

A second-order ``K ωn² / (s² + 2ζωn s + ωn²)`` discretised with zero-order hold maps every
pole exactly (``z = e^{sT}``) and keeps the DC gain, so natural frequency, damping and
static sensitivity recovered from the discrete polynomials must match to rounding.
"""

import hashlib
import json
import math

import numpy as np
import pytest
from scipy import signal

from sensor_comp.core.estimators import Estimate, fit_oe, Segment
from sensor_comp.core.identification.model import (frequency_response, load, Model, ModelError,
                                                   SCHEMA, Source, step_response)

G0 = 9.80665
FN, ZETA = 5000.0, 0.05
SENS_MPA_PER_G = 1.4e-4
GAIN = SENS_MPA_PER_G * 1e6 / G0  # Pa per m/s²


def zoh(fs, *, fn=FN, zeta=ZETA, gain=GAIN):
    """Return ``(b, a)`` of the ZOH-discretised truth with ``nk = 1``, ``nb = 2``."""
    w = 2 * math.pi * fn
    ss = (np.array([[0.0, 1.0], [-w * w, -2 * zeta * w]]), np.array([[0.0], [gain * w * w]]),
          np.array([[1.0, 0.0]]), np.array([[0.0]]))
    num, den = signal.ss2tf(*signal.cont2discrete(ss, 1 / fs, method='zoh')[:4])
    return num.ravel()[1:], den


def model(fs=1e6, **kw):
    b, a = zoh(fs, **{k: kw.pop(k) for k in ('fn', 'zeta', 'gain') if k in kw})
    return Model(fs=fs, structure='oe', inputs=('a_z',), b=b, a=a, nk=1, **kw)


@pytest.mark.parametrize('fs', [1e6, 200e3])
def test_continuous_view_matches_truth(fs):
    view = model(fs, charge_sensitivity_pC_per_MPa=100.0).continuous()
    assert not view.overdamped
    assert view.natural_frequency_hz == pytest.approx(FN, rel=1e-6)
    assert view.damping_ratio == pytest.approx(ZETA, rel=1e-6)
    assert view.static_gain[0] == pytest.approx(GAIN, rel=1e-9)
    assert view.sensitivity_MPa_per_g == pytest.approx(SENS_MPA_PER_G, rel=1e-9)
    assert view.sensitivity_pC_per_g == pytest.approx(SENS_MPA_PER_G * 100.0, rel=1e-9)
    assert model(fs).continuous().sensitivity_pC_per_g is None


def test_overdamped_view_gives_time_constants():
    zeta = 2.0
    view = model(1e6, zeta=zeta).continuous()
    assert view.overdamped and view.natural_frequency_hz is None and view.damping_ratio is None
    w = 2 * math.pi * FN
    poles = np.roots([1, 2 * zeta * w, w * w])  # both real, negative
    assert view.time_constants_s == pytest.approx(sorted(-1 / poles, reverse=True), rel=1e-6)
    assert view.to_json()['damping_ratio'] == 'overdamped'


def test_dominant_pair_is_the_resonance():
    # A second, heavily damped pair far above the resonance must not be reported.
    b, a = zoh(1e6)
    w2 = 2 * math.pi * 100e3
    extra = np.real(np.poly(np.exp(np.roots([1, 2 * 0.7 * w2, w2 * w2]) / 1e6)))
    m = Model(fs=1e6, structure='oe', inputs=('a_z',), b=b * extra.sum(),
              a=np.convolve(a, extra), nk=1)
    view = m.continuous()
    assert view.natural_frequency_hz == pytest.approx(FN, rel=1e-6)
    assert view.static_gain[0] == pytest.approx(GAIN, rel=1e-9)


def test_frequency_and_step_response():
    m = model(1e6)
    f, h = frequency_response(m, f_hz=[1.0, FN * math.sqrt(1 - 2 * ZETA ** 2), 1000.0])
    assert h.shape == (1, 3)
    assert abs(h[0, 0]) == pytest.approx(GAIN, rel=1e-6)
    # Resonance peak of a second-order system: K / (2ζ√(1−ζ²)).
    assert abs(h[0, 1]) == pytest.approx(GAIN / (2 * ZETA * math.sqrt(1 - ZETA ** 2)),
                                         rel=1e-3)
    w, wn = 2 * math.pi * 1000.0, 2 * math.pi * FN
    analog = GAIN * wn ** 2 / (wn ** 2 - w ** 2 + 2j * ZETA * wn * w)
    assert abs(h[0, 2]) == pytest.approx(abs(analog), rel=1e-3)
    f, h = frequency_response(m, n=256)
    assert f.shape == (256,) and f[0] > 0 and f[-1] == pytest.approx(0.5e6)

    t, y = step_response(m, duration_s=5e-3)
    assert t.shape == y[0].shape == (5000,)
    assert y[0, 0] == 0.0 and y[0, -1] == pytest.approx(GAIN, rel=1e-3)
    overshoot = y[0].max() / GAIN - 1
    assert overshoot == pytest.approx(math.exp(-math.pi * ZETA / math.sqrt(1 - ZETA ** 2)),
                                      rel=1e-3)
    with pytest.raises(ModelError, match='positive'):
        step_response(m, duration_s=0)


def test_round_trip(tmp_path):
    bag = tmp_path / 'shots.mcap'
    bag.write_bytes(b'not really a bag' * 100)
    source = Source.from_file(bag, shots=[0, 2, {'index': 3, 'start': 10, 'stop': 20}])
    assert source.sha256 == hashlib.sha256(bag.read_bytes()).hexdigest()
    rng = np.random.default_rng(0)
    b, a = zoh(200e3)
    u = np.zeros((2, 400))
    u[0, 20:120] = np.sin(np.linspace(0, np.pi, 100))
    u[1, 60:200] = np.sin(np.linspace(0, np.pi, 140))
    segs = [Segment(u, signal.lfilter(np.r_[0, b], a, u[0] - 0.3 * u[1])
                    + 1e-4 * rng.standard_normal(400))]
    est = fit_oe(segs, nf=2, nb=2, nk=1)
    m = Model.from_estimate(est, fs=200e3, inputs=('a_z', 'a_x'),
                            charge_sensitivity_pC_per_MPa=98.5, fit={'valid_fit': 97.5},
                            provenance=[source],
                            effects=[{'id': 'transverse_sensitivity', 'axis': 'x'}])
    path = tmp_path / 'model.json'
    m.save(path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ['model.json', 'shots.mcap']
    doc = json.loads(path.read_text())
    assert doc['schema'] == SCHEMA and doc['orders'] == {'na': 2, 'nb': 2, 'nc': 0, 'nd': 0,
                                                         'nk': 1}
    assert doc['continuous']['natural_frequency_hz'] == pytest.approx(
        m.continuous().natural_frequency_hz)
    back = Model.load(path)
    for name in ('fs', 'structure', 'inputs', 'nk', 'charge_sensitivity_pC_per_MPa', 'fit',
                 'provenance', 'effects', 'created', 'version'):
        assert getattr(back, name) == getattr(m, name), name
    for name in ('a', 'b', 'a_std', 'b_std'):
        np.testing.assert_array_equal(getattr(back, name), getattr(m, name))
    assert back.c is None and back.d is None
    assert back.fit['valid_fit'] == 97.5 and back.fit['n_parameters'] == 6
    np.testing.assert_array_equal(back.b_std, est.b_std)
    assert back.continuous() == m.continuous()
    m.save(path)  # overwrite in place
    assert sorted(p.name for p in tmp_path.iterdir()) == ['model.json', 'shots.mcap']


def test_from_estimate_checks_inputs():
    est = Estimate(structure='arx', a=[1.0, -0.5], b=[[1.0]], nk=0, covariance=np.eye(2),
                   noise_variance=1.0, loss=1.0, n_samples=10)
    with pytest.raises(ModelError, match=r"shape \(2, nb\)"):
        Model.from_estimate(est, fs=1e3, inputs=('a_z', 'a_x'))
    m = Model.from_estimate(est, fs=1e3)
    assert m.inputs == ('a_z',) and m.created.endswith('Z')
    with pytest.raises(ModelError, match='effect 0'):
        Model.from_estimate(est, fs=1e3, effects=[{'name': 'no id'}])


def test_unstable_model_is_refused():
    m = Model(fs=1e6, structure='arx', inputs=('a_z',), b=[1e-3], a=[1.0, -2.1, 1.1], nk=0)
    with pytest.raises(ModelError, match=r'unstable.*\|z\| = 1\.100000'):
        m.check_stable()
    model(1e6).check_stable()
    with pytest.raises(ModelError, match='unstable'):
        model(1e6).check_stable(margin=0.01)  # the poles sit at |z| = 0.9984


def _write(tmp_path, doc):
    path = tmp_path / 'm.json'
    path.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    return path


@pytest.mark.parametrize('change, match', [
    (lambda d: d.update(schema='sensor_comp.model/2'), r"model/2.*cannot read"),
    (lambda d: d.update(schema='something else'), 'not a sensor_comp model'),
    (lambda d: d.pop('denominator'), "lacks the key.*'denominator'"),
    (lambda d: d.update(fs='1e6'), "'fs' must be int/float"),
    (lambda d: d.update(fs=-5.0), 'positive finite'),
    (lambda d: d['orders'].update(nb=3), 'orders.nb = 3 does not match'),
    (lambda d: d.update(denominator=[2.0, -1.0]), 'must start with 1'),
    (lambda d: d.update(numerators={'a_x': [1.0, 2.0]}), 'one list per input'),
    (lambda d: d['numerators'].update(a_z=[1.0, 'x']), r"numerators\['a_z'\] must be a list"),
    (lambda d: d.update(structure='fir'), 'structure must be one of'),
    (lambda d: d.update(effects=[{'id': 3}]), 'effect 0'),
    (lambda d: d.update(provenance=[{'path': 'a.mcap'}]), r'provenance\[0\]'),
    (lambda d: d['fit'].update(loss=[1, 2]), "fit statistic 'loss'"),
])
def test_schema_errors(tmp_path, change, match):
    doc = model(1e6).to_json()
    doc['fit'] = {'loss': 1.0}
    change(doc)
    with pytest.raises(ModelError, match=match) as info:
        load(_write(tmp_path, doc))
    assert 'm.json' in str(info.value)


def test_non_finite_and_broken_files(tmp_path):
    text = json.dumps(model(1e6).to_json())
    first = text.index('"denominator": [') + len('"denominator": [')
    broken = text[:first] + 'NaN' + text[text.index(',', first):]
    with pytest.raises(ModelError, match='finite'):
        load(_write(tmp_path, broken))
    with pytest.raises(ModelError, match='finite'):
        load(_write(tmp_path, text.replace('"fs": 1000000.0', '"fs": 1e999')))
    with pytest.raises(ModelError, match='not valid JSON'):
        load(_write(tmp_path, text[:-10]))
    with pytest.raises(ModelError, match='JSON object'):
        load(_write(tmp_path, '[1, 2]'))
    with pytest.raises(ModelError, match='cannot read'):
        load(tmp_path / 'missing.json')
    with pytest.raises(ModelError, match='cannot write'):
        model(1e6).save(tmp_path / 'no' / 'such' / 'dir.json')
    with pytest.raises(ModelError, match='non-finite'):
        Model(fs=1e6, structure='oe', inputs=('a_z',), b=[np.nan], a=[1.0, -0.5], nk=0)
