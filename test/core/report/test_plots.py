"""Report figures: the axes hold the data handed in (in MPa and ms), PNGs have content."""

import numpy as np
import pytest
from matplotlib.image import imread

from sensor_comp.core.compensation.compare import Comparison, ShotComparison
from sensor_comp.core.report.plots import (
    comparison_figure, comparison_residual_figure, frequency_response_figure, overlay_figure,
    PlotError, residual_figure, step_response_figure)

FS = 100e3


def traces(n_shots=3):
    rng = np.random.default_rng(0)
    times, measured, arx, oe = [], [], [], []
    for i in range(n_shots):
        t = (1000 * i + np.arange(400)) / FS
        clean = 1.4e5 * np.exp(-((t - t[100]) / 5e-4) ** 2)
        times.append(t)
        measured.append(clean + rng.standard_normal(t.size) * 2e3)
        arx.append(1.03 * clean)
        oe.append(0.98 * clean)
    return times, measured, {'ARX': arx, 'OE': oe}


def assert_png_has_content(path):
    image = imread(path)
    assert image.shape[0] > 200 and image.shape[1] > 300
    # Not a blank canvas: many distinct colours (lines, text, grid).
    assert len(np.unique(image.reshape(-1, image.shape[-1]), axis=0)) > 50


def test_overlay_holds_measured_and_model_traces(tmp_path):
    times, measured, models = traces()
    path = tmp_path / 'fig12.png'
    fig = overlay_figure(times, measured, models, path=path)
    axes = [ax for ax in fig.axes if ax.get_visible()]
    assert len(axes) == 3
    for i, ax in enumerate(axes):
        lines = ax.get_lines()
        assert [line.get_label() for line in lines] == ['measured', 'ARX', 'OE']
        assert np.allclose(lines[0].get_xdata(), 1e3 * (times[i] - times[i][0]))
        assert np.allclose(lines[0].get_ydata(), measured[i] / 1e6)
        assert np.allclose(lines[2].get_ydata(), models['OE'][i] / 1e6)
    assert_png_has_content(path)


def test_residual_figure_draws_the_compensated_pressure():
    times, measured, models = traces(2)
    residual = {'ARX': [m - s for m, s in zip(measured, models['ARX'])]}
    fig = residual_figure(times, residual, measured=measured)
    lines = [line for line in fig.axes[1].get_lines() if not line.get_label().startswith('_')]
    assert [line.get_label() for line in lines] == ['uncompensated', 'ARX']
    assert np.allclose(lines[1].get_ydata(), residual['ARX'][1] / 1e6)


def test_frequency_response_in_db_and_degrees(tmp_path):
    f = np.logspace(1, 4.5, 200)
    h = 14.0 / (1 - (f / 8e3) ** 2 + 2j * 0.1 * f / 8e3)
    path = tmp_path / 'fig13.png'
    fig = frequency_response_figure(f, {'ARX': h}, path=path)
    mag, phase = fig.axes
    assert np.allclose(mag.get_lines()[0].get_ydata(), 20 * np.log10(np.abs(h)))
    assert np.allclose(phase.get_lines()[0].get_xdata(), f)
    assert phase.get_lines()[0].get_ydata()[-1] == pytest.approx(-180, abs=5)
    assert mag.get_xscale() == 'log'
    assert_png_has_content(path)


def test_step_response():
    t = np.arange(500) / FS
    y = 14.0 * (1 - np.exp(-t / 3e-4))
    fig = step_response_figure(t, {'ARX': y, 'OE': 0.9 * y})
    lines = fig.axes[0].get_lines()
    assert np.allclose(lines[0].get_xdata(), 1e3 * t)
    assert np.allclose(lines[1].get_ydata(), 0.9 * y)


def test_figures_from_comparisons():
    times, measured, models = traces(2)

    def comparison(label):
        shots = tuple(ShotComparison(
            index=i, start_s=t[0], stop_s=t[-1], fit_percent=90.0, peak_mpa=0.14,
            model_peak_mpa=0.14, peak_error_mpa=0.0, peak_error_percent=0.0,
            peak_residual_percent=5.0, t=t, measured=m, simulated=s)
            for i, (t, m, s) in enumerate(zip(times, measured, models[label])))
        return Comparison(label=label, fit_percent=90.0, peak_residual_percent=5.0,
                          shots=shots)

    results = [comparison('ARX'), comparison('OE')]
    fig = comparison_figure(results)
    assert fig.axes[1].get_title().startswith('shot 1')
    assert np.allclose(fig.axes[1].get_lines()[1].get_ydata(), models['ARX'][1] / 1e6)
    fig = comparison_residual_figure(results)
    assert np.allclose(fig.axes[0].get_lines()[2].get_ydata(),
                       (measured[0] - models['OE'][0]) / 1e6)


def test_mismatched_data_are_refused():
    times, measured, models = traces(2)
    with pytest.raises(PlotError, match="'ARX'"):
        overlay_figure(times, measured, {'ARX': models['ARX'][:1]})
    with pytest.raises(PlotError, match='no shot'):
        overlay_figure([], [], {})
    with pytest.raises(PlotError, match='shape'):
        step_response_figure(np.arange(5), {'x': np.arange(4)})
