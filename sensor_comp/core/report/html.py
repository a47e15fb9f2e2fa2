"""
One self-contained HTML report of the diagnosis loop, read top to bottom.

Shots, overlay, residual and its tests, where the model fails, the diagnosis and an
optional before/after; figures embedded as base64 PNG so the file stands alone.
"""

from __future__ import annotations

import base64
from collections.abc import Mapping, Sequence
import datetime
import html
import io
import os

from matplotlib.figure import Figure

from ..compensation.compare import Comparison, format_table
from ..diagnosis.findings import ATTENTION, NEXT_STEP, VERDICTS
from .plots import comparison_figure, comparison_residual_figure
from ..diagnosis.residual import ResidualAnalysis
from .residual_plots import (amplitude_figure, cross_correlation_figure, probes_figure,
                             segments_figure, spectrum_figure, whiteness_figure)
from ..shots.detection import Shot, shot_table
from ...version import __version__
from ...files import write_text_atomically

__all__ = ['embedded_png', 'html_report', 'verdict_html', 'write_report']

_STYLE = """
body { font-family: sans-serif; max-width: 1100px; margin: 2em auto; color: #222; }
h1 { font-size: 1.6em; } h2 { border-bottom: 1px solid #ccc; padding-bottom: .2em; }
pre { background: #f6f6f6; padding: .8em; overflow-x: auto; font-size: .85em; }
img { max-width: 100%; } table { border-collapse: collapse; }
td, th { border: 1px solid #ccc; padding: .3em .6em; text-align: left; }
.verdict { font-size: 1.2em; font-weight: bold; }
.ok { color: #1a7f37; } .bad { color: #b3261e; } .partly { color: #9a6700; }
"""


def embedded_png(fig: Figure) -> str:
    """Return ``fig`` as an ``<img>`` with the PNG inline: a report is one self-contained file."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format='png', dpi=90)
    return ('<img alt="figure" src="data:image/png;base64,'
            + base64.b64encode(buffer.getvalue()).decode('ascii') + '">')


def _pre(text: str) -> str:
    return f'<pre>{html.escape(text)}</pre>'


def _ranking_table(ranking: Sequence[Mapping]) -> str:
    rows = ['<table><tr><th>#</th><th>effect</th><th>score</th><th>significant</th>'
            '<th>parameters</th><th>evidence</th></tr>']
    for position, entry in enumerate(ranking, 1):
        parameters = ', '.join(f'{k} = {_number(v)}'
                               for k, v in (entry.get('parameters') or {}).items())
        significant = entry.get('significant')
        rows.append(
            f'<tr><td>{position}</td><td>{html.escape(str(entry.get("effect")))}</td>'
            f'<td>{_number(entry.get("score"))}</td>'
            f'<td>{"" if significant is None else ("yes" if significant else "no")}</td>'
            f'<td>{html.escape(parameters)}</td>'
            f'<td>{html.escape(str(entry.get("evidence", "")))}</td></tr>')
    return '\n'.join(rows) + '</table>'


def _number(value) -> str:
    if isinstance(value, float):
        return f'{value:.4g}'
    if isinstance(value, Mapping):  # e.g. {'value': 12.3, 'std': 0.4, 'unit': 'µs'}
        text = _number(value.get('value'))
        if value.get('std') is not None:
            text += f' ± {_number(value["std"])}'
        return text + (f' {value["unit"]}' if value.get('unit') else '')
    if isinstance(value, (list, tuple)) and len(value) == 2:
        return f'{_number(value[0])} ± {_number(value[1])}' if value[1] is not None \
            else _number(value[0])
    return html.escape(str(value))


def html_report(*, title: str, shots: Sequence[Shot], comparisons: Sequence[Comparison],
                analysis: ResidualAnalysis, diagnosis: Mapping | None = None,
                after: Sequence[Comparison] = (), sources: Sequence[str] = ()) -> str:
    """
    Return the report as one HTML document.

    ``comparisons`` are the base model (first) and others on the validation ``shots``;
    ``analysis`` is the base model's residual analysis; ``diagnosis`` is
    ``Diagnosis.to_dict()`` or None; ``after`` compares extended models (base first);
    ``sources`` are listed at the top.
    """
    parts = [f'<!DOCTYPE html><html><head><meta charset="utf-8"><title>{html.escape(title)}'
             f'</title><style>{_STYLE}</style></head><body>',
             f'<h1>{html.escape(title)}</h1>',
             f'<p>sensor_comp {__version__}, '
             f'{datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC. '
             + ''.join(f'<br>{html.escape(s)}' for s in sources) + '</p>']
    if diagnosis is not None:
        parts.append(verdict_html(diagnosis))
    parts.append('<h2>1. Shots</h2>' + _pre(shot_table(shots)))
    parts.append('<h2>2. Model against measurement</h2>'
                 '<p>Each model simulated from the measured acceleration over every shot '
                 'window, from rest (MATLAB <code>compare</code>).</p>'
                 + _pre(format_table(comparisons))
                 + embedded_png(comparison_figure(comparisons)))
    parts.append('<h2>3. Residual</h2>'
                 + embedded_png(comparison_residual_figure(comparisons[:1])))
    parts.append('<h2>4. Residual tests</h2>'
                 '<p>Whiteness: autocorrelation of the residual; independence: its '
                 'cross-correlation with the accelerations, with 99 % bands valid for '
                 'coloured shock inputs (Bartlett).</p>'
                 + embedded_png(whiteness_figure(analysis))
                 + embedded_png(cross_correlation_figure(analysis)))
    parts.append('<h2>5. Where the model fails</h2>'
                 + _pre('\n'.join(analysis.summary()))
                 + ''.join(embedded_png(figure(analysis)) for figure in (
                     segments_figure, spectrum_figure, amplitude_figure, probes_figure)))
    if diagnosis is not None:
        parts.append('<h2>6. Diagnosis: which physical effect is missing</h2>'
                     + _ranking_table(diagnosis.get('ranking', [])))
        for line in diagnosis.get('notes', []) or []:
            parts.append(f'<p>{html.escape(str(line))}</p>')
    if after:
        parts.append('<h2>7. Before and after adding the effect</h2>'
                     + _pre(format_table(after)) + embedded_png(comparison_figure(after))
                     + embedded_png(comparison_residual_figure(after)))
    parts.append('</body></html>')
    return '\n'.join(parts)


def verdict_html(diagnosis: Mapping) -> str:
    """
    Return the verdict paragraph: verdict, explanation and next step, coloured.

    Green only for ``adequate``, amber for ``partly_explained``, red for the others and for
    a verdict this version does not know.
    """
    verdict = str(diagnosis.get('verdict'))
    if verdict not in VERDICTS:
        return (f'<p class="verdict bad">Verdict: {html.escape(verdict)} (unknown to this '
                f'version)</p>')
    css = ('partly' if verdict == 'partly_explained' else
           'bad' if ATTENTION[verdict] else 'ok')
    named = list(diagnosis.get('named') or ())
    if verdict == 'ambiguous' and diagnosis.get('alternatives') is not None:
        named = named[:1] + list(diagnosis['alternatives'])  # older reports lack them
    named = (' or ' if verdict == 'ambiguous' else ', ').join(named)
    parts = [f'<p class="verdict {css}">Verdict: {html.escape(verdict)}'
             + (f' ({html.escape(named)})' if named else '') + '</p>']
    if diagnosis.get('explanation'):
        parts.append(f'<p>{html.escape(str(diagnosis["explanation"]))}</p>')
    parts.append(f'<p>Next: {html.escape(NEXT_STEP[verdict])}</p>')
    return '\n'.join(parts)


def write_report(path: str | os.PathLike, text: str) -> None:
    """Write the report atomically (a temporary file renamed into place)."""
    write_text_atomically(path, text)
