"""The panels of the jog UI: the components table, the plots, the status line and the log."""

from __future__ import annotations

import math
import time

from rich.text import Text
from textual.app import ComposeResult
from textual.containers import Vertical
from textual.widgets import DataTable, Label, RichLog, Sparkline, Static

from .controls import LogEntry
from .session import JogRow, JogSession

__all__ = ["ComponentTable", "EventLog", "PlotPanel", "StatusLine", "format_values"]

COLUMNS = (  # key, label, width (None: the widest cell at start)
    ("plot", "plot", 4),
    ("name", "component", None),
    ("kind", "kind", 8),
    ("state", "state", 12),
    ("value", "value", 22),
    ("target", "target", 9),
    ("limits", "limits", None),
)
STATE_STYLES = {
    "Active": "green",
    "Inactive": "yellow",
    "Error": "bold red",
    "Initialized": "yellow",
    "Initializing": "yellow",
    "Finalized": "dim",
}
LEVEL_STYLES = {"info": "", "warning": "yellow", "error": "bold red"}


def _number(value: float) -> str:
    return f"{value:+.4f}" if math.isfinite(value) else str(value)


def format_values(row: JogRow) -> str:
    """The row's last values (with its units), ``-`` before the first read."""
    if not row.values:
        return "-"
    text = "  ".join(_number(v) for v in row.values)
    return f"{text} {row.units}" if row.units else text


def _limits(row: JogRow) -> str:
    limits = row.limits
    if limits is None:
        return ""
    return f"[{limits[0]:g}, {limits[1]:g}]"


class ComponentTable(DataTable[Text | str]):
    """Every component, one a row (the cursor row is the selected one)."""

    def setup(self, jogger: JogSession) -> None:
        self.cursor_type = "row"
        self.zebra_stripes = True
        for key, label, width in COLUMNS:
            self.add_column(label, key=key, width=width)
        self._shown: dict[str, list[Text | str]] = {}
        for row in jogger.rows:
            cells = self._cells(row)
            self.add_row(*cells, key=row.name)
            self._shown[row.name] = cells
        self.move_cursor(row=jogger.selected)

    def _cells(self, row: JogRow) -> list[Text | str]:
        return [
            "●" if row.plotted else "",
            row.name,
            row.kind,
            Text(row.state, style=STATE_STYLES.get(row.state, "")),
            format_values(row) if row.read_error is None else Text("read failed", style="red"),
            "" if row.target is None else _number(row.target),
            _limits(row),
        ]

    def show(self, jogger: JogSession) -> None:
        """Update the cells that changed (a redraw of the table costs)."""
        for row in jogger.rows:
            shown = self._shown[row.name]
            for i, ((key, _, _), cell) in enumerate(zip(COLUMNS, self._cells(row), strict=True)):
                if cell != shown[i]:
                    self.update_cell(row.name, key, cell)
                    shown[i] = cell


class PlotRow(Vertical):
    """One component's plot: its name and range, then a sparkline of its history."""

    def __init__(self, row: JogRow) -> None:
        super().__init__(classes="plot")
        self.row = row
        self._data: list[float] | None = None

    def compose(self) -> ComposeResult:
        yield Label(self.row.name, classes="plot-label")
        yield Sparkline([], summary_function=max)

    def show(self) -> None:
        data = list(self.row.history)
        if data == self._data:
            return
        self._data = data
        label = self.row.name
        if data:
            label += f"  {_number(data[-1])}  (min {_number(min(data))}, max {_number(max(data))})"
        self.query_one(Label).update(label)
        self.query_one(Sparkline).data = data


class PlotPanel(Vertical):
    """The plots of the components marked for plotting (``p`` toggles)."""

    async def show(self, jogger: JogSession) -> None:
        plots = {plot.row.name: plot for plot in self.query(PlotRow)}
        wanted = [row for row in jogger.rows if row.plotted]
        for name, plot in plots.items():
            if name not in {row.name for row in wanted}:
                await plot.remove()
        for row in wanted:
            found = plots.get(row.name)
            if found is None:
                found = PlotRow(row)
                await self.mount(found)
            found.show()


class StatusLine(Static):
    """The selected axis, the step and velocity, the e-stop."""

    shown: Text | None = None

    def show(self, jogger: JogSession) -> None:
        row = jogger.row
        text = Text()
        text.append(f" {row.name} ", style="bold reverse")
        if jogger.jogs(row):
            text.append(f"  step {jogger.step:g}  velocity {jogger.velocity:g}/s")
        else:
            text.append("  (not an axis: nothing to jog)", style="dim")
        text.append(f"  completed {jogger.completed}", style="dim")
        if jogger.estopped:
            text.append("   E-STOP (r releases)", style="bold white on red")
        if text != self.shown:
            self.shown = text
            self.update(text)


class EventLog(RichLog):
    """Events, errors and state changes, newest last."""

    def add(self, entry: LogEntry) -> None:
        stamp = time.strftime("%H:%M:%S", time.localtime(entry.time))
        line = Text(f"{stamp} ", style="dim")
        line.append(entry.text, style=LEVEL_STYLES.get(entry.level, ""))
        self.write(line)
