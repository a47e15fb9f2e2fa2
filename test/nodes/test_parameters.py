"""Parameters every node checks at start: output files, input files, unknown names."""

import hashlib

import pytest

from sensor_comp.io.bag_writer import write_recording
from sensor_comp.nodes.acquisition import Acquisition
from sensor_comp.nodes.compensation import Compensation
from sensor_comp.nodes.errors import NodeError
from sensor_comp.nodes.identification import Identification
from sensor_comp.nodes.player import Player
from sensor_comp.nodes.recorder import Recorder
from sensor_comp.sim import random_shots, RigConfig, simulate

#: A small simulated acquisition: one shot at 20 kS/s.
SIM = {'source': 'sim', 'sim_fs': 2e4, 'sim_shots': 1, 'sim_seed': 2}


@pytest.fixture
def bag(tmp_path):
    """Write a small MCAP recording (one being played, say); return its path."""
    path = tmp_path / 'played.mcap'
    write_recording(path, simulate(RigConfig(fs=2e4, shots=random_shots(1, seed=2),
                                             seed=2)).recording)
    return path


def _sha256(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_identification_never_writes_its_model_over_a_bag(context, params, bag):
    before = _sha256(bag)
    with pytest.raises(NodeError, match=f"/rig/identification: parameter 'model_file': output "
                                        f"{bag} exists and is an MCAP recording, not a "
                                        f"sensor_comp model file; choose another name$"):
        Identification(context=context, parameter_overrides=params(model_file=str(bag)))
    assert _sha256(bag) == before


def test_identification_model_file_needs_a_writable_folder(context, params, tmp_path):
    missing = tmp_path / 'no_such_folder' / 'sensor.json'
    with pytest.raises(NodeError, match=f"parameter 'model_file': output folder {missing.parent} "
                                        f"does not exist"):
        Identification(context=context, parameter_overrides=params(model_file=str(missing)))
    with pytest.raises(NodeError, match=f"parameter 'model_file': output {tmp_path} is a folder"):
        Identification(context=context, parameter_overrides=params(model_file=str(tmp_path)))
    assert list(tmp_path.iterdir()) == []  # nothing created, not even a probe


def test_compensation_model_file_must_be_a_model(context, params, bag):
    with pytest.raises(NodeError, match=f"parameter 'model_file' '{bag}' cannot be used"):
        Compensation(context=context, parameter_overrides=params(model_file=str(bag)))


def test_a_recorder_never_records_over_the_bag_being_played(context, params, make_player, bag):
    before = _sha256(bag)
    player = make_player(bag)
    with pytest.raises(NodeError, match="/rig/recorder: parameter 'output' must be the name of "
                                        "a file that does not exist yet"):
        Recorder(context=context, parameter_overrides=params(output=str(bag)))
    player.destroy_node()
    assert _sha256(bag) == before


def test_recorder_output_needs_an_existing_folder(context, params, tmp_path):
    missing = tmp_path / 'no_such_folder' / 'run.mcap'
    with pytest.raises(NodeError, match=f"parameter 'output': output folder {missing.parent} "
                                        f"does not exist"):
        Recorder(context=context, parameter_overrides=params(output=str(missing)))
    with pytest.raises(NodeError, match=f"parameter 'output': output folder {missing.parent} "
                                        f"does not exist"):
        Recorder(context=context, parameter_overrides=params(output=str(missing),
                                                             max_bag_size=1 << 20))


@pytest.mark.parametrize('node_class, values, name', [
    (Player, {'bag': '/no/such/bag.mcap'}, 'bag'),
    (Acquisition, {**SIM, 'sim_seed': -1}, 'sim_seed'),
    (Acquisition, {**SIM, 'sim_effects': ['channel_delay:delay_us=x']}, 'sim_effects'),
    (Acquisition, {**SIM, 'sim_pressure_noise': -1.0}, r'sim_\*.*pressure_noise'),
])
def test_input_and_simulator_parameters_are_checked(context, params, node_class, values, name):
    with pytest.raises(NodeError, match=f'parameter.*{name}'):
        node_class(context=context, parameter_overrides=params(**values))


@pytest.mark.parametrize('node_class, typo, meant', [
    (Acquisition, 'sorce', 'source'),
    (Identification, 'min_shot', 'min_shots'),
    (Compensation, 'modelfile', 'model_file'),
    (Recorder, 'ouput', 'output'),
    (Player, 'rates', 'rate'),
])
def test_unknown_parameters_are_warned_about_with_the_closest_name(
        context, params, node_log, tmp_path, bag, node_class, typo, meant):
    needed = {Acquisition: SIM, Recorder: {'output': str(tmp_path / 'run.mcap')},
              Player: {'bag': str(bag)}}.get(node_class, {})
    node = node_class(context=context, parameter_overrides=params(
        **needed, **{typo: 'x', 'zzz_unrelated': 1}))
    logger = node.get_logger().name
    node.destroy_node()
    warned = node_log.matching(f'[{logger}]', 'unknown parameter')
    assert len(warned) == 2, warned
    assert f"unknown parameter '{typo}' (did you mean '{meant}'?) is ignored" in warned[0]
    assert "unknown parameter 'zzz_unrelated' (this node has " in warned[1]
    assert f"'{meant}'" not in warned[1] and meant in warned[1]


def test_unknown_parameters_given_on_the_command_line_are_warned_about(node_process):
    proc = node_process('acquisition', **SIM, pacing='fast', sorce='csv')
    assert proc.wait() == 0, proc.output()
    assert "unknown parameter 'sorce' (did you mean 'source'?) is ignored" in proc.output()
    assert 'published' in proc.output()  # the default source, sim
