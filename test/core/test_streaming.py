"""
Live compensation of block streams: pairing by stamp, state across blocks, accounting.

The data are a short simulated rig run (two Table-2 shots) at 192 kS/s, a rate whose sample
period (5208.3 ns) is not a whole number of nanoseconds, so block stamps carry rounding as
a real DAQ's do. The filter is the simulator's sensor discretised at that rate on ``a_z``
plus a small derivative path on ``da_x``: both the ``lfilter`` state and the derivative's
carried sample must cross block boundaries. The reference is one
:class:`CompensationFilter` run over the whole signal at once; the tolerance 1e-9 of the
peak is float64 round-off of a 2nd-order recursion, far below any real error (a lost
sample or a restarted state changes the output by the size of the induced pressure).
"""

import numpy as np
import pytest
from scipy import signal

from sensor_comp.core.compensation import CompensationError, CompensationFilter
from sensor_comp.core.streaming import BlockCompensator
from sensor_comp.sim import RigConfig, simulate, TABLE2
from sensor_comp.streams import Gap

FS = 192e3
T0_NS = 1_700_000_000_000_000_017
#: Relative tolerance of block-wise against whole-signal output (round-off).
REL = 1e-9


@pytest.fixture(scope='module')
def run():
    """Return a short simulated run: the 2185 g and the 180 g Table-2 shots."""
    sim = simulate(RigConfig(shots=(TABLE2[9], TABLE2[5]), fs=FS, pre_trigger_s=0.002,
                             post_shot_s=0.008, seed=4))
    return sim.recording


def make_filter(scale: float = 1.0) -> CompensationFilter:
    """Return a fresh filter: the simulated sensor on ``a_z``, a derivative path on ``da_x``."""
    sensor = RigConfig().sensor
    wn = 2 * np.pi * sensor.fn_hz
    num, den, _ = signal.cont2discrete(
        ([sensor.gain_pa_per_ms2 * wn ** 2], [1, 2 * sensor.zeta * wn, wn ** 2]), 1 / FS,
        method='foh')
    num = np.ravel(num)
    b = scale * np.vstack([num, 1e-4 * num[::-1]])
    return CompensationFilter(b, den, nk=2, inputs=('a_z', 'da_x'), fs=FS)


def cut(n: int, rng: np.random.Generator, *, largest: int = 1500) -> list[tuple[int, int]]:
    """Return random ``(start, stop)`` block bounds covering ``n`` samples, tiny ones too."""
    sizes = [1, 2, 1]  # below the filter order and the delay
    while sum(sizes) < n:
        sizes.append(int(rng.choice([1, 3, 17, 250, 999, largest])))
    edges = np.minimum(np.cumsum([0] + sizes), n)
    return [(int(i), int(j)) for i, j in zip(edges[:-1], edges[1:]) if j > i]


def stamp(start: int) -> int:
    """Return the stamp of the block starting at sample ``start`` (rounded to 1 ns)."""
    return T0_NS + round(start * 1e9 / FS)


def whole(recording, start: int = 0, stop: int | None = None, **options):
    """Return ``(compensated, induced)`` of a fresh filter run over ``start:stop`` at once."""
    return make_filter(**options).process(recording.acceleration[:, start:stop],
                                          recording.pressure[start:stop])


def assert_close(actual, expected):
    """Assert two output arrays agree to round-off of the expected one's peak."""
    assert actual.shape == expected.shape
    assert np.max(np.abs(actual - expected)) <= REL * np.max(np.abs(expected))


def feed(compensator, recording, events):
    """
    Feed ``events`` (``('p' | 'a', start, stop)``) and return the blocks produced.

    Each event sends samples ``start:stop`` of the pressure or acceleration with the stamp of
    ``start``.
    """
    out = []
    for topic, start, stop in events:
        if topic == 'p':
            out += compensator.add_pressure(stamp(start), recording.pressure[start:stop])
        else:
            out += compensator.add_acceleration(stamp(start),
                                                recording.acceleration[:, start:stop])
    return out


def in_order(bounds):
    """Return events sending each block's pressure, then its acceleration."""
    return [(topic, i, j) for i, j in bounds for topic in ('p', 'a')]


def joined(blocks):
    """Return the concatenated compensated and induced outputs."""
    return (np.concatenate([b.compensated for b in blocks]),
            np.concatenate([b.induced for b in blocks]))


def assert_accounted(counters):
    """Assert every received sample was output or counted unpaired."""
    assert counters.pressure_samples == counters.output_samples + counters.unpaired_pressure
    assert counters.acceleration_samples == (counters.output_samples
                                             + counters.unpaired_acceleration)


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_blocks_of_random_sizes_give_the_whole_signal_output(run, seed):
    bounds = cut(run.n_samples, np.random.default_rng(seed))
    compensator = BlockCompensator(make_filter(), fs=FS)
    blocks = feed(compensator, run, in_order(bounds))
    compensator.flush()
    assert [b.stamp_ns for b in blocks] == [stamp(i) for i, _ in bounds]
    compensated, induced = joined(blocks)
    expected_compensated, expected_induced = whole(run)
    assert_close(induced, expected_induced)
    assert_close(compensated, expected_compensated)
    # The induced pressure is large: losing state at a block boundary would show.
    assert np.max(np.abs(expected_induced)) > 0.5 * np.max(np.abs(run.pressure))
    counters = compensator.counters
    assert counters.output_samples == counters.pressure_samples == run.n_samples
    assert counters.acceleration_samples == run.n_samples
    assert counters.gaps == [] and counters.mismatched == 0 and counters.model_changes == 0
    assert counters.unpaired_pressure == counters.unpaired_acceleration == 0
    assert counters.pending_ok


def test_topics_arriving_in_either_order_still_pair(run):
    rng = np.random.default_rng(5)
    bounds = cut(run.n_samples, rng, largest=400)
    # Each topic's blocks come in time order, the two topics interleaved at random: either
    # may lead the other by several blocks.
    queues = {'p': list(bounds), 'a': list(bounds)}
    events = []
    while queues['p'] or queues['a']:
        topic = rng.choice([t for t in 'pa' if queues[t]])
        events.append((str(topic), *queues[topic].pop(0)))
    assert sum(events.index(('a', *b)) < events.index(('p', *b)) for b in bounds) > 3
    compensator = BlockCompensator(make_filter(), fs=FS)
    blocks = feed(compensator, run, events)
    compensator.flush()
    assert [b.stamp_ns for b in blocks] == [stamp(i) for i, _ in bounds]
    assert_close(joined(blocks)[0], whole(run)[0])
    counters = compensator.counters
    assert counters.output_samples == run.n_samples and counters.gaps == []
    assert counters.unpaired_pressure == counters.unpaired_acceleration == 0


@pytest.mark.parametrize('lost', ['both', 'pressure', 'acceleration'])
def test_missing_block_is_a_gap_and_the_filter_restarts_from_rest(run, lost):
    bounds = [(i, min(i + 250, run.n_samples)) for i in range(0, run.n_samples, 250)]
    # Lose the blocks carrying the first shot's peak, where the filter state is largest.
    peak = int(np.argmax(np.abs(run.axial)))
    k = next(n for n, (i, j) in enumerate(bounds) if i <= peak < j)
    assert k >= 1, 'the gap must follow a compensated block'
    missing_start, missing_stop = bounds[k][0], bounds[k + 1][1]
    events = [e for e in in_order(bounds)
              if not (missing_start <= e[1] < missing_stop
                      and (lost == 'both' or e[0] == lost[0]))]
    compensator = BlockCompensator(make_filter(), fs=FS)
    blocks = feed(compensator, run, events)
    compensator.flush()
    counters = compensator.counters
    assert counters.gaps == [Gap(missing_start, missing_stop - missing_start)]
    assert counters.output_samples == run.n_samples - (missing_stop - missing_start)
    before = [b for b in blocks if b.stamp_ns < stamp(missing_start)]
    after = [b for b in blocks if b.stamp_ns >= stamp(missing_stop)]
    assert len(before) + len(after) == len(blocks)
    assert_close(joined(before)[0], whole(run, 0, missing_start)[0])
    fresh = whole(run, missing_stop)
    assert_close(joined(after)[0], fresh[0])
    assert_close(joined(after)[1], fresh[1])
    # Continuing the state instead would differ by far more than round-off here.
    continued = whole(run)[1][missing_stop:]
    assert np.max(np.abs(continued - fresh[1])) > 1e3 * REL * np.max(np.abs(fresh[1]))
    # The partner of a lost block never pairs: its samples are counted, not dropped.
    width = missing_stop - missing_start
    assert counters.unpaired_pressure == (width if lost == 'acceleration' else 0)
    assert counters.unpaired_acceleration == (width if lost == 'pressure' else 0)
    assert_accounted(counters)


def test_unpaired_blocks_are_counted_by_samples_at_flush(run):
    bounds = [(0, 500), (500, 1200), (1200, 1300), (1300, 1800)]
    # The last two acceleration blocks and the last pressure block never arrive.
    events = in_order(bounds[:2]) + [('p', 1200, 1300), ('a', 1300, 1800)]
    compensator = BlockCompensator(make_filter(), fs=FS)
    blocks = feed(compensator, run, events)
    counters = compensator.counters
    assert len(blocks) == 2 and counters.output_samples == 1200
    assert counters.unpaired_pressure == counters.unpaired_acceleration == 0  # still waiting
    compensator.flush()
    assert counters.unpaired_pressure == 100
    assert counters.unpaired_acceleration == 500
    assert_accounted(counters)
    assert not counters.pending_ok


def test_blocks_waiting_too_long_are_given_up_oldest_first(run):
    compensator = BlockCompensator(make_filter(), fs=FS, max_pending=4)
    feed(compensator, run, [('p', 100 * i, 100 * i + 100) for i in range(7)])
    counters = compensator.counters
    assert counters.unpaired_pressure == 300 and counters.output_samples == 0
    # The newest four still pair.
    blocks = feed(compensator, run, [('a', 100 * i, 100 * i + 100) for i in range(3, 7)])
    assert [b.stamp_ns for b in blocks] == [stamp(100 * i) for i in range(3, 7)]
    assert_close(joined(blocks)[0], whole(run, 300, 700)[0])
    compensator.flush()
    assert counters.unpaired_pressure == 300 and counters.unpaired_acceleration == 0
    assert_accounted(counters)


def test_pairs_of_different_widths_are_counted_and_not_compensated(run):
    bounds = [(0, 400), (400, 800), (800, 1200)]
    events = [('p', 0, 400), ('a', 0, 400), ('p', 400, 800), ('a', 400, 799),
              ('p', 800, 1200), ('a', 800, 1200)]
    compensator = BlockCompensator(make_filter(), fs=FS)
    blocks = feed(compensator, run, events)
    compensator.flush()
    counters = compensator.counters
    assert counters.mismatched == 1
    assert counters.unpaired_pressure == 400 and counters.unpaired_acceleration == 399
    assert [b.stamp_ns for b in blocks] == [stamp(0), stamp(800)]
    assert counters.output_samples == 800
    # The samples of the rejected pair are missing from the output: the filter restarts.
    assert counters.gaps == [Gap(400, 400)]
    assert_close(blocks[1].compensated, whole(run, *bounds[2])[0])
    assert_accounted(counters)


def test_set_filter_changes_the_output_from_the_next_block_only(run):
    bounds = cut(run.n_samples, np.random.default_rng(7), largest=600)
    half = len(bounds) // 2
    compensator = BlockCompensator(make_filter(), fs=FS)
    first = feed(compensator, run, in_order(bounds[:half]))
    compensator.set_filter(make_filter(scale=0.5))
    second = feed(compensator, run, in_order(bounds[half:]))
    compensator.flush()
    split = bounds[half][0]
    assert_close(joined(first)[1], whole(run, 0, split)[1])
    # The new model from rest on the rest of the signal; no sample dropped or repeated.
    assert_close(joined(second)[1], whole(run, split, scale=0.5)[1])
    counters = compensator.counters
    assert counters.model_changes == 1 and counters.gaps == []
    assert counters.output_samples == run.n_samples
    compensator.set_filter(make_filter())
    assert counters.model_changes == 2


@pytest.mark.parametrize('seed', range(8))
def test_every_pressure_sample_is_output_or_counted_unpaired(run, seed):
    rng = np.random.default_rng(100 + seed)
    bounds = cut(run.n_samples, rng, largest=300)
    timeline = []
    for i, j in bounds:
        fate = str(rng.choice(['pair', 'pair', 'pair', 'swap', 'no_p', 'no_a', 'narrow',
                               'late']))
        pair = {'pair': [('p', i, j), ('a', i, j)], 'swap': [('a', i, j), ('p', i, j)],
                'no_p': [('a', i, j)], 'no_a': [('p', i, j)],
                'narrow': [('p', i, j), ('a', i, max(i + 1, j - 1))],
                'late': [('p', i, j)]}[fate]
        timeline += [(len(timeline), event) for event in pair]
        if fate == 'late':
            # Its acceleration comes after the next pairs: too late to pair.
            timeline.append((len(timeline) + 6.5, ('a', i, j)))
    events = [event for _, event in sorted(timeline)]
    compensator = BlockCompensator(make_filter(), fs=FS, max_pending=8)
    blocks = feed(compensator, run, events)
    compensator.flush()
    counters = compensator.counters
    assert counters.pressure_samples == sum(j - i for t, i, j in events if t == 'p')
    assert counters.acceleration_samples == sum(j - i for t, i, j in events if t == 'a')
    assert counters.output_samples == sum(b.compensated.size for b in blocks)
    assert_accounted(counters)
    assert counters.unpaired_pressure > 0 and counters.unpaired_acceleration > 0


def test_a_pressure_block_received_twice_is_accounted(run):
    # A re-delivered block (same stamp) before its partner: one copy is compensated, the
    # other must show up as unpaired, not vanish from the accounting.
    events = [('p', 0, 500), ('p', 0, 500), ('a', 0, 500), ('p', 500, 900), ('a', 500, 900)]
    compensator = BlockCompensator(make_filter(), fs=FS)
    blocks = feed(compensator, run, events)
    compensator.flush()
    counters = compensator.counters
    assert counters.pressure_samples == 1400
    assert counters.output_samples == 900 and len(blocks) == 2
    assert counters.unpaired_pressure == 500
    assert_accounted(counters)


def test_blocks_with_the_wrong_channels_are_refused(run):
    compensator = BlockCompensator(make_filter(), fs=FS)
    with pytest.raises(CompensationError, match=r'one channel.*\(2, 10\)'):
        compensator.add_pressure(T0_NS, np.zeros((2, 10)))
    with pytest.raises(CompensationError, match=r'3 rows.*\(2, 10\)'):
        compensator.add_acceleration(T0_NS, np.zeros((2, 10)))
    # A (1, w) pressure block is one channel.
    assert compensator.add_pressure(stamp(0), run.pressure[None, :10]) == []
    assert len(compensator.add_acceleration(stamp(0), run.acceleration[:, :10])) == 1
