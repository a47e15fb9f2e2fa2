"""Shared fixtures of the bag and message tests: small recordings and hand-made messages."""

import numpy as np
import pytest

from sensor_comp.io.cdr import CdrWriter
from sensor_comp.streams import Recording

#: A realistic absolute start time (2023-11-14) with a non-zero nanosecond part.
T0_NS = 1_700_000_000_123_456_789


@pytest.fixture
def make_recording():
    """Return a factory of noisy recordings with distinct, reproducible samples."""
    def make(n: int = 2500, *, fs: float = 10_000.0, seed: int = 0,
             t0_ns: int = T0_NS) -> Recording:
        rng = np.random.default_rng(seed)
        return Recording(fs=fs, t0_ns=t0_ns, pressure=rng.normal(0.0, 1e5, n),
                         acceleration=rng.normal(0.0, 50.0, (3, n)), frame_id='piezo',
                         metadata={'charge_sensitivity_pC_per_MPa': '100.0'})
    return make


@pytest.fixture
def image_cdr():
    """Return a builder of arbitrary (possibly invalid) ``sensor_msgs/msg/Image`` CDR bytes."""
    def build(*, height: int = 1, width: int = 4, encoding: str = '64FC1',
              is_bigendian: int = 0, step: int | None = None, data: bytes | None = None,
              stamp: tuple[int, int] = (1, 2), frame_id: str = 'sensor') -> bytes:
        step = 8 * width if step is None else step
        data = bytes(height * step) if data is None else data
        w = CdrWriter()
        w.int32(stamp[0])
        w.uint32(stamp[1])
        w.string(frame_id)
        w.uint32(height)
        w.uint32(width)
        w.string(encoding)
        w.uint8(is_bigendian)
        w.uint32(step)
        w.primitive_sequence(data, itemsize=1, count=len(data))
        return w.getvalue()
    return build
