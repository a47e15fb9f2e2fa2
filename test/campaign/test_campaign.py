"""
``sensor-comp campaign`` and :func:`sensor_comp.campaign.run_campaign` on a small campaign.

Most runs use the synchronous engine (every task in this process); one runs the same
campaign on a real two-worker LocalCluster and must give the same table.
"""

import json
import math
from pathlib import Path
import shutil

import numpy as np
import pyarrow as pa
import pyarrow.csv as pa_csv
import pyarrow.parquet as pq
import pytest

from sensor_comp.campaign import (CampaignError, IdentifyOptions, read_models, run_campaign,
                                  SCHEMA, SensorMap, SYNCHRONOUS)
from sensor_comp.io.recording_file import load_recording
from sensor_comp.cli.main import main
from sensor_comp.core.compensation.compare import compare
from sensor_comp.core.identification.identify import ShotSource
from sensor_comp.core.identification.model import load

#: Columns that must equal the single-recording core functions' numbers.
_SHOT_COLUMNS = ('peak_g', 'width_ms', 'peak_pressure_mpa', 'mpa_per_g')
_MODEL_COLUMNS = ('fit_percent', 'peak_residual_percent')


def _run(campaign, output, **kwargs):
    kwargs.setdefault('models', read_models([campaign.model]))
    kwargs.setdefault('scheduler', SYNCHRONOUS)
    return run_campaign([campaign.folder], output, **kwargs)


def _rows(output) -> list[dict]:
    """Return the per-shot table as dicts, stamps in integer ns."""
    table = pq.read_table(Path(output) / 'shots.parquet')
    i = table.schema.get_field_index('stamp')
    return table.set_column(i, 'stamp', table.column(i).cast(pa.int64())).to_pylist()


def _error(capsys, argv, words) -> str:
    """Run the CLI; assert one ``sensor-comp: error:`` line holding ``words``."""
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert err.startswith('sensor-comp: error: ') and err.count('\n') == 1, err
    for word in words:
        assert word in err, err
    return err


@pytest.fixture(scope='module')
def first_run(campaign, tmp_path_factory):
    """Return ``(summary, output)`` of a synchronous run with the ARX model for every sensor."""
    output = tmp_path_factory.mktemp('out') / 'campaign'
    return _run(campaign, output), output


def test_table_equals_single_recording_core(campaign, first_run):
    summary, output = first_run
    rows = _rows(output)
    model = load(campaign.model)
    for path in campaign.good:
        recording = load_recording(path)
        source = ShotSource.detect(recording, path=path)
        usable = [s for s in source.shots if s.usable]
        compared = {s.index: s for s in compare([model], recording, usable)[0].shots}
        mine = sorted((r for r in rows if Path(r['bag']).name == Path(path).name),
                      key=lambda r: r['shot'])
        assert [r['shot'] for r in mine] == [s.index for s in source.shots]
        for row, shot in zip(mine, source.shots):
            assert row['mode'] == shot.mode == 'normal'
            assert row['sensor'] == recording.frame_id
            assert row['stamp'] == recording.t0_ns + round(shot.onset * 1e9 / recording.fs)
            for name in _SHOT_COLUMNS:
                assert row[name] == pytest.approx(getattr(shot, name), rel=1e-12), name
            for name in _MODEL_COLUMNS:
                assert row[name] == pytest.approx(getattr(compared[shot.index], name),
                                                  rel=1e-9), name
            assert row['model'] == campaign.model
            assert abs(row['compensated_peak_mpa']) <= abs(row['peak_pressure_mpa'])
            assert row['sensitivity_mpa_per_g'] == pytest.approx(1.4e-4, rel=0.1)
    assert summary.bags == 6 and summary.failed == 1
    assert summary.shots == 15 == sum(r['mode'] != 'failed' for r in rows)
    assert [s.sensor for s in summary.sensors] == ['S1', 'S2', 'S3']


def test_failed_recording_is_one_row(campaign, first_run):
    summary, output = first_run
    failed = [r for r in _rows(output) if r['mode'] == 'failed']
    assert len(failed) == 1
    assert Path(failed[0]['bag']).name == 'run_0004.mcap'
    assert 'sensor-comp repair' in failed[0]['reason']
    assert failed[0]['shot'] is None and failed[0]['peak_g'] is None
    bags = pa_csv.read_csv(Path(output) / 'bags.csv').to_pylist()
    assert [b['status'] for b in bags].count('failed') == 1
    assert sum(b['shots'] for b in bags) == summary.shots


def test_outputs(first_run):
    summary, output = first_run
    table = pq.read_table(output / 'shots.parquet')
    assert table.schema.remove_metadata() == SCHEMA
    csv = pa_csv.read_csv(output / 'shots.csv')
    assert csv.num_rows == table.num_rows and csv.column_names == SCHEMA.names
    report = (output / 'report.html').read_text()
    assert report.count('data:image/png;base64,') >= 4  # 3 sensors + residuals
    assert 'src="http' not in report and 'run_0004.mcap' in report
    doc = json.loads((output / 'summary.json').read_text())
    assert doc['bags'] == 6 and len(doc['sensors']) == 3
    sensors = pa_csv.read_csv(output / 'sensors.csv').to_pylist()
    s1 = next(s for s in sensors if s['sensor'] == 'S1')
    assert s1['usable_shots'] == 9 and s1['basis'] == 'model'
    # A steady sensor: no significant drift, no change point.
    assert not s1['drift_significant'] and s1['change_points'] == 0
    assert s1['drift_ci95_low'] < 0 < s1['drift_ci95_high']


def test_resume_processes_only_what_is_new(campaign, copy_of, tmp_path):
    folder = copy_of(campaign)
    models = read_models([campaign.model])
    output = tmp_path / 'out'
    first = run_campaign([folder], output, models=models, scheduler=SYNCHRONOUS, report=False)
    assert (first.processed, first.cached) == (6, 0)
    again = run_campaign([folder], output, models=models, scheduler=SYNCHRONOUS, report=False)
    assert (again.processed, again.cached) == (0, 6)
    assert _rows(output) == _rows(output)  # readable, complete
    shutil.copy(folder / 'run_0001.mcap', folder / 'run_0009.mcap')  # same bytes: cached
    shutil.copy(campaign.good[3], folder / 'extra.mcap')
    campaign.write(folder / 'run_0010.mcap', index=5, sensor='S2')
    more = run_campaign([folder], output, models=models, scheduler=SYNCHRONOUS, report=False)
    assert more.processed == 1 and more.bags == 9 and more.cached == 8
    assert more.shots == first.shots + 3 + 3 + 3


class _Bars:
    """A progress factory that records every bar; optionally interrupts after some shots."""

    def __init__(self, stop_after: int | None = None):
        self.bars, self.stop_after = [], stop_after

    def __call__(self, label, total):
        outer = self

        class Bar:
            def __init__(self):
                self.label, self.total, self.done = label, total, 0

            def __enter__(self):
                return self

            def __exit__(self, *_):
                return None

            def advance(self, units=1):
                self.done += units
                if outer.stop_after is not None and self.done >= outer.stop_after:
                    raise KeyboardInterrupt

        self.bars.append(Bar())
        return self.bars[-1]


def test_progress_counts_shots_and_an_interrupted_run_resumes(campaign, copy_of, tmp_path):
    folder = copy_of(campaign)
    models = read_models([campaign.model])
    output = tmp_path / 'out'
    with pytest.raises(KeyboardInterrupt):
        run_campaign([folder], output, models=models, scheduler=SYNCHRONOUS,
                     progress=_Bars(stop_after=6))
    assert not (output / 'shots.parquet').exists()
    bars = _Bars()
    summary = run_campaign([folder], output, models=models, scheduler=SYNCHRONOUS,
                           progress=bars, report=False)
    assert 0 < summary.cached < 6 and summary.processed == 6 - summary.cached
    (bar,) = bars.bars
    assert bar.done == bar.total == summary.shots == 15


def test_new_model_recomputes(campaign, copy_of, tmp_path):
    folder = copy_of(campaign)
    output = tmp_path / 'out'
    run_campaign([folder], output, scheduler=SYNCHRONOUS, report=False)
    assert all(r['fit_percent'] is None for r in _rows(output))
    s2 = read_models([f'S2={campaign.model}'])
    after = run_campaign([folder], output, models=s2, scheduler=SYNCHRONOUS, report=False)
    assert after.processed == 1  # the S2 recording; the broken one stays failed (cached)
    fitted = {r['sensor'] for r in _rows(output) if r['fit_percent'] is not None}
    assert fitted == {'S2'}


def test_cli_json_on_a_local_cluster(campaign, first_run, capsys, tmp_path):
    output = tmp_path / 'cluster'
    assert main(['-q', 'campaign', str(campaign.folder), '-o', str(output), '--model',
                 campaign.model, '--workers', '2', '--json', '--no-report']) == 0
    doc = json.loads(capsys.readouterr().out)
    assert {k: doc[k] for k in ('bags', 'failed', 'shots', 'workers', 'engine')} == {
        'bags': 6, 'failed': 1, 'shots': 15, 'workers': 2, 'engine': 'local'}
    assert doc['seconds'] > 0 and doc['worker_memory_mb'] > 0
    assert not (output / 'report.html').exists()
    mine = {(Path(r['bag']).name, r['shot']): r for r in _rows(output)}
    for row in _rows(first_run[1]):
        other = mine[(Path(row['bag']).name, row['shot'])]
        for name in _SHOT_COLUMNS + _MODEL_COLUMNS:
            assert other[name] == row[name] or math.isclose(other[name], row[name],
                                                            rel_tol=1e-9), name


def test_a_running_cluster_by_address(campaign, first_run, monkeypatch, tmp_path):
    from distributed import LocalCluster
    with LocalCluster(n_workers=1, threads_per_worker=1, dashboard_address=None) as cluster:
        monkeypatch.setenv('DASK_SCHEDULER_ADDRESS', cluster.scheduler_address)
        summary = _run(campaign, tmp_path / 'out', scheduler=None, report=False)
    assert (summary.engine, summary.workers) == ('distributed', 1)
    assert _rows(tmp_path / 'out') == _rows(first_run[1])


def test_identify_a_model_per_sensor(campaign, tmp_path):
    output = tmp_path / 'out'
    options = IdentifyOptions(structure='oe', orders=(2, 2), delay=1, max_shots=6)
    bars = _Bars()
    summary = run_campaign([campaign.good[0], campaign.good[1], campaign.good[3]], output,
                           identify=options, scheduler=SYNCHRONOUS, report=False,
                           progress=bars)
    assert [(b.label.split()[0], b.done) for b in bars.bars] == [
        ('shots', 9), ('identify', 2), ('compare', 9)]
    assert (output / 'models' / 'S1.json').exists() and (output / 'models' / 'S2.json').exists()
    model = load(output / 'models' / 'S1.json')
    assert model.fit['campaign_sensor'] == 'S1'
    assert model.continuous().sensitivity_MPa_per_g == pytest.approx(1.4e-4, rel=0.05)
    assert {p.path for p in model.provenance} == {campaign.good[0], campaign.good[1]}
    rows = _rows(output)
    assert all(r['fit_percent'] > 80 for r in rows)
    assert {r['model'] for r in rows if r['sensor'] == 'S1'} == {
        str(output / 'models' / 'S1.json')}
    assert summary.processed == 3
    again = run_campaign([campaign.good[0], campaign.good[1], campaign.good[3]], output,
                         identify=options, scheduler=SYNCHRONOUS, report=False)
    assert (again.processed, again.cached) == (0, 3)


def test_sensor_map(campaign, tmp_path):
    mapping = tmp_path / 'sensors.yaml'
    mapping.write_text(f'A: ["{campaign.folder}/run_000[0-2].mcap"]\nB: [run_0003.mcap]\n')
    summary = _run(campaign, tmp_path / 'out', sensor_map=SensorMap.read(mapping),
                   report=False)
    sensors = {Path(r['bag']).name: r['sensor'] for r in _rows(tmp_path / 'out')}
    assert sensors == {'run_0000.mcap': 'A', 'run_0001.mcap': 'A', 'run_0002.mcap': 'A',
                       'run_0003.mcap': 'B', 'run_0004.mcap': '', 'scope.csv': 'S3'}
    assert [s.sensor for s in summary.sensors] == ['A', 'B', 'S3']
    unmapped = _run(campaign, tmp_path / 'out', report=False)  # the same model for all
    assert unmapped.processed == 0 and [s.sensor for s in unmapped.sensors] == ['S1', 'S2', 'S3']
    mapping.write_text('A: ["*.mcap"]\nB: [run_0003.mcap]\n')
    with pytest.raises(CampaignError, match='matches the patterns of A and B'):
        _run(campaign, tmp_path / 'out2', sensor_map=SensorMap.read(mapping))
    assert not (tmp_path / 'out2').exists()


def test_output_safety(campaign, capsys, tmp_path):
    base = ['campaign', '--scheduler', SYNCHRONOUS, '--no-report']
    _error(capsys, base + [str(campaign.folder), '-o', str(campaign.folder)],
           ['input', str(campaign.folder)])
    inner = tmp_path / 'out'
    inner.mkdir()
    bag = inner / 'run.mcap'
    shutil.copy(campaign.good[0], bag)
    _error(capsys, base + [str(bag), '-o', str(inner)], ['contains the input', str(bag)])
    other = tmp_path / 'photos'
    other.mkdir()
    (other / 'holiday.jpg').write_bytes(b'\xff\xd8\xff')
    _error(capsys, base + [campaign.good[0], '-o', str(other)], ['--force', 'not a campaign'])
    _error(capsys, base + [campaign.good[0], '-o', str(tmp_path / 'no' / 'out')],
           ['does not exist'])
    _error(capsys, base + [str(tmp_path / 'nothing*.mcap'), '-o', str(tmp_path / 'o')],
           ['matches it'])
    assert not (tmp_path / 'o').exists()
    assert main(base + [campaign.good[0], '-o', str(other), '--force']) == 0
    assert (other / 'holiday.jpg').exists() and (other / 'shots.parquet').exists()


def test_output_inside_an_input_folder_is_left_out(campaign, copy_of):
    folder = copy_of(campaign)
    output = folder / 'results'
    models = read_models([campaign.model])
    first = run_campaign([folder], output, models=models, scheduler=SYNCHRONOUS)
    again = run_campaign([folder], output, models=models, scheduler=SYNCHRONOUS, report=False)
    assert first.bags == again.bags == 6 and again.processed == 0  # its shots.csv is no input
    assert not any('results' in r['bag'] for r in _rows(output))


def test_shots_table_column_names_are_documented():
    assert len(SCHEMA) == len(set(SCHEMA.names)) and SCHEMA.field('stamp').type == \
        pa.timestamp('ns', tz='UTC')
    assert np.all([n.islower() for n in SCHEMA.names])


def test_every_bad_bag_of_the_corpus_is_one_row_with_its_reason(tmp_path):
    corpus = Path(__file__).resolve().parents[1] / 'data' / 'bad_bags'
    summary = run_campaign([corpus], tmp_path / 'out', scheduler=SYNCHRONOUS, report=False)
    bags = pa_csv.read_csv(tmp_path / 'out' / 'bags.csv').to_pylist()
    assert len(bags) == summary.bags == len(list(corpus.rglob('*.mcap')))
    failed = [b for b in bags if b['status'] == 'failed']
    assert len(failed) == summary.failed >= 20
    for bag in failed:  # a clear reason naming the file, never an internal error
        assert Path(bag['bag']).name in bag['reason'] and 'analysis failed' not in bag['reason']


def test_a_table_writer_that_cannot_start_leaves_no_temporary_file(tmp_path, monkeypatch):
    # The Parquet file's temporary stayed behind when the CSV writer failed to start.
    import pyarrow.csv as pa_csv
    from sensor_comp.campaign.table import TableWriter

    def refused(*args, **kwargs):
        raise OSError('refused')

    monkeypatch.setattr(pa_csv, 'CSVWriter', refused)
    with pytest.raises(OSError, match='refused'):
        TableWriter(tmp_path / 'shots.parquet', tmp_path / 'shots.csv')
    assert list(tmp_path.iterdir()) == []
