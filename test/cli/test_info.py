"""``sensor-comp info``: topics, message counts and streams of a bag, as written."""

import json
import math
import re

import numpy as np
import pytest

from sensor_comp.cli.main import main
from sensor_comp.io.bag_writer import write_recording, write_streams
from sensor_comp.streams import Gap, Recording, Stream

FS = 200e3
#: A realistic absolute start time with a non-zero nanosecond part.
T0_NS = 1_700_000_000_123_456_789
N = 12_345
WIDTH = 700


@pytest.fixture
def recording():
    """Return a noisy recording of ``N`` samples (not a whole number of blocks)."""
    rng = np.random.default_rng(3)
    return Recording(fs=FS, t0_ns=T0_NS, pressure=rng.normal(0.0, 1e5, N),
                     acceleration=rng.normal(0.0, 50.0, (3, N)), frame_id='piezo',
                     metadata={'charge_sensitivity_pC_per_MPa': '100'})


def info_json(capsys, path):
    """Run ``info --json`` and return the parsed output."""
    assert main(['info', str(path), '--json']) == 0
    return json.loads(capsys.readouterr().out)


def test_json_lists_what_was_written(recording, tmp_path, capsys):
    path = tmp_path / 'run.mcap'
    write_recording(path, recording, block_width=WIDTH)
    summary = info_json(capsys, path)
    assert summary['bag'] == str(path) and summary['truncated'] is False
    blocks = math.ceil(N / WIDTH)
    assert summary['topics'] == {
        '/rig/acceleration': {'type': 'sensor_msgs/msg/Image', 'latched': False,
                              'messages': blocks},
        '/rig/pressure/raw': {'type': 'sensor_msgs/msg/Image', 'latched': False,
                              'messages': blocks},
        '/rig/stream_info': {'type': 'diagnostic_msgs/msg/DiagnosticArray', 'latched': True,
                             'messages': 1}}
    streams = summary['streams']
    assert set(streams) == {'acceleration', 'pressure/raw'}
    for name, channels, unit in (('acceleration', ['x', 'y', 'z'], 'm/s^2'),
                                 ('pressure/raw', ['p'], 'Pa')):
        stream = streams[name]
        assert stream['fs_hz'] == FS and stream['samples'] == N
        assert stream['t0_ns'] == T0_NS
        assert stream['duration_s'] == pytest.approx(N / FS, rel=1e-12)
        assert (stream['channels'], stream['unit']) == (channels, unit)
        assert stream['frame_id'] == 'piezo' and stream['gaps'] == []
        assert stream['metadata'] == {'charge_sensitivity_pC_per_MPa': '100'}


def test_gaps_are_listed(recording, tmp_path, capsys):
    gap = Gap(5_000, 1_234)
    streams = []
    for stream in recording.streams():
        data = stream.data.copy()
        data[:, gap.start:gap.start + gap.count] = np.nan
        streams.append(Stream(stream.info, stream.t0_ns, data, (gap,)))
    path = tmp_path / 'gap.mcap'
    write_streams(path, streams, block_width=1000)
    summary = info_json(capsys, path)
    # Blocks never span the gap: 5 before it, then 7 for the 6111 samples after it.
    assert summary['topics']['/rig/pressure/raw']['messages'] == 5 + 7
    for stream in summary['streams'].values():
        assert stream['samples'] == N
        assert stream['gaps'] == [{'start': gap.start, 'count': gap.count}]
    assert main(['info', str(path)]) == 0
    out = capsys.readouterr().out
    assert re.search(r'\b1 gaps?\b', out), out


def test_text_lists_topics_and_streams(recording, tmp_path, capsys):
    path = tmp_path / 'run.mcap'
    write_recording(path, recording, block_width=WIDTH)
    assert main(['info', str(path)]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    topic = next(line for line in lines if '/rig/stream_info' in line)
    assert 'latched' in topic and ' 1 msgs' in topic
    stream = next(line for line in lines if line.split()[:1] == ['pressure/raw'])
    assert '200 kS/s' in stream and f'{N} samples' in stream


def test_missing_bag_exits_1_naming_it(tmp_path, capsys):
    missing = tmp_path / 'missing.mcap'
    assert main(['info', str(missing)]) == 1
    err = capsys.readouterr().err
    assert err.startswith('sensor-comp: error:') and str(missing) in err
