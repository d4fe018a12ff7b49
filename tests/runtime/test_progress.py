import io

from rrbc_core.runtime.progress import ProgressBar


class _Tty(io.StringIO):
    def isatty(self):
        return True


def test_silent_for_short_runs_and_off_a_terminal():
    out = _Tty()
    bar = ProgressBar(10, "work", stream=out, delay_s=60.0)
    bar.update(5)
    bar.close()
    assert out.getvalue() == ""  # shorter than the delay: nothing
    plain = io.StringIO()
    bar = ProgressBar(10, "work", stream=plain, delay_s=0.0)
    bar.update(5)
    bar.close()
    assert plain.getvalue() == ""  # not a terminal: nothing


def test_draws_on_a_terminal_after_the_delay():
    out = _Tty()
    bar = ProgressBar(4, "simulating", stream=out, delay_s=0.0)
    bar.update(2)
    bar.update(2, "done")
    bar.close()
    text = out.getvalue()
    assert "50.0 %" in text and "100.0 %" in text and text.endswith("\n")
