"""
The signal stream contract: uniformly sampled multi-channel streams and their metadata.

Samples on the last axis, ``t0_ns`` integer stamp plus ``fs``, SI units; the rate travels
on the latched ``stream_info`` topic (:class:`StreamInfo`). See ``doc/streams.md``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
import math

import numpy as np

from .errors import SensorCompError

__all__ = [
    'ACCELERATION',
    'COMPENSATED',
    'G0',
    'G_PER_MS',
    'INDUCED',
    'PRESSURE_RAW',
    'STREAM_INFO',
    'Gap',
    'Recording',
    'Stream',
    'StreamError',
    'StreamInfo',
]

#: Standard gravity in m/s² (reports show g, topics carry m/s²).
G0 = 9.80665
#: One g per millisecond in m/s³: the unit of jerk in strain sensitivities (Pa per g/ms).
G_PER_MS = G0 * 1e3

#: Topic names relative to the rig namespace.
ACCELERATION = 'acceleration'
PRESSURE_RAW = 'pressure/raw'
COMPENSATED = 'pressure/compensated'
INDUCED = 'pressure/induced'
STREAM_INFO = 'stream_info'


class StreamError(SensorCompError, ValueError):
    """A stream is malformed: wrong shape, rate, stamps or metadata."""


@dataclass(frozen=True)
class StreamInfo:
    """
    Metadata of one block stream, as published on the latched ``stream_info`` topic.

    A non-positive or non-finite rate or an empty channel list raises StreamError.

    Attributes:
        topic: Topic name relative to the rig namespace, e.g. ``'acceleration'``.
        fs: Sample rate in Hz.
        channels: One name per row, e.g. ``('x', 'y', 'z')``.
        unit: SI unit of every channel, e.g. ``'Pa'`` or ``'m/s^2'``.
        frame_id: Sensor frame of the samples.
        metadata: Further sensor facts as strings.

    """

    topic: str
    fs: float
    channels: tuple[str, ...]
    unit: str
    frame_id: str = 'sensor'
    metadata: dict[str, str] = field(default_factory=dict)

    def __post_init__(self):
        if not (isinstance(self.fs, (int, float)) and math.isfinite(self.fs) and self.fs > 0):
            raise StreamError(f'stream {self.topic!r}: sample rate must be a positive number '
                              f'of Hz, got {self.fs!r}')
        if not self.channels:
            raise StreamError(f'stream {self.topic!r}: needs at least one channel')
        object.__setattr__(self, 'channels', tuple(self.channels))
        object.__setattr__(self, 'fs', float(self.fs))


@dataclass(frozen=True)
class Gap:
    """Samples missing from a stream: ``count`` samples starting at sample ``start``."""

    start: int
    count: int


@dataclass(frozen=True)
class Stream:
    """
    A uniformly sampled ``(channels, samples)`` float64 stream assembled from blocks.

    ``t0_ns`` is the acquisition time of sample 0; ``gaps`` are runs of samples no block
    delivered (NaN in ``data``). ``data`` without one row per channel raises StreamError.
    """

    info: StreamInfo
    t0_ns: int
    data: np.ndarray
    gaps: tuple[Gap, ...] = ()

    def __post_init__(self):
        data = np.asarray(self.data, dtype=np.float64)
        if data.ndim != 2 or data.shape[0] != len(self.info.channels):
            raise StreamError(
                f'stream {self.info.topic!r}: data must have shape '
                f'({len(self.info.channels)}, samples), got {data.shape}')
        object.__setattr__(self, 'data', data)
        object.__setattr__(self, 't0_ns', int(self.t0_ns))

    @property
    def fs(self) -> float:
        return self.info.fs

    @property
    def n_samples(self) -> int:
        return self.data.shape[-1]

    def times(self) -> np.ndarray:
        """Return the time of every sample in seconds since ``t0_ns``."""
        return np.arange(self.n_samples) / self.fs

    def stamp_ns(self, index: int) -> int:
        """Return the nanosecond stamp of sample ``index``."""
        return self.t0_ns + round(index * 1e9 / self.fs)

    def channel(self, name: str) -> np.ndarray:
        """Return the row of channel ``name``; StreamError if there is none."""
        try:
            return self.data[self.info.channels.index(name)]
        except ValueError:
            raise StreamError(f'stream {self.info.topic!r} has no channel {name!r}; it has '
                              f'{", ".join(self.info.channels)}') from None


@dataclass(frozen=True)
class Recording:
    """
    Pressure (Pa) and triaxial acceleration (m/s², rows x, y, z; z the sensor axis) of one rig.

    ``pressure`` is ``(samples,)``, ``acceleration`` ``(3, samples)`` (else StreamError),
    ``t0_ns`` the time of sample 0; ``metadata`` holds sensor facts, e.g.
    ``{'charge_sensitivity_pC_per_MPa': '100.0'}``.
    """

    fs: float
    t0_ns: int
    pressure: np.ndarray
    acceleration: np.ndarray
    frame_id: str = 'sensor'
    metadata: dict[str, str] = field(default_factory=dict)

    def __post_init__(self):
        pressure = np.asarray(self.pressure, dtype=np.float64)
        acceleration = np.asarray(self.acceleration, dtype=np.float64)
        if pressure.ndim != 1:
            raise StreamError(f'pressure must be one channel, got shape {pressure.shape}')
        if acceleration.shape != (3, pressure.size):
            raise StreamError(f'acceleration must have shape (3, {pressure.size}) to match '
                              f'the pressure, got {acceleration.shape}')
        StreamInfo(PRESSURE_RAW, self.fs, ('p',), 'Pa')  # validates fs
        object.__setattr__(self, 'pressure', pressure)
        object.__setattr__(self, 'acceleration', acceleration)
        object.__setattr__(self, 'fs', float(self.fs))
        object.__setattr__(self, 't0_ns', int(self.t0_ns))

    @property
    def n_samples(self) -> int:
        return self.pressure.size

    @property
    def axial(self) -> np.ndarray:
        """Return the acceleration along the sensor axis (row z) in m/s²."""
        return self.acceleration[2]

    @property
    def charge_sensitivity(self) -> float | None:
        """Return the charge sensitivity in pC/MPa, or None when the metadata lacks it."""
        value = self.metadata.get('charge_sensitivity_pC_per_MPa')
        return None if value in (None, '') else float(value)

    def times(self) -> np.ndarray:
        """Return the time of every sample in seconds since ``t0_ns``."""
        return np.arange(self.n_samples) / self.fs

    def streams(self) -> tuple[Stream, Stream]:
        """Return the ``(acceleration, pressure/raw)`` streams of this recording."""
        accel = StreamInfo(ACCELERATION, self.fs, ('x', 'y', 'z'), 'm/s^2', self.frame_id,
                           dict(self.metadata))
        press = StreamInfo(PRESSURE_RAW, self.fs, ('p',), 'Pa', self.frame_id,
                           dict(self.metadata))
        return (Stream(accel, self.t0_ns, self.acceleration),
                Stream(press, self.t0_ns, self.pressure[np.newaxis]))

    def slice(self, start: int, stop: int) -> Recording:
        """Return samples ``start:stop`` as a new recording with its own ``t0_ns``."""
        start, stop, _ = slice(start, stop).indices(self.n_samples)
        return replace(self, t0_ns=self.t0_ns + round(start * 1e9 / self.fs),
                       pressure=self.pressure[start:stop],
                       acceleration=self.acceleration[:, start:stop])

    @classmethod
    def from_streams(cls, acceleration: Stream, pressure: Stream) -> Recording:
        """
        Join an acceleration and a pressure stream on their common time span.

        Raises StreamError if rates differ, the streams do not overlap, or their sample grids are
        offset by a fraction of a sample.
        """
        accel_name, press_name = acceleration.info.topic, pressure.info.topic
        if acceleration.data.shape[0] != 3:
            raise StreamError(f'stream {accel_name!r} must have 3 channels (x, y, z), has '
                              f'{acceleration.data.shape[0]} '
                              f'({", ".join(acceleration.info.channels)})')
        if pressure.data.shape[0] != 1:
            raise StreamError(f'stream {press_name!r} must have 1 channel, has '
                              f'{pressure.data.shape[0]} ({", ".join(pressure.info.channels)})')
        if not math.isclose(acceleration.fs, pressure.fs, rel_tol=1e-9):
            raise StreamError(f'sample rates differ: {accel_name!r} at '
                              f'{acceleration.fs:g} Hz, {press_name!r} at '
                              f'{pressure.fs:g} Hz; resample one of them first')
        fs = acceleration.fs
        offset = (pressure.t0_ns - acceleration.t0_ns) * fs / 1e9
        shift = round(offset)
        if abs(offset - shift) > 0.01:
            raise StreamError(f'{press_name!r} starts at {pressure.t0_ns} ns and {accel_name!r} '
                              f'at {acceleration.t0_ns} ns, {offset:.3f} samples apart at '
                              f'{fs:g} Hz: they are not on one grid; the two streams must '
                              f'come from one DAQ, whose blocks share stamps')
        a_start = max(0, shift)
        p_start = max(0, -shift)
        n = min(acceleration.n_samples - a_start, pressure.n_samples - p_start)
        if n <= 0:
            raise StreamError(f'{accel_name!r} ({_span(acceleration)}) and {press_name!r} '
                              f'({_span(pressure)}) do not overlap in time: record them '
                              f'together')
        metadata = {**acceleration.info.metadata, **pressure.info.metadata}
        return cls(fs=fs, t0_ns=acceleration.stamp_ns(a_start),
                   pressure=pressure.data[0, p_start:p_start + n],
                   acceleration=acceleration.data[:, a_start:a_start + n],
                   frame_id=pressure.info.frame_id, metadata=metadata)


def _span(stream: Stream) -> str:
    return f'{stream.t0_ns} to {stream.stamp_ns(stream.n_samples)} ns'
