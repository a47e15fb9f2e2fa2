"""
Residual figures: each axes holds the analysis' numbers, PNGs have content, no pyplot state.

The analysis comes from the rig simulator at 200 kS/s (Table-2 shots, a hidden 10 kHz
second mode plus load-dependent sensitivity) against the true single-mode sensor.
"""

import math

from matplotlib.image import imread
import numpy as np
import pytest
from scipy import signal

from sensor_comp.core.identification.model import Model
from sensor_comp.core.diagnosis.residual import analyse, SEGMENTS
from sensor_comp.core.report.residual_plots import (
    amplitude_figure, cross_correlation_figure, probes_figure, SEGMENT_COLOURS,
    segments_figure, spectrum_figure, whiteness_figure)
from sensor_comp.core.shots.detection import detect_shots
from sensor_comp.sim.config import RigConfig
from sensor_comp.sim.rig import simulate
from sensor_comp.sim.sensor import SensorConfig
from sensor_comp.sim.shots import TABLE2
from sensor_comp.streams import G0

FS = 200e3


@pytest.fixture(scope='module')
def analysis():
    sim = simulate(RigConfig(fs=FS, shots=TABLE2[:5], seed=2,
                             effects=('second_resonance', 'nonlinear_sensitivity')))
    sensor = SensorConfig()
    wn = 2 * math.pi * sensor.fn_hz
    gain = sensor.sensitivity_mpa_per_g * 1e6 / G0
    # The simulator integrates with a first-order hold: its exact discrete equivalent.
    b, a, _ = signal.cont2discrete(([gain * wn ** 2], [1, 2 * sensor.zeta * wn, wn ** 2]),
                                   1 / FS, method='foh')
    model = Model(fs=FS, structure='oe', inputs=('a_z',), b=np.atleast_2d(np.ravel(b)), a=a,
                  nk=0)
    return analyse(model, sim.recording, detect_shots(sim.recording))


def assert_png_has_content(path):
    image = imread(path)
    assert image.shape[0] > 200 and image.shape[1] > 300
    assert len(np.unique(image.reshape(-1, image.shape[-1]), axis=0)) > 50


def test_whiteness_figure_draws_the_autocorrelation_and_its_bands(analysis, tmp_path):
    fig = whiteness_figure(analysis, path=tmp_path / 'acf.png')
    (ax,) = fig.axes
    lines = ax.get_lines()
    w = analysis.whiteness
    assert np.allclose(lines[0].get_xdata(), 1e6 * w.lags[1:] / FS)
    assert np.allclose(lines[0].get_ydata(), w.values[1:])
    assert np.allclose(lines[1].get_ydata(), w.band[1:])
    assert np.allclose(lines[3].get_ydata(), w.family_band[1:])
    (noise,) = [line for line in lines if line.get_label() == 'noise before the trigger']
    assert np.allclose(noise.get_ydata(), analysis.pretrigger.values[1:])
    assert_png_has_content(tmp_path / 'acf.png')


def test_cross_correlation_figure_has_one_panel_per_channel(analysis, tmp_path):
    fig = cross_correlation_figure(analysis, path=tmp_path / 'ccf.png')
    axes = [ax for ax in fig.axes if ax.get_visible()]
    assert [ax.get_title().split(':')[0] for ax in axes] == ['a_z', 'a_x', 'a_y']
    for ax, name in zip(axes, ('a_z', 'a_x', 'a_y')):
        c = analysis.cross[name]
        line = ax.get_lines()[0]
        assert np.allclose(line.get_xdata(), 1e6 * c.lags / FS)
        assert np.allclose(line.get_ydata(), c.values)
    assert_png_has_content(tmp_path / 'ccf.png')


def test_segments_figure_colours_the_residual_of_each_shot(analysis, tmp_path):
    fig = segments_figure(analysis, path=tmp_path / 'segments.png')
    axes = [ax for ax in fig.axes if ax.get_visible()]
    assert len(axes) == len(analysis.shots)
    for ax, shot in zip(axes, analysis.shots):
        traces = [line for line in ax.get_lines() if not line.get_label().startswith('_')]
        assert [line.get_label().split()[0] for line in traces] == list(SEGMENTS)
        for line, name in zip(traces, SEGMENTS):
            assert line.get_color() == SEGMENT_COLOURS[name]
        # The segments join into the whole residual (kPa), one shared sample at each joint.
        joined = np.concatenate([traces[0].get_ydata()] +
                                [line.get_ydata()[1:] for line in traces[1:]])
        assert np.allclose(joined, shot.residual / 1e3)
    assert_png_has_content(tmp_path / 'segments.png')


def test_spectrum_figure_marks_the_peaks(analysis, tmp_path):
    fig = spectrum_figure(analysis, path=tmp_path / 'psd.png')
    (ax,) = fig.axes
    sp = analysis.spectrum
    assert np.allclose(ax.get_lines()[0].get_ydata(), sp.psd[1:])
    markers = [line for line in ax.get_lines() if line.get_marker() == 'o']
    assert [line.get_xdata()[0] for line in markers] == pytest.approx(
        [p.frequency_hz / 1e3 for p in sp.peaks])
    # The hidden 10 kHz mode is drawn as a peak the model lacks (red).
    second = [m for m, p in zip(markers, sp.peaks) if abs(p.frequency_hz - 10e3) < 300]
    assert second and second[0].get_color() == 'tab:red'
    assert_png_has_content(tmp_path / 'psd.png')


def test_amplitude_figure_draws_the_fitted_power_law(analysis, tmp_path):
    trend = analysis.amplitude
    assert trend.exponent is not None
    fig = amplitude_figure(analysis, path=tmp_path / 'amplitude.png')
    (ax,) = fig.axes
    points, law = ax.get_lines()[:2]
    assert len(points.get_xdata()) == sum(trend.used)
    x, y = law.get_xdata(), law.get_ydata()
    slope = np.log(y[-1] / y[0]) / np.log(x[-1] / x[0])
    assert slope == pytest.approx(trend.exponent)
    assert y[0] == pytest.approx(trend.scale_pa * x[0] ** trend.exponent / 1e3)
    assert_png_has_content(tmp_path / 'amplitude.png')


def test_probes_figure_bars_are_the_fractions(analysis, tmp_path):
    fig = probes_figure(analysis, path=tmp_path / 'probes.png')
    (ax,) = fig.axes
    names = [t.get_text() for t in ax.get_yticklabels()]
    joint, alone = ax.containers
    assert [bar.get_width() for bar in joint] == pytest.approx(
        [100 * analysis.probes[n].fraction for n in names])
    assert [bar.get_width() for bar in alone] == pytest.approx(
        [100 * analysis.probes[n].fraction_alone for n in names])
    assert names[-1] in ('abs_square', 'square')   # the load-dependent sensitivity on top
    assert_png_has_content(tmp_path / 'probes.png')


def test_no_pyplot_figures_are_left_behind(analysis):
    pyplot = pytest.importorskip('matplotlib.pyplot')
    before = pyplot.get_fignums()
    for draw in (whiteness_figure, cross_correlation_figure, segments_figure, spectrum_figure,
                 amplitude_figure, probes_figure):
        draw(analysis)
    assert pyplot.get_fignums() == before
