"""The Textual app of ``openel-async jog``: :class:`JogApp` over a jog session (a
:class:`~.jogger.Jogger`, or a driver's remote one: :class:`~.session.JogSession`).

Keys: up/down (k/j) select a component; left/right (h/l) jog the selected axis by one step; ``[`` /
``]`` the step, ``-`` / ``+`` the velocity; space stops the jogs; ``e`` enables (re-initializes
a faulted component, or holds the axis where it is) and ``d`` disables (torque off); ``x`` is
the rig's e-stop, ``r`` releases it and re-initializes; ``p`` plots the selected component or
not; ``q`` quits, Ctrl-C quits with exit status 130. Device calls that wait (enable, disable,
stop, e-stop, release) run as workers, so the UI and the e-stop key stay live meanwhile.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import ClassVar

import anyio
from textual.app import App, ComposeResult
from textual.binding import Binding, BindingType
from textual.css.query import NoMatches
from textual.widgets import DataTable, Footer, Header

from .controls import LogEntry
from .session import JogSession
from .widgets import ComponentTable, EventLog, PlotPanel, StatusLine

__all__ = ["EXIT_INTERRUPTED", "REFRESH_S", "JogApp"]

REFRESH_S = 0.25
"""How often the values are read and the screen refreshed."""
EXIT_INTERRUPTED = 130
"""The app's return code when Ctrl-C ends it (as a SIGINT would)."""


class JogApp(App[None]):
    """The jog UI of a rig (see the module docstring)."""

    TITLE = "openel-async jog"
    CSS = """
    ComponentTable { height: auto; max-height: 45%; }
    StatusLine { height: 1; width: 100%; background: $boost; }
    PlotPanel { height: auto; max-height: 50%; }
    .plot { height: 2; }
    .plot-label { height: 1; width: 100%; color: $text-muted; }
    Sparkline { height: 1; width: 100%; }
    EventLog { height: 1fr; min-height: 4; border-top: solid $primary; }
    """
    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("up,k", "select(-1)", "select", show=False, priority=True),
        Binding("down,j", "select(1)", "select", show=False, priority=True),
        Binding("x", "estop", "E-STOP", priority=True),
        Binding("left,h", "jog(-1)", "jog -", priority=True),
        Binding("right,l", "jog(1)", "jog +", priority=True),
        Binding("left_square_bracket", "step(-1)", "step -"),
        Binding("right_square_bracket", "step(1)", "step +"),
        Binding("minus", "velocity(-1)", "vel -"),
        Binding("plus,equals_sign", "velocity(1)", "vel +"),
        Binding("space", "stop", "stop"),
        Binding("e", "enable", "enable"),
        Binding("d", "disable", "disable"),
        Binding("r", "release", "release"),
        Binding("p", "plot", "plot"),
        Binding("q", "quit_jog", "quit"),
        Binding("ctrl+c", "interrupt", "quit (130)", show=False, priority=True),
    ]

    def __init__(self, jogger: JogSession, *, refresh_s: float = REFRESH_S) -> None:
        super().__init__()
        self.jogger = jogger
        self.refresh_s = refresh_s
        self._queue = anyio.Lock()  # FIFO: the queued commands run in the order given
        self.sub_title = jogger.title

    def compose(self) -> ComposeResult:
        yield Header()
        yield ComponentTable(id="components")
        yield StatusLine(id="status")
        yield PlotPanel(id="plots")
        yield EventLog(id="log", max_lines=500, wrap=True)
        yield Footer()

    async def on_mount(self) -> None:
        table = self.query_one(ComponentTable)
        table.setup(self.jogger)
        table.focus()
        log = self.query_one(EventLog)
        for entry in self.jogger.log:
            log.add(entry)
        self.jogger.on_log = self._logged
        await self.tick()
        self.set_interval(self.refresh_s, self.tick)

    def on_unmount(self) -> None:
        self.jogger.on_log = None

    def _logged(self, entry: LogEntry) -> None:
        self.query_one(EventLog).add(entry)

    async def tick(self) -> None:
        """Read the values once and show them."""
        await self.jogger.poll()
        await self.show()

    async def show(self) -> None:
        try:
            table = self.query_one(ComponentTable)
            status = self.query_one(StatusLine)
            plots = self.query_one(PlotPanel)
        except NoMatches:  # the app is closing: its widgets are gone
            return
        table.show(self.jogger)
        status.show(self.jogger)
        await plots.show(self.jogger)

    def on_data_table_row_highlighted(self, event: DataTable.RowHighlighted) -> None:
        self.jogger.select(event.cursor_row)
        self.query_one(StatusLine).show(self.jogger)

    def _selected(self) -> None:
        """The table's cursor row is the selected component (its highlight message may
        still be on its way when a key that acts on the selection comes)."""
        self.jogger.select(self.query_one(ComponentTable).cursor_row)

    def _work(self, call: Callable[[], Awaitable[None]], name: str, *, queued: bool = True) -> None:
        """Run ``call`` in a worker; ``queued``: after the commands before it, in order
        (the e-stop is not queued: it runs at once)."""

        async def run() -> None:
            if queued:
                async with self._queue:
                    await call()
            else:
                await call()
            await self.show()

        self.run_worker(run(), name=name, group="commands")

    # -- actions -------------------------------------------------------------------------------
    def action_select(self, delta: int) -> None:
        """Up/down move the selection at once (the table's own bindings would move it when
        the table gets to the key, after a jog key pressed next)."""
        table = self.query_one(ComponentTable)
        table.move_cursor(row=table.cursor_row + delta)
        self._selected()
        self.query_one(StatusLine).show(self.jogger)

    async def action_jog(self, direction: int) -> None:
        self._selected()
        self.jogger.jog(direction)
        await self.show()

    def action_step(self, delta: int) -> None:
        self.jogger.change_step(delta)
        self.query_one(StatusLine).show(self.jogger)

    def action_velocity(self, delta: int) -> None:
        self.jogger.change_velocity(delta)
        self.query_one(StatusLine).show(self.jogger)

    async def action_plot(self) -> None:
        self._selected()
        self.jogger.toggle_plot()
        await self.show()

    def action_stop(self) -> None:
        self._work(self.jogger.stop, "stop")

    def action_enable(self) -> None:
        self._selected()
        self._work(self.jogger.enable, "enable")

    def action_disable(self) -> None:
        self._selected()
        self._work(self.jogger.disable, "disable")

    def action_estop(self) -> None:
        self._work(self.jogger.estop, "estop", queued=False)

    def action_release(self) -> None:
        self._work(self.jogger.release, "release")

    def action_quit_jog(self) -> None:
        self.exit(return_code=0)

    def action_interrupt(self) -> None:
        self.exit(return_code=EXIT_INTERRUPTED)
