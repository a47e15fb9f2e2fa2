"""
Compensate a whole bag: a copy with ``pressure/compensated`` and ``pressure/induced`` added.

Package-level because it joins the core's streaming filter to the io's bags, and the core
never imports io (the ``compensate`` command and the demo call it).
"""

from __future__ import annotations

from collections import deque

import numpy as np

from .blocks import BlockSequence
from .core.compensation.filter import CompensationFilter
from .core.compensation.initial_state import rest_start_note
from .core.compensation.streaming import BlockCompensator, fit_recording_disturbances
from .errors import SensorCompError
from .files import check_output
from .io.bag_reader import (BagReader, block_topics, find_namespace, read_stream_infos,
                            require_described)
from .io.bag_writer import BagWriter
from .io.messages import decode_block, encode_block, encode_stream_info, IMAGE, MessageError
from .io.rosbag2_layout import topic_name
from .streams import (ACCELERATION, COMPENSATED, INDUCED, PRESSURE_RAW, STREAM_INFO,
                      StreamError, StreamInfo)

__all__ = ['compensate_bag']


def compensate_bag(model, input_path: str, output_path: str, *,
                   namespace: str | None = None, force: bool = False) -> dict:
    """
    Copy the bag at ``input_path`` to ``output_path`` with the compensated streams added.

    Two passes (disturbances fitted on the whole bag, then compensation in time order); the
    output is checked first (``force`` replaces a file of another kind, never the input) and
    written atomically. ``namespace`` is found from ``stream_info`` when None. Returns the
    sample accounting plus ``copied_messages``, ``first_unpaired``,
    ``disturbance_warnings`` and ``notes`` (what starting from rest leaves).

    Raises:
        SensorCompError: On a bag cut short or without both described raw streams of one
            rate, a model/bag rate mismatch, bad or unpairable blocks, or a refused output.

    """
    check_output(output_path, inputs=(input_path,), kind='bag', force=force)
    with BagReader(input_path) as bag:
        bag.check_complete()
        namespace = find_namespace(bag) if namespace is None else namespace
        infos = read_stream_infos(bag, namespace=namespace)
        topics = {name: topic_name(namespace, name)
                  for name in (ACCELERATION, PRESSURE_RAW, COMPENSATED, INDUCED, STREAM_INFO)}
        _check_inputs(input_path, bag, infos, topics)
        raw, accel = infos[PRESSURE_RAW], infos[ACCELERATION]
        if abs(model.fs - raw.fs) > 1e-9 * raw.fs:
            raise SensorCompError(f'model identified at {model.fs:g} Hz but {input_path} is '
                                  f'sampled at {raw.fs:g} Hz: identify a model at this rate')
        # Offline: the model's disturbances (mains hum) are fitted on the whole recording
        # in a first pass over the raw blocks, then removed from the first sample on.
        disturbances = fit_recording_disturbances(model, _raw_blocks(bag, topics), fs=raw.fs)
        compensator = BlockCompensator(
            CompensationFilter.from_model(model, trackers=disturbances is None), fs=raw.fs,
            disturbances=disturbances)
        sequences = {topics[PRESSURE_RAW]: BlockSequence(raw, name=topics[PRESSURE_RAW]),
                     topics[ACCELERATION]: BlockSequence(accel, name=topics[ACCELERATION])}
        pairing = _Pairing(topics[PRESSURE_RAW], topics[ACCELERATION])
        copied = 0
        # An error or interruption inside removes the temporary file: a partial output
        # would only mislead.
        with BagWriter(output_path, atomic=True) as out:
            for name, info in bag.topics.items():
                out.add_topic(name, info.msgtype, latched=info.latched)
            for name in (COMPENSATED, INDUCED):
                out.add_topic(topics[name], IMAGE)
            announced = False
            for msg in bag.messages():
                out.write(msg.topic, msg.data, log_time_ns=msg.log_time_ns,
                          publish_time_ns=msg.publish_time_ns)
                copied += 1
                if msg.topic == topics[STREAM_INFO] and not announced:
                    out.write(msg.topic, _output_info(raw, msg.publish_time_ns),
                              log_time_ns=msg.log_time_ns,
                              publish_time_ns=msg.publish_time_ns)
                    announced = True
                elif msg.topic in sequences:
                    stamp, data = _checked_block(input_path, msg, sequences[msg.topic])
                    pairing.received(msg.topic, stamp, data.shape[1])
                    add = (compensator.add_pressure if msg.topic == topics[PRESSURE_RAW]
                           else compensator.add_acceleration)
                    for block in add(stamp, data):
                        pairing.paired(block.stamp_ns)
                        for name, values in ((COMPENSATED, block.compensated),
                                             (INDUCED, block.induced)):
                            out.write(topics[name], encode_block(
                                values[None], stamp_ns=block.stamp_ns,
                                frame_id=raw.frame_id),
                                log_time_ns=msg.log_time_ns, publish_time_ns=block.stamp_ns)
            compensator.flush()
            pairing.finish()
            if not compensator.counters.output_samples:
                raise SensorCompError(pairing.describe_failure(input_path, raw.fs))
    note = rest_start_note(model.inputs)
    return {**compensator.counters.to_dict(), 'copied_messages': copied,
            'first_unpaired': pairing.first_unpaired(),
            'disturbance_warnings': disturbances.warnings if disturbances else [],
            'notes': [note] if note else []}


def _raw_blocks(bag: BagReader, topics: dict):
    """Yield ``(kind, stamp, data)`` of the raw blocks (a bad one is the second pass's)."""
    kinds = {topics[PRESSURE_RAW]: PRESSURE_RAW, topics[ACCELERATION]: ACCELERATION}
    for msg in bag.messages(list(kinds)):
        try:
            stamp, _, data = decode_block(msg.data)
        except MessageError:
            continue
        yield kinds[msg.topic], stamp, data


def _check_inputs(path: str, bag: BagReader, infos: dict, topics: dict) -> None:
    """Check that the bag has both raw block streams, described, of one rate."""
    raw_topics = block_topics(bag, namespace=topics[STREAM_INFO][:-len(STREAM_INFO)],
                              names=(ACCELERATION, PRESSURE_RAW))
    require_described(path, infos, raw_topics, topics[STREAM_INFO])
    for name, rows in ((ACCELERATION, 3), (PRESSURE_RAW, 1)):
        if len(infos[name].channels) != rows:
            raise SensorCompError(f'{path}: {topics[STREAM_INFO]} gives {topics[name]} '
                                  f'{len(infos[name].channels)} channels '
                                  f'({", ".join(infos[name].channels)}); compensation needs '
                                  f'{rows}')
    for name in (COMPENSATED, INDUCED):
        if topics[name] in bag.topics:
            raise SensorCompError(f'{path} already holds {topics[name]}: compensate '
                                  f'the original recording instead')
    accel, raw = infos[ACCELERATION], infos[PRESSURE_RAW]
    if abs(accel.fs - raw.fs) > 1e-9 * raw.fs:
        raise SensorCompError(f'{path}: {topics[ACCELERATION]} is sampled at {accel.fs:g} Hz '
                              f'and {topics[PRESSURE_RAW]} at {raw.fs:g} Hz; the compensation '
                              f'pairs blocks of one DAQ at one rate: resample one of them')


def _checked_block(path: str, msg, sequence: BlockSequence) -> tuple[int, np.ndarray]:
    """Decode a block and check it against its stream's previous block."""
    try:
        stamp, _, data = decode_block(msg.data)
        sequence.add(stamp, data)
    except (MessageError, StreamError) as exc:
        raise SensorCompError(f'{path}: {msg.topic} message at log time {msg.log_time_ns} '
                              f'ns: {exc}') from None
    return stamp, data


class _Pairing:
    """Which blocks found a partner, to say which did not (the compensator only counts)."""

    def __init__(self, pressure: str, acceleration: str):
        self.topics = (pressure, acceleration)
        self._pending = {t: deque() for t in self.topics}
        self._first = dict.fromkeys(self.topics)
        self._last = dict.fromkeys(self.topics)
        self._unpaired = dict.fromkeys(self.topics)

    def received(self, topic: str, stamp: int, width: int) -> None:
        """Note a block as it goes to the compensator."""
        if width:
            self._pending[topic].append((stamp, width))
            self._first[topic] = self._first[topic] or (stamp, width)
            self._last[topic] = (stamp, width)

    def paired(self, stamp: int) -> None:
        """Note a compensated block; blocks before it can no longer pair."""
        for topic, pending in self._pending.items():
            while pending and pending[0][0] <= stamp:
                block = pending.popleft()
                if block[0] < stamp and self._unpaired[topic] is None:
                    self._unpaired[topic] = block

    def finish(self) -> None:
        """Note every block still waiting as unpaired (end of the bag)."""
        for topic, pending in self._pending.items():
            if pending and self._unpaired[topic] is None:
                self._unpaired[topic] = pending[0]
            pending.clear()

    def first_unpaired(self) -> dict:
        """Return per topic the first block without partner, as JSON-ready values."""
        return {topic: None if block is None else {'stamp_ns': block[0], 'samples': block[1]}
                for topic, block in self._unpaired.items()}

    def describe_failure(self, path: str, fs: float) -> str:
        """Explain why no block paired."""
        pressure, acceleration = self.topics
        (p_stamp, p_width), (a_stamp, a_width) = self._first[pressure], self._first[acceleration]
        ends = {t: self._last[t][0] + round(self._last[t][1] * 1e9 / fs) for t in self.topics}
        if ends[pressure] <= a_stamp or ends[acceleration] <= p_stamp:
            why = '; they do not overlap in time'
        elif p_stamp != a_stamp:
            why = f' ({(p_stamp - a_stamp) * fs / 1e9:.3f} samples apart at {fs:g} Hz)'
        else:
            why = ''
        return (f'{path}: no {pressure} block pairs with a {acceleration} block (same stamp '
                f'and width), so nothing can be compensated: {pressure} blocks start at stamp '
                f'{p_stamp} ns with {p_width} samples, {acceleration} blocks at stamp '
                f'{a_stamp} ns with {a_width} samples{why}; the two streams must come from '
                f'one DAQ, whose blocks share stamps and widths')


def _output_info(raw: StreamInfo, stamp_ns: int) -> bytes:
    infos = [StreamInfo(name, raw.fs, ('p',), 'Pa', raw.frame_id, dict(raw.metadata))
             for name in (COMPENSATED, INDUCED)]
    return encode_stream_info(infos, stamp_ns=stamp_ns)
