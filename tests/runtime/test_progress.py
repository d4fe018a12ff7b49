"""The command line's progress bars (tqdm, issue 26): on stderr, silent off a terminal, so `--json` on stdout and a
piped stderr stay clean."""

import io

from rrbc_core.cli import advance, main, progress_bar
from tests.paths import DEMO


class _Tty(io.StringIO):
    def isatty(self):
        return True


def test_a_command_off_a_terminal_prints_no_bar(capsys):
    assert main(["plan", str(DEMO), "--add", "1", "--json"]) == 0
    out, err = capsys.readouterr()
    assert out.startswith("{") and err == ""


def test_the_bar_is_tqdm_on_stderr_silent_for_a_second_and_off_a_terminal(monkeypatch):
    tty = _Tty()
    monkeypatch.setattr("sys.stderr", tty)
    bar = progress_bar(4, "simulating")
    assert bar.delay == 1.0 and bar.fp is not None and not bar.disable  # a terminal: enabled, after a second
    advance(bar, 2, "half")
    assert bar.n == 2 and bar.desc == "half"
    bar.close()
    monkeypatch.setattr("sys.stderr", io.StringIO())
    assert progress_bar(4, "x").disable  # not a terminal: off
