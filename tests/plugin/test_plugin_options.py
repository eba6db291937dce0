"""Options, ini twins, usage errors, the header: what a person types and reads first."""

from __future__ import annotations

from pathlib import Path

import pytest
from certify_helpers import FAST, UNIT, PrivateMosquitto, certify

from conformance.broker import free_port
from conformance.plugin import NOT_CERTIFIED_EXIT


def test_without_unit_the_plugin_changes_nothing(pytester: pytest.Pytester) -> None:
    pytester.makepyfile(test_plain="def test_ok():\n    assert True\n")
    result = pytester.runpytest_inprocess("-p", "no:cacheprovider")
    result.assert_outcomes(passed=1)
    assert "certifying" not in result.stdout.str()
    assert "== waraps-conformance ==" not in result.stdout.str()  # no summary section
    assert not (pytester.path / "reports").exists()


def test_importing_the_plugin_is_cheap() -> None:
    import subprocess
    import sys

    code = ("import sys, conformance.plugin; heavy = {'paho', 'amqtt', 'jsonschema_rs', "
            "'hypothesis_jsonschema', 'conformance.checks', 'conformance.sim'}; "
            "print(sorted(m for m in heavy if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "[]"


@pytest.mark.parametrize(("args", "message"), [
    (["--unit", "waraps/unit/uav/simulation/dji0"], "agent type 'uav' is not one of"),
    (["--unit", "dji0"], "expected PREFIX1/unit/TYPE/ROLE/UNIT"),
    (["--profile", "strickt"], "did you mean strict"),
    (["--timing-scale", "0"], "a positive number is needed"),
    (["--broker", "http://x:1"], "scheme 'http' is not one of mqtt, mqtts, embedded"),
    (["--broker", "mqtt://user:secret@127.0.0.1:1883"], "put it in WARAPS_PASSWORD"),
    (["--sim-fault", "pong-mising"], "did you mean pong-missing"),
    (["--broker", "mqtt://127.0.0.1:1883", "--sim-fault", "pong-missing"],
     "runs only with --broker embedded"),
    (["--sim-variant", "strikt"], "did you mean strict"),
    (["--sim-variant", "terse", "--sim-variant", "verbose"], "cannot be combined"),
    (["--broker", "mqtt://127.0.0.1:1883", "--sim-variant", "strict"],
     "runs only with --broker embedded"),
    (["--sim-variant", "mqtt5-qos1"], "the embedded amqtt broker refuses MQTT 5"),
    (["--broker", "mqtt://127.0.0.1:1883", "--ca-file", "/no/such.pem"], "no such file"),
    (["--broker", "mqtt://127.0.0.1:1883", "--tls-insecure"], "need an mqtts:// broker"),
    (["--seed", "abc"], "a whole number is needed"),
    (["-n", "2"], "leave out -n/--dist"),
])
def test_a_bad_value_is_a_usage_error_that_says_how_to_fix_it(
        pytester: pytest.Pytester, args: list[str], message: str) -> None:
    full = ["--broker", "embedded", *args] if "--broker" not in args else list(args)
    if "--unit" not in full:
        full = ["--unit", UNIT, *full]
    result = pytester.runpytest_inprocess("-p", "no:cacheprovider", *full)
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    assert message in "\n".join(result.errlines + result.outlines)
    assert "secret" not in "\n".join(result.errlines + result.outlines)


def test_no_broker_anywhere_is_a_usage_error(pytester: pytest.Pytester,
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("WARAPS_BROKER", raising=False)
    result = pytester.runpytest_inprocess("-p", "no:cacheprovider", "--unit", UNIT)
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    assert "no broker: pass --broker" in "\n".join(result.errlines)


def test_ini_twins_and_the_header(pytester: pytest.Pytester) -> None:
    """Every option but --unit has an ini twin; the header says what is certified, how, and
    the seed that repeats the run."""
    pytester.makeini(f"""
        [pytest]
        waraps_broker = embedded
        waraps_profile = {FAST}
        waraps_timing_scale = 2
        waraps_reports_dir = elsewhere
    """)
    run = certify(pytester, "--unit", UNIT, "--sim-rate", "2", "--seed", "42", "-k",
                  "EXEC-PING-001")
    assert run.result.ret == 0, run.text
    text = run.text
    assert "certifying waraps/unit/air/simulation/dji0" in text
    assert "embedded mqtt://127.0.0.1:" in text and "with the bundled reference unit" in text
    assert "profile:  fast-selftest" in text and "timing scale 2" in text
    assert "levels: sensor, direct execution" in text
    assert "Using --seed=42" in text and "--timing-scale 2" in text
    # --reports-dir given on the command line wins over the ini file.
    assert run.report is not None


def test_reports_dir_from_the_ini_file(pytester: pytest.Pytester) -> None:
    pytester.makeini("""
        [pytest]
        waraps_reports_dir = elsewhere
    """)
    result = pytester.runpytest_inprocess("-p", "no:cacheprovider", "--unit", UNIT, "--broker",
                                          "embedded", "--sim-rate", "3", f"--profile={FAST}",
                                          "-k", "EXEC-PING-001")
    assert result.ret == 0
    assert len(list((pytester.path / "elsewhere").glob("dji0-*.json"))) == 1


def test_password_from_the_environment_never_shows(pytester: pytest.Pytester,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("WARAPS_USERNAME", "certifier")
    monkeypatch.setenv("WARAPS_PASSWORD", "hunter2-secret")
    port = free_port()  # nothing listens there
    run = certify(pytester, "--unit", UNIT, "--broker", f"mqtt://127.0.0.1:{port}")
    assert run.result.ret == NOT_CERTIFIED_EXIT  # the broker cannot be reached
    assert f"cannot reach the broker at mqtt://certifier@127.0.0.1:{port}" in run.text
    assert "hunter2" not in run.text
    assert run.report is not None and "hunter2" not in str(run.report)


def test_dry_run_publishes_nothing_and_prints_what_it_would(pytester: pytest.Pytester) -> None:
    run = certify(pytester, "--unit", UNIT, "--broker", "embedded", "--sim-rate", "2",
                  f"--profile={FAST}", "--dry-run", "-k", "test_ping or test_start_task")
    assert run.result.ret == 0, run.text
    assert "DRY RUN: nothing is published" in run.text
    assert "dry run: would publish to waraps/unit/air/simulation/dji0/exec/command: " in run.text
    assert '"command":"ping"' in run.text and '"command":"start-task"' in run.text
    assert set(run.outcomes.values()) == {"skipped"}
    rules = run.unit_rules()
    assert rules["EXEC-PING-001"]["verdict"] == "could-not-test"
    assert rules["EXEC-PING-001"]["reason"].startswith("dry run: would publish")
    assert run.report["meta"]["commands_sent"] == "0"


def test_the_arena_environment_variables_name_the_broker(pytester: pytest.Pytester,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    port = free_port()  # nothing listens there: the error names where it looked
    monkeypatch.setenv("WARAPS_BROKER", "127.0.0.1")
    monkeypatch.setenv("WARAPS_PORT", str(port))
    monkeypatch.setenv("WARAPS_TLS_CONNECTION", "false")
    run = certify(pytester, "--unit", UNIT)
    assert run.result.ret == NOT_CERTIFIED_EXIT
    assert f"cannot reach the broker at mqtt://127.0.0.1:{port}" in run.text


def test_a_refused_login_says_why_once_and_no_link_was_lost(
        pytester: pytest.Pytester, monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("WARAPS_USERNAME", "alice")
    monkeypatch.setenv("WARAPS_PASSWORD", "wrong-secret")
    broker = PrivateMosquitto(tmp_path, users={"alice": "right"}).start()
    try:
        run = certify(pytester, "--unit", UNIT, "--broker", broker.url)
    finally:
        broker.stop()
    assert run.result.ret == NOT_CERTIFIED_EXIT
    assert run.text.count("did not accept the connection: Not authorized") == 1
    assert "connection lost" not in run.text  # it was never connected
    assert "wrong-secret" not in run.text
