"""The console script: one package, a thin module per subcommand, the option names they share."""

from __future__ import annotations

import subprocess
import sys

import pytest

from conformance.cli import COMMANDS, main
from conformance.cli import lint as lint_cli
from conformance.cli import record as record_cli
from conformance.cli import sim as sim_cli
from conformance.cli.options import capture_options, parse_duration


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_every_subcommand_has_help(command: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_:
        main([command, "--help"])
    assert exit_.value.code == 0
    assert f"usage: waraps-conformance {command}" in capsys.readouterr().out


def test_the_overview_lists_every_command_and_loads_nothing_heavy() -> None:
    code = ("import sys; from conformance.cli import main; main(['--help']); "
            "heavy = ('paho', 'amqtt', 'jsonschema_rs', 'conformance.schema', 'yaml'); "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in heavy "
            "or m in heavy))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert all(f"  {name}" in out for name in COMMANDS)
    assert out.strip().splitlines()[-1] == "[]"


def test_an_unknown_command_says_which_it_meant(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["lnit"]) == 2
    assert "Did you mean 'lint'?" in capsys.readouterr().err


@pytest.mark.parametrize("cli", [lint_cli, record_cli, sim_cli])
def test_tls_options_are_spelled_as_the_plugin_spells_them(
        cli: object, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        cli.build_parser().parse_args(["--help"])  # type: ignore[attr-defined]
    text = capsys.readouterr().out
    for option in ("--ca-file PEM", "--cert-file PEM", "--key-file PEM", "--tls-insecure"):
        assert option in text
    assert "--insecure " not in text  # the deprecated alias is hidden


@pytest.mark.parametrize("cli", [lint_cli, record_cli])
@pytest.mark.parametrize(("flag", "insecure", "warned"), [
    ("--tls-insecure", True, False), ("--insecure", True, True), (None, False, False)])
def test_tls_insecure_and_its_deprecated_alias(
        cli: object, flag: str | None, insecure: bool, warned: bool,
        capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["--broker", "mqtts://broker.example:8883", "--ca-file", "ca.pem", "-o", "x.jsonl"]
    if cli is lint_cli:
        argv = argv[:-2]
    args = cli.build_parser().parse_args(argv + ([flag] if flag else []))  # type: ignore[attr-defined]
    broker = capture_options(args).broker
    assert broker is not None and broker.insecure is insecure and broker.ca_file == "ca.pem"
    err = capsys.readouterr().err
    assert ("--insecure is deprecated, use --tls-insecure" in err) is warned


def test_lint_refuses_a_recording_and_a_broker_together(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["lint", "--from", "x.jsonl", "--broker", "mqtt://127.0.0.1:1"]) == 2
    assert "--from and --broker exclude each other" in capsys.readouterr().err


def test_sim_lists_its_faults(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "--list-faults"]) == 0
    assert "pong-missing" in capsys.readouterr().out


def test_sim_refuses_a_fault_it_does_not_have(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_:
        main(["sim", "--broker", "mqtt://127.0.0.1:1", "--fault", "no-such-fault"])
    assert exit_.value.code == 2
    assert "no-such-fault" in capsys.readouterr().err


@pytest.mark.parametrize(("text", "seconds"), [
    ("600", 600.0), ("90s", 90.0), ("10m", 600.0), ("10min", 600.0), ("1h30m", 5400.0),
    ("1.5h", 5400.0), ("250ms", 0.25), (" 2 m ", 120.0)])
def test_one_duration_syntax_for_every_option(text: str, seconds: float) -> None:
    assert parse_duration(text) == pytest.approx(seconds)


@pytest.mark.parametrize("text", ["", "0", "-5s", "10 parsecs", "m", "1h-30m"])
def test_a_bad_duration_says_what_is_accepted(text: str) -> None:
    with pytest.raises(ValueError, match="not a positive time like 90s, 10m, 1h30m"):
        parse_duration(text)


def test_lint_reads_the_duration_as_the_plugin_does(capsys: pytest.CaptureFixture[str]) -> None:
    args = lint_cli.build_parser().parse_args(["--broker", "mqtt://127.0.0.1:1",
                                               "--duration", "10min"])
    assert capture_options(args).duration == 600.0
    assert main(["lint", "--broker", "mqtt://127.0.0.1:1", "--duration", "soon"]) == 2
    assert "duration 'soon' is not a positive time" in capsys.readouterr().err
