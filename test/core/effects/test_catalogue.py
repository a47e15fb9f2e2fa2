"""The diagnosis's and the simulator's effect catalogues describe the same effects."""

from dataclasses import fields, is_dataclass

import numpy as np
import pytest

from sensor_comp.core.effects import EFFECTS, PROBES, probe_owner, RIVALS
from sensor_comp.core.effects import base
from sensor_comp.core.effects.mains_hum import HARMONICS
from sensor_comp.core.identification.extended import ExtendedFit
from sensor_comp.core.identification.model import Model
from sensor_comp.core.diagnosis import residual
from sensor_comp.sim.effects import base as sim_base
from sensor_comp.sim.effects import EFFECTS as SIM_EFFECTS


def identified(cls) -> dict[str, str]:
    """Return the simulator effect's parameters the diagnosis fits, with their units."""
    return {f.name: f.metadata['unit'] for f in fields(cls) if f.metadata['identified']}


def test_both_catalogues_have_the_same_effects_in_the_same_signal_path_order():
    assert sorted(EFFECTS) == sorted(SIM_EFFECTS)
    assert {i: e.order for i, e in EFFECTS.items()} == {i: c.order for i, c in SIM_EFFECTS.items()}


@pytest.mark.parametrize('effect_id', sorted(EFFECTS))
def test_parameter_names_and_units_agree(effect_id):
    assert EFFECTS[effect_id].parameters == identified(SIM_EFFECTS[effect_id])


def test_both_catalogues_register_by_subclassing():
    assert sorted(base.registry()) == sorted(EFFECTS)
    assert sim_base.registry() == SIM_EFFECTS

    class Variant(type(EFFECTS['zero_shift'])):   # no id of its own: not registered
        pass

    assert base.registry()['zero_shift'] is type(EFFECTS['zero_shift'])


def test_every_probe_belongs_to_exactly_one_effect_or_is_generic():
    generic = [p.name for p in residual.GENERIC_PROBES]
    declared = [p.name for effect in EFFECTS.values() for p in effect.probes]
    assert len(set(declared)) == len(declared) == len(PROBES)
    assert not set(generic) & set(declared)
    rivals = [p.name for effect in EFFECTS.values() for p in effect.rivals]
    assert len(set(rivals)) == len(rivals) == len(RIVALS)
    assert not set(rivals) & set(generic + declared)
    assert sorted(residual.PROBES) == sorted(generic + declared + rivals)
    assert all(probe_owner(name) is None for name in generic + rivals)
    for effect in EFFECTS.values():
        assert all(probe_owner(p.name) == effect.id for p in effect.probes)


@pytest.mark.parametrize('name', sorted(PROBES))
def test_a_probe_reads_parameters_of_its_effect(name):
    probe, effect = PROBES[name], EFFECTS[probe_owner(name)]
    reading = probe.reading(np.array([-1.0, 0.5]), probe.grid[0] if probe.grid else None)
    assert set(reading) & set(effect.parameters)
    assert probe.tests and probe.words


@pytest.mark.parametrize('protocol, cls', [
    (base.FittedModel, Model),
    (base.FitView, ExtendedFit),
    (base.ResidualView, residual.ResidualAnalysis),
    (base.ProbeView, residual.Probe),
    (base.SegmentView, residual.SegmentEnergy),
    (base.PeakView, residual.SpectralPeak),
    (base.SpectrumView, residual.ResidualSpectrum),
    (base.TrendView, residual.AmplitudeTrend),
])
def test_the_protocols_effects_read_match_what_they_stand_for(protocol, cls):
    members = {n for n in (*vars(protocol), *getattr(protocol, '__annotations__', {}))
               if not n.startswith('_')}
    has = set(dir(cls)) | ({f.name for f in fields(cls)} if is_dataclass(cls) else set())
    assert members and members <= has


def test_the_mains_settings_agree():
    # The diagnosis chooses between the simulator's mains frequencies and fits as many odd
    # harmonics as the simulator adds by default.
    sim = {f.name: f for f in fields(SIM_EFFECTS['mains_hum'])}
    assert tuple(c['freq_hz'] for c in EFFECTS['mains_hum'].choices()) == \
        sim['freq_hz'].metadata['choices']
    assert HARMONICS == sim['harmonics'].default
