"""
EMD denoising of one shot window (emd-signal's ``PyEMD.EMD``).

Empirical mode decomposition splits a window into intrinsic mode functions (IMFs), roughly
one octave each from the highest frequencies down, plus a residue (trend). On white noise it
acts as a dyadic filter bank (Flandrin, Rilling & Gonçalves, IEEE SPL 11(2), 2004): the
energy of noise IMF ``k`` falls geometrically with ``k``. The selection rule here uses that
model (chosen over an IMF–signal correlation threshold because it needs no tuning to the
signal's amplitude and states what it assumes: white noise):

1. The first IMF is taken as noise; its robust scale ``σ₁ = median|IMF₁| / 0.6745`` (robust
   to the shock leaking into it) fixes the white-noise energy expected in every IMF,
   ``E₁ = c₁ N σ₁²`` and ``E_k = c N σ₁² ρ^-k`` for ``k ≥ 2``.
2. The reconstruction keeps the IMFs from the first one whose energy exceeds
   ``factor`` × its noise energy, and every slower IMF and the residue after it (partial
   reconstruction; slower IMFs hold the shock's energy, and a stray slow noise IMF is
   cheap to keep).

``factor = 2`` is the mean-square-error break-even: an IMF holding signal energy ``S`` and
noise energy ``W`` costs ``S`` when dropped and ``W`` when kept, so it is worth keeping when
``S + W > 2 W``. The constants ``c₁ = 2^-0.61``, ``c = 2^-0.29`` and ``ρ = 2^0.89`` were
calibrated on emd-signal's default sifting (white Gaussian noise, 10k–20k samples, 35 runs);
they differ from Flandrin's ``β = 0.719``, ``ρ = 2.01`` because the sifting stops earlier.
The IMF energies of noise scatter by less than ±0.2 in log2 for ``k ≤ 5``, so a
noise IMF passes ``factor = 2`` by chance very rarely. Coloured noise (e.g. amplifier
low-pass) breaks the white-noise model: then IMF1 underestimates the noise in slower IMFs.

The window is scaled to unit RMS before sifting, because emd-signal's stopping thresholds
(``range_thr``, ``total_power_thr``) are absolute, and its scale-dependent ``svar_thr`` test
is disabled; the result is then independent of the unit.

EMD costs super-linear time (about 0.15 s for 10k samples, 1.5 s for 50k, minutes for 1M):
run it per shot window, never on a whole recording; :data:`MAX_SAMPLES` guards that.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import time

import numpy as np
from PyEMD import EMD

from .shots import mad_sigma
from ..errors import SensorCompError

__all__ = ['DEFAULT_FACTOR', 'DenoiseError', 'DenoiseResult', 'EmdDenoiser', 'MAX_SAMPLES',
           'emd_denoise', 'white_noise_energy']

#: Keep IMFs from the first one with more than this multiple of its white-noise energy.
DEFAULT_FACTOR = 2.0
#: Longest window EMD is run on (its cost grows faster than the length).
MAX_SAMPLES = 200_000
# White-noise IMF energies relative to N σ₁², calibrated for emd-signal (see module doc).
_IMF1_RATIO = 2.0 ** -0.61
_NOISE_SCALE = 2.0 ** -0.29
_NOISE_DECAY = 2.0 ** 0.89


class DenoiseError(SensorCompError, ValueError):
    """A window cannot be denoised (NaN samples, too long)."""


def white_noise_energy(n_imfs: int, n_samples: int, sigma1: float) -> np.ndarray:
    """
    Return the energy expected in each of ``n_imfs`` IMFs of white noise.

    Args:
        n_imfs: Number of IMFs.
        n_samples: Window length.
        sigma1: Robust scale of IMF1 (``median|IMF₁| / 0.6745``).

    Returns:
        ``(n_imfs,)`` energies (sums of squares).

    """
    k = np.arange(1, n_imfs + 1)
    energy = n_samples * sigma1 ** 2 * _NOISE_SCALE * _NOISE_DECAY ** -k.astype(float)
    energy[:1] = n_samples * sigma1 ** 2 * _IMF1_RATIO
    return energy


@dataclass(frozen=True)
class DenoiseResult:
    """
    A denoised window and what the selection kept.

    Args:
        signal: The denoised window (same length and unit as the input).
        kept: 1-based numbers of the IMFs kept (the residue is always kept).
        n_imfs: Number of IMFs found.
        imf_energy: Energy (sum of squares) of each IMF, in the input unit squared.
        noise_energy: White-noise energy expected in each IMF.
        noise_rms: Estimated RMS of the white noise in the input.
        seconds: Wall time of the decomposition.

    """

    signal: np.ndarray = field(repr=False)
    kept: tuple[int, ...]
    n_imfs: int
    imf_energy: np.ndarray = field(repr=False)
    noise_energy: np.ndarray = field(repr=False)
    noise_rms: float
    seconds: float

    def summary(self) -> str:
        """Return one line for reports, e.g. ``'kept IMF 4-11 of 11, noise 512 ...'``."""
        kept = f'IMF {self.kept[0]}-{self.kept[-1]}' if self.kept else 'no IMF'
        return (f'kept {kept} of {self.n_imfs} + residue, noise RMS {self.noise_rms:.4g}, '
                f'{self.seconds:.2f} s')


def emd_denoise(x: np.ndarray, *, factor: float = DEFAULT_FACTOR,
                max_samples: int = MAX_SAMPLES) -> DenoiseResult:
    """
    Denoise one window by EMD partial reconstruction (see the module doc for the rule).

    Args:
        x: ``(n,)`` window, e.g. pressure in Pa with its baseline removed.
        factor: Energy multiple of the white-noise model that marks the first kept IMF.
        max_samples: Refuse longer windows (cost).

    Returns:
        The denoised window and the selection.

    Raises:
        DenoiseError: On a non-1-D or non-finite window, or one longer than ``max_samples``.

    """
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
    scale = float(np.sqrt(np.mean(x ** 2))) if x.size else 0.0
    if x.size < 8 or scale == 0:
        return DenoiseResult(x.copy(), (), 0, np.zeros(0), np.zeros(0), 0.0, 0.0)
    began = time.perf_counter()
    emd = EMD(svar_thr=0.0)
    emd.emd(x / scale)
    imfs, residue = emd.get_imfs_and_residue()
    seconds = time.perf_counter() - began
    imfs = imfs * scale
    residue = residue * scale
    n_imfs = imfs.shape[0]
    energy = np.sum(imfs ** 2, axis=1)
    sigma1 = mad_sigma(imfs[0]) if n_imfs else 0.0
    noise = white_noise_energy(n_imfs, x.size, sigma1)
    significant = np.flatnonzero(energy > factor * noise)
    first = int(significant[0]) if significant.size else n_imfs
    kept = tuple(range(first + 1, n_imfs + 1))
    total = _IMF1_RATIO + _NOISE_SCALE * _NOISE_DECAY ** -2 / (1 - 1 / _NOISE_DECAY)
    return DenoiseResult(signal=imfs[first:].sum(axis=0) + residue, kept=kept, n_imfs=n_imfs,
                         imf_energy=energy, noise_energy=noise,
                         noise_rms=float(sigma1 * np.sqrt(total)), seconds=seconds)


class EmdDenoiser:
    """
    A callable for :func:`sensor_comp.core.shots.segments` that keeps its results.

    Args:
        factor: As in :func:`emd_denoise`.
        max_samples: As in :func:`emd_denoise`.

    Attributes:
        results: One :class:`DenoiseResult` per window denoised, in call order (for reports).

    """

    def __init__(self, *, factor: float = DEFAULT_FACTOR, max_samples: int = MAX_SAMPLES):
        self.factor = factor
        self.max_samples = max_samples
        self.results: list[DenoiseResult] = []

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Return the denoised window and record what was kept."""
        result = emd_denoise(x, factor=self.factor, max_samples=self.max_samples)
        self.results.append(result)
        return result.signal
