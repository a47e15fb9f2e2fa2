"""
The identification node's fits, run in a worker process.

A fit (EMD, the output-error search) and its diagnosis take seconds to minutes of Python
and numpy. Run in a thread of the node, they held the GIL for long stretches and starved
block reception: in the soak the node fell behind by 0.3-0.5 s per second of fit, the
backlog sitting in its DDS queue. Here they run in the one process of a
:class:`~concurrent.futures.ProcessPoolExecutor` started with ``spawn``: a fresh
interpreter, because forking a process that runs rclpy and DDS threads copies locks held
by other threads. This module imports no ROS; what crosses the process boundary is
picklable (numpy arrays, frozen dataclasses, option dicts), and errors of the core come
back as text, so a worker never needs the node's classes.

The worker ignores SIGINT: a Ctrl-C reaches the whole process group, and the node itself
decides when to stop its worker (:meth:`Identification.destroy_node
<sensor_comp.nodes.identification.Identification.destroy_node>`).
"""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
import multiprocessing
import os
import signal

from ..core.diagnose import diagnose
from ..core.identify import identify, ShotSource
from ..core.model import Model
from ..core.shots import Shot
from ..errors import SensorCompError
from ..streams import Recording

__all__ = ['Diagnosis', 'Fitted', 'diagnose_fit', 'fit_shots', 'start_pool']


@dataclass(frozen=True)
class Fitted:
    """
    What a fit in the worker gave.

    Attributes:
        model: The identified model (provenance as :func:`identify` made it), or None.
        error: Why the fit failed (the core's message), or None.
        roles: ``'calibration'`` or ``'validation'`` by shot index.
        calibration: The shots fitted on (for the diagnosis).
        validation: The shots reported on (for the diagnosis).
        pid: The worker process that fitted.

    """

    model: Model | None
    error: str | None = None
    roles: dict | None = None
    calibration: tuple[ShotSource, ...] = ()
    validation: tuple[ShotSource, ...] = ()
    pid: int = 0


@dataclass(frozen=True)
class Diagnosis:
    """
    The diagnosis of a fitted model, as ``/diagnostics`` shows it.

    Attributes:
        verdict: ``diagnosis_*`` key/value pairs.
        explanation: The diagnosis's explanation (empty when it failed).

    """

    verdict: dict
    explanation: str = ''


def _ignore_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)


#: Tasks (a fit and its diagnosis) a worker process runs before a fresh one replaces it.
TASKS_PER_WORKER = 2


def start_pool() -> ProcessPoolExecutor:
    """
    Return a pool of one spawned worker process that ignores SIGINT.

    The worker is replaced after every fit and its diagnosis: a fit allocates hundreds of
    MB (EMD, the search), and a long-lived interpreter keeps some of it (the 10-minute soak
    measured its node plus worker growing by 4 MB/min with one worker for every fit); a
    fresh interpreter costs about a second against fits of tens of seconds.
    """
    return ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context('spawn'),
                               initializer=_ignore_sigint,
                               max_tasks_per_child=TASKS_PER_WORKER)


def fit_shots(recording: Recording, shots: tuple[Shot, ...], options: dict) -> Fitted:
    """
    Identify a model on ``shots`` of ``recording`` (what the node's fit does).

    Args:
        recording: The kept shot windows joined into one recording.
        shots: The shots in it.
        options: Keyword arguments of :func:`~sensor_comp.core.identify.identify`.

    Returns:
        The model and the shots' roles, or the error of the core.

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
                 model: Model) -> Diagnosis:
    """Diagnose ``model`` on the shots it was fitted and validated on."""
    try:
        found = diagnose(calibration, validation, base=model)
    except SensorCompError as exc:
        return Diagnosis({'diagnosis_verdict': 'failed', 'diagnosis_error': str(exc)})
    verdict = {'diagnosis_verdict': found.verdict}
    if found.ranking:
        top = found.ranking[0]
        verdict.update({'diagnosis_top_effect': top.effect,
                        'diagnosis_top_score': top.score,
                        'diagnosis_top_significant': top.significant})
    return Diagnosis(verdict, found.explanation)
