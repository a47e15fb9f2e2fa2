"""The slow state a recording's first window starts from: which models have one, and where."""

import numpy as np

from sensor_comp.core.compensation.initial_state import first_windows, rest_start_note
from sensor_comp.core.shots.windows import Window


def test_only_models_with_a_slow_state_get_a_note_naming_it():
    assert rest_start_note(['a_z', 'a_x', 'da_z', 'a_z_abs_a_z', 'a_z@delay_us=3']) is None
    zero_shift = rest_start_note(['a_z', 'peak_a_z(tau_ms=80)'])
    assert 'zero shift' in zero_shift and 'high-pass' not in zero_shift
    both = rest_start_note(['a_z@highpass_ms=50', 'peak_a_z(tau_ms=80)@highpass_ms=50'])
    assert 'zero shift' in both and 'high-pass charge' in both and 'first shot' in both


def test_the_first_window_of_each_recording_is_its_earliest_whatever_the_order():
    def window(start, source):
        return Window(np.zeros((3, 4)), np.zeros(4), start, 2, source)
    windows = [window(500, 0), window(100, 1), window(200, 0), window(50, 1), window(900, 2)]
    assert first_windows(windows) == {0: 2, 1: 3, 2: 4}
