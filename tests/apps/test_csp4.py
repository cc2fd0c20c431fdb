"""The csp4 app in process: four simulated CiA 402 drives in CSP on SYNC from the AxisGroup's
timer (rigs/csp4.yaml with --sim), each move reached, a result line per move."""

from __future__ import annotations

import re

import pytest

from openel_async.app import find_app, run_app

LINE = re.compile(
    r"move (\d): \[.+\] rad reached in [\d.]+ s, max error ([\d.]+) rad, SYNC cycles (\d+)"
)


def test_csp4_moves_four_simulated_drives_in_csp(capsys: pytest.CaptureFixture[str]) -> None:
    status = run_app(find_app("csp4"), ["--moves", "2"], prog="csp4", sim=True)
    out = capsys.readouterr().out
    assert status == 0, out
    assert "4 axes in CSP, SYNC every 1.5 ms" in out
    moves = LINE.findall(out)
    assert [m[0] for m in moves] == ["1", "2"], out
    assert all(float(m[1]) <= 2e-3 for m in moves)
    assert 0 < int(moves[0][2]) < int(moves[1][2])
    assert "summary (CSP, four axes): all moves reached" in out
    assert "hold: AXIS_1 done" in out


def test_csp4_refuses_a_bad_move_count(capsys: pytest.CaptureFixture[str]) -> None:
    assert run_app(find_app("csp4"), ["--moves", "9"], prog="csp4", sim=True) == 2
    assert "--moves 9" in capsys.readouterr().err
