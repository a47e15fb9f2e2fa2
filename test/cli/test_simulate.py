"""Tests of ``sensor-comp simulate``: arguments, configuration and the written bag."""

import numpy as np
import pytest

from sensor_comp.cli.main import build_parser, main
from sensor_comp.cli.simulate import build_config
from sensor_comp.sim import simulate, TABLE2


def _config(*argv):
    return build_config(build_parser().parse_args(['simulate', '-o', 'x.mcap', *argv]))


def test_defaults_are_the_table2_rig():
    config = _config()
    assert config.shots == TABLE2
    assert config.fs == 1e6 and config.pressure_noise == 0.005 and config.effects == ()
    assert config.sensor.fn_hz == 5000.0 and config.sensor.sensitivity_mpa_per_g == 1.4e-4


def test_arguments_map_to_the_configuration():
    config = _config('--shots', '4', '--peak-g', '300', '900', '--width-ms', '1', '2',
                     '--fs', '200000', '--noise', '1.5', '--accel-noise', '0.2',
                     '--lateral', '3', '--seed', '9', '--fn', '6000', '--zeta', '0.08',
                     '--sensitivity', '2e-4', '--sign', '-1', '--pre-ms', '5',
                     '--post-ms', '30', '--effect', 'channel_delay:delay_us=7.5',
                     '--effect', 'mains_hum')
    assert len(config.shots) == 4
    assert all(300 <= s.peak_g <= 900 and 1e-3 <= s.width_s <= 2e-3 for s in config.shots)
    assert config.fs == 2e5 and config.seed == 9
    assert config.pressure_noise == pytest.approx(0.015)
    assert config.accel_noise == pytest.approx(0.002)
    assert config.lateral_ratio == pytest.approx(0.03)
    assert config.pre_trigger_s == pytest.approx(0.005)
    assert config.post_shot_s == pytest.approx(0.03)
    sensor = config.sensor
    assert (sensor.fn_hz, sensor.zeta, sensor.sensitivity_mpa_per_g, sensor.sign) == (
        6000.0, 0.08, 2e-4, -1)
    assert [e.id for e in config.effects] == ['channel_delay', 'mains_hum']
    assert config.effects[0].delay_us == 7.5
    # Random shots depend on the seed only.
    assert _config('--shots', '4', '--seed', '9').shots == _config(
        '--shots', '4', '--seed', '9').shots


@pytest.mark.parametrize('argv, words', [
    (['--peak-g', '100', '200'], ['--peak-g', '--shots N']),
    (['--effect', 'bogus'], ['bogus', 'channel_delay']),
    (['--effect', 'zero_shift:tau_ms=-1'], ['zero_shift', 'tau_ms']),
    (['--fs', '0'], ['fs']),
])
def test_user_errors_exit_1_with_a_message(argv, words, tmp_path, capsys):
    assert main(['simulate', '-o', str(tmp_path / 'x.mcap'), *argv]) == 1
    err = capsys.readouterr().err
    for word in words:
        assert word in err
    assert not (tmp_path / 'x.mcap').exists()


def test_missing_output_and_bad_shot_count(capsys):
    assert main(['simulate']) == 1
    assert '-o' in capsys.readouterr().err
    with pytest.raises(SystemExit) as info:
        main(['simulate', '-o', 'x.mcap', '--shots', 'many'])
    assert info.value.code == 2


def test_list_effects(capsys):
    assert main(['simulate', '--list-effects']) == 0
    out = capsys.readouterr().out
    for word in ('channel_delay', 'delay_us', 'mains_hum', 'Pa/(g/ms)'):
        assert word in out


def test_writes_the_simulated_recording(tmp_path, capsys):
    read_recording = pytest.importorskip('sensor_comp.io.bag_reader').read_recording
    path = tmp_path / 'sim.mcap'
    argv = ['--shots', '2', '--fs', '200000', '--seed', '3', '--post-ms', '10',
            '--effect', 'channel_delay:delay_us=5']
    assert main(['simulate', '-o', str(path), *argv]) == 0
    out = capsys.readouterr().out
    assert '2 shots' in out and 'channel_delay:delay_us=5' in out
    recording = read_recording(path)
    expected = simulate(_config(*argv)).recording
    assert recording.fs == expected.fs and recording.t0_ns == expected.t0_ns
    assert np.array_equal(recording.pressure, expected.pressure)
    assert np.array_equal(recording.acceleration, expected.acceleration)
    assert recording.charge_sensitivity == 100.0
    assert recording.metadata['sim_effects'] == 'channel_delay:delay_us=5'


def test_quiet_prints_nothing(tmp_path, capsys):
    path = tmp_path / 'q.mcap'
    assert main(['--quiet', 'simulate', '-o', str(path), '--shots', '1', '--fs', '200000',
                 '--post-ms', '5']) == 0
    assert capsys.readouterr().out == ''
    assert path.stat().st_size > 0


def test_blind_bag_hides_the_simulator_truth(tmp_path, capsys):
    from sensor_comp.io.bag_reader import read_streams

    path = tmp_path / 'case.mcap'
    assert main(['simulate', '-o', str(path), '--shots', '2', '--fs', '200000',
                 '--effect', 'channel_delay', '--blind']) == 0
    assert 'channel_delay' not in capsys.readouterr().out
    for stream in read_streams(path).values():
        assert not [k for k in stream.info.metadata if k.startswith('sim_')]
        assert stream.info.metadata['charge_sensitivity_pC_per_MPa'] == '100'
