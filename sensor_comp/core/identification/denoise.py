"""
EMD denoising of one shot window (emd-signal's ``PyEMD.EMD``), and of many in parallel.

IMFs whose energy matches a calibrated white-noise model are removed (partial
reconstruction). The rule, the sifting choice, its calibration and timings:
``doc/denoising.md``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
import time

import numpy as np
from PyEMD import EMD

from ..shots.detection import mad_sigma
from ...errors import SensorCompError
from ...sharing import pool_size, share

__all__ = ['DEFAULT_FACTOR', 'MAX_SAMPLES', 'MIN_POOL_SAMPLES', 'REFERENCE_SIFTING',
           'SIFTING', 'DenoiseError', 'DenoiseResult', 'EmdDenoiser', 'Sifting',
           'denoise_windows', 'emd_denoise', 'white_noise_energy']

#: Keep IMFs from the first one with more than this multiple of its white-noise energy.
DEFAULT_FACTOR = 2.0
#: Longest window EMD is run on (its cost grows faster than the length).
MAX_SAMPLES = 200_000
#: Fewest samples in all the windows for which helpers are started (~0.7 s of EMD here).
MIN_POOL_SAMPLES = 500_000


class DenoiseError(SensorCompError, ValueError):
    """A window cannot be denoised (NaN samples, too long)."""


@dataclass(frozen=True)
class Sifting:
    """
    PyEMD settings (``options``) and the white-noise IMF energies calibrated for them.

    ``log2_imf1`` is ``log2 c₁`` (IMF 1's energy over ``N σ₁²``), ``log2_scale`` ``log2 c``
    and ``log2_decay`` ``log2 ρ`` (the later IMFs' scale and fall per IMF).
    """

    options: tuple[tuple[str, object], ...]
    log2_imf1: float
    log2_scale: float
    log2_decay: float

    def emd(self) -> EMD:
        """Return a PyEMD ``EMD`` with these settings."""
        return EMD(**dict(self.options))

    @property
    def noise_total(self) -> float:
        """Return the white-noise energy of all IMFs over ``N σ₁²`` (for the noise RMS)."""
        decay = 2.0 ** self.log2_decay
        return 2.0 ** self.log2_imf1 + 2.0 ** self.log2_scale * decay ** -2 / (1 - 1 / decay)


#: The sifting used: 5 iterations per IMF, cubic splines, simple extrema (see module docs).
SIFTING = Sifting(options=(('spline_kind', 'cubic'), ('extrema_detection', 'simple'),
                           ('FIXE', 5), ('svar_thr', 0.0)),
                  log2_imf1=-0.49, log2_scale=0.09, log2_decay=1.07)
#: The sifting of earlier versions (emd-signal's default stopping test, ``svar_thr`` off):
#: ~14× slower; kept for the benchmark's comparison.
REFERENCE_SIFTING = Sifting(options=(('svar_thr', 0.0),), log2_imf1=-0.61, log2_scale=-0.29,
                            log2_decay=0.89)


def white_noise_energy(n_imfs: int, n_samples: int, sigma1: float, *,
                       sifting: Sifting = SIFTING) -> np.ndarray:
    """
    Return the energy expected in each of ``n_imfs`` IMFs of white noise of ``n_samples``.

    ``sigma1`` is IMF 1's robust scale, ``median|IMF₁| / 0.6745``.
    """
    k = np.arange(1, n_imfs + 1, dtype=float)
    energy = n_samples * sigma1 ** 2 * 2.0 ** (sifting.log2_scale - sifting.log2_decay * k)
    energy[:1] = n_samples * sigma1 ** 2 * 2.0 ** sifting.log2_imf1
    return energy


@dataclass(frozen=True)
class DenoiseResult:
    """
    A denoised window and what the selection removed.

    Args:
        signal: The denoised window (same length and unit as the input).
        removed: Number of IMFs removed as noise (IMF 1 to ``removed``).
        n_imfs: IMFs separated: the noise IMFs and the first signal IMF.
        imf_energy: Energy of each IMF separated, in the input unit squared.
        noise_energy: White-noise energy expected in each IMF separated.
        noise_rms: Estimated RMS of the white noise in the input.
        seconds: Wall time of the decomposition.

    """

    signal: np.ndarray = field(repr=False)
    removed: int
    n_imfs: int
    imf_energy: np.ndarray = field(repr=False)
    noise_energy: np.ndarray = field(repr=False)
    noise_rms: float
    seconds: float

    @property
    def kept(self) -> tuple[int, ...]:
        """Return the 1-based numbers of the separated IMFs kept: the first signal IMF."""
        return tuple(range(self.removed + 1, self.n_imfs + 1))

    def summary(self) -> str:
        """Return one line for reports, e.g. ``'removed IMF 1-5 as noise, kept ...'``."""
        removed = f'IMF 1-{self.removed}' if self.removed else 'no IMF'
        return (f'removed {removed} as noise, kept the slower IMFs and the residue, noise '
                f'RMS {self.noise_rms:.4g}, {self.seconds:.2f} s')


def _check(x: np.ndarray, factor: float, max_samples: int) -> np.ndarray:
    """Return ``x`` as a float64 window, or raise DenoiseError."""
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 1:
        raise DenoiseError(f'EMD denoising takes one window (n,), got shape {x.shape}')
    if x.size > max_samples:
        raise DenoiseError(f'window of {x.size} samples is longer than {max_samples}: EMD '
                           f'cost grows faster than the length; shorten the shot windows '
                           f'or turn denoising off')
    bad = np.flatnonzero(~np.isfinite(x))
    if bad.size:
        raise DenoiseError(f'window holds a non-finite sample at index {bad[0]}')
    if not factor > 0:
        raise DenoiseError(f'factor must be positive, got {factor!r}')
    return x


def emd_denoise(x: np.ndarray, *, factor: float = DEFAULT_FACTOR,
                max_samples: int = MAX_SAMPLES, sifting: Sifting = SIFTING) -> DenoiseResult:
    """
    Denoise one ``(n,)`` window by EMD partial reconstruction.

    ``factor`` is the multiple of the white-noise energy that marks the first kept IMF;
    windows longer than ``max_samples`` are refused (cost).

    Raises:
        DenoiseError: On a non-1-D or non-finite window, or one longer than ``max_samples``.

    """
    x = _check(x, factor, max_samples)
    scale = float(np.sqrt(np.mean(x ** 2))) if x.size else 0.0
    if x.size < 8 or scale == 0:
        return DenoiseResult(x.copy(), 0, 0, np.zeros(0), np.zeros(0), 0.0, 0.0)
    began = time.perf_counter()
    emd = sifting.emd()
    remainder = x / scale
    energies, noise, sigma1 = [], [], 0.0
    while True:
        # One IMF at a time from what is left: the same IMFs as emd.emd(x) in one go (it
        # sifts each from the signal minus the IMFs before), stopped at the first that
        # holds signal.
        emd.emd(remainder, max_imf=1)
        imfs, rest = emd.get_imfs_and_residue()
        if not imfs.shape[0]:  # what is left is a trend
            break
        imf = imfs[0] * scale
        if not energies:
            sigma1 = mad_sigma(imf)
        energies.append(float(imf @ imf))
        noise.append(float(white_noise_energy(len(energies), x.size, sigma1,
                                              sifting=sifting)[-1]))
        if energies[-1] > factor * noise[-1]:
            break  # this IMF holds signal: it and every slower one are kept
        ended = emd.end_condition(remainder, imfs)  # where emd.emd(x) would stop
        remainder = rest
        if ended:
            break
    removed = len(energies) - (1 if energies and energies[-1] > factor * noise[-1] else 0)
    return DenoiseResult(signal=remainder * scale, removed=removed, n_imfs=len(energies),
                         imf_energy=np.array(energies), noise_energy=np.array(noise),
                         noise_rms=float(sigma1 * np.sqrt(sifting.noise_total)),
                         seconds=time.perf_counter() - began)


def denoise_windows(windows: Sequence[np.ndarray], *, factor: float = DEFAULT_FACTOR,
                    max_samples: int = MAX_SAMPLES, sifting: Sifting = SIFTING,
                    processes: int | None = None,
                    done: Callable[[], None] | None = None) -> list[DenoiseResult]:
    """
    Denoise many windows, in parallel processes when worth it (``doc/denoising.md``).

    Options as :func:`emd_denoise`; ``processes`` as :func:`~sensor_comp.sharing.pool_size`
    (helpers from :data:`MIN_POOL_SAMPLES` samples in all); ``done`` is called once per
    window denoised, in this thread. Returns one result per window, in order.

    Raises:
        DenoiseError: For the first bad window (in order).

    """
    windows = [_check(w, factor, max_samples) for w in windows]
    size = pool_size(sum(w.size for w in windows), MIN_POOL_SAMPLES, processes)
    if len(windows) < 3:
        size = 1
    options = {'factor': factor, 'max_samples': max_samples, 'sifting': sifting}
    return share(_denoise, [(w, options) for w in windows], processes=size,
                 name='EMD helper', done=done)


def _denoise(window: np.ndarray, options: dict) -> DenoiseResult:
    """Return :func:`emd_denoise` of one window (a job of :func:`denoise_windows`)."""
    return emd_denoise(window, **options)


class EmdDenoiser:
    """
    A callable for :func:`~sensor_comp.core.shots.detection.segments` that keeps its results.

    Args as :func:`emd_denoise`; ``results`` holds one :class:`DenoiseResult` per window.
    """

    def __init__(self, *, factor: float = DEFAULT_FACTOR, max_samples: int = MAX_SAMPLES,
                 sifting: Sifting = SIFTING):
        self.factor = factor
        self.max_samples = max_samples
        self.sifting = sifting
        self.results: list[DenoiseResult] = []

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Return the denoised window and record what was kept."""
        result = emd_denoise(x, factor=self.factor, max_samples=self.max_samples,
                             sifting=self.sifting)
        self.results.append(result)
        return result.signal

    def map(self, windows: Sequence[np.ndarray], *,
            done: Callable[[], None] | None = None) -> list[np.ndarray]:
        """
        Return every window denoised (in parallel when worth it) and record the results.

        Raises:
            DenoiseError: For the first bad window.

        """
        results = denoise_windows(windows, factor=self.factor, max_samples=self.max_samples,
                                  sifting=self.sifting, done=done)
        self.results.extend(results)
        return [r.signal for r in results]
