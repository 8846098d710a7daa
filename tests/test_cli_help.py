"""`ridgeloc --help` lists every command (a help text with a literal % once made argparse raise)."""

import pytest

from pipeline.cli import main


def test_top_level_help_lists_the_commands(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "overlay" in out and "95 % ellipse" in out
