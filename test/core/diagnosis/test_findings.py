"""The verdicts a diagnosis can return, each with its next step and documentation."""

from pathlib import Path

from sensor_comp.core.diagnosis import verdict
from sensor_comp.core.diagnosis.findings import ATTENTION, NEXT_STEP, VERDICTS

DOC = Path(__file__).resolve().parents[3] / 'doc' / 'diagnosis.md'


def test_every_verdict_has_a_next_step_and_an_attention_flag():
    assert set(NEXT_STEP) == set(VERDICTS) == set(ATTENTION)
    assert set(VERDICTS) == {'missing_effect', 'ambiguous', 'partly_explained', 'adequate',
                             'unexplained'}
    assert [v for v in VERDICTS if not ATTENTION[v]] == ['adequate']


def test_every_verdict_is_documented():
    assert all(f'``{v}``' in verdict.__doc__ for v in VERDICTS)
    verdicts = DOC.read_text(encoding='utf-8').split('## Verdicts', 1)[1]
    assert all(f"- `'{v}'`: " in verdicts for v in VERDICTS)
