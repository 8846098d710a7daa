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
