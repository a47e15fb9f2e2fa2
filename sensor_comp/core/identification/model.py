"""
The identified sensor model: polynomials, physics view, provenance and its JSON file.

A :class:`Model` is what identification hands to compensation. File schema, validation
rules and the sensitivity plausibility ranges: ``doc/model-file.md``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
import datetime
import hashlib
import json
import math
import os
from pathlib import Path

import numpy as np
from scipy import signal

from ...version import __version__
from ...errors import SensorCompError
from ...files import write_text_atomically
from ...streams import G0
from ..effects import EFFECTS
from ..estimators.estimate import Estimate, STRUCTURES
from ..estimators.least_squares import delayed_numerator
from ..estimators.polynomials import max_root_radius
from ..shots.inputs import InputError, parse_channel

__all__ = ['PLAUSIBLE_MPA_PER_G', 'SCHEMA', 'TYPICAL_MPA_PER_G', 'ContinuousView', 'Model',
           'ModelError', 'Source', 'frequency_response', 'load', 'sensitivity_problem',
           'step_response']

#: Schema identifier written to and required in model files.
SCHEMA = 'sensor_comp.model/1'
_SCHEMA_PREFIX = 'sensor_comp.model/'
_REQUIRED = ('schema', 'fs', 'structure', 'orders', 'inputs', 'numerators', 'denominator',
             'created', 'sensor_comp_version')


#: Acceleration sensitivities of piezoelectric pressure sensors in MPa/g as datasheets give
#: them: 1e-5 to 1e-3 bar/g (1e-6 to 1e-4 MPa/g) from the vendors, 1.4e-4 MPa/g for the seed
#: paper's sensor, whose Table 2 gives peak pressure over peak acceleration of 0.9e-4 to
#: 1.8e-4 MPa/g. A shot's peak ratio exceeds the static sensitivity by the sensor's ringing
#: (up to twice for a shock shorter than the resonance period), hence the upper end.
TYPICAL_MPA_PER_G = (1e-6, 4e-4)
#: The range any such sensor can show, in MPa/g. Above: the sensitivity is the inertia of
#: the diaphragm and crystal stack over the diaphragm area, ρ·t·g; a 5 mm quartz stack
#: (2650 kg/m³) gives 130 Pa/g = 1.3e-4 MPa/g, so 1e-3 MPa/g would take a stack eight times
#: heavier than any sensor has; twice that for ringing. Below: two decades under the best
#: acceleration-compensated sensors (their datasheets bound it at 1e-5 bar/g = 1e-6 MPa/g):
#: a compensating mass can cancel nearly all of the static response, leaving the two
#: modes' ringing. A pressure in MPa or bar where Pa is expected moves a sensitivity
#: 10^6 or 10^5 down, below it for any sensor.
PLAUSIBLE_MPA_PER_G = (1e-8, 2e-3)

#: Unit mistakes that scale an identified sensitivity, as (mistake, factor to the truth).
_UNIT_MISTAKES = (
    ('the pressure is recorded in kPa instead of Pa', 1e3),
    ('the pressure is recorded in MPa instead of Pa', 1e6),
    ('the pressure is recorded in bar instead of Pa', 1e5),
    ('the pressure is recorded in psi instead of Pa', 6894.757293168),
    ('the pressure is recorded in Pa but labelled kPa (scaled up 10^3)', 1e-3),
    ('the pressure is recorded in Pa but labelled MPa (scaled up 10^6)', 1e-6),
    ('the acceleration is recorded in g instead of m/s²', 1 / G0),
    ('the acceleration is recorded in m/s² but labelled g', G0),
)


class ModelError(SensorCompError, ValueError):
    """A model is malformed, unstable, or its file cannot be read."""


def sensitivity_problem(mpa_per_g: float, *, what: str = 'the static sensitivity'
                        ) -> tuple[bool, str] | None:
    """
    Return ``(fatal, why)`` when a static sensitivity (MPa/g) looks like a unit mistake.

    Fatal outside :data:`PLAUSIBLE_MPA_PER_G`, a warning outside :data:`TYPICAL_MPA_PER_G`;
    None when plausible. ``what`` begins the message.
    """
    size = abs(mpa_per_g)
    if TYPICAL_MPA_PER_G[0] <= size <= TYPICAL_MPA_PER_G[1]:
        return None
    if size == 0 or not math.isfinite(size):
        return True, (f'{what} is {mpa_per_g:g} MPa/g: the pressure does not follow the '
                      f'acceleration; check the pressure channel and its mapping')
    low, high = PLAUSIBLE_MPA_PER_G
    fatal = not low <= size <= high
    bound, where = ((low, 'below') if size < low else (high, 'above')) if fatal else (
        (TYPICAL_MPA_PER_G[0], 'below') if size < TYPICAL_MPA_PER_G[0]
        else (TYPICAL_MPA_PER_G[1], 'above'))
    decades = abs(math.log10(size / bound))
    guesses = [f'{mistake} (then {size * factor:.2g} MPa/g)'
               for mistake, factor in _UNIT_MISTAKES
               if TYPICAL_MPA_PER_G[0] <= size * factor <= TYPICAL_MPA_PER_G[1]]
    guess = ('; or '.join(guesses) if guesses else
             'no single unit mistake explains it: check the channel mapping and the units')
    span = (f'the range any piezoelectric pressure sensor can show ({low:g} to {high:g} MPa/g)'
            if fatal else f'the usual range ({TYPICAL_MPA_PER_G[0]:g} to '
                          f'{TYPICAL_MPA_PER_G[1]:g} MPa/g)')
    return fatal, (f'{what} {size:.3g} MPa/g is {decades:.1f} decades {where} '
                   f'{span}. Likely {guess}. Recordings must hold pressure in Pa and '
                   f'acceleration in m/s²: convert them (sensor-comp import converts CSV '
                   f'columns named with their unit, e.g. pressure_MPa, accel_z_g) and '
                   f'identify again')


@dataclass(frozen=True)
class Source:
    """
    One recording a model was identified from.

    Args:
        path: File name as given (bag or CSV).
        sha256: Hex SHA-256 of the file's bytes.
        shots: The shots used (indices, or dicts with ``index``, ``start``, ``stop``).

    """

    path: str
    sha256: str
    shots: tuple = ()

    @classmethod
    def from_file(cls, path: str | os.PathLike, *, shots: Iterable = ()) -> Source:
        """
        Hash the file at ``path`` and return its source entry.

        Raises:
            ModelError: If the file cannot be read.

        """
        digest = hashlib.sha256()
        try:
            with open(path, 'rb') as f:
                for chunk in iter(lambda: f.read(1 << 20), b''):
                    digest.update(chunk)
        except OSError as exc:
            raise ModelError(f'cannot hash source file {os.fspath(path)!r}: {exc}') from None
        return cls(os.fspath(path), digest.hexdigest(), tuple(shots))

    def to_json(self) -> dict:
        """Return the JSON object of this source."""
        return {'path': self.path, 'sha256': self.sha256, 'shots': list(self.shots)}


@dataclass(frozen=True)
class ContinuousView:
    """
    The continuous-time physics of the input-0 path.

    Attributes:
        natural_frequency_hz: Of the pole pair with the highest resonance; None if overdamped.
        damping_ratio: Of that pair; None if overdamped.
        overdamped: True when there is no complex pole pair.
        time_constants_s: Of the positive real poles, slowest first.
        static_gain: DC gain ``B_i(1)/A(1)`` of every input (Pa per input unit).
        sensitivity_MPa_per_g: ``static_gain[0] · G0 / 1e6``.
        sensitivity_pC_per_g: The same in pC/g when the charge sensitivity is known.

    """

    natural_frequency_hz: float | None
    damping_ratio: float | None
    overdamped: bool
    time_constants_s: tuple[float, ...]
    static_gain: tuple[float, ...]
    sensitivity_MPa_per_g: float
    sensitivity_pC_per_g: float | None

    def to_json(self) -> dict:
        """Return the JSON object of this view."""
        return {'natural_frequency_hz': self.natural_frequency_hz,
                'damping_ratio': 'overdamped' if self.overdamped else self.damping_ratio,
                'time_constants_s': list(self.time_constants_s),
                'static_gain_Pa_per_input_unit': list(self.static_gain),
                'sensitivity_MPa_per_g': self.sensitivity_MPa_per_g,
                'sensitivity_pC_per_g': self.sensitivity_pC_per_g}


def _poly(value, what: str, *, monic: bool) -> np.ndarray:
    arr = np.array(value, dtype=np.float64)
    if arr.ndim != 1 or arr.size == 0:
        raise ModelError(f'{what} must be a non-empty list of numbers, got shape {arr.shape}')
    if not np.all(np.isfinite(arr)):
        raise ModelError(f'{what} holds a non-finite value: {arr.tolist()}')
    if monic and arr[0] != 1.0:
        raise ModelError(f'{what} must start with 1 (monic), got {arr[0]!r}')
    arr.flags.writeable = False
    return arr


def _optional_poly(value, what: str, *, monic: bool) -> np.ndarray | None:
    return None if value is None else _poly(value, what, monic=monic)


@dataclass(frozen=True, eq=False)
class Model:
    """
    An identified input → induced-pressure model, immutable (see ``doc/model-file.md``).

    Args:
        fs: Sample rate in Hz the polynomials belong to.
        structure: ``'arx'``, ``'armax'``, ``'ararx'`` or ``'oe'``.
        inputs: Input names, ``('a_z',)`` for the base model.
        b: Numerators ``(n_inputs, nb)``; ``b[i, j]`` multiplies ``u_i(k − nk − j)``.
        a: Common monic denominator ``[1, a1, ..., ana]``.
        nk: Input delay in samples.
        c: Noise numerator or None; ``d``: noise denominator or None.
        b_std: Standard deviations of ``b`` (``a_std``, ``c_std``, ``d_std`` alike), or None.
        charge_sensitivity_pC_per_MPa: The sensor's charge sensitivity, if known.
        fit: Fit statistics (names to numbers, booleans or strings).
        provenance: The recordings and shots the model comes from.
        effects: Extra physical effects, each a dict with at least an ``'id'``.
        created: Creation time, ISO 8601 UTC.
        version: ``sensor_comp`` version that created the model.

    Raises:
        ModelError: On inconsistent shapes, non-finite numbers or bad values.

    """

    fs: float
    structure: str
    inputs: tuple[str, ...]
    b: np.ndarray
    a: np.ndarray
    nk: int
    c: np.ndarray | None = None
    d: np.ndarray | None = None
    b_std: np.ndarray | None = None
    a_std: np.ndarray | None = None
    c_std: np.ndarray | None = None
    d_std: np.ndarray | None = None
    charge_sensitivity_pC_per_MPa: float | None = None
    fit: Mapping[str, float | int | bool | str] = field(default_factory=dict)
    provenance: tuple[Source, ...] = ()
    effects: tuple[Mapping, ...] = ()
    created: str = ''
    version: str = __version__

    def __post_init__(self):
        _check_header(self.fs, self.structure, self.nk)
        inputs = _check_inputs(self.inputs)
        values = {'fs': float(self.fs), 'inputs': inputs, 'nk': int(self.nk),
                  **self._polynomials(inputs),
                  'fit': _check_fit(self.fit), 'provenance': tuple(self.provenance),
                  'effects': _check_effects(self.effects)}
        cs = self.charge_sensitivity_pC_per_MPa
        if cs is not None:
            if not _is_number(cs) or cs <= 0:
                raise ModelError(f'charge sensitivity must be a positive number of pC/MPa, '
                                 f'got {cs!r}')
            values['charge_sensitivity_pC_per_MPa'] = float(cs)
        for name, value in values.items():
            object.__setattr__(self, name, value)

    def _polynomials(self, inputs: tuple[str, ...]) -> dict:
        """Return the checked polynomials and their standard deviations."""
        b = _numerators(self.b, inputs, 'model numerators')
        values = {'b': b, 'a': _poly(self.a, 'model denominator', monic=True),
                  'c': _optional_poly(self.c, 'model noise numerator c', monic=True),
                  'd': _optional_poly(self.d, 'model noise denominator d', monic=True)}
        for name in ('a', 'c', 'd'):
            std = _optional_poly(getattr(self, f'{name}_std'), f'standard deviations of {name}',
                                 monic=False)
            if std is not None and (values[name] is None or std.shape != values[name].shape):
                raise ModelError(f'standard deviations of {name} do not match its shape')
            values[f'{name}_std'] = std
        if self.b_std is not None:
            values['b_std'] = _numerators(self.b_std, inputs,
                                          'standard deviations of the numerators')
            if values['b_std'].shape != b.shape:
                raise ModelError(f'standard deviations of the numerators must have shape '
                                 f'{b.shape}, got {values["b_std"].shape}')
        return values

    @classmethod
    def from_estimate(cls, estimate: Estimate, *, fs: float,
                      inputs: Sequence[str] = ('a_z',),
                      charge_sensitivity_pC_per_MPa: float | None = None,
                      fit: Mapping[str, float | int | bool | str] | None = None,
                      provenance: Iterable[Source] = (), effects: Iterable[Mapping] = (),
                      created: str | None = None) -> Model:
        """
        Build a model from an identification result (``fit`` merged over its statistics).

        Raises:
            ModelError: When the inputs do not match the estimate or a value is bad.

        """
        known = bool(np.all(np.isfinite(estimate.std)))  # not for over-parameterised fits
        return cls(fs=fs, structure=estimate.structure, inputs=tuple(inputs), b=estimate.b,
                   a=estimate.a, nk=estimate.nk, c=estimate.c, d=estimate.d,
                   b_std=estimate.b_std if known else None,
                   a_std=estimate.a_std if known else None,
                   c_std=estimate.c_std if known else None,
                   d_std=estimate.d_std if known else None,
                   charge_sensitivity_pC_per_MPa=charge_sensitivity_pC_per_MPa,
                   fit={**estimate.statistics(), **(fit or {})},
                   provenance=tuple(provenance), effects=tuple(effects),
                   created=created or _now())

    @classmethod
    def load(cls, path: str | os.PathLike) -> Model:
        """Read a model file; see :func:`load`."""
        return load(path)

    @property
    def orders(self) -> dict[str, int]:
        """Orders ``na``, ``nb``, ``nc``, ``nd`` and delay ``nk``."""
        return {'na': self.a.size - 1, 'nb': self.b.shape[1],
                'nc': 0 if self.c is None else self.c.size - 1,
                'nd': 0 if self.d is None else self.d.size - 1, 'nk': self.nk}

    @property
    def static_gain(self) -> np.ndarray:
        """
        DC gain ``B_i(1)/A(1)`` of each input (Pa per input unit).

        Raises:
            ModelError: If the denominator has a pole at ``z = 1``.

        """
        den = float(np.sum(self.a))
        if den == 0.0:
            raise ModelError('the model has a pole at z = 1: its static gain is infinite')
        return self.b.sum(axis=1) / den

    def check_stable(self, *, margin: float = 0.0) -> None:
        """Raise :class:`ModelError` unless every pole lies inside ``|z| < 1 − margin``."""
        radius = max_root_radius(self.a)
        if not radius < 1.0 - margin:
            raise ModelError(f'the model is unstable: a pole of the denominator {self.a.tolist()}'
                             f' lies at |z| = {radius:.6f} (>= {1.0 - margin:g}); it cannot be '
                             f'simulated or used for compensation. Re-identify with output error '
                             f'(fit_oe), which keeps the poles inside the unit circle')

    def check_rate(self, fs: float, *, model_name: str = 'the model',
                   data_name: str = 'the recording') -> None:
        """Raise :class:`ModelError` unless ``fs`` is the model's sample rate."""
        if not math.isclose(self.fs, fs, rel_tol=1e-9):
            raise ModelError(f'{model_name} was identified at {self.fs:g} Hz but {data_name} '
                             f'is sampled at {fs:g} Hz: a discrete model belongs to one rate; '
                             f'identify a model on recordings at {fs:g} Hz')

    def continuous(self) -> ContinuousView:
        """
        Return the continuous-time view of the input-0 path (``s = fs · ln z``).

        Negative real poles have no continuous counterpart and are left out.
        """
        poles = np.roots(self.a) if self.a.size > 1 else np.empty(0)
        pairs = [z for z in poles if z.imag > 1e-12]
        real = sorted((z.real for z in poles if abs(z.imag) <= 1e-12 and z.real > 0),
                      reverse=True)
        taus = tuple(-1.0 / (self.fs * math.log(z)) for z in real if z < 1.0)
        fn = zeta = None
        if pairs:
            num = delayed_numerator(self.b, self.nk)[0]
            # Dominant pair: the one whose resonance shows the highest gain.
            z = max(pairs, key=lambda p: _gain_at(num, self.a, float(np.angle(p))))
            s = complex(np.log(z)) * self.fs
            fn = abs(s) / (2 * math.pi)
            zeta = -s.real / abs(s)
        gain = self.static_gain
        mpa_per_g = float(gain[0]) * G0 / 1e6
        cs = self.charge_sensitivity_pC_per_MPa
        return ContinuousView(fn, zeta, not pairs, taus, tuple(float(g) for g in gain),
                              mpa_per_g, None if cs is None else mpa_per_g * cs)

    def to_json(self) -> dict:
        """Return the JSON object of this model (schema :data:`SCHEMA`)."""
        def lst(x):
            return None if x is None else x.tolist()

        std = None
        if self.b_std is not None or self.a_std is not None:
            std = {'numerators': None if self.b_std is None else dict(
                       zip(self.inputs, self.b_std.tolist())),
                   'denominator': lst(self.a_std), 'c': lst(self.c_std),
                   'd': lst(self.d_std)}
        try:
            continuous = self.continuous().to_json()
        except ModelError:
            continuous = None
        return {
            'schema': SCHEMA, 'fs': self.fs, 'structure': self.structure,
            'orders': self.orders, 'inputs': list(self.inputs),
            'numerators': dict(zip(self.inputs, self.b.tolist())),
            'denominator': self.a.tolist(), 'noise': {'c': lst(self.c), 'd': lst(self.d)},
            'std': std, 'charge_sensitivity_pC_per_MPa': self.charge_sensitivity_pC_per_MPa,
            'continuous': continuous, 'fit': dict(self.fit),
            'provenance': [s.to_json() for s in self.provenance],
            'effects': [dict(e) for e in self.effects], 'created': self.created,
            'sensor_comp_version': self.version,
        }

    def save(self, path: str | os.PathLike) -> None:
        """
        Write the model as JSON to ``path`` atomically.

        Raises:
            ModelError: If the file cannot be written.

        """
        path = Path(path)
        text = json.dumps(self.to_json(), indent=2, allow_nan=False) + '\n'
        try:
            write_text_atomically(path, text)
        except OSError as exc:
            raise ModelError(f'cannot write model file {os.fspath(path)!r}: {exc}') from None


def _gain_at(num: np.ndarray, den: np.ndarray, omega: float) -> float:
    """Return ``|N(e^jω)/D(e^jω)|`` for polynomials in ``q⁻¹``."""
    zinv = np.exp(-1j * omega) ** np.arange(max(num.size, den.size))
    return abs(np.dot(num, zinv[:num.size]) / np.dot(den, zinv[:den.size]))


def _is_number(x) -> bool:
    return (isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, bool)
            and math.isfinite(x))


def _now() -> str:
    return datetime.datetime.now(datetime.timezone.utc).strftime('%Y-%m-%dT%H:%M:%SZ')


def _check_fit(fit) -> dict:
    if not isinstance(fit, Mapping):
        raise ModelError(f'model fit statistics must be a mapping, got {type(fit).__name__}')
    out = {}
    for key, value in fit.items():
        if not isinstance(key, str):
            raise ModelError(f'fit statistic names must be strings, got {key!r}')
        if isinstance(value, (bool, str)):
            out[key] = value
        elif _is_number(value):
            out[key] = value.item() if isinstance(value, np.generic) else value
        else:
            raise ModelError(f'fit statistic {key!r} must be a finite number, a boolean or a '
                             f'string, got {value!r}')
    return out


def _check_effects(effects) -> tuple[dict, ...]:
    out = []
    for index, effect in enumerate(effects):
        if not isinstance(effect, Mapping) or not isinstance(effect.get('id'), str):
            raise ModelError(f'effect {index} must be an object with a string "id", got '
                             f'{effect!r}')
        if effect['id'] not in EFFECTS:
            raise ModelError(f'effect {index} has the unknown id {effect["id"]!r}; this '
                             f'sensor_comp {__version__} knows {", ".join(EFFECTS)} (a model '
                             f'from a newer version?)')
        out.append(dict(effect))
    return tuple(out)


def _reject_constant(name: str):
    raise ValueError(f'non-finite number {name}')


def _check_finite_json(value, where: str) -> None:
    if isinstance(value, float) and not math.isfinite(value):
        raise ModelError(f'{where} is {value}; every number must be finite')
    if isinstance(value, dict):
        for key, item in value.items():
            _check_finite_json(item, f'{where}.{key}')
    elif isinstance(value, list):
        for index, item in enumerate(value):
            _check_finite_json(item, f'{where}[{index}]')


def _expect(obj: Mapping, key: str, types, where: str):
    value = obj.get(key)
    if isinstance(value, bool) or not isinstance(value, types):
        names = '/'.join(t.__name__ for t in (types if isinstance(types, tuple) else (types,)))
        raise ModelError(f'{where}: key {key!r} must be {names}, got '
                         f'{type(value).__name__} {value!r}'[:300])
    return value


def _numbers(value, where: str) -> list[float]:
    if not isinstance(value, list) or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
        raise ModelError(f'{where} must be a list of numbers, got {value!r}'[:300])
    return value


def load(path: str | os.PathLike) -> Model:
    """
    Read a model file written by :meth:`Model.save`; its continuous view is recomputed.

    Raises:
        ModelError: If the file cannot be read or parsed, or is not a valid model file of
            this schema and version (see ``doc/model-file.md``).

    """
    where = f'model file {os.fspath(path)!r}'
    doc = _read_document(path, where)
    _check_finite_json(doc, where)
    inputs = _expect(doc, 'inputs', list, where)
    numerators = _expect(doc, 'numerators', dict, where)
    if not all(isinstance(n, str) for n in inputs) or set(numerators) != set(inputs):
        raise ModelError(f'{where}: "numerators" must have one list per input {inputs!r}, '
                         f'has {sorted(numerators)!r}')
    orders = _expect(doc, 'orders', dict, where)
    for key in ('na', 'nb', 'nk'):
        _expect(orders, key, int, f'{where}: orders')
    model = _model_of(doc, inputs, numerators, orders, where)
    actual = model.orders
    for key in ('na', 'nb', 'nk'):
        if orders[key] != actual[key]:
            raise ModelError(f'{where}: orders.{key} = {orders[key]} does not match the '
                             f'polynomials ({key} = {actual[key]})')
    return model


def _model_of(doc: dict, inputs: list, numerators: dict, orders: dict, where: str) -> Model:
    """Build the model of a checked model file; errors name the file."""
    noise = doc.get('noise') or {}
    std = doc.get('std')
    if std is not None and not isinstance(std, dict):
        raise ModelError(f'{where}: "std" must be an object or null')
    std = std or {}
    std_num = std.get('numerators')
    try:
        return Model(
            fs=_expect(doc, 'fs', (int, float), where),
            structure=_expect(doc, 'structure', str, where), inputs=tuple(inputs),
            b=[_numbers(numerators[n], f'{where}: numerators[{n!r}]') for n in inputs],
            a=_numbers(doc['denominator'], f'{where}: denominator'), nk=orders['nk'],
            c=None if noise.get('c') is None else _numbers(noise['c'], f'{where}: noise.c'),
            d=None if noise.get('d') is None else _numbers(noise['d'], f'{where}: noise.d'),
            b_std=None if std_num is None else [
                _numbers(std_num.get(n), f'{where}: std.numerators[{n!r}]') for n in inputs],
            a_std=std.get('denominator'), c_std=std.get('c'), d_std=std.get('d'),
            charge_sensitivity_pC_per_MPa=doc.get('charge_sensitivity_pC_per_MPa'),
            fit=doc.get('fit') or {},
            provenance=tuple(_source(s, f'{where}: provenance[{i}]')
                             for i, s in enumerate(_list(doc, 'provenance', where))),
            effects=tuple(_list(doc, 'effects', where)),
            created=_expect(doc, 'created', str, where),
            version=_expect(doc, 'sensor_comp_version', str, where))
    except ModelError as exc:
        if str(exc).startswith(where):
            raise
        raise ModelError(f'{where}: {exc}') from None
    except (TypeError, ValueError) as exc:
        raise ModelError(f'{where}: malformed value ({exc})') from None


def _read_document(path: str | os.PathLike, where: str) -> dict:
    """Return the JSON object of a model file whose schema this version reads."""
    try:
        text = Path(path).read_text(encoding='utf-8')
    except (OSError, UnicodeDecodeError) as exc:
        raise ModelError(f'cannot read {where}: {exc}') from None
    try:
        doc = json.loads(text, parse_constant=_reject_constant)
    except ValueError as exc:
        raise ModelError(f'{where} is not valid JSON ({exc}); every number must be '
                         f'finite') from None
    if not isinstance(doc, dict):
        raise ModelError(f'{where} must hold a JSON object, got {type(doc).__name__}')
    schema = doc.get('schema')
    if not isinstance(schema, str) or not schema.startswith(_SCHEMA_PREFIX):
        raise ModelError(f'{where} is not a sensor_comp model (schema {schema!r}, expected '
                         f'{SCHEMA!r})')
    if schema != SCHEMA:
        raise ModelError(f'{where} has schema {schema!r}, which this sensor_comp '
                         f'{__version__} cannot read (it reads {SCHEMA!r}); use the '
                         f'sensor_comp version that wrote it or re-identify the model')
    missing = [key for key in _REQUIRED if key not in doc]
    if missing:
        raise ModelError(f'{where} lacks the key(s) {", ".join(map(repr, missing))}')
    return doc


def _check_header(fs, structure, nk) -> None:
    """Raise ModelError unless the rate, structure and delay are valid."""
    if not _is_number(fs) or not fs > 0:
        raise ModelError(f'model sample rate fs must be a positive finite number of Hz, '
                         f'got {fs!r}')
    if structure not in STRUCTURES:
        raise ModelError(f'model structure must be one of {", ".join(STRUCTURES)}, got '
                         f'{structure!r}')
    if isinstance(nk, bool) or not isinstance(nk, (int, np.integer)) or nk < 0:
        raise ModelError(f'model delay nk must be an integer >= 0, got {nk!r}')


def _check_inputs(names) -> tuple[str, ...]:
    """Return the input names; refuse duplicates and names this version cannot compute."""
    inputs = tuple(names)
    if not inputs or not all(isinstance(n, str) and n for n in inputs) \
            or len(set(inputs)) != len(inputs):
        raise ModelError(f'model inputs must be distinct non-empty names, got {inputs!r}')
    for name in inputs:
        try:
            parse_channel(name)
        except InputError as exc:
            raise ModelError(f'{exc}; this sensor_comp {__version__} cannot compute it '
                             f'(a model from a newer version?)') from None
    return inputs


def _numerators(values, inputs: tuple[str, ...], what: str) -> np.ndarray:
    """Return one finite, read-only row of numerator coefficients per input."""
    b = np.array(values, dtype=np.float64)
    b = b[np.newaxis] if b.ndim == 1 else b
    if b.ndim != 2 or b.shape[0] != len(inputs) or b.shape[1] == 0:
        raise ModelError(f'{what} must have shape ({len(inputs)}, nb) for inputs {inputs}, '
                         f'got {b.shape}')
    if not np.all(np.isfinite(b)):
        raise ModelError(f'{what} hold a non-finite value: {b.tolist()}')
    b.flags.writeable = False
    return b


def _list(doc: Mapping, key: str, where: str) -> list:
    value = doc.get(key, [])
    if not isinstance(value, list):
        raise ModelError(f'{where}: {key!r} must be a list, got {type(value).__name__}')
    return value


def _source(entry, where: str) -> Source:
    if not isinstance(entry, dict) or not isinstance(entry.get('path'), str) \
            or not isinstance(entry.get('sha256'), str) \
            or not isinstance(entry.get('shots', []), list):
        raise ModelError(f'{where} must be an object with string "path" and "sha256" and a '
                         f'"shots" list, got {entry!r}'[:300])
    return Source(entry['path'], entry['sha256'], tuple(
        tuple(s) if isinstance(s, list) else s for s in entry.get('shots', [])))


def frequency_response(model: Model, *, n: int = 1024,
                       f_hz: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """
    Return ``(f_hz, h)``: each input path's complex response in Pa per unit (Fig. 13).

    At ``f_hz`` if given, else ``n`` log-spaced frequencies from ``fs·1e-5`` to ``fs/2``;
    ``h`` is ``(n_inputs, n)``, the delay included.
    """
    f = (np.geomspace(model.fs * 1e-5, model.fs / 2, n) if f_hz is None
         else np.asarray(f_hz, dtype=np.float64))
    num = delayed_numerator(model.b, model.nk)
    h = np.array([signal.freqz(row, model.a, worN=f, fs=model.fs)[1] for row in num])
    return f, h


def step_response(model: Model, *, duration_s: float) -> tuple[np.ndarray, np.ndarray]:
    """
    Return ``(t, y)``: the response to a unit step on each input, from rest (Fig. 14).

    Raises:
        ModelError: If ``duration_s`` is not positive.

    """
    if not _is_number(duration_s) or duration_s <= 0:
        raise ModelError(f'step response duration must be a positive number of seconds, got '
                         f'{duration_s!r}')
    count = max(int(round(duration_s * model.fs)), 1)
    num = delayed_numerator(model.b, model.nk)
    step = np.ones(count)
    return (np.arange(count) / model.fs,
            np.array([signal.lfilter(row, model.a, step) for row in num]))
