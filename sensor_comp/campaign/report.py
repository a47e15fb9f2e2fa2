"""
The campaign's HTML report: one self-contained file (figures embedded as base64 PNG).

Sections are listed in ``doc/campaign.md``.
"""

from __future__ import annotations

import datetime
import html
import math
import os

from matplotlib.figure import Figure
import numpy as np

from .store import CampaignFolder
from .summary import BASES, CampaignSummary, SensorSummary
from .table import read_columns
from ..version import __version__
from ..core.report.html import embedded_png
from ..files import write_text_atomically

__all__ = ['WORST_SHOTS', 'campaign_report', 'write_report']

#: Shots listed in the worst-shots section.
WORST_SHOTS = 20

_STYLE = """
body { font-family: sans-serif; max-width: 1200px; margin: 2em auto; color: #222; }
h2 { border-bottom: 1px solid #ccc; padding-bottom: .2em; } img { max-width: 100%; }
table { border-collapse: collapse; font-size: .9em; }
td, th { border: 1px solid #ccc; padding: .25em .5em; text-align: left; }
td.n { text-align: right; font-variant-numeric: tabular-nums; }
.bad { color: #b3261e; } .ok { color: #1a7f37; } code { font-size: .85em; }
"""


def _iso(stamp_ns) -> str:
    if stamp_ns is None:
        return ''
    moment = datetime.datetime.fromtimestamp(stamp_ns / 1e9, datetime.timezone.utc)
    return moment.strftime('%Y-%m-%d %H:%M:%S.%f')[:-3] + ' UTC'


def _num(value, spec: str = '.4g') -> str:
    if value is None or isinstance(value, float) and not math.isfinite(value):
        return '–'
    return format(value, spec)


def _table(header: list[str], rows: list[list[str]]) -> str:
    """Return an HTML table; cells are HTML already (escape before)."""
    head = ''.join(f'<th>{html.escape(h)}</th>' for h in header)
    body = ''.join('<tr>' + ''.join(f'<td>{c}</td>' for c in row) + '</tr>' for row in rows)
    return f'<table><tr>{head}</tr>{body}</table>'


def _drift_text(s: SensorSummary) -> str:
    t = s.trend
    if t is None:
        return '– (too few shots over time)'
    return (f'{_num(t.percent_over_span(t.slope_per_day), "+.3g")} % over '
            f'{_num(t.span_days, ".3g")} d [{_num(t.percent_over_span(t.low_per_day), "+.3g")}, '
            f'{_num(t.percent_over_span(t.high_per_day), "+.3g")}] '
            f'({_num(t.percent_per_30_days(t.slope_per_day), "+.3g")} % / 30 d)')


def _drift(s: SensorSummary) -> str:
    text = html.escape(_drift_text(s))
    return f'<span class="bad">{text} significant</span>' if s.trend and s.trend.significant \
        else text


def _changes(s: SensorSummary) -> str:
    return '<br>'.join(f'{html.escape(_iso(c.stamp_ns))}: {_num(c.shift_percent, "+.3g")} % '
                       f'(p = {_num(c.p_value, ".2g")})' for c in s.change_points) or 'none'


def _sensor_rows(summary: CampaignSummary) -> str:
    rows = [[html.escape(s.sensor), f'{s.recordings} ({s.failed_recordings} failed)',
             f'{s.shots} ({s.usable_shots} usable)', html.escape(s.models or '–'),
             f'{_num(s.sensitivity_mpa_per_g)} ({"model" if s.basis == "model" else "peak"})',
             _drift(s), _changes(s), _num(s.fit_percent_median, '.2f'),
             f'{_num(s.peak_residual_percent_median, ".2f")} / '
             f'{_num(s.peak_residual_percent_worst, ".2f")}']
            for s in summary.sensors]
    return _table(['sensor', 'recordings', 'shots', 'model', 'sensitivity MPa/g',
                   'drift (95 % CI)', 'change points', 'fit % (median)',
                   'peak residual % median / worst'], rows)


def _series(data: dict, s: SensorSummary) -> tuple[np.ndarray, np.ndarray]:
    mask = (data['sensor'] == s.sensor) & (data['mode'] == 'normal')
    values = data['sensitivity_mpa_per_g' if s.basis == 'model' else 'mpa_per_g'][mask]
    keep = np.isfinite(values)
    return data['stamp'][mask][keep], values[keep]


def _sensitivity_figure(data: dict, s: SensorSummary) -> Figure:
    stamps, values = _series(data, s)
    fig = Figure(figsize=(10, 3.2))
    ax = fig.add_subplot()
    times = stamps.astype('datetime64[ns]')
    ax.plot(times, values, '.', ms=3, color='tab:blue', label='shots')
    if s.trend is not None:
        order = np.argsort(stamps)
        ax.plot(times[order], s.trend.at(stamps[order]), color='tab:red',
                label=f'Theil–Sen trend {_drift_text(s)}')
    for change in s.change_points:
        ax.axvline(np.datetime64(change.stamp_ns, 'ns'), color='tab:orange', ls='--', lw=1)
    ax.set_title(f'{s.sensor}: {BASES[s.basis]}', fontsize=9)
    ax.set_ylabel('MPa/g')
    ax.legend(fontsize=8, loc='best')
    fig.autofmt_xdate()
    fig.tight_layout()
    return fig


def _residual_figure(data: dict, summary: CampaignSummary) -> Figure | None:
    groups = [(s.sensor, data['peak_residual_percent'][(data['sensor'] == s.sensor)])
              for s in summary.sensors]
    groups = [(name, v[np.isfinite(v)]) for name, v in groups]
    groups = [(name, v) for name, v in groups if v.size]
    if not groups:
        return None
    fig = Figure(figsize=(10, 3.5))
    ax = fig.add_subplot()
    top = max(float(v.max()) for _, v in groups)
    bins = np.linspace(0, top * 1.02 or 1, 40)
    for name, values in groups:
        ax.hist(values, bins=bins, histtype='step', label=f'{name} ({values.size})')
    ax.set_xlabel('peak residual after compensation, % of the shot peak')
    ax.set_ylabel('shots')
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def _link(folder: CampaignFolder, bag: str) -> str:
    target = os.path.relpath(os.path.abspath(bag), os.path.abspath(folder.path))
    return f'<a href="{html.escape(target)}">{html.escape(bag)}</a>'


def _worst(data: dict, folder: CampaignFolder) -> str:
    residual = data['peak_residual_percent']
    order = [i for i in np.argsort(-np.nan_to_num(residual, nan=-1.0))
             if np.isfinite(residual[i])][:WORST_SHOTS]
    if not order:
        return '<p>No shot was compared with a model (give --model or --identify).</p>'
    rows = []
    for i in order:
        command = (f'sensor-comp compare {data["model"][i]} {data["bag"][i]} --window '
                   f'{data["offset_s"][i] - 0.005:.4f} {data["offset_s"][i] + 0.03:.4f}')
        rows.append([_link(folder, data['bag'][i]), str(int(data['shot'][i])),
                     html.escape(_iso(int(data['stamp'][i]))),
                     html.escape(data['sensor'][i]), _num(data['peak_g'][i], '.1f'),
                     _num(data['fit_percent'][i], '.2f'), _num(residual[i], '.2f'),
                     f'<code>{html.escape(command)}</code>'])
    return _table(['recording', 'shot', 'pulse onset', 'sensor', 'peak g', 'fit %',
                   'peak residual %', 'to look at it'], rows)


def _failed(data: dict, folder: CampaignFolder) -> str:
    rows = [[_link(folder, data['bag'][i]), html.escape(data['sensor'][i] or '–'),
             html.escape(data['reason'][i])]
            for i in np.flatnonzero(data['mode'] == 'failed')]
    return _table(['recording', 'sensor', 'reason'], rows) if rows else '<p>None.</p>'


def _read(folder: CampaignFolder) -> dict[str, np.ndarray]:
    return read_columns(folder.file('shots.parquet'), [
        'bag', 'sensor', 'shot', 'stamp', 'offset_s', 'peak_g', 'mode', 'reason', 'model',
        'mpa_per_g', 'sensitivity_mpa_per_g', 'fit_percent', 'peak_residual_percent'])


def campaign_report(folder: CampaignFolder, summary: CampaignSummary) -> str:
    """Return the report of the campaign in ``folder`` as one HTML document."""
    data = _read(folder)
    now = datetime.datetime.now(datetime.timezone.utc)
    parts = [f'<!DOCTYPE html><html><head><meta charset="utf-8"><title>campaign '
             f'{html.escape(str(folder.path))}</title><style>{_STYLE}</style></head><body>',
             f'<h1>Campaign {html.escape(str(folder.path))}</h1>',
             f'<p>sensor_comp {__version__}, {now:%Y-%m-%d %H:%M} UTC; engine '
             f'{summary.engine}, {summary.workers} worker(s).</p>',
             f'<p>{summary.bags} recordings ({summary.failed} failed), {summary.shots} '
             f'shots ({summary.usable_shots} usable), {len(summary.sensors)} sensor(s); '
             f'{summary.processed} recordings analysed by this run, {summary.cached} from '
             f'the cache.</p>']
    parts += [f'<p class="bad">{html.escape(n)}</p>' for n in summary.notes]
    parts.append('<h2>1. Sensors</h2><p>Sensitivity: median of the series; drift: Theil–Sen '
                 'slope over the time the shots span, in % of the median, with its 95 % '
                 'interval, and per 30 days; change points: CUSUM binary segmentation, '
                 'p &lt; 0.01 per test (see sensor_comp.campaign.drift).</p>'
                 + _sensor_rows(summary))
    parts.append('<h2>2. Sensitivity over the campaign</h2>' + ''.join(
        embedded_png(_sensitivity_figure(data, s)) for s in summary.sensors if s.usable_shots))
    residual = _residual_figure(data, summary)
    parts.append('<h2>3. Peak residual after compensation</h2>'
                 + (embedded_png(residual) if residual else '<p>No shot was compared with a '
                    'model.</p>'))
    parts.append(f'<h2>4. The {WORST_SHOTS} worst shots</h2>' + _worst(data, folder))
    parts.append('<h2>5. Recordings that failed</h2>' + _failed(data, folder))
    parts.append('</body></html>')
    return '\n'.join(parts)


def write_report(folder: CampaignFolder, summary: CampaignSummary) -> None:
    """Write ``report.html`` atomically."""
    write_text_atomically(folder.file('report.html'), campaign_report(folder, summary))
