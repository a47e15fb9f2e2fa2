"""The ranking of scored candidates, on stand-in entries (no fits)."""

from types import SimpleNamespace

from scipy import stats

from sensor_comp.core.diagnosis.findings import Ranked
from sensor_comp.core.diagnosis.scoring import ordered


def test_candidates_the_energy_does_not_tell_apart_go_by_their_evidence():
    # Seed 25's rig 114 (a 67 kHz mode at 220 kS/s): a delay removed the most energy
    # (score 0.076) and a second mode the least (0.054), but the mode left 0.019 noise
    # energies beyond its own floor against the delay's 0.062 (within the practical share,
    # 0.05) and its change followed the residual more surely (z 47.7 against 35.0).
    def ranked(effect, score, z, beyond, *, significant=True):
        left = SimpleNamespace(excess=beyond, noise_variance=1.0)
        return Ranked(effect=effect, title=effect, score=score, parameters={}, evidence='',
                      significant=significant, statistic=z, test='z',
                      p_value=float(stats.norm.sf(z)), fit_percent=99.0,
                      peak_residual_percent=1.0, leftover=left,
                      log_p_value=float(stats.norm.logsf(z)))

    ctx = SimpleNamespace(noise=SimpleNamespace(variance=1.0))
    delay, mode = ranked('channel_delay', 0.076, 35.0, 0.062), ranked('mode', 0.054, 47.7, 0.019)
    strain = ranked('strain', 0.068, 35.1, 0.042)
    weak = ranked('hum', 0.5, 99.0, 0.0, significant=False)
    assert [r.effect for r in ordered([delay, strain, weak, mode], ctx)] == [
        'mode', 'strain', 'channel_delay', 'hum']
    # Beyond the practical share the energy tells them apart: the least excess comes first.
    far = ranked('channel_delay', 0.076, 35.0, 0.019 + 0.051)
    assert [r.effect for r in ordered([far, mode], ctx)] == ['mode', 'channel_delay']
    near = ranked('channel_delay', 0.076, 60.0, 0.019 + 0.049)
    assert [r.effect for r in ordered([mode, near], ctx)] == ['channel_delay', 'mode']
