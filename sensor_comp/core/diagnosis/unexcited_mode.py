"""
A base mode the calibration shots do not excite but the validation shots do.

Shots too long or too soft for the sensor's mode leave it to the accelerometer noise: least
squares then damp or move it, with nothing in the calibration data to say otherwise. A
harder validation shot rings the real mode, and the base's misfit there is structure no
catalogued effect explains. The diagnosis says so rather than leave a bare
``unexplained`` (a clean 502 kS/s rig: a 39.1 kHz, ζ 0.082 sensor read 38.3 kHz, ζ 0.126 from
shots whose signal there was 0.18 times the accelerometer noise; a 2023 g validation shot,
at 2.2 times, left a residual peak of 10 σ).
"""

from __future__ import annotations

from collections.abc import Sequence

from ..identification.identify import excitation, MIN_EXCITATION
from ..identification.shot_sources import ShotSource
from ..identification.model import Model, ModelError

__all__ = ['unexcited_mode']


def unexcited_mode(model: Model, calibration: Sequence[ShotSource],
                   validation: Sequence[ShotSource]) -> str | None:
    """
    Return a clause saying the calibration shots leave the model's mode unmeasured, or None.

    Args:
        model: The base model (its most resonant pole pair is the sensor's mode).
        calibration: The shots it was fitted on.
        validation: The shots its residual is judged on.

    Returns:
        The clause (starting ``'; '``) when the calibration's signal at the mode is below
        :data:`~sensor_comp.core.identification.identify.MIN_EXCITATION` times the
        accelerometer noise and the validation's is not; None otherwise, without a mode or
        without a pre-trigger to measure the noise on.

    """
    try:
        fn = model.continuous().natural_frequency_hz
    except ModelError:
        return None
    if fn is None:
        return None
    calibrated, validated = excitation(calibration, fn), excitation(validation, fn)
    if calibrated is None or validated is None:
        return None
    if not (calibrated < MIN_EXCITATION <= validated):
        return None
    return (f'; the calibration shots do not excite the base\'s mode at {fn / 1e3:.3g} kHz '
            f'(their signal there is {max(calibrated, 0.0):.2g} times the accelerometer '
            f'noise power), the validation shots do ({validated:.2g} times): its frequency '
            f'and damping come from the noise, not from the sensor, and the structure may be '
            f'its misfit; calibrate on shots that reach it (shorter, harder ones)')
