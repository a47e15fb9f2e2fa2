"""
``sensor-comp repair``: the report it prints, its refusals, and a recorder killed for real.

The last test runs the ``recorder`` and ``player`` nodes as processes on a ROS domain of its
own (reserved with the same lock files as the node tests), kills the recorder with SIGKILL
while the player publishes, repairs the file and checks that every message the recorder had
flushed is in the repaired bag, unchanged and in order.
"""

import fcntl
import json
import os
from pathlib import Path
import random
import signal
import subprocess
import sys
import tempfile
import time

import numpy as np
import pytest

from sensor_comp.cli.main import main
from sensor_comp.io.bag_reader import BagReader, read_streams
from sensor_comp.io.bag_writer import write_recording
from sensor_comp.io.messages import decode_stream_info
from sensor_comp.streams import Recording

ROOT = Path(__file__).resolve().parents[2]
CORPUS = ROOT / 'test' / 'data' / 'bad_bags'


def test_repair_prints_what_was_recovered_and_lost(tmp_path, capsys):
    bag = tmp_path / 'truncated.mcap'
    bag.write_bytes((CORPUS / 'truncated.mcap').read_bytes())
    assert main(['repair', str(bag)]) == 0
    out = capsys.readouterr().out
    fixed = tmp_path / 'truncated.repaired.mcap'  # the default output
    with BagReader(fixed) as reader:
        counts = {t: i.message_count for t, i in reader.topics.items()}
        assert reader.has_summary and not reader.truncated
    for topic, count in counts.items():
        assert any(line.split()[:2] == [topic, str(count)] for line in out.splitlines()), out
    assert f'recovered {sum(counts.values())} messages on 3 topics' in out
    assert 'cut short at byte' in out and 'lost: the file stops' in out
    assert out.rstrip().endswith(f'wrote {fixed}')

    assert main(['repair', str(bag)]) == 1  # the output exists now
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and f'{fixed} exists; pass --force' in err
    assert main(['repair', str(bag), '--force', '--json']) == 0
    report = json.loads(capsys.readouterr().out)
    assert report['recovered'] == counts and report['state'] == 'cut'
    assert report['lost_anything'] is True and report['lost_bytes'] > 0


def test_repair_refuses_to_replace_its_input(tmp_path, capsys):
    bag = tmp_path / 'run.mcap'
    bag.write_bytes((CORPUS / 'truncated.mcap').read_bytes())
    assert main(['repair', str(bag), '-o', str(bag), '--force']) == 1
    err = capsys.readouterr().err
    assert err.startswith('sensor-comp: error:') and 'never replaced' in err
    assert bag.read_bytes() == (CORPUS / 'truncated.mcap').read_bytes()
    assert main(['repair', str(CORPUS / 'not_mcap.mcap'), '-o', str(tmp_path / 'x.mcap')]) == 1
    assert 'not an MCAP file' in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ['run.mcap']


def _reserve_domain():
    """Return ``(domain, lock)``: a ROS domain id no other test process on this host uses."""
    candidates = list(range(1, 102))
    random.Random(os.getpid() ^ time.monotonic_ns()).shuffle(candidates)
    for domain in candidates:
        lock = open(Path(tempfile.gettempdir()) / f'sensor_comp_ros_domain_{domain}.lock', 'w')
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            lock.close()
            continue
        return domain, lock
    pytest.fail('every ROS domain id is in use by other test processes')


@pytest.fixture
def start_node(tmp_path):
    """Return a starter of node processes on a reserved domain; leftovers are killed."""
    pytest.importorskip('rclpy')
    domain, lock = _reserve_domain()
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               AMENT_PREFIX_PATH=os.environ.get('AMENT_PREFIX_PATH', sys.prefix),
               PYTHONPATH=str(ROOT), PYTHONUNBUFFERED='1')
    started = []

    def start(name: str, **params):
        args = [sys.executable, '-m', f'sensor_comp.nodes.{name}', '--ros-args']
        for key, value in params.items():
            args += ['-p', f'{key}:={value}']
        log = tmp_path / f'{name}.log'
        with open(log, 'w') as out:
            proc = subprocess.Popen(args, cwd=ROOT, env=env, stdout=out,
                                    stderr=subprocess.STDOUT)
        started.append(proc)
        return proc, log

    yield start
    for proc in started:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    lock.close()


def _wait(condition, what: str, timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f'timed out waiting for {what}'
        time.sleep(0.02)


def _by_topic(path) -> dict[str, list[bytes]]:
    found = {}
    with BagReader(path) as bag:
        for msg in bag.messages():
            found.setdefault(msg.topic, []).append(msg.data)
    return found


@pytest.mark.ros
def test_a_recorder_killed_mid_stream_is_repaired_with_every_flushed_message(
        start_node, tmp_path, capsys):
    fs, n, width = 20_000.0, 40_000, 100  # 2 s of rig time, 400 blocks per stream
    rng = np.random.default_rng(11)
    source = tmp_path / 'source.mcap'
    write_recording(source, Recording(fs=fs, t0_ns=1_700_000_000_000_000_000,
                                      pressure=rng.normal(0.0, 1e5, n),
                                      acceleration=rng.normal(0.0, 50.0, (3, n)),
                                      frame_id='piezo'), block_width=width)
    published = _by_topic(source)
    blocks = len(published['/rig/pressure/raw'])

    out = tmp_path / 'killed.mcap'
    recorder, recorder_log = start_node('recorder', output=out, flush_period=0.1,
                                        chunk_size=1 << 16, discovery_period=0.1)
    _wait(lambda: 'recording every topic under /rig' in recorder_log.read_text(),
          'the recorder to start')
    start_node('player', bag=source, wait_for_subscribers=1)

    def flushed() -> int:
        try:
            with BagReader(out) as bag:
                return sum(1 for m in bag.messages() if m.topic == '/rig/pressure/raw')
        except Exception:  # the header may not be on disk yet
            return 0

    _wait(lambda: flushed() >= blocks // 3, 'a third of the blocks to reach the file')
    before = flushed()
    recorder.send_signal(signal.SIGKILL)
    assert recorder.wait(20) == -signal.SIGKILL
    assert before < blocks, 'the recorder was killed after the stream ended'

    fixed = tmp_path / 'fixed.mcap'
    assert main(['repair', str(out), '-o', str(fixed), '--json']) == 0
    report = json.loads(capsys.readouterr().out)
    assert report['state'] == 'cut' and report['recovered_total'] >= before
    recovered = _by_topic(fixed)
    assert set(recovered) == set(published)
    for topic, data in recovered.items():
        if topic.endswith('stream_info'):  # DDS may re-serialise it: compare what it says
            assert [decode_stream_info(d) for d in data] == \
                [decode_stream_info(d) for d in published[topic]]
        else:
            assert data == published[topic][:len(data)], topic  # unchanged, in order, whole
    assert len(recovered['/rig/pressure/raw']) >= before
    with BagReader(fixed) as bag:
        assert bag.has_summary and not bag.truncated and bag.topics['/rig/stream_info'].latched
    streams = read_streams(fixed)
    original = read_streams(source)
    for name, stream in streams.items():
        assert stream.gaps == () and stream.t0_ns == original[name].t0_ns
        np.testing.assert_array_equal(stream.data,
                                      original[name].data[:, :stream.n_samples])
