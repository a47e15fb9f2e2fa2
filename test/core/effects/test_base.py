"""The effect readings' shared helpers: the delta method's deviations."""

import math

import numpy as np
import pytest

from sensor_comp.core.effects import get_effect
from sensor_comp.core.effects.base import delta_std
from sensor_comp.core.identification.model import Model

# Seed 35's rig 79 (1.81 MS/s): the base's pair is a 6.65 kHz, ζ 0.013 second mode (the
# search took the sensor's 38.2 kHz mode), five taps on one input. Their regressors are
# nearly collinear: each coefficient's deviation reaches 46 while their combinations are
# known to 1e-4 (the correlation matrix's eigenvalues span 1.8e-16 to 5.7).
FS = 1_811_000.0
A = np.array([1.0, -1.9988537599092275, 0.9993860253925274])
B = np.array([[5.508935044826163, -5.590961798155765, 0.02303889205587614,
               -5.281861035898278, 5.349409543594203]])
INPUTS = ('a_z@mode=38.23072333640459,0.08462139716833675',)
COVARIANCE = np.array([
    [7.2417778410879151e-12, -7.2654901726847276e-12, -1.0391877534574072e-05,
     4.2409576892832956e-05, -6.4883841508277091e-05, 4.4107014049784790e-05,
     -1.1240873502951315e-05],
    [-7.2654901726847276e-12, 7.2922420270284981e-12, 1.0642090498079090e-05,
     -4.3441934116336236e-05, 6.6479760761815684e-05, -4.5202649041243837e-05,
     1.1522733557153588e-05],
    [-1.0391877534574072e-05, 1.0642090498079090e-05, 5.2840846841023051e+01,
     -2.1751099032541154e+02, 3.3551625228165307e+02, -2.2986625943057911e+02,
     5.9020157694911859e+01],
    [4.2409576892832956e-05, -4.3441934116336236e-05, -2.1751099032541154e+02,
     8.9541043742070747e+02, -1.3812818316760445e+03, 9.4639007995110558e+02,
     -2.4300772435206488e+02],
    [-6.4883841508277091e-05, 6.6479760761815684e-05, 3.3551625228165307e+02,
     -1.3812818316760445e+03, 2.1309272084753056e+03, -1.4600952045099841e+03,
     3.7493362000901425e+02],
    [4.4107014049784790e-05, -4.5202649041243837e-05, -2.2986625943057911e+02,
     9.4639007995110558e+02, -1.4600952045099841e+03, 1.0004998052721891e+03,
     -2.5692845174428601e+02],
    [-1.1240873502951315e-05, 1.1522733557153588e-05, 5.9020157694911859e+01,
     -2.4300772435206488e+02, 3.7493362000901425e+02, -2.5692845174428601e+02,
     6.5982406194147600e+01]])


def _model(a: np.ndarray, b: np.ndarray) -> Model:
    """Return rig 79's fitted model with the polynomials ``a`` and ``b``."""
    return Model(fs=FS, structure='oe', inputs=INPUTS, b=b, a=a, nk=0,
                 effects=({'id': 'second_resonance', 'std': {}},))


def _sampled_std(func, samples: int = 4000) -> np.ndarray:
    """Return half the central 68 % width of ``func`` over draws of the coefficients."""
    scale = np.sqrt(np.diag(COVARIANCE))
    share, vectors = np.linalg.eigh(COVARIANCE / np.outer(scale, scale))
    axes = scale[:, None] * vectors * np.sqrt(np.clip(share, 0.0, None))
    theta = np.concatenate([A[1:], B.ravel()])
    rng = np.random.default_rng(0)
    values = []
    for _ in range(samples):
        t = theta + axes @ rng.standard_normal(theta.size)
        values.append(func(np.concatenate([[1.0], t[:2]]), t[2:].reshape(B.shape)))
    low, high = np.percentile(np.array(values), [15.87, 84.13], axis=0)
    return (high - low) / 2


def test_deviations_of_collinear_numerators_follow_the_sampled_spread():
    # The second mode's readings sampled from the covariance (4000 draws: the spread's
    # own error about 1.5 %) against the delta method's: within 5 %. Steps along each
    # coefficient read the gain -0.0126 ± 0.075 (round-off over a 1e-8 step weighted by
    # a variance of 2000); the spread is ± 1.0e-4, so the mode is told from zero.
    effect = get_effect('second_resonance')
    read = effect.physical(_model(A, B), covariance=COVARIANCE)

    def readings(a, b):
        return [v for v, _ in effect.physical(_model(a, b)).values()]

    sampled = _sampled_std(readings, samples=4000)
    for (name, (value, std)), spread in zip(read.items(), sampled):
        assert std == pytest.approx(spread, rel=0.05), name
    gain, std = read['gain']
    assert gain == pytest.approx(-0.0126, abs=1e-4)
    assert abs(gain) > 50 * std


def test_a_linear_reading_has_its_exact_deviation():
    # A linear reading's variance is the covariance's quadratic form, whatever the axes.
    def reading(a, b):
        return float(2 * a[1] + b[0, 0] - b[0, 2])

    g = np.array([2.0, 0.0, 1.0, 0.0, -1.0, 0.0, 0.0])
    exact = math.sqrt(g @ COVARIANCE @ g)
    assert delta_std(reading, A, B, COVARIANCE) == pytest.approx(exact, rel=1e-6)


def test_no_deviation_without_a_covariance():
    def first(a, b):
        return float(a[1])

    assert delta_std(first, A, B, None) is None
    assert delta_std(first, A, B, np.full((7, 7), np.nan)) is None
    assert delta_std(first, A, B, np.eye(3)) is None  # not the coefficients' shape
    broken = np.eye(7)
    broken[0, 1] = broken[1, 0] = 2.0  # a correlation of 2: no covariance
    assert delta_std(first, A, B, broken) is None
    assert delta_std(first, A, B, np.diag([4.0] + [1.0] * 6)) == pytest.approx(2.0)
