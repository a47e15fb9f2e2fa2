"""
The result of every estimator: polynomials, uncertainty and fit statistics.

:class:`Estimate` keeps the input-path denominator in ``a`` (``A``, or ``F`` for output
error) so that ``y = B/a q^-nk u`` for every structure; the structures and their noise
models are tabled in ``doc/estimators.md``.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

__all__ = ['CRITERIA', 'STRUCTURES', 'Estimate']

STRUCTURES = ('arx', 'armax', 'ararx', 'oe')
CRITERIA = ('aic', 'aicc', 'bic', 'fpe')


def _length(poly: np.ndarray | None) -> int:
    return 0 if poly is None else poly.size - 1


@dataclass(frozen=True, eq=False)
class Estimate:
    """
    An identified model with its uncertainty.

    Args:
        structure: One of :data:`STRUCTURES`.
        a: Input-path denominator ``[1, a1, ..., ana]`` (``A`` or ``F``).
        b: Numerators ``(n_inputs, nb)``; ``b[i, j]`` multiplies ``u_i(k − nk − j)``.
        nk: Input delay in samples (common to all inputs).
        covariance: Parameter covariance over :attr:`parameter_names`.
        noise_variance: Variance of the white innovation ``e``.
        loss: Mean squared residual (prediction or simulation error, by structure).
        n_samples: Number of residuals the loss averages.
        c: Noise numerator ``[1, c1, ...]`` (ARMAX) or None.
        d: Noise denominator ``[1, d1, ...]`` (ARARX) or None.
        iterations: Iterations the estimator ran (0 for a direct solution).
        converged: Whether the iteration met its tolerance.
        method: How the estimate was computed, in words.

    """

    structure: str
    a: np.ndarray
    b: np.ndarray
    nk: int
    covariance: np.ndarray
    noise_variance: float
    loss: float
    n_samples: int
    c: np.ndarray | None = None
    d: np.ndarray | None = None
    iterations: int = 0
    converged: bool = True
    method: str = ''

    def __post_init__(self):
        object.__setattr__(self, 'a', np.asarray(self.a, dtype=np.float64))
        object.__setattr__(self, 'b', np.atleast_2d(np.asarray(self.b, dtype=np.float64)))
        for name in ('c', 'd'):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, np.asarray(getattr(self, name), np.float64))
        object.__setattr__(self, 'nk', int(self.nk))

    @property
    def na(self) -> int:
        """Order of the input-path denominator."""
        return self.a.size - 1

    @property
    def nb(self) -> int:
        """Numerator coefficients per input."""
        return self.b.shape[1]

    @property
    def nc(self) -> int:
        """Order of the noise numerator ``C`` (0 without one)."""
        return _length(self.c)

    @property
    def nd(self) -> int:
        """Order of the noise denominator ``D`` (0 without one)."""
        return _length(self.d)

    @property
    def n_inputs(self) -> int:
        """Count of inputs."""
        return self.b.shape[0]

    @property
    def n_parameters(self) -> int:
        """Count of estimated parameters."""
        return self.na + self.b.size + self.nc + self.nd

    @property
    def parameter_names(self) -> list[str]:
        """Names in the order of :attr:`covariance`: ``a1``, ``b0[0]``, ``c1``, ``d1``."""
        return ([f'a{j}' for j in range(1, self.na + 1)]
                + [f'b{i}[{j}]' for i in range(self.n_inputs) for j in range(self.nb)]
                + [f'c{j}' for j in range(1, self.nc + 1)]
                + [f'd{j}' for j in range(1, self.nd + 1)])

    @property
    def std(self) -> np.ndarray:
        """Parameter standard deviations, ordered as :attr:`parameter_names`."""
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    def _split(self) -> dict[str, np.ndarray | None]:
        std = self.std
        na, nbt, nc = self.na, self.b.size, self.nc
        return {
            'a': np.concatenate([[0.0], std[:na]]),
            'b': std[na:na + nbt].reshape(self.b.shape),
            'c': None if self.c is None else np.concatenate([[0.0], std[na + nbt:][:nc]]),
            'd': None if self.d is None else np.concatenate([[0.0], std[na + nbt + nc:]]),
        }

    @property
    def a_std(self) -> np.ndarray:
        """Uncertainty of ``a``: standard deviations (0 for the fixed leading 1)."""
        return self._split()['a']

    @property
    def b_std(self) -> np.ndarray:
        """Uncertainty of ``b``: standard deviations, shape ``(n_inputs, nb)``."""
        return self._split()['b']

    @property
    def c_std(self) -> np.ndarray | None:
        """Uncertainty of ``c``: standard deviations (0 for the leading 1), or None."""
        return self._split()['c']

    @property
    def d_std(self) -> np.ndarray | None:
        """Uncertainty of ``d``: standard deviations (0 for the leading 1), or None."""
        return self._split()['d']

    def _log_loss(self) -> float:
        return math.log(max(self.loss, np.finfo(np.float64).tiny))

    @property
    def aic(self) -> float:
        """Akaike's criterion ``N ln V + 2p`` (constant terms dropped)."""
        return self.n_samples * self._log_loss() + 2 * self.n_parameters

    @property
    def aicc(self) -> float:
        """Small-sample corrected AIC ``AIC + 2p(p+1)/(N−p−1)``."""
        p, n = self.n_parameters, self.n_samples
        return self.aic + 2 * p * (p + 1) / max(n - p - 1, 1)

    @property
    def bic(self) -> float:
        """Bayesian criterion ``N ln V + p ln N``."""
        return self.n_samples * self._log_loss() + self.n_parameters * math.log(self.n_samples)

    @property
    def fpe(self) -> float:
        """Akaike's final prediction error ``V (1 + p/N) / (1 − p/N)``."""
        ratio = self.n_parameters / self.n_samples
        return self.loss * (1 + ratio) / max(1 - ratio, 1e-12)

    def criterion(self, name: str) -> float:
        """
        Return the information criterion ``name`` (one of :data:`CRITERIA`).

        Raises:
            ValueError: For an unknown name.

        """
        if name not in CRITERIA:
            raise ValueError(f'unknown criterion {name!r}; use one of {", ".join(CRITERIA)}')
        return float(getattr(self, name))

    def noise_model(self) -> tuple[np.ndarray, np.ndarray]:
        """Return ``(numerator, denominator)`` of the noise model ``H`` (see module table)."""
        if self.structure == 'oe':
            return np.ones(1), np.ones(1)
        num = np.ones(1) if self.c is None else self.c
        den = self.a if self.d is None else np.convolve(self.a, self.d)
        return num, den

    def statistics(self) -> dict[str, float | int | bool | str]:
        """Return the fit statistics as a flat JSON-ready dict."""
        return {'loss': float(self.loss), 'noise_variance': float(self.noise_variance),
                'n_samples': int(self.n_samples), 'n_parameters': int(self.n_parameters),
                'aic': float(self.aic), 'aicc': float(self.aicc), 'bic': float(self.bic),
                'fpe': float(self.fpe), 'iterations': int(self.iterations),
                'converged': bool(self.converged), 'method': self.method}
