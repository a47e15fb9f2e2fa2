"""``sensor-comp compensate``: add compensated and induced pressure streams to a bag."""

from __future__ import annotations

import argparse
import json
import os

from .sources import load_model
from ..core.compensation import CompensationFilter
from ..core.streaming import BlockCompensator
from ..errors import SensorCompError
from ..io.bag_reader import BagReader, find_namespace, read_stream_infos
from ..io.bag_writer import BagWriter, topic_name
from ..io.messages import decode_block, encode_block, encode_stream_info, IMAGE, MessageError
from ..streams import ACCELERATION, COMPENSATED, INDUCED, PRESSURE_RAW, STREAM_INFO, StreamInfo

__all__ = ['compensate_bag', 'register', 'run']


def register(subparsers) -> None:
    """Add the ``compensate`` sub-command."""
    parser = subparsers.add_parser(
        'compensate', help='write a bag with compensated and induced pressure added',
        description='Run the streaming compensation filter of a model over a bag, block by '
                    'block, and write a new bag with pressure/compensated and '
                    'pressure/induced added; every other message is copied unchanged.')
    parser.add_argument('model', help='model file (.json)')
    parser.add_argument('input', help='input bag (.mcap)')
    parser.add_argument('-o', '--output', required=True, help='output bag (.mcap)')
    parser.add_argument('--namespace', help='rig namespace (default: found from stream_info)')
    parser.add_argument('--json', action='store_true', help='print the sample accounting')
    parser.set_defaults(func=run)


def compensate_bag(model, input_path: str, output_path: str, *,
                   namespace: str | None = None) -> dict:
    """
    Copy a bag and add the model's ``pressure/compensated`` and ``pressure/induced``.

    The output is written atomically (``OUTPUT.partial`` renamed when complete). Blocks are
    paired by stamp and compensated in time order with state carried across blocks; a
    stamp gap restarts the filter from rest.

    Args:
        model: The model (``b``, ``a``, ``nk``, ``inputs``, ``fs``).
        input_path: The bag to read.
        output_path: The bag to write (not the input).
        namespace: Rig namespace; found from the ``stream_info`` topic when None.

    Returns:
        The sample accounting (see :class:`~sensor_comp.core.streaming.StreamCounters`)
        plus ``copied_messages``.

    Raises:
        SensorCompError: On a model/bag rate mismatch, a bag without the raw streams, or
            when the output would overwrite the input.

    """
    if os.path.abspath(output_path) == os.path.abspath(input_path):
        raise SensorCompError(f'{output_path}: the output must not overwrite the input bag')
    with BagReader(input_path) as bag:
        namespace = find_namespace(bag) if namespace is None else namespace
        infos = read_stream_infos(bag, namespace=namespace)
        topics = {name: topic_name(namespace, name)
                  for name in (ACCELERATION, PRESSURE_RAW, COMPENSATED, INDUCED, STREAM_INFO)}
        for name in (ACCELERATION, PRESSURE_RAW):
            if name not in infos or topics[name] not in bag.topics:
                raise SensorCompError(f'{input_path}: no {topics[name]} stream to compensate')
        for name in (COMPENSATED, INDUCED):
            if topics[name] in bag.topics:
                raise SensorCompError(f'{input_path} already holds {topics[name]}: compensate '
                                      f'the original recording instead')
        raw = infos[PRESSURE_RAW]
        if abs(model.fs - raw.fs) > 1e-9 * raw.fs:
            raise SensorCompError(f'model identified at {model.fs:g} Hz but {input_path} is '
                                  f'sampled at {raw.fs:g} Hz: identify a model at this rate')
        compensator = BlockCompensator(CompensationFilter.from_model(model), fs=raw.fs)
        copied = 0
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
                              log_time_ns=msg.log_time_ns, publish_time_ns=msg.publish_time_ns)
                    announced = True
                elif msg.topic in (topics[PRESSURE_RAW], topics[ACCELERATION]):
                    try:
                        stamp, _, data = decode_block(msg.data)
                    except MessageError as exc:
                        raise SensorCompError(f'{input_path}: {msg.topic} message at log '
                                              f'time {msg.log_time_ns} ns: {exc}') from None
                    add = (compensator.add_pressure if msg.topic == topics[PRESSURE_RAW]
                           else compensator.add_acceleration)
                    for block in add(stamp, data):
                        for name, values in ((COMPENSATED, block.compensated),
                                             (INDUCED, block.induced)):
                            out.write(topics[name], encode_block(
                                values[None], stamp_ns=block.stamp_ns, frame_id=raw.frame_id),
                                log_time_ns=msg.log_time_ns, publish_time_ns=block.stamp_ns)
        compensator.flush()
    return {**compensator.counters.to_dict(), 'copied_messages': copied}


def _output_info(raw: StreamInfo, stamp_ns: int) -> bytes:
    infos = [StreamInfo(name, raw.fs, ('p',), 'Pa', raw.frame_id, dict(raw.metadata))
             for name in (COMPENSATED, INDUCED)]
    return encode_stream_info(infos, stamp_ns=stamp_ns)


def run(args: argparse.Namespace) -> int:
    """Compensate the bag; return the exit code."""
    model = load_model(args.model)
    counts = compensate_bag(model, args.input, args.output, namespace=args.namespace)
    if args.json:
        print(json.dumps(counts, indent=2))
    elif not args.quiet:
        print(f'{args.input} -> {args.output}: {counts["output_samples"]} of '
              f'{counts["pressure_samples"]} pressure samples compensated, '
              f'{counts["copied_messages"]} messages copied')
        for key in ('unpaired_pressure_samples', 'unpaired_acceleration_samples',
                    'mismatched_blocks'):
            if counts[key]:
                print(f'warning: {counts[key]} {key.replace("_", " ")}')
        if counts['gaps']:
            print(f'warning: {len(counts["gaps"])} stamp gaps; the filter restarted from rest '
                  f'after each')
    return 0
