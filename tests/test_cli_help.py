"""`ridgeloc --help` and every command's `--help` print their usage and exit 0."""

import pytest

from pipeline.cli import COMMANDS, main


def test_top_level_help_lists_every_command(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for name in COMMANDS:
        assert name in out
    assert "95 % ellipse" in out  # a literal percent sign in a command's HELP survives argparse's formatting


@pytest.mark.parametrize("name", COMMANDS)
def test_command_help(name, capsys):
    with pytest.raises(SystemExit) as exc:
        main([name, "--help"])
    assert exc.value.code == 0
    assert f"usage: ridgeloc {name}" in capsys.readouterr().out


def test_no_command_prints_help_and_exits_2(capsys):
    assert main([]) == 2
    assert "COMMAND" in capsys.readouterr().out


def test_output_into_a_closed_pipe_stops_without_a_traceback():
    """`ridgeloc inspect LOG | head -1`: the reader closes the pipe before ridgeloc has printed; ridgeloc stops
    quietly with 141 (as Unix tools do), not with a BrokenPipeError traceback."""
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    p = subprocess.Popen([sys.executable, "-m", "pipeline", "inspect", "configs/flights/group1.yaml"], cwd=root,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    p.stdout.close()  # before the child prints (it is still importing)
    err = p.stderr.read().decode()
    assert p.wait(timeout=120) == 141 and err == ""


def test_output_piped_into_a_reader_that_stops_early_ends_quietly():
    """`ridgeloc locate ... --json | head` closes the pipe after a few lines: no traceback, the SIGPIPE status.
    A command printing more than a pipe holds stands in for a long output."""
    import subprocess
    import sys

    code = ("import sys\n"
            "from pipeline import cli\n"
            "import types\n"
            "def main_(args):\n"
            "    for i in range(100000):\n"
            "        print('line', i)\n"
            "    return 0\n"
            "mod = types.SimpleNamespace(HELP='h', add_arguments=lambda p: None, main=main_)\n"
            "cli._load_commands = lambda: {'inspect': mod}\n"
            "raise SystemExit(cli.main(['inspect']))\n")
    p = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    p.stdout.readline()
    p.stdout.close()  # the reader goes away, as `head -1` does
    err = p.stderr.read().decode()
    assert p.wait(timeout=60) == 141
    assert "Traceback" not in err and "BrokenPipeError" not in err, err


def test_solve_given_a_flight_config_says_what_it_takes(capsys):
    from pathlib import Path

    config = Path(__file__).resolve().parents[1] / "configs" / "flights" / "group1.yaml"
    assert main(["solve", str(config)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "a YAML config, not an observations JSON file: `ridgeloc run` takes flight" in err
