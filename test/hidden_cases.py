"""
Hidden-effect bag pairs for the diagnosis tests: the case table and the script that writes them.

Each case is a calibration and a validation run of the simulated drop-hammer rig (two
seeds of the same rig: other shots, noise and sub-sample onsets) with no, one or two
physical effects of the simulator switched on. The bags are written with
``sensor-comp simulate --blind``, so they do not tell which effect is in them: the answers
live only here and in ``test_hidden_cases.py``. The letters do not follow the catalogue.

Every run is digitised like a shock-measurement channel: a 4-pole Bessel anti-alias filter at
a tenth of the sample rate on every channel (the usual rule for shock data: sample at ten
times the filter corner), then white digitiser noise. Without it a sampled model could not
follow the jerk step at a pulse corner (the step falls between samples).

Effect sizes are realistic but well above the noise, chosen (within the simulator's
physical ranges) so that the residual of the wrong model stands out of the noise of the
weakest validation shot; time constants are short enough for the tails to die out before
the next shot, so that every window starts at rest and the bags stay small.

Regenerate the bags from the repository root with ``python test/hidden_cases.py``.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
import math
from pathlib import Path
import sys

ROOT = Path(__file__).resolve().parents[1]
BAGS = ROOT / 'bags'
ROLES = ('calib', 'valid')
#: -3 dB frequency of every case's anti-alias filter relative to the sample rate (a 4-pole
#: Bessel: flat group delay, little overshoot on a shock pulse).
ANTI_ALIAS = 0.1

#: Physical parameters checked against the truth, per effect (same names in the
#: simulator and in the fitted model).
CHECKED = {
    'nonlinear_sensitivity': ('beta_per_g',),
    'second_resonance': ('freq_khz', 'zeta', 'gain'),
    'amplifier_highpass': ('tau_ms',),
    'channel_delay': ('delay_us',),
    'strain_sensitivity': ('pa_per_g_per_ms',),
    'transverse_sensitivity': ('ratio', 'angle_deg'),
    'mains_hum': ('freq_hz', 'amplitude_pa'),
    'zero_shift': ('pa_per_g', 'tau_ms'),
}


@dataclass(frozen=True)
class Case:
    """
    One hidden-effect pair: the rig settings shared by its two runs.

    Args:
        name: Letter of the case (bags ``case_<name>_calib.mcap``, ``..._valid.mcap``).
        effects: Simulator effects, ``'ID:param=value,...'`` as ``--effect`` takes them.
        fs: Sample rate in Hz.
        shots: Random shots of the calibration and of the validation run.
        seeds: Seeds of the calibration and of the validation run.
        noise: Pressure noise in % of the largest induced peak.
        accel_noise: Accelerometer noise in % of the largest axial peak.
        peak_g: Range of the shots' peaks in g.
        width_ms: Range of the shots' pulse widths in ms.
        lateral: Largest lateral acceleration in % of the axial peak.
        post_ms: Quiet time after each shot in ms (the pre-trigger is 5 ms).

    """

    name: str
    effects: tuple[str, ...]
    fs: float
    shots: tuple[int, int]
    seeds: tuple[int, int]
    noise: float
    accel_noise: float
    peak_g: tuple[float, float]
    width_ms: tuple[float, float]
    lateral: float = 5.0
    post_ms: float = 15.0

    @property
    def effect_ids(self) -> tuple[str, ...]:
        """Return the ids of the hidden effects."""
        return tuple(spec.partition(':')[0] for spec in self.effects)

    def bag(self, role: str) -> str:
        """Return the file name of the ``'calib'`` or ``'valid'`` bag."""
        return f'case_{self.name}_{role}.mcap'

    def argv(self, role: str) -> list[str]:
        """Return the ``sensor-comp simulate`` options of one run (no output, not blind)."""
        index = ROLES.index(role)
        argv = ['--shots', str(self.shots[index]), '--seed', str(self.seeds[index]),
                '--fs', f'{self.fs:g}', '--noise', f'{self.noise:g}',
                '--accel-noise', f'{self.accel_noise:g}',
                '--peak-g', *(f'{g:g}' for g in self.peak_g),
                '--width-ms', *(f'{w:g}' for w in self.width_ms),
                '--lateral', f'{self.lateral:g}', '--pre-ms', '5',
                '--post-ms', f'{self.post_ms:g}',
                '--anti-alias-khz', f'{self.fs * ANTI_ALIAS / 1e3:g}']
        for spec in self.effects:
            argv += ['--effect', spec]
        return argv

    def truth(self) -> dict[str, dict[str, float]]:
        """Return the checked physical parameters of each effect: ``{id: {name: value}}``."""
        from sensor_comp.sim import parse_effect

        out = {}
        for spec in self.effects:
            effect = parse_effect(spec)
            values = {f.name: getattr(effect, f.name) for f in fields(effect)}
            out[effect.id] = {name: float(values[name]) for name in CHECKED[effect.id]}
        return out


#: The cases. Two runs each; 200 kS/s unless said otherwise.
CASES = (
    Case('a', ('zero_shift:pa_per_g=5,tau_ms=12',), fs=200e3, shots=(6, 4), seeds=(101, 102),
         noise=0.1, accel_noise=0.1, peak_g=(500, 1500), width_ms=(0.8, 2.0), post_ms=35),
    Case('b', ('mains_hum:freq_hz=60,amplitude_pa=2000',), fs=200e3, shots=(6, 4),
         seeds=(201, 202), noise=0.1, accel_noise=0.1, peak_g=(200, 800),
         width_ms=(1.0, 3.0)),
    Case('c', (), fs=200e3, shots=(6, 4), seeds=(301, 302), noise=0.5, accel_noise=0.1,
         peak_g=(300, 2500), width_ms=(0.9, 3.0)),
    Case('d', ('channel_delay:delay_us=40',), fs=1e6, shots=(3, 2), seeds=(401, 402),
         noise=0.1, accel_noise=0.05, peak_g=(800, 2500), width_ms=(0.5, 1.0), post_ms=12),
    Case('e', ('nonlinear_sensitivity:beta_per_g=-8e-5',
               'mains_hum:freq_hz=50,amplitude_pa=3000'), fs=200e3, shots=(6, 4),
         seeds=(501, 502), noise=0.15, accel_noise=0.1, peak_g=(800, 2500),
         width_ms=(0.8, 2.0)),
    Case('f', ('amplifier_highpass:tau_ms=8',), fs=200e3, shots=(6, 4), seeds=(601, 602),
         noise=0.3, accel_noise=0.1, peak_g=(1000, 3000), width_ms=(1.0, 2.5), post_ms=35),
    # The strain term is a derivative: the fit estimates it from differenced acceleration,
    # whose high-frequency noise biases it towards a lagging, smoothed jerk (errors in the
    # variables) and leaves the pulse corners unexplained. 0.005 % is a 16-bit digitiser on
    # a +-5000 g range; at 0.03 % the peak residual falls by 57 % rather than 76 %.
    Case('g', ('strain_sensitivity:pa_per_g_per_ms=3',), fs=200e3, shots=(6, 4),
         seeds=(701, 702), noise=0.15, accel_noise=0.005, peak_g=(800, 2400),
         width_ms=(0.8, 1.6)),
    Case('h', ('second_resonance:freq_khz=20,zeta=0.015,gain=0.4',), fs=1e6, shots=(3, 2),
         seeds=(801, 802), noise=0.2, accel_noise=0.1, peak_g=(1000, 3000),
         width_ms=(0.4, 0.8), post_ms=12),
    Case('i', ('nonlinear_sensitivity:beta_per_g=-1e-4',), fs=200e3, shots=(6, 4),
         seeds=(901, 902), noise=0.4, accel_noise=0.1, peak_g=(600, 2400),
         width_ms=(0.8, 2.0)),
    Case('j', ('transverse_sensitivity:ratio=0.12,angle_deg=40',), fs=200e3, shots=(6, 4),
         seeds=(1001, 1002), noise=0.1, accel_noise=0.1, peak_g=(800, 2500),
         width_ms=(0.8, 2.0), lateral=30),
)


def main(argv: list[str] | None = None) -> int:
    """
    Write the bags of every case (or of the cases named in ``argv``) into ``bags/``.

    Returns:
        0 on success, else the first failing ``sensor-comp`` exit code.

    """
    sys.path.insert(0, str(ROOT))
    from sensor_comp.cli.main import main as sensor_comp

    names = set(sys.argv[1:] if argv is None else argv)
    total = 0
    for case in CASES:
        if names and case.name not in names:
            continue
        for role in ROLES:
            path = BAGS / case.bag(role)
            code = sensor_comp(['--quiet', 'simulate', '-o', str(path), '--blind',
                                *case.argv(role)])
            if code:
                return code
            size = path.stat().st_size
            total += size
            print(f'{path.name}: {size / 1e6:.2f} MB')
    everything = math.fsum(p.stat().st_size for p in BAGS.iterdir())
    print(f'written: {total / 1e6:.2f} MB; {BAGS}: {everything / 1e6:.2f} MB')
    return 0


if __name__ == '__main__':
    sys.exit(main())
