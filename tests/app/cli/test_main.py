"""The `imucap` entry point: what any command does with a bad input or a Ctrl-C it does not handle."""

from __future__ import annotations

import signal

from app.cli import data as cli_data
from app.cli import main as cli_main


def test_a_ctrl_c_a_command_does_not_handle_ends_with_130_and_one_line(monkeypatch, capsys):
    def interrupted(args):  # noqa: ARG001 - a real SIGINT, through Python's own handler
        signal.raise_signal(signal.SIGINT)
        return 0

    monkeypatch.setattr(cli_data, "_cmd_inspect", interrupted)  # registered afresh by each main()
    assert cli_main.main(["data", "inspect", "x.bvh"]) == 130
    err = capsys.readouterr().err
    assert err.strip() == "imucap data: interrupted"


def test_a_bad_input_ends_with_2_and_one_line(monkeypatch, capsys):
    def bad(args):  # noqa: ARG001
        raise FileNotFoundError("x.bvh: no such file")

    monkeypatch.setattr(cli_data, "_cmd_inspect", bad)
    assert cli_main.main(["data", "inspect", "x.bvh"]) == 2
    assert capsys.readouterr().err.strip() == "imucap data: error: x.bvh: no such file"
