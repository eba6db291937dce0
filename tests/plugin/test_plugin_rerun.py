"""The "repeat this run" line (header, summary, each failure's rerun): it repeats every option
that changes what is tested or how, TLS files included, and never a password."""

from __future__ import annotations

import shlex
from pathlib import Path

import pytest

from conformance.suite.settings import Settings, read

UNIT = "waraps/unit/air/real/dji0"


def settings_of(pytester: pytest.Pytester, *args: str) -> Settings:
    """The settings the plugin reads from this command line (nothing connects)."""
    return read(pytester.parseconfig("-p", "no:cacheprovider", *args))


@pytest.fixture
def pem_files(tmp_path: Path) -> dict[str, str]:
    files = {}
    for name in ("ca file", "cert", "key"):  # a space: the line must quote paths
        path = tmp_path / f"{name}.pem"
        path.write_text("not read: no connection is made\n")
        files[name] = str(path)
    return files


def test_the_rerun_line_repeats_every_option_that_matters(
        pytester: pytest.Pytester, pem_files: dict[str, str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("WARAPS_USERNAME", "alice")
    monkeypatch.setenv("WARAPS_PASSWORD", "pw-secret-1")
    first = settings_of(
        pytester, "--unit", UNIT, "--broker", "mqtts://broker.example:8883",
        f"--ca-file={pem_files['ca file']}", f"--cert-file={pem_files['cert']}",
        f"--key-file={pem_files['key']}", "--tls-insecure", "--profile", "strict",
        "--timing-scale", "2.5", "--reboot-cmd", "ssh dji0 'sudo reboot'", "--allow-motion",
        "--dry-run", "--max-duration", "20m", "--seed", "42", "--observe", "30",
        "--tst-command-topic", "waraps/unit/ground/real/op0", "--rule", "HB-003")
    line = first.rerun_command()
    assert "pw-secret-1" not in line
    for expected in ("--broker mqtts://alice@broker.example:8883", "--tls-insecure",
                     f"--ca-file={shlex.quote(pem_files['ca file'])}",
                     f"--cert-file={shlex.quote(pem_files['cert'])}",
                     f"--key-file={shlex.quote(pem_files['key'])}",
                     "--reboot-cmd ", "--allow-motion", "--dry-run", "--max-duration 1200",
                     "--timing-scale 2.5", "--profile strict", "--seed 42", "--observe 30",
                     "--rule=HB-003"):
        assert expected in line, (expected, line)

    # Run as a shell would split it, the line gives the same run (and the same line again).
    words = shlex.split(line)
    assert words[0] == "pytest"
    again = settings_of(pytester, *words[1:])
    assert again.broker == first.broker  # the TLS files and --tls-insecure included
    assert again.broker.ca_file == pem_files["ca file"] and again.broker.insecure
    for field in ("unit", "timing_scale", "reboot_cmd", "allow_motion", "dry_run",
                  "max_duration", "seed", "observe", "rules", "tst_command_topic"):
        assert getattr(again, field) == getattr(first, field), field
    assert again.profile.name == "strict"
    assert again.rerun_command() == line


def test_a_rule_rerun_names_the_rule_and_keeps_the_tls_options(
        pytester: pytest.Pytester, pem_files: dict[str, str]) -> None:
    s = settings_of(pytester, "--unit", UNIT, "--broker", "mqtts://127.0.0.1:8883",
                    f"--ca-file={pem_files['ca file']}", "--seed", "7")
    line = s.rerun_command("HB-003", observe=12)
    assert line.endswith("--seed 7 --observe 12 -k HB-003")
    assert f"--ca-file={shlex.quote(pem_files['ca file'])}" in line
    assert "--tls-insecure" not in line and "--cert-file" not in line


def test_defaults_stay_off_the_line(pytester: pytest.Pytester) -> None:
    line = settings_of(pytester, "--unit", UNIT, "--broker", "embedded", "--seed", "3",
                       ).rerun_command()
    assert line == f"pytest --unit {UNIT} --broker embedded --seed 3"


def test_durations_read_as_the_subcommands_read_them(pytester: pytest.Pytester) -> None:
    s = settings_of(pytester, "--unit", UNIT, "--broker", "embedded", "--seed", "3",
                    "--max-duration", "1h30m", "--observe", "10min")
    assert (s.max_duration, s.observe) == (5400.0, 600.0)
    assert "--max-duration 5400 --seed 3 --observe 600" in s.rerun_command()


def test_a_selection_is_kept_shell_quoted(pytester: pytest.Pytester) -> None:
    """A run of selected rules is partial; its repeat line selects the same rules:
    -k and -m as typed, quoted for a shell; a rule's own rerun line names only the rule."""
    s = settings_of(pytester, "--unit", UNIT, "--broker", "embedded", "--seed", "3",
                    "-k", "HB-003 or EXEC-PING-001", "-m", "not slow", "--rule", "HB-012")
    line = s.rerun_command()
    assert line.endswith("--seed 3 --rule=HB-012 -k 'HB-003 or EXEC-PING-001' -m 'not slow'")
    words = shlex.split(line)
    again = settings_of(pytester, *words[1:])
    assert (again.keyword, again.markexpr, again.rules) == (s.keyword, s.markexpr, s.rules)
    assert again.rerun_command() == line
    assert s.rerun_command("HB-003").endswith("--seed 3 -k HB-003")


@pytest.mark.slow
def test_a_rule_only_exploration_found_reruns_by_replaying_its_story(
        pytester: pytest.Pytester) -> None:
    """A rule found by exploration printed `-k EXEC-SEQ-002`, which sends no
    such order of commands and passed on the unit that still had the fault. Its rerun line
    replays the story, and fails again against the same fault. (The other kinds of rerun line,
    `-k RULE` with or without --observe and the whole run's, run again in
    test_plugin_faults.py's RERUN.)"""
    import re

    from certify_helpers import FAST, certify

    embedded = ("--unit", "waraps/unit/air/simulation/dji0", "--broker", "embedded",
                "--sim-rate", "3", f"--profile={FAST}", "--sim-fault=pause-pauses-all")
    rule = "EXEC-SEQ-002"
    run = certify(pytester, *embedded, "--explore=60s", "--seed", "1",
                  "-k", f"test_explore or {rule}")
    assert run.result.ret == 1 and run.outcomes.get(rule) == "failed", run.text
    # The rule's own test's failure (not the story test_explore tells, whose lines replay).
    section = re.search(rf"^_+ [^\n]*\[{re.escape(rule)}\] _+$(.*?)(?=^_+ |^=+ )", run.text,
                        re.M | re.S)
    assert section, run.text
    found = re.search(r"^\s*rerun\s+(pytest .*)$", section.group(1), re.M)
    assert found, section.group(1)
    line = found.group(1)
    assert "--explore-replay=" in line and f"-k {rule}" not in line, line
    again = certify(pytester, *shlex.split(line)[1:])
    assert again.result.ret == 1, again.text
    assert "disagree again" in again.text and rule in again.text
    # The replay's exit status, verdict and report agree: the rule it judged
    # failed, not 'not run: not selected (-k test_explore)'.
    assert again.report is not None
    assert (again.report["verdict"], again.report["conclusion"]["exit_code"]) == ("fail", 1)
    assert again.unit_rules()[rule]["verdict"] == "fail"
