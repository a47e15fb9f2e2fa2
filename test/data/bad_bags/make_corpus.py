"""
Regenerate the malformed-bag corpus in this folder, byte for byte.

Run from the repository root (``AMENT_PREFIX_PATH`` set, for the message definitions)::

    python test/data/bad_bags/make_corpus.py

Every entry of :data:`CASES` is one malformed bag (a file, or a rosbag2 directory), the
``sensor-comp`` commands that must refuse it, and fragments their one-line error must
contain (``{path}`` stands for the path given on the command line). The files are written
with the ``mcap`` library directly and a fixed library string, so they do not change with
the ``sensor_comp`` version; ``README.md`` is generated from the same table.
``test/cli/test_bad_bags.py`` runs every case through the CLI and checks that regenerating
gives the committed bytes.
"""

from __future__ import annotations

from pathlib import Path
import shutil
import sys
from typing import NamedTuple

from mcap.writer import CompressionType, Writer
import numpy as np

ROOT = Path(__file__).resolve().parents[3]
if str(ROOT) not in sys.path:  # run as a script from anywhere
    sys.path.insert(0, str(ROOT))

from sensor_comp.io.cdr import CdrWriter  # noqa: E402
from sensor_comp.io.messages import (DIAGNOSTIC_ARRAY, encode_block,  # noqa: E402
                                     encode_stream_info, encode_string, IMAGE, STRING)
from sensor_comp.io.msgdefs import message_definition, type_hash  # noqa: E402
from sensor_comp.io.rosbag2_layout import offered_qos_profiles  # noqa: E402
from sensor_comp.streams import StreamInfo  # noqa: E402

HERE = Path(__file__).resolve().parent
LIBRARY = 'sensor_comp bad_bags corpus'
T0 = 1_700_000_000_000_000_000
FS = 10_000.0
N = 400
WIDTH = 40
PERIOD_NS = round(WIDTH * 1e9 / FS)  # 4 ms per block
ACC, RAW, INFO = '/rig/acceleration', '/rig/pressure/raw', '/rig/stream_info'
FLOAT_ARRAY = 'std_msgs/msg/Float64MultiArray'
#: Where truncated.mcap ends: inside its third chunk (checked when it is written).
TRUNCATE_AT = 4700

#: Commands that read a recording; ``info`` describes a bag and also reads its streams.
ANALYSIS = ('identify', 'compensate', 'diagnose', 'compare', 'report')
ALL = ('info',) + ANALYSIS


class Case(NamedTuple):
    """One corpus entry: name, what is wrong, commands that refuse it, error fragments."""

    name: str
    problem: str
    commands: tuple[str, ...]
    fragments: tuple[str, ...]


CASES = (
    Case('empty.mcap', 'a 0-byte file', ALL, ('{path}', 'empty (0 bytes)')),
    Case('not_mcap.mcap', 'a CSV export renamed .mcap', ALL,
         ('{path}', 'not an MCAP file', "b'time,pressure")),
    Case('header_only.mcap', 'the first 20 bytes of a bag: the writer died at once', ALL,
         ('{path}', 'before its header record is complete', 'nothing was recorded')),
    Case('foreign_profile.mcap', 'an MCAP file that is not a ROS 2 bag (JSON messages)', ALL,
         ('{path}', "MCAP profile is ''", 'not a ROS 2 bag')),
    Case('truncated.mcap', 'cut in the middle of a chunk (recorder killed)', ANALYSIS,
         ('{path}', f'cut short at byte {TRUNCATE_AT}', 'sensor-comp repair {path}')),
    Case('damaged_chunk.mcap', 'one flipped byte inside the second chunk', ALL,
         ('{path}', 'chunk at byte', 'CRC', 'sensor-comp repair {path}')),
    Case('no_blocks.mcap', 'stream_info only: the acquisition never published', ANALYSIS,
         ('{path}', 'no blocks on /rig/acceleration, /rig/pressure/raw',
          'streams with blocks: none')),
    Case('missing_pressure.mcap', 'acceleration blocks only', ANALYSIS,
         ('{path}', 'no blocks on /rig/pressure/raw', 'streams with blocks: acceleration')),
    Case('wrong_type.mcap', f'{RAW} carries {FLOAT_ARRAY}', ALL,
         ('{path}', RAW, FLOAT_ARRAY, IMAGE)),
    Case('wrong_info_type.mcap', f'{INFO} carries {STRING}', ALL,
         ('{path}', INFO, STRING, DIAGNOSTIC_ARRAY)),
    Case('wrong_encoding.mcap', 'pressure blocks with Image encoding mono8', ALL,
         ('{path}', RAW, f'stamp {T0} ns', "'mono8'", '64FC1')),
    Case('big_endian.mcap', 'pressure blocks flagged is_bigendian = 1', ALL,
         ('{path}', RAW, f'stamp {T0} ns', 'is_bigendian is 1', 'little-endian')),
    Case('bad_step.mcap', 'pressure blocks whose step is not 8*width', ALL,
         ('{path}', RAW, 'step is 48 bytes', '8*width = 320')),
    Case('wrong_shape.mcap', 'acceleration blocks with 2 rows for channels x, y, z', ALL,
         ('{path}', ACC, f'stamp {T0} ns', 'shape (2, 40)', 'x, y, z')),
    Case('overlap.mcap', 'a pressure block starts 10 samples before the previous one ends',
         ALL, ('{path}', RAW, f'stamp {T0 + 4 * PERIOD_NS - 1_000_000} ns', 'overlaps')),
    Case('out_of_order.mcap', 'pressure blocks 4 and 5 swapped', ALL,
         ('{path}', RAW, f'stamp {T0 + 4 * PERIOD_NS} ns', 'out of order')),
    Case('unpaired_offset.mcap', 'pressure stamps half a sample after the acceleration ones',
         ANALYSIS, ('{path}', 'acceleration', 'pressure/raw', '0.500 samples')),
    Case('unpaired_widths.mcap', 'pressure blocks of 40 samples, acceleration blocks of 50',
         ('compensate',), ('{path}', RAW, ACC, f'stamp {T0} ns', '40 samples', '50 samples')),
    Case('no_overlap.mcap', 'acceleration in the first 20 ms, pressure in the next 20 ms',
         ANALYSIS, ('{path}', 'acceleration', 'pressure/raw', 'do not overlap in time')),
    Case('mismatched_rates.mcap', 'acceleration announced at 10 kHz, pressure at 20 kHz',
         ANALYSIS, ('{path}', 'acceleration', '10000 Hz', 'pressure/raw', '20000 Hz')),
    Case('no_stream_info.mcap', 'blocks without any stream_info topic', ALL,
         ('{path}', 'stream_info', 'never decoded by guessing its rate')),
    Case('empty_stream_info.mcap', 'a stream_info topic that holds no message', ALL,
         ('{path}', INFO, 'holds no message')),
    Case('incomplete_stream_info.mcap', 'stream_info describes the acceleration only', ALL,
         ('{path}', RAW, 'does not describe')),
    Case('bad_stream_info.mcap', 'a stream_info status without sample_rate_hz', ALL,
         ('{path}', INFO, 'sample_rate_hz')),
    Case('not_a_bag_dir', 'a directory without any bag file', ALL,
         ('{path}', 'no .mcap file')),
    Case('rosbag2_sqlite', 'a rosbag2 directory recorded with the SQLite storage', ALL,
         ('{path}', 'sqlite3', 'ros2 bag convert')),
    Case('split_bag', 'a rosbag2 directory split into two .mcap files', ALL,
         ('{path}', 'split_bag_0.mcap, split_bag_1.mcap', 'pass one')),
    Case('metadata_missing_file', 'metadata.yaml names a .mcap file that is not there', ALL,
         ('{path}', 'metadata_missing_file_0.mcap', 'missing')),
)


def _signals(n: int = N, fs: float = FS) -> tuple[np.ndarray, np.ndarray]:
    """Return a smooth shot: acceleration (3, n) in m/s² and pressure (1, n) in Pa."""
    t = np.arange(n) / fs
    pulse = np.where(t < 0.01, np.sin(np.pi * t / 0.01), 0.0)
    accel = np.stack([50.0 * pulse, -30.0 * pulse, 2000.0 * pulse])
    pressure = (1e5 + 3e4 * pulse)[np.newaxis]
    return accel, pressure


def _infos(*, accel_fs: float = FS, pressure_fs: float = FS, accel: bool = True,
           pressure: bool = True) -> list[StreamInfo]:
    meta = {'charge_sensitivity_pC_per_MPa': '100.0'}
    infos = []
    if accel:
        infos.append(StreamInfo('acceleration', accel_fs, ('x', 'y', 'z'), 'm/s^2', 'piezo',
                                meta))
    if pressure:
        infos.append(StreamInfo('pressure/raw', pressure_fs, ('p',), 'Pa', 'piezo', meta))
    return infos


def _blocks(topic: str, data: np.ndarray, *, width: int = WIDTH, fs: float = FS,
            t0: int = T0) -> list[tuple[str, int, bytes]]:
    out = []
    for start in range(0, data.shape[1], width):
        stamp = t0 + round(start * 1e9 / fs)
        out.append((topic, stamp, encode_block(data[:, start:start + width], stamp_ns=stamp,
                                               frame_id='piezo')))
    return out


def _interleave(*streams) -> list[tuple[str, int, bytes]]:
    """Merge per-topic message lists by time, stable (as a recorder writes them)."""
    merged = [m for stream in streams for m in stream]
    return sorted(merged, key=lambda m: m[1])


def _rig(*, infos=None, accel=None, pressure=None) -> list[tuple[str, int, bytes]]:
    """Return the messages of a good recording, with parts replaced."""
    a, p = _signals()
    info = [(INFO, T0, encode_stream_info(_infos() if infos is None else infos,
                                          stamp_ns=T0))]
    return info + _interleave(_blocks(ACC, a) if accel is None else accel,
                              _blocks(RAW, p) if pressure is None else pressure)


RIG_TOPICS = {INFO: (DIAGNOSTIC_ARRAY, True), ACC: (IMAGE, False), RAW: (IMAGE, False)}


def write_bag(path: Path, messages, *, topics=None, compression: str = 'zstd',
              chunk_size: int = 4096, profile: str = 'ros2', message_encoding: str = 'cdr',
              schema_encoding: str = 'ros2msg') -> None:
    """Write ``(topic, time, data)`` messages in the rosbag2 layout with the mcap library."""
    topics = RIG_TOPICS if topics is None else topics
    compressions = {'none': CompressionType.NONE, 'zstd': CompressionType.ZSTD}
    with open(path, 'wb') as f:
        writer = Writer(f, chunk_size=chunk_size, compression=compressions[compression])
        writer.start(profile=profile, library=LIBRARY)
        schemas, channels = {}, {}
        for topic, (msgtype, latched) in topics.items():
            if msgtype not in schemas:
                text = (message_definition(msgtype) if schema_encoding == 'ros2msg'
                        else '{"type": "object"}')
                schemas[msgtype] = writer.register_schema(msgtype, schema_encoding,
                                                          text.encode())
            metadata = {'offered_qos_profiles': offered_qos_profiles(latched=latched)}
            digest = type_hash(msgtype)
            if digest:
                metadata['topic_type_hash'] = digest
            channels[topic] = writer.register_channel(topic, message_encoding,
                                                      schemas[msgtype], metadata)
        sequence = dict.fromkeys(channels, 0)
        for topic, stamp, data in messages:
            writer.add_message(channels[topic], log_time=stamp, data=data, publish_time=stamp,
                               sequence=sequence[topic])
            sequence[topic] += 1
        writer.finish()


def _image(*, encoding: str = '64FC1', is_bigendian: int = 0, step_extra: int = 0,
           height: int = 1, width: int = WIDTH, stamp: int = T0) -> bytes:
    """Return a hand-made Image; the data hold ``height * step`` bytes."""
    step = (8 if encoding == '64FC1' else 1) * width + step_extra
    w = CdrWriter()
    w.int32(stamp // 1_000_000_000)
    w.uint32(stamp % 1_000_000_000)
    w.string('piezo')
    w.uint32(height)
    w.uint32(width)
    w.string(encoding)
    w.uint8(is_bigendian)
    w.uint32(step)
    data = bytes(height * step)
    w.primitive_sequence(data, itemsize=1, count=len(data))
    return w.getvalue()


def _float_array(values: np.ndarray) -> bytes:
    w = CdrWriter()
    w.sequence_length(0)  # layout.dim
    w.uint32(0)  # layout.data_offset
    raw = np.ascontiguousarray(values, '<f8').tobytes()
    w.primitive_sequence(raw, itemsize=8, count=len(raw) // 8)
    return w.getvalue()


def _with_pressure(build) -> list[tuple[str, int, bytes]]:
    """Return the rig's messages with each pressure block replaced by ``build(stamp)``."""
    return _rig(pressure=[(t, s, build(s)) for t, s, _ in _blocks(RAW, _signals()[1])])


def _metadata_yaml(storage: str, files: list[str]) -> str:
    listed = ''.join(f'\n    - {name}' for name in files)
    return ('rosbag2_bagfile_information:\n  version: 9\n'
            f'  storage_identifier: {storage}\n  relative_file_paths:{listed}\n'
            '  duration:\n    nanoseconds: 0\n  message_count: 0\n')


def build(folder: Path = HERE) -> None:
    """Write every corpus file into ``folder`` (existing entries are replaced)."""
    a, p = _signals()
    for case in CASES:
        target = folder / case.name
        if target.is_dir():
            shutil.rmtree(target)
    (folder / 'empty.mcap').write_bytes(b'')
    (folder / 'not_mcap.mcap').write_text('time,pressure,acceleration\n0.0,1.0e5,0.0\n')

    good = folder / 'good.tmp'
    write_bag(good, _rig())
    (folder / 'header_only.mcap').write_bytes(good.read_bytes()[:20])
    good.unlink()
    write_bag(folder / 'truncated.mcap', _rig(), compression='zstd', chunk_size=2048)
    raw = (folder / 'truncated.mcap').read_bytes()
    chunks = _chunk_offsets(raw)
    assert chunks[2] < TRUNCATE_AT - 100 and TRUNCATE_AT + 100 < chunks[3], chunks
    (folder / 'truncated.mcap').write_bytes(raw[:TRUNCATE_AT])

    write_bag(folder / 'foreign_profile.mcap', [('/log', T0, b'{"text": "hello"}')],
              topics={'/log': ('log_line', False)}, profile='', message_encoding='json',
              schema_encoding='jsonschema')

    damaged = folder / 'damaged_chunk.mcap'
    write_bag(damaged, _rig(), compression='none')
    data = bytearray(damaged.read_bytes())
    second = _chunk_offsets(bytes(data))[1]
    data[second + 200] ^= 0xFF  # inside the chunk's records, covered by its CRC
    damaged.write_bytes(bytes(data))

    write_bag(folder / 'no_blocks.mcap', _rig(accel=[], pressure=[]))
    write_bag(folder / 'missing_pressure.mcap', _rig(pressure=[]),
              topics={INFO: (DIAGNOSTIC_ARRAY, True), ACC: (IMAGE, False)})
    write_bag(folder / 'wrong_type.mcap',
              _rig(pressure=[(RAW, s, _float_array(p[0, (s - T0) // 100_000:][:WIDTH]))
                             for _, s, _ in _blocks(RAW, p)]),
              topics={**RIG_TOPICS, RAW: (FLOAT_ARRAY, False)})
    write_bag(folder / 'wrong_info_type.mcap',
              [(INFO, T0, encode_string('acceleration at 10 kHz'))] + _rig()[1:],
              topics={**RIG_TOPICS, INFO: (STRING, True)})
    write_bag(folder / 'wrong_encoding.mcap',
              _with_pressure(lambda s: _image(encoding='mono8', stamp=s)))
    write_bag(folder / 'big_endian.mcap', _with_pressure(lambda s: _image(is_bigendian=1,
                                                                          stamp=s)))
    write_bag(folder / 'bad_step.mcap', _with_pressure(lambda s: _image(width=40, stamp=s,
                                                                        step_extra=-272)))
    write_bag(folder / 'wrong_shape.mcap', _rig(accel=_blocks(ACC, a[:2])))

    blocks = _blocks(RAW, p)
    topic, stamp, _ = blocks[4]
    early = stamp - 1_000_000  # 10 samples at 10 kHz
    blocks[4] = (topic, early, encode_block(p[:, 160:200], stamp_ns=early, frame_id='piezo'))
    write_bag(folder / 'overlap.mcap', _rig(pressure=blocks))
    blocks = _blocks(RAW, p)
    blocks[4], blocks[5] = blocks[5], blocks[4]
    write_bag(folder / 'out_of_order.mcap',
              [_rig()[0]] + [m for m in _rig()[1:] if m[0] == ACC] + blocks)

    write_bag(folder / 'unpaired_offset.mcap', _rig(pressure=_blocks(RAW, p, t0=T0 + 50_000)))
    write_bag(folder / 'unpaired_widths.mcap', _rig(accel=_blocks(ACC, a, width=50)))
    write_bag(folder / 'no_overlap.mcap',
              _rig(accel=_blocks(ACC, a[:, :200]), pressure=_blocks(RAW, p[:, 200:],
                                                                    t0=T0 + 20_000_000)))
    _, p2 = _signals(2 * N, 2 * FS)
    write_bag(folder / 'mismatched_rates.mcap',
              _rig(infos=_infos(pressure_fs=2 * FS),
                   pressure=_blocks(RAW, p2, width=2 * WIDTH, fs=2 * FS)))
    write_bag(folder / 'no_stream_info.mcap', _rig()[1:],
              topics={ACC: (IMAGE, False), RAW: (IMAGE, False)})
    write_bag(folder / 'empty_stream_info.mcap', _rig()[1:])
    write_bag(folder / 'incomplete_stream_info.mcap', _rig(infos=_infos(pressure=False)))
    bad_info = bytearray(encode_stream_info(_infos(), stamp_ns=T0))
    key = bad_info.index(b'sample_rate_hz')
    bad_info[key:key + 14] = b'sample_rate_Hz'  # a misspelt key, same length
    write_bag(folder / 'bad_stream_info.mcap', [(INFO, T0, bytes(bad_info))] + _rig()[1:])

    (folder / 'not_a_bag_dir').mkdir()
    (folder / 'not_a_bag_dir' / 'notes.txt').write_text('shot 3 of the morning run\n')
    sqlite = folder / 'rosbag2_sqlite'
    sqlite.mkdir()
    (sqlite / 'metadata.yaml').write_text(_metadata_yaml('sqlite3', ['rosbag2_sqlite_0.db3']))
    (sqlite / 'rosbag2_sqlite_0.db3').write_bytes(b'SQLite format 3\x00' + bytes(496))
    split = folder / 'split_bag'
    split.mkdir()
    (split / 'metadata.yaml').write_text(_metadata_yaml('mcap', ['split_bag_0.mcap',
                                                                 'split_bag_1.mcap']))
    messages = _rig()
    write_bag(split / 'split_bag_0.mcap', messages[:11])
    write_bag(split / 'split_bag_1.mcap', messages[11:])
    missing = folder / 'metadata_missing_file'
    missing.mkdir()
    (missing / 'metadata.yaml').write_text(_metadata_yaml('mcap', [
        'metadata_missing_file_0.mcap']))
    write_bag(missing / 'renamed.mcap', _rig())
    (folder / 'README.md').write_text(readme())


def _chunk_offsets(data: bytes) -> list[int]:
    """Return the file offsets of the chunk records (opcode 0x06) of the data section."""
    offsets, pos = [], 8
    while pos + 9 <= len(data):
        opcode = data[pos]
        length = int.from_bytes(data[pos + 1:pos + 9], 'little')
        if opcode == 0x06:
            offsets.append(pos)
        if opcode == 0x0F:  # data end
            break
        pos += 9 + length
    return offsets


def readme() -> str:
    """Return the corpus README: every entry, the commands that refuse it, the error."""
    rows = '\n'.join(
        f'| `{c.name}` | {c.problem} | {", ".join(c.commands)} | '
        + '; '.join(f'`{f}`' for f in c.fragments).replace('|', '\\|') + ' |'
        for c in CASES)
    return f"""# Malformed bags

Small bags that `sensor-comp` must refuse with one line `sensor-comp: error: ...` naming the
file, the topic, the stamp or sample and what to do, exit code 1 and no traceback.
`test/cli/test_bad_bags.py` runs each entry through the listed commands and checks that the
error contains every fragment (`{{path}}` is the path given on the command line).

Regenerate them with `python test/data/bad_bags/make_corpus.py` (from the repository root,
with `AMENT_PREFIX_PATH` set); the test checks that this gives the committed bytes, so
regenerate after upgrading `zstandard` or the ROS message packages (schema texts). Each bag
holds a 40 ms recording at 10 kS/s in blocks of 40 samples (acceleration `(3, w)` m/s²,
raw pressure `(1, w)` Pa, latched `stream_info`) unless the entry says otherwise.

Not in the corpus because they are not errors, or cannot be committed: stamp gaps (NaN plus
a `Gap`, listed by `info`), a bag cut in its summary only (all messages are read), a missing
file and an unreadable file (tested with temporary files).

| entry | problem | refused by | the error contains |
|---|---|---|---|
{rows}
"""


if __name__ == '__main__':
    build()
