"""
Rewrite a cut-short, unfinished or damaged bag as a clean, finalised one.

Every surviving message is copied unchanged with the source's schemas, channels, metadata
and attachments; the output appears only once complete and read back. Details:
``doc/recording.md``, repair.
"""

from __future__ import annotations

from dataclasses import dataclass
import os
from pathlib import Path

from .bag_reader import (AttachmentRecord, BagError, BagReader, DamagedChunk, MetadataRecord,
                         RawMessage)
from .bag_writer import BagWriter
from ..files import open_temporary, publish

__all__ = ['RepairError', 'RepairReport', 'default_output', 'repair_bag']


class RepairError(BagError):
    """A bag cannot be repaired into the requested output."""


@dataclass(frozen=True)
class RepairReport:
    """
    What :func:`repair_bag` found, kept and lost.

    Attributes:
        source: The file read.
        output: The bag written.
        source_bytes: Size of the source in bytes.
        state: ``'finalised'``, ``'no summary'``, ``'unfinalised'``, ``'cut'`` or
            ``'damaged'`` (``doc/recording.md``).
        warning: The reader's description of the cut or damage, ``''`` if none.
        lost_bytes: Bytes after the cut that hold no complete record (0 if not cut).
        partial_chunk: Log-time span ``(start, end)`` in ns of the chunk the cut fell in.
        damaged: Damaged chunks (or the damaged record) skipped, in file order.
        recovered: Messages written per topic (every topic of the source, 0 included).
        expected: Messages per topic by the source's summary; None without a usable one.
        metadata_records: MCAP metadata records copied.
        attachments: MCAP attachments copied.
        last_log_time_ns: Log time of the last message recovered, None if none.

    """

    source: Path
    output: Path
    source_bytes: int
    state: str
    warning: str
    lost_bytes: int
    partial_chunk: tuple[int, int] | None
    damaged: tuple[DamagedChunk, ...]
    recovered: dict[str, int]
    expected: dict[str, int] | None
    metadata_records: int
    attachments: int
    last_log_time_ns: int | None

    @property
    def total(self) -> int:
        """Return the number of messages recovered."""
        return sum(self.recovered.values())

    @property
    def lost_messages(self) -> dict[str, int] | None:
        """Return the messages lost per topic when the summary tells, else ``None``."""
        if self.expected is None:
            return None
        return {t: self.expected.get(t, 0) - n for t, n in self.recovered.items()
                if self.expected.get(t, 0) != n}

    @property
    def lost_anything(self) -> bool:
        """Return whether anything of the source is missing from the output."""
        return bool(self.lost_bytes or self.damaged or self.lost_messages or
                    self.state == 'cut')

    def lines(self) -> list[str]:
        """Return the report as lines of text: state, recovered per topic, what was lost."""
        states = {
            'finalised': 'complete and finalised: nothing to recover, copied as it is',
            'no summary': 'complete, without a summary with message counts (read by '
                          'scanning): nothing was lost',
            'unfinalised': 'its data are complete but its summary is cut short (the writer '
                           'died while finalising): nothing was lost',
            'cut': f'cut short at byte {self.source_bytes} (the writer did not finish)',
            'damaged': 'damaged (see below)',
        }
        lines = [f'{self.source} ({self.source_bytes} bytes): {states[self.state]}']
        counts = self.expected or {}
        lines.append(f'recovered {self.total} messages on {len(self.recovered)} topics:')
        width = max((len(t) for t in self.recovered), default=0)
        for topic, count in self.recovered.items():
            of = f' of {counts[topic]}' if topic in counts else ''
            lines.append(f'  {topic:{width}s} {count:9d}{of}')
        if self.last_log_time_ns is not None:
            lines.append(f'last message recovered: logged at {self.last_log_time_ns} ns')
        lines.extend(self._lost())
        if self.metadata_records or self.attachments:
            lines.append(f'copied {self.metadata_records} metadata records and '
                         f'{self.attachments} attachments')
        lines.append(f'wrote {self.output}')
        return lines

    def _lost(self) -> list[str]:
        lost = []
        if self.state == 'cut':
            if self.partial_chunk:
                start, end = self.partial_chunk
                text = (f'lost: the file stops {self.lost_bytes} bytes into a chunk of '
                        f'messages logged {start}..{end} ns; the complete messages at its '
                        f'start were kept, the rest of it is lost')
            elif self.lost_bytes:
                text = f'lost: the last {self.lost_bytes} bytes of the file, an incomplete record'
            else:
                text = ('lost: whatever the writer had still to write (the file ends between '
                        'two records)')
            lost.append(text + '; how many messages that was is unknown: the writer died '
                               'before it counted them')
        for part in self.damaged:
            span = ('' if part.start_ns is None else
                    f' (messages logged {part.start_ns}..{part.end_ns} ns)')
            lost.append(f'lost: {part.reason}{span}')
        if self.lost_messages:
            lost.append('lost messages per topic: ' + ', '.join(
                f'{t} {n}' for t, n in self.lost_messages.items()))
        if self.state == 'damaged' and not self.damaged:
            lost.append(f'note: {self.warning}')
        return lost or ['lost: nothing']

    def to_dict(self) -> dict:
        """Return the report as JSON-ready values."""
        return {'source': str(self.source), 'output': str(self.output),
                'source_bytes': self.source_bytes, 'state': self.state,
                'warning': self.warning, 'lost_bytes': self.lost_bytes,
                'partial_chunk_ns': list(self.partial_chunk) if self.partial_chunk else None,
                'damaged': [p._asdict() for p in self.damaged],
                'recovered': dict(self.recovered), 'recovered_total': self.total,
                'expected': self.expected, 'lost_messages': self.lost_messages,
                'lost_anything': self.lost_anything,
                'metadata_records': self.metadata_records, 'attachments': self.attachments,
                'last_log_time_ns': self.last_log_time_ns}


def default_output(source) -> Path:
    """Return the default output of ``sensor-comp repair SOURCE``: ``run.repaired.mcap``."""
    source = Path(source)
    name = source.name.removesuffix('.partial').removesuffix('.mcap')
    return source.with_name(f'{name}.repaired.mcap')


def _same_file(a: Path, b: Path) -> bool:
    return a.exists() and b.exists() and os.path.samefile(a, b)


def _check_output(source: Path, output: Path, overwrite: bool) -> None:
    """Refuse outputs that would replace the input or an existing file without overwrite."""
    if _same_file(output, source) or output.resolve() == source.resolve():
        raise RepairError(f'{output} is the bag being repaired; the input is never replaced: '
                          f'give another output (-o), e.g. {default_output(source)}')
    if output.is_dir():
        raise RepairError(f'{output} is a directory; give the output bag a file name, e.g. '
                          f'{output / default_output(source).name}')
    if output.exists() and not overwrite:
        raise RepairError(f'{output} exists; pass --force to replace it (it is replaced only '
                          f'once the repaired bag is complete)')


def repair_bag(source, output=None, *, overwrite: bool = False) -> RepairReport:
    """
    Write every recoverable message of ``source`` into a clean, finalised bag.

    Args:
        source: The bag to repair (an ``.mcap`` file, or a rosbag2 directory holding one).
        output: The bag to write; :func:`default_output` when None.
        overwrite: Replace ``output`` if it exists (never the source).

    Raises:
        RepairError: If the output is the source, a directory, or exists without
            ``overwrite``, or cannot be written.
        BagError: If the source is not a ROS 2 MCAP bag or holds nothing readable.

    """
    output = default_output(source) if output is None else Path(output)
    with BagReader(source, skip_damaged=True) as bag:
        _check_output(bag.path, output, overwrite)
        recovered = {topic: 0 for topic in bag.topics}
        metadata = attachments = 0
        last = None
        added = set()
        try:
            # Written under a unique temporary name, read back, then renamed: the output
            # never holds a half-written or unverified bag, and concurrent runs never collide.
            file, partial = open_temporary(output)
            file.close()
        except OSError as exc:
            raise RepairError(f'cannot write {output}: {exc.strerror or exc}') from None
        try:
            with BagWriter(partial) as out:
                for channel in bag.channels.values():
                    if channel.topic in added:
                        continue  # a second channel of one topic: its messages join the first
                    added.add(channel.topic)
                    schema = bag.schemas[channel.schema_id]
                    out.copy_topic(channel.topic, msgtype=schema.name,
                                   schema_encoding=schema.encoding, schema_data=schema.data,
                                   metadata=channel.metadata)
                for record in bag.records():
                    if isinstance(record, RawMessage):
                        out.write(record.topic, record.data, log_time_ns=record.log_time_ns,
                                  publish_time_ns=record.publish_time_ns,
                                  sequence=record.sequence)
                        recovered[record.topic] += 1
                        last = record.log_time_ns
                    elif isinstance(record, MetadataRecord):
                        out.add_metadata(record.name, record.metadata)
                        metadata += 1
                    elif isinstance(record, AttachmentRecord):
                        out.add_attachment(record.name, record.data,
                                           media_type=record.media_type,
                                           log_time_ns=record.log_time_ns,
                                           create_time_ns=record.create_time_ns)
                        attachments += 1
            _verify(partial, recovered)
            publish(partial, output)
        except OSError as exc:
            partial.unlink(missing_ok=True)
            raise RepairError(f'cannot write {output}: {exc.strerror or exc}') from None
        except BaseException:
            # A bad bag found half-way, Ctrl-C or SIGTERM: no temporary file is left.
            partial.unlink(missing_ok=True)
            raise
        return RepairReport(
            source=bag.path, output=output, source_bytes=bag.size, state=_state(bag),
            warning=bag.warning,
            lost_bytes=0 if bag.cut_at is None else bag.size - bag.cut_at,
            partial_chunk=bag.partial_chunk, damaged=tuple(bag.damaged),
            recovered=recovered,
            expected=({t: i.message_count for t, i in bag.topics.items()}
                      if bag.has_summary else None),
            metadata_records=metadata, attachments=attachments, last_log_time_ns=last)


def _state(bag: BagReader) -> str:
    if bag.cut_in_data:
        return 'cut'
    if bag.damaged or (bag.warning and not bag.truncated):
        return 'damaged'
    if bag.truncated:
        return 'unfinalised'
    return 'finalised' if bag.has_summary else 'no summary'


def _verify(path: Path, recovered: dict[str, int]) -> None:
    """Read the written bag's summary back: it must hold exactly what was recovered."""
    with BagReader(path) as check:
        counts = {t: i.message_count for t, i in check.topics.items()}
        if not check.has_summary or counts != recovered:
            raise RepairError(f'{path}: the repaired bag does not read back as written '
                              f'(summary {"found" if check.has_summary else "missing"}, '
                              f'counts {counts} instead of {recovered}); it was not kept')
