"""
The identification node's fits, run in a worker process (no ROS imported here).

Fits held the GIL and starved block reception when run in a thread; a fresh interpreter
per fit also returns its memory. Why and how much: ``doc/nodes.md`` (the fit worker).
"""

from __future__ import annotations

from dataclasses import dataclass
import os

from ..sharing import PROCESSES_ENV
from ..core.diagnosis.diagnose import diagnose
from ..core.identification.identify import identify, ShotSource
from ..core.identification.model import Model
from ..core.shots.detection import Shot
from ..errors import SensorCompError
from ..streams import Recording
from ..worker import Worker

__all__ = ['DiagnosisStatus', 'Fitted', 'diagnose_fit', 'fit_shots', 'start_worker']


@dataclass(frozen=True)
class Fitted:
    """
    What a fit in the worker gave.

    Attributes:
        model: The identified model, or None.
        error: Why the fit failed (the core's message), or None.
        roles: ``'calibration'`` or ``'validation'`` by shot index.
        calibration: The shots fitted on.
        validation: The shots reported on.
        pid: The worker process that fitted.

    """

    model: Model | None
    error: str | None = None
    roles: dict | None = None
    calibration: tuple[ShotSource, ...] = ()
    validation: tuple[ShotSource, ...] = ()
    pid: int = 0


@dataclass(frozen=True)
class DiagnosisStatus:
    """
    The diagnosis of a fitted model, as ``/diagnostics`` shows it.

    Attributes:
        verdict: ``diagnosis_*`` key/value pairs.
        explanation: The diagnosis's explanation (empty when it failed).

    """

    verdict: dict
    explanation: str = ''


def start_worker() -> Worker:
    """Return a new worker process (one per fit and its diagnosis, then retired)."""
    # EMD in this one process: helper processes would take the cores the node receives
    # blocks on.
    return Worker(name='fit worker', env={PROCESSES_ENV: '1'})


def fit_shots(recording: Recording, shots: tuple[Shot, ...], options: dict) -> Fitted:
    """
    Identify a model on ``shots`` of ``recording`` (what the node's fit does).

    ``options`` are :func:`identify` keyword arguments; errors of the core come back in
    :attr:`Fitted.error`.
    """
    try:
        result = identify([ShotSource(recording, shots)], **options)
    except SensorCompError as exc:
        return Fitted(None, str(exc), pid=os.getpid())
    roles = {shot.index: role for role, sources in (
        ('calibration', result.calibration), ('validation', result.validation))
        for source in sources for shot in source.shots}
    return Fitted(result.model, None, roles, result.calibration, result.validation,
                  os.getpid())


def diagnose_fit(calibration: tuple[ShotSource, ...], validation: tuple[ShotSource, ...],
                 model: Model) -> DiagnosisStatus:
    """Diagnose ``model`` on the shots it was fitted and validated on."""
    try:
        found = diagnose(calibration, validation, base=model)
    except SensorCompError as exc:
        return DiagnosisStatus({'diagnosis_verdict': 'failed', 'diagnosis_error': str(exc)})
    verdict = {'diagnosis_verdict': found.verdict, 'diagnosis_next_step': found.next_step}
    if found.named:
        verdict['diagnosis_named'] = found.named_words
    if found.leftover is not None:
        verdict['diagnosis_leftover_noise_energy'] = found.leftover.energy_ratio
    if found.limits:  # what in the shots limits a verdict that names no cause
        verdict['diagnosis_limits'] = ', '.join(found.limits)
    if found.ranking:
        top = found.ranking[0]
        verdict.update({'diagnosis_top_effect': top.effect,
                        'diagnosis_top_score': top.score,
                        'diagnosis_top_significant': top.significant})
    return DiagnosisStatus(verdict, found.explanation)
