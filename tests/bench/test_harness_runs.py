"""docs/benchmarks.md keeps two runs of each benchmark: a new run records the one it replaces."""

from __future__ import annotations

from pathlib import Path

from benchmarks.harness import PREVIOUS_RUN, BenchResult, Row, write_document


def result(ratios: dict[str, float], *, quick: bool = False) -> BenchResult:
    rows = tuple(
        Row(metric=m, value=r, ratio=r, ratio_label="ours/peer", target="<= 1x", passed=r <= 1)
        for m, r in ratios.items()
    )
    rows += (Row(metric="informational", value=3.0),)
    return BenchResult(name="demo", title="a demo", rows=rows, quick=quick)


def test_two_runs_in_a_row_leave_both_with_the_rows_met_in_both(tmp_path: Path) -> None:
    doc = tmp_path / "benchmarks.md"
    write_document([result({"a | pipe": 0.5, "b": 1.5, "c": 0.9})], doc)
    assert PREVIOUS_RUN not in doc.read_text()  # nothing to carry yet
    write_document([result({"a | pipe": 0.6, "b": 0.8, "c": 1.1})], doc)
    text = doc.read_text()
    assert text.count(PREVIOUS_RUN) == 1
    carried = text.split(PREVIOUS_RUN, 1)[1]
    assert "| a \\| pipe | 0.5 | 0.50x ours/peer | **PASS** |" in carried
    assert "| b | 1.5 | 1.50x ours/peer | **FAIL** |" in carried
    assert "informational" not in carried
    assert "Targets met in both runs: 1 of 3. Missed in one run or both: b; c." in carried
    # A third run carries the second, not the first: exactly one previous run is kept.
    write_document([result({"a | pipe": 0.7, "b": 0.9, "c": 0.95})], doc)
    text = doc.read_text()
    assert text.count(PREVIOUS_RUN) == 1
    carried = text.split(PREVIOUS_RUN, 1)[1]
    assert "| b | 0.8 | 0.80x ours/peer | **PASS** |" in carried
    assert "Targets met in both runs: 2 of 3. Missed in one run or both: c." in carried


def test_quick_runs_are_neither_carried_nor_carry(tmp_path: Path) -> None:
    doc = tmp_path / "benchmarks.md"
    write_document([result({"a": 0.5})], doc)
    write_document([result({"a": 0.5}, quick=True)], doc)
    assert PREVIOUS_RUN not in doc.read_text()
    write_document([result({"a": 0.5})], doc)
    assert PREVIOUS_RUN not in doc.read_text()
