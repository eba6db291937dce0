"""Evidence reads right: the topic printed with a payload is the topic that payload came on."""

from __future__ import annotations

import pytest
from certify_helpers import FAST, UNIT, certify_virtual

pytestmark = pytest.mark.slow


def test_an_answer_shown_for_missing_feedback_is_labelled_with_the_response_topic(
        pytester: pytest.Pytester) -> None:
    # pause-ignored: $pause is answered 'ok' but no 'paused' feedback follows; the evidence
    # shows the answer, so its topic is exec/response, not exec/feedback.
    run = certify_virtual(pytester, UNIT, f"--profile={FAST}", "-k", "EXEC-SIG-003",
                          faults=("pause-ignored",), rate=3.0)
    assert run.failed == {"EXEC-SIG-003"}, run.text[-3000:]
    (v,) = [v for v in run.unit_rules()["EXEC-SIG-003"]["violations"]
            if v["expected"] == "feedback 'paused' after $pause"]  # the scenario's finding
    assert '"response":' in v["excerpt"], v
    assert v["topic"] == f"{UNIT}/exec/response", v
