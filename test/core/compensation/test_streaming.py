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

from sensor_comp.core.compensation.filter import CompensationError, CompensationFilter
from sensor_comp.core.compensation.streaming import BlockCompensator, BlockError
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


def make_filter(scale: float = 1.0, *, fn_scale: float = 1.0,
                zeta: float | None = None) -> CompensationFilter:
    """
    Return a fresh filter: the simulated sensor on ``a_z``, a derivative path on ``da_x``.

    ``scale`` multiplies its gain, ``fn_scale`` its natural frequency; ``zeta`` replaces its
    damping ratio.
    """
    sensor = RigConfig().sensor
    wn = 2 * np.pi * sensor.fn_hz * fn_scale
    zeta = sensor.zeta if zeta is None else zeta
    num, den, _ = signal.cont2discrete(
        ([sensor.gain_pa_per_ms2 * wn ** 2], [1, 2 * zeta * wn, wn ** 2]), 1 / FS,
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
    """
    Return ``(compensated, induced)`` of a fresh filter run over ``start:stop`` at once.

    ``options`` go to :func:`make_filter`.
    """
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
    """Assert every received sample was output or counted unpaired or overlapping."""
    assert counters.pressure_samples == (counters.output_samples + counters.unpaired_pressure
                                         + counters.overlapping)
    assert counters.acceleration_samples == (counters.output_samples
                                             + counters.unpaired_acceleration
                                             + counters.overlapping)


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
    # The acceleration stream passed the pressure block's stamp: its partner cannot come.
    # The acceleration block still waits: the pressure stream has not reached its stamp.
    assert counters.unpaired_pressure == 100 and counters.unpaired_acceleration == 0
    compensator.flush()
    assert counters.unpaired_pressure == 100
    assert counters.unpaired_acceleration == 500
    assert_accounted(counters)
    assert not counters.pending_ok


def test_blocks_waiting_longer_than_max_wait_are_given_up_oldest_first(run):
    # The safety net: 100-sample blocks, max_wait 350 samples of data.
    compensator = BlockCompensator(make_filter(), fs=FS, max_wait=350 / FS)
    feed(compensator, run, [('p', 100 * i, 100 * i + 100) for i in range(7)])
    counters = compensator.counters
    # Blocks 0-2 start more than 350 samples before the newest (600).
    assert counters.unpaired_pressure == 300 and counters.output_samples == 0
    # The newest four still pair.
    blocks = feed(compensator, run, [('a', 100 * i, 100 * i + 100) for i in range(3, 7)])
    assert [b.stamp_ns for b in blocks] == [stamp(100 * i) for i in range(3, 7)]
    assert_close(joined(blocks)[0], whole(run, 300, 700)[0])
    compensator.flush()
    assert counters.unpaired_pressure == 300 and counters.unpaired_acceleration == 0
    assert_accounted(counters)


@pytest.mark.parametrize('late', ['a', 'p'])
def test_a_partner_stream_late_by_thousands_of_blocks_still_pairs_everything(run, late):
    # 2 000 blocks of 2 samples: one topic arrives whole before the other (old bound: 1000
    # blocks waiting, and then everything was given up as unpaired).
    lines = []
    compensator = BlockCompensator(make_filter(), fs=FS, log=lines.append)
    bounds = [(i, i + 2) for i in range(0, 4000, 2)]
    early = 'p' if late == 'a' else 'a'
    blocks = feed(compensator, run, [(early, i, j) for i, j in bounds]
                  + [(late, i, j) for i, j in bounds])
    compensator.flush()
    counters = compensator.counters
    assert lines == []
    assert counters.output_samples == 4000 and len(blocks) == 2000
    assert counters.unpaired_pressure == counters.unpaired_acceleration == 0
    assert_close(joined(blocks)[0], whole(run, 0, 4000)[0])


def test_truly_missing_blocks_are_counted_exactly_and_a_run_is_two_lines(run):
    lines = []
    compensator = BlockCompensator(make_filter(), fs=FS, log=lines.append)
    bounds = [(i, i + 2) for i in range(0, 4000, 2)]
    lost = {700} | set(range(1200, 1500))  # acceleration blocks that never come
    feed(compensator, run, [('p', i, j) for i, j in bounds]
         + [('a', i, j) for k, (i, j) in enumerate(bounds) if k not in lost])
    counters = compensator.counters
    # Each is given up as soon as the next acceleration block passed its stamp.
    assert counters.unpaired_pressure == 2 * len(lost) and counters.unpaired_acceleration == 0
    compensator.flush()
    assert counters.output_samples == 4000 - 2 * len(lost)
    assert counters.gaps == [Gap(1400, 2), Gap(2398, 600)]
    assert_accounted(counters)
    unpaired = [line for line in lines if 'unpaired' in line]
    assert unpaired == [
        f'pressure/raw block at stamp {stamp(1400)} ns (2 samples) got no acceleration block '
        f'(the pair at stamp {stamp(1402)} ns came first): counted as unpaired',
        f'pressure/raw block at stamp {stamp(2400)} ns (2 samples) got no acceleration block '
        f'(the pair at stamp {stamp(3000)} ns came first): counted as unpaired',
        f'pressure/raw: 300 consecutive blocks (600 samples) from stamp {stamp(2400)} ns on '
        f'got no acceleration block: counted as unpaired']


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


#: The model the swap tests change to: another sensor (fn +15 %, ζ 0.08, gain -20 %).
OTHER = {'scale': 0.8, 'fn_scale': 1.15, 'zeta': 0.08}


@pytest.mark.parametrize('where', ['quiet', 'shot'])
def test_a_new_model_continues_as_if_it_had_run_all_along(run, where):
    peak = int(np.argmax(np.abs(run.axial)))
    # In the pre-trigger of the second shot, or at the first shot's peak.
    split = {'quiet': 2400, 'shot': peak}[where]
    assert (np.max(np.abs(run.axial[split - 50:split + 50])) < 0.01 * np.abs(run.axial[peak])
            ) == (where == 'quiet')
    rng = np.random.default_rng(7)
    bounds = cut(split, rng, largest=600) + [(i + split, j + split) for i, j in
                                             cut(run.n_samples - split, rng, largest=600)]
    half = next(n for n, (i, _) in enumerate(bounds) if i == split)
    compensator = BlockCompensator(make_filter(), fs=FS)
    first = feed(compensator, run, in_order(bounds[:half]))
    used = compensator.set_filter(make_filter(**OTHER))
    second = feed(compensator, run, in_order(bounds[half:]))
    compensator.flush()
    assert used == split  # the whole history: shorter than the filter's memory
    assert_close(joined(first)[1], whole(run, 0, split)[1])
    # After the swap: the new model's output as if it had run from the start; the step in
    # the compensated pressure is the change of the induced estimate, nothing more.
    assert_close(joined(second)[0], whole(run, **OTHER)[0][split:])
    assert_close(joined(second)[1], whole(run, **OTHER)[1][split:])
    # A new filter from rest would differ by far more (its start-up transient).
    cold = whole(run, split, **OTHER)[1]
    scale = np.max(np.abs(whole(run, **OTHER)[1]))
    assert np.max(np.abs(cold - joined(second)[1])) > {'quiet': 1e3, 'shot': 1e8}[where] * (
        REL * scale)
    counters = compensator.counters
    assert counters.model_changes == 1 and counters.gaps == []
    assert counters.output_samples == run.n_samples
    compensator.set_filter(make_filter())
    assert counters.model_changes == 2


def test_the_history_for_a_new_model_is_bounded_and_restarts_at_a_gap():
    # Four shots at 192 kS/s: longer than twice the filter's memory.
    sim = simulate(RigConfig(shots=TABLE2[6:10], fs=FS, pre_trigger_s=0.002,
                             post_shot_s=0.02, seed=5))
    rec = sim.recording
    keep = 2 * make_filter().memory()
    bounds = [(i, min(i + 500, rec.n_samples)) for i in range(0, rec.n_samples, 500)]
    split = bounds[-6][0]
    assert split > keep + 2000
    compensator = BlockCompensator(make_filter(), fs=FS)
    feed(compensator, rec, in_order(bounds[:-6]))
    assert compensator.set_filter(make_filter(**OTHER)) == keep
    second = feed(compensator, rec, in_order(bounds[-6:]))
    # The history left out has decayed far below round-off.
    assert_close(joined(second)[1], whole(rec, **OTHER)[1][split:])
    # After a stamp gap only the samples since the gap count: the filter restarted there.
    gap_compensator = BlockCompensator(make_filter(), fs=FS)
    restart = bounds[-9][0]  # the block before it is lost
    feed(gap_compensator, rec, in_order(bounds[:-10] + bounds[-9:-6]))
    assert gap_compensator.set_filter(make_filter(**OTHER)) == split - restart < keep
    after = feed(gap_compensator, rec, in_order(bounds[-6:]))
    assert_close(joined(after)[1], whole(rec, restart, **OTHER)[1][split - restart:])


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
    compensator = BlockCompensator(make_filter(), fs=FS)
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


def test_blocks_with_the_wrong_channels_or_no_sample_are_refused(run):
    compensator = BlockCompensator(make_filter(), fs=FS)
    with pytest.raises(CompensationError, match=rf'pressure/raw block at stamp {T0_NS} ns '
                                                r'must be one channel.*\(2, 10\)'):
        compensator.add_pressure(T0_NS, np.zeros((2, 10)))
    with pytest.raises(CompensationError, match=r'3 rows.*\(2, 10\)'):
        compensator.add_acceleration(T0_NS, np.zeros((2, 10)))
    with pytest.raises(BlockError, match=rf'acceleration block at stamp {T0_NS} ns holds no '
                                         r'sample \(width 0\)'):
        compensator.add_acceleration(T0_NS, np.zeros((3, 0)))
    with pytest.raises(BlockError, match='width 0'):
        compensator.add_pressure(T0_NS, np.zeros(0))
    assert compensator.counters.pressure_samples == 0
    # A (1, w) pressure block is one channel.
    assert compensator.add_pressure(stamp(0), run.pressure[None, :10]) == []
    assert len(compensator.add_acceleration(stamp(0), run.acceleration[:, :10])) == 1


def test_every_stream_fault_is_one_log_line_and_the_state_survives_it(run):
    lines = []
    compensator = BlockCompensator(make_filter(), fs=FS, log=lines.append)
    bounds = [(i, min(i + 300, run.n_samples)) for i in range(0, run.n_samples, 300)]
    bad_a = run.acceleration.copy()
    bad_a[2, 1210:1220] = np.nan  # ten lost acceleration samples in block 4
    bad_a[2, 1500] = np.inf  # and a corrupted one in block 5
    out = []

    def pair(i, j, *, acceleration=run.acceleration, at=None, p_width=None):
        at = i if at is None else at
        out.extend(compensator.add_pressure(stamp(at), run.pressure[i:p_width or j]))
        out.extend(compensator.add_acceleration(stamp(at), acceleration[:, i:j]))

    for k, (i, j) in enumerate(bounds):
        if k == 2:
            pair(*bounds[0])  # block 0 again: out of order
            pair(i - 150, j - 150)  # half of block 1 again: overlapping
        if k in (4, 5):
            pair(i, j, acceleration=bad_a)
        elif k == 8:
            pair(i, j, p_width=j - 1)  # a pair of two widths
        elif k == 12:
            continue  # lost: a stamp gap
        elif k == 14:
            out.extend(compensator.add_pressure(stamp(i) + 7, run.pressure[i:j]))  # no partner
            pair(i, j)
        else:
            pair(i, j)
    compensator.flush()
    counters = compensator.counters
    assert_accounted(counters)
    assert counters.overlapping == 600 and counters.mismatched == 1
    assert counters.unpaired_pressure == 299 + 300 and counters.unpaired_acceleration == 300
    assert counters.invalid_samples == 11
    # Block 8 (dropped) and block 12 (lost) are missing from the output.
    assert counters.gaps == [Gap(2400, 300), Gap(3300, 300)]
    expected = {
        f'pressure/raw + acceleration pair at stamp {stamp(0)} ns (300 samples) dropped: it '
        f'starts 600 samples before the end of the previous pair (stamp {stamp(300)} ns); out '
        f'of order',
        f'pair at stamp {stamp(450)} ns (300 samples) dropped: it starts 150 samples before',
        f'pressure/raw + acceleration: non-finite samples from the block at stamp {stamp(1200)} '
        f'ns on (10 of its 300): their compensated samples are NaN',
        f'pressure/raw + acceleration: finite samples again from the block at stamp '
        f'{stamp(1800)} ns: 11 non-finite samples since stamp {stamp(1200)} ns',
        f'pair at stamp {stamp(2400)} ns dropped: the pressure block has 299 samples but the '
        f'acceleration block 300',
        f'pressure/raw + acceleration: stamp gap, 300 samples missing before the pair at stamp '
        f'{stamp(2700)} ns (the previous pair ended at {stamp(2400)} ns); the compensation '
        f'filter restarts from rest',
        f'stamp gap, 300 samples missing before the pair at stamp {stamp(3900)} ns (the '
        f'previous pair ended at {stamp(3600)} ns); the compensation filter restarts from rest',
        f'pressure/raw block at stamp {stamp(4200) + 7} ns (300 samples) got no acceleration '
        f'block (the pair at stamp {stamp(4500)} ns came first): counted as unpaired',
    }
    assert len(lines) == len(expected)
    for text in expected:
        assert sum(text in line for line in lines) == 1, (text, lines)
    # The output: the whole-signal compensation of each stretch between gaps, from rest
    # (the dropped pairs changed no state; the non-finite samples restart the filter as
    # offline).
    compensated = joined(out)[0]
    expected_out = np.concatenate([make_filter().process(bad_a[:, i:j], run.pressure[i:j])[0]
                                   for i, j in ((0, 2400), (2700, 3600), (3900, None))])
    assert np.flatnonzero(np.isnan(compensated)).tolist() == [*range(1210, 1220), 1500]
    assert np.array_equal(np.isnan(compensated), np.isnan(expected_out))
    finite = ~np.isnan(expected_out)
    assert_close(compensated[finite], expected_out[finite])


def _file_rss_kb() -> int:
    """Return this process's resident file-backed memory in kB (Linux)."""
    for line in open('/proc/self/status'):
        if line.startswith('RssFile:'):
            return int(line.split()[1])
    pytest.skip('no RssFile in /proc/self/status')


@pytest.mark.parametrize('compression', ['zstd', 'none'])
def test_a_pass_over_a_bag_leaves_its_pages_unmapped(tmp_path, monkeypatch, compression):
    # Compensating a bag reads it once, block by block: what it has read must not stay
    # resident (the reader maps the file; a 1 GB bag would end with 1 GB resident).
    import mmap
    from sensor_comp.io import bag_reader
    from sensor_comp.io.bag_writer import write_recording
    from sensor_comp.streams import Recording
    rng = np.random.default_rng(0)
    n = 600_000  # ~19 MB of float64 samples: noise does not compress
    recording = Recording(fs=1e6, t0_ns=0, pressure=rng.standard_normal(n),
                          acceleration=rng.standard_normal((3, n)))
    path = tmp_path / 'noise.mcap'
    write_recording(path, recording, compression=compression, block_width=10_000)
    size_kb = path.stat().st_size // 1024
    first = []
    for release in (1 << 40, mmap.PAGESIZE):  # never, then after every page
        monkeypatch.setattr(bag_reader, 'RELEASE_BYTES', release)
        with bag_reader.BagReader(path) as bag:
            before = _file_rss_kb()
            datas = [m.data for m in bag.messages()]
            grown = _file_rss_kb() - before
        if not first:
            first = datas
            assert grown > size_kb // 2
        else:
            assert datas == first
            assert grown < size_kb // 10
