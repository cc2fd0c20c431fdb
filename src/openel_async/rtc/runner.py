"""Running the component an RTC Profile describes (``openel-async run RTC.yaml``).

The profile names its Python implementation with a ``parameters`` entry::

    parameters:
      - name: implementation
        defaultValue: "pan_tilt:PanTilt"     # module:Class

The module is looked up next to the profile file first (``pan_tilt.py`` or a package
``pan_tilt/``), then on ``sys.path`` (a dotted name). It is a Python module name, never a
path: an absolute path, ``..`` or a path separator is refused (ProfileError). Loading
the implementation *executes* that module's code. Without the entry the module is
the snake_case form of ``basicInfo.name`` next to the profile (``PanTilt`` ->
``pan_tilt.py``) and the class is ``basicInfo.name``. The class must derive from
:class:`~openel_async.rtc.RTObject` (from :class:`~openel_async.rtc.MultiModeObject`
when ``componentKind`` names a multi-mode component) and accept
``cls(instance_name, configuration=..., clock=...)``.

The execution context comes from ``basicInfo.executionType`` (``PeriodicExecutionContext``
or ``PERIODIC``; ``EventDrivenExecutionContext`` or ``EVENTDRIVEN``;
``SporadicExecutionContext`` or ``SPORADIC``; ``ExtTrigExecutionContext`` or ``EXTTRIG``,
ticked by a :data:`Ticker`) and the rate from ``basicInfo.executionRate``, else the
``exec_ctxt.periodic.rate`` parameter, else 1000 Hz (the spec's default). docs/rtc.md
describes the whole sequence.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import math
import os
import re
import signal
import stat
import sys
from collections.abc import Awaitable, Callable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from types import ModuleType

import anyio
import anyio.to_thread
from anyio.abc import TaskStatus

from openel_async.logs import get_logger

from ..clock import NS_PER_S, Clock, MonotonicClock, VirtualClock
from ..run_profile_args import CLI_MAX_VIRTUAL_CYCLES, parse_profile_run_args
from .configuration import Configuration, ConfigurationError
from .context import (
    MAX_RATE_HZ,
    MIN_RATE_HZ,
    EventDrivenExecutionContext,
    ExecutionContext,
    ExecutionKind,
    ExtTrigExecutionContext,
    LifeCycleState,
    PeriodicExecutionContext,
    SporadicExecutionContext,
)
from .modes import MultiModeObject
from .profile import ProfileError, RtcProfile, load_profile
from .rtobject import RTObject
from .run_cli import PROG, duration_problem, finish_run, read_problem

__all__ = [
    "DEFAULT_RATE_HZ",
    "IMPLEMENTATION_PARAMETER",
    "RATE_PARAMETER",
    "ExecutionSpec",
    "PreparedRun",
    "RunSummary",
    "Ticker",
    "build_configuration",
    "execution_spec",
    "load_implementation",
    "make_context",
    "prepare_profile",
    "run_prepared",
    "run_profile",
    "run_profile_cli",
    "tick_lines",
    "ticks",
]

log = get_logger(__name__)

IMPLEMENTATION_PARAMETER = "implementation"
RATE_PARAMETER = "exec_ctxt.periodic.rate"
DEFAULT_RATE_HZ = 1000.0
CLI_SET = "cli"
"""Name of the configuration set made of ``--set`` values."""

_PERIODIC_TYPES = frozenset({"periodicexecutioncontext", "periodic"})
_EVENT_TYPES = frozenset({"eventdrivenexecutioncontext", "eventdriven", "event_driven"})
_SPORADIC_TYPES = frozenset({"sporadicexecutioncontext", "sporadic"})
_EXT_TRIG_TYPES = frozenset({"exttrigexecutioncontext", "exttrig", "ext_trig"})
KNOWN_EXECUTION_TYPES = (
    "PeriodicExecutionContext (PERIODIC), EventDrivenExecutionContext (EVENTDRIVEN), "
    "SporadicExecutionContext (SPORADIC) or ExtTrigExecutionContext (EXTTRIG)"
)
"""The execution types ``openel-async run`` knows (case-insensitive)."""
_BASIC = "rtcProfile.basicInfo"
_loaded: dict[Path, ModuleType] = {}
"""Implementation modules imported from files, by path (imported once per process)."""


@dataclass(frozen=True, slots=True)
class ExecutionSpec:
    """The execution context a profile asks for."""

    kind: ExecutionKind
    rate_hz: float | None
    """Rate of a periodic context; None for an event-driven one; for a sporadic one
    (kind OTHER) its highest rate (None: no minimum interval); for an ExtTrig one its
    nominal rate."""
    ext_trig: bool = False
    """An :class:`~openel_async.rtc.ExtTrigExecutionContext`: kind PERIODIC (as in
    OpenRTM-aist), one cycle per tick, nothing ticks at ``rate_hz``."""

    def describe(self) -> str:
        """``PERIODIC at 100 Hz``, ``EVENT_DRIVEN``, ``EXT_TRIG (one cycle per tick,
        nominal 1000 Hz)``..."""
        if self.ext_trig:
            return f"EXT_TRIG (one cycle per tick, nominal {self.rate_hz:g} Hz)"
        rate = f" at {self.rate_hz:g} Hz" if self.rate_hz is not None else ""
        return f"{self.kind}{rate}"


@dataclass(slots=True)
class RunSummary:
    """What a profile run did."""

    component: str
    profile_id: str
    kind: ExecutionKind
    rate_hz: float | None
    duration_s: float
    cycles: int = 0
    overruns: int = 0
    skipped: int = 0
    timer_missed: int = 0
    """Periods the context's timer skipped because it woke a whole period late."""
    lateness_p50_us: float = 0.0
    lateness_p99_us: float = 0.0
    lateness_max_us: float = 0.0
    final_state: LifeCycleState | None = None
    """State in the context just before deactivation."""
    ext_trig: bool = False
    """The context was an ExtTrigExecutionContext (``rate_hz`` is its nominal rate)."""
    mode: str | None = None
    report: dict[str, object] = field(default_factory=dict)
    stopped_by: str | None = None
    """The signal that ended the run (``"SIGINT"``, ``"SIGTERM"``), None otherwise."""

    def lines(self) -> list[str]:
        context = ExecutionSpec(self.kind, self.rate_hz, self.ext_trig).describe()
        out = [
            f"component          {self.component} ({self.profile_id})",
            f"context            {context}",
            f"duration           {self.duration_s:.3f} s",
            f"cycles             {self.cycles} (overruns {self.overruns}, skipped {self.skipped}"
            f", periods missed {self.timer_missed})",
            f"cycle lateness     p50 {self.lateness_p50_us:.0f} us, p99 "
            f"{self.lateness_p99_us:.0f} us, max {self.lateness_max_us:.0f} us",
            f"state at the end   {self.final_state}",
        ]
        if self.mode is not None:
            out.append(f"mode at the end    {self.mode}")
        if self.stopped_by is not None:
            out.append(f"stopped by         {self.stopped_by}")
        out += [f"{key:<18} {value}" for key, value in self.report.items()]
        return out


# -- what the profile asks for ----------------------------------------------------------


def _parameter(profile: RtcProfile, name: str) -> tuple[str, str | None] | None:
    for i, param in enumerate(profile.parameters):
        if param.name == name:
            return f"rtcProfile.parameters[{i}].defaultValue", param.default_value
    return None


def execution_spec(profile: RtcProfile, rate_hz: float | None = None) -> ExecutionSpec:
    """The context kind and rate of a profile (``rate_hz`` overrides the profile's).

    Raises ProfileError naming ``executionType``, ``executionRate`` or the rate
    parameter when they cannot be used.
    """
    basic = profile.basic_info
    kind_text = basic.execution_type.strip().lower()
    if kind_text in _EVENT_TYPES:
        return ExecutionSpec(ExecutionKind.EVENT_DRIVEN, None)
    sporadic = kind_text in _SPORADIC_TYPES
    ext_trig = kind_text in _EXT_TRIG_TYPES
    if kind_text not in _PERIODIC_TYPES and not (sporadic or ext_trig):
        raise ProfileError(
            f"{_BASIC}.executionType",
            f"unsupported execution type {basic.execution_type!r}; expected "
            + KNOWN_EXECUTION_TYPES,
        )
    if sporadic and rate_hz is None and basic.execution_rate is None:
        return ExecutionSpec(ExecutionKind.OTHER, None)
    if rate_hz is not None:
        path, rate = "--rate", rate_hz
    elif basic.execution_rate is not None:
        path, rate = f"{_BASIC}.executionRate", basic.execution_rate
    elif (entry := _parameter(profile, RATE_PARAMETER)) is not None:
        path, text = entry
        try:
            rate = float(text or "")
        except ValueError:
            raise ProfileError(path, f"{RATE_PARAMETER} must be a number, got {text!r}") from None
    else:
        path, rate = "", DEFAULT_RATE_HZ
    if not (math.isfinite(rate) and MIN_RATE_HZ <= rate <= MAX_RATE_HZ):
        raise ProfileError(
            path,
            f"the rate must be a number of Hz, {MIN_RATE_HZ:g} <= rate <= {MAX_RATE_HZ:g}, "
            f"got {rate!r}",
        )
    kind = ExecutionKind.OTHER if sporadic else ExecutionKind.PERIODIC
    return ExecutionSpec(kind, float(rate), ext_trig)


def build_configuration(
    profile: RtcProfile, settings: Mapping[str, str] | None = None
) -> Configuration:
    """The profile's configuration, every default checked against its constraint, with
    ``settings`` (name -> text) in a set ``cli`` made active when given.

    Raises ConfigurationError naming the parameter.
    """
    config = Configuration.from_profile(profile)
    if settings:
        config.add_set(CLI_SET, dict(settings))
        config.activate_set(CLI_SET)
    return config


def _snake(name: str) -> str:
    return re.sub(r"(?<=[a-z0-9])(?=[A-Z])", "_", name).lower()


def _import_next_to(directory: Path, module: str, path: str) -> ModuleType | None:
    if "." in module:
        return None
    candidates = (directory / f"{module}.py", directory / module / "__init__.py")
    file = next((c for c in candidates if c.is_file()), None)
    if file is None:
        return None
    resolved = file.resolve()
    cached = _loaded.get(resolved)
    if cached is not None:
        return cached
    unique = f"openel_rtc_app{len(_loaded) + 1}_{module}"
    spec = importlib.util.spec_from_file_location(
        unique,
        file,
        submodule_search_locations=[str(file.parent)] if file.stem == "__init__" else None,
    )
    if spec is None or spec.loader is None:
        raise ProfileError(path, f"{file} cannot be imported as a Python module")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[unique] = mod
    try:
        spec.loader.exec_module(mod)
    except Exception as exc:
        del sys.modules[unique]
        raise ProfileError(path, f"importing {file} failed: {exc!r}") from exc
    _loaded[resolved] = mod
    return mod


def load_implementation(profile: RtcProfile, profile_path: Path) -> type[RTObject]:
    """The component class a profile names (see the module docstring).

    Raises ProfileError naming the ``implementation`` parameter (or ``basicInfo.name``
    when it is absent) when the module or class cannot be found or is not a component.
    """
    basic = profile.basic_info
    entry = _parameter(profile, IMPLEMENTATION_PARAMETER)
    if entry is not None:
        path, text = entry
        module_name, _, class_name = (text or "").strip().partition(":")
        module_name, class_name = module_name.strip(), class_name.strip() or basic.name
        if not module_name:
            raise ProfileError(path, f"expected 'module:Class', got {text!r}")
        if not all(part.isidentifier() for part in module_name.split(".")):
            raise ProfileError(
                path,
                f"expected 'module:Class' with a Python module name (a file next to the "
                f"profile, or a dotted importable module), not a path: got {text!r}",
            )
    else:
        path, module_name, class_name = f"{_BASIC}.name", _snake(basic.name), basic.name
    directory = profile_path.resolve().parent
    module = _import_next_to(directory, module_name, path)
    if module is None:
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            if exc.name is not None and not module_name.startswith(exc.name):
                raise ProfileError(path, f"importing {module_name!r} failed: {exc}") from exc
            raise ProfileError(
                path,
                f"no module {module_name!r}: neither {directory / (module_name + '.py')} "
                "nor an importable module of that name" + _not_python(profile, class_name),
            ) from None
        except Exception as exc:
            raise ProfileError(path, f"importing {module_name!r} failed: {exc!r}") from exc
    cls = getattr(module, class_name, None)
    if cls is None:
        raise ProfileError(path, f"module {module_name!r} has no class {class_name!r}")
    if not (isinstance(cls, type) and issubclass(cls, RTObject)):
        raise ProfileError(path, f"{module_name}:{class_name} is not an RTObject subclass")
    if "multimode" in basic.component_kind.lower() and not issubclass(cls, MultiModeObject):
        raise ProfileError(
            f"{_BASIC}.componentKind",
            f"{basic.component_kind} needs a MultiModeObject; "
            f"{module_name}:{class_name} has no modes",
        )
    _check_actions(profile, cls)
    return cls


def _not_python(profile: RtcProfile, class_name: str) -> str:
    """A hint when the profile describes a component in another language."""
    language = profile.language.kind if profile.language is not None else None
    if language is None or language.strip().lower() == "python":
        return ""
    return (
        f" (the profile describes a {language} component; openel-async runs a Python "
        f"implementation: write the class {class_name} there, or name one with an "
        f"'{IMPLEMENTATION_PARAMETER}' parameter)"
    )


def _check_actions(profile: RtcProfile, cls: type[RTObject]) -> None:
    """Warn when the profile says a callback is implemented and the class does not
    override it (or the reverse): the profile and the code disagree."""
    for name, status in profile.actions.items():
        if not hasattr(RTObject, name) and not hasattr(MultiModeObject, name):
            continue  # on_action: finite state machines are not supported
        if name == "on_mode_changed" and not issubclass(cls, MultiModeObject):
            overridden = False  # a component without modes has no on_mode_changed
        else:
            base = MultiModeObject if name == "on_mode_changed" else RTObject
            overridden = getattr(cls, name, None) is not getattr(base, name, None)
        if status.implemented != overridden:
            log.warning(
                "profile_action_mismatch",
                action=name,
                profile_says=status.implemented,
                class_overrides=overridden,
            )


def make_context(
    spec: ExecutionSpec, *, owner: RTObject, clock: Clock, name: str = ""
) -> ExecutionContext:
    """The context of an ExecutionSpec."""
    if spec.ext_trig:
        rate = DEFAULT_RATE_HZ if spec.rate_hz is None else spec.rate_hz
        return ExtTrigExecutionContext(rate, name=name, owner=owner, clock=clock)
    if spec.kind is ExecutionKind.EVENT_DRIVEN:
        return EventDrivenExecutionContext(name=name, owner=owner, clock=clock)
    if spec.kind is ExecutionKind.OTHER:
        interval = 0.0 if spec.rate_hz is None else 1.0 / spec.rate_hz
        return SporadicExecutionContext(interval, name=name, owner=owner, clock=clock)
    assert spec.rate_hz is not None
    return PeriodicExecutionContext(spec.rate_hz, name=name, owner=owner, clock=clock)


# -- ticking an ExtTrig context ----------------------------------------------------------

Ticker = Callable[[ExtTrigExecutionContext], Awaitable[None]]
"""What ticks the ExtTrig context of a run: ``await ticker(ec)`` calls ``ec.tick()`` as it
likes; the run ends when it returns (or at ``duration_s`` / a signal, if sooner)."""


def ticks(
    count: int | None = None, *, rate_hz: float | None = None, clock: Clock | None = None
) -> Ticker:
    """A Ticker: ``count`` ticks (None: no end), back to back (each after the previous
    cycle returned) or ``rate_hz`` a second on ``clock`` (the context's clock when None),
    the first at once. ValueError naming ``count`` or ``rate_hz`` when they are unusable."""
    if count is not None and (isinstance(count, bool) or not isinstance(count, int) or count < 0):
        raise ValueError(f"count={count!r}: expected a number of ticks >= 0, or None")
    if rate_hz is not None and (
        isinstance(rate_hz, bool)
        or not isinstance(rate_hz, int | float)
        or not (math.isfinite(rate_hz) and MIN_RATE_HZ <= rate_hz <= MAX_RATE_HZ)
    ):
        raise ValueError(
            f"rate_hz={rate_hz!r}: expected ticks per second, {MIN_RATE_HZ:g} to "
            f"{MAX_RATE_HZ:g}, or None (back to back)"
        )

    async def run(ec: ExtTrigExecutionContext) -> None:
        on = clock or ec.clock
        period = None if rate_hz is None else max(1, round(NS_PER_S / rate_hz))
        start = on.now_ns()
        n = 0
        while count is None or n < count:
            if period is not None:
                await on.sleep_until(start + n * period)
            await ec.tick()
            n += 1

    return run


async def _read_chunk(fd: int) -> bytes:
    """Read what ``fd`` has, without blocking the event loop."""
    mode = os.fstat(fd).st_mode
    if stat.S_ISFIFO(mode) or stat.S_ISSOCK(mode) or stat.S_ISCHR(mode):
        try:
            await anyio.wait_readable(fd)
        except OSError:  # no readiness notification for it (e.g. /dev/null): just read
            pass
        else:
            return os.read(fd, 4096)
    return await anyio.to_thread.run_sync(os.read, fd, 4096)


def tick_lines(fd: int | None = None) -> Ticker:
    """A Ticker reading lines from ``fd`` (standard input when None): an empty line is
    one tick, a line holding a number N is N ticks; the run ends at end of file (Ctrl-D
    on a terminal). Other lines are logged (``tick_line_ignored``) and skipped."""

    async def run(ec: ExtTrigExecutionContext) -> None:
        source = sys.stdin.fileno() if fd is None else fd
        pending = b""
        while True:
            chunk = await _read_chunk(source)
            if not chunk:
                return
            pending += chunk
            *lines, pending = pending.split(b"\n")
            for raw in lines:
                text = raw.decode(errors="replace").strip()
                if not text:
                    count = 1
                elif text.isdigit() and len(text) <= 7:
                    count = int(text)
                else:
                    log.warning("tick_line_ignored", line=text[:80], expected="empty or N")
                    continue
                for _ in range(count):
                    await ec.tick()

    return run


async def _drive(ticker: Ticker, ec: ExtTrigExecutionContext, scope: anyio.CancelScope) -> None:
    await ticker(ec)
    scope.cancel()


# -- running ---------------------------------------------------------------------------


async def _until_signal(
    scope: anyio.CancelScope,
    summary: RunSummary,
    *,
    task_status: TaskStatus[None] = anyio.TASK_STATUS_IGNORED,
) -> None:
    with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
        task_status.started()
        async for signum in signals:
            summary.stopped_by = signal.Signals(signum).name
            log.info("signal_received", signal=summary.stopped_by)
            scope.cancel()
            return


async def _until_duration(clock: Clock, end_ns: int, scope: anyio.CancelScope) -> None:
    await clock.sleep_until(end_ns)
    scope.cancel()


@dataclass(frozen=True, slots=True)
class PreparedRun:
    """A loaded and checked profile, ready to run."""

    path: Path
    profile: RtcProfile
    spec: ExecutionSpec
    configuration: Configuration
    implementation: type[RTObject]


def prepare_profile(
    path: Path, *, rate_hz: float | None = None, settings: Mapping[str, str] | None = None
) -> PreparedRun:
    """Load and validate the profile, check the execution type and rate, build the
    configuration (every value checked against its constraint) and import the
    implementation. Raises ProfileError or ConfigurationError naming the field, and
    OSError when the file cannot be read."""
    profile = load_profile(path)
    spec = execution_spec(profile, rate_hz)
    config = build_configuration(profile, settings)
    cls = load_implementation(profile, path)
    return PreparedRun(path, profile, spec, config, cls)


async def run_profile(
    path: Path,
    *,
    duration_s: float | None = None,
    clock: Clock | None = None,
    rate_hz: float | None = None,
    settings: Mapping[str, str] | None = None,
    instance_name: str | None = None,
    handle_signals: bool = True,
    ticker: Ticker | None = None,
) -> RunSummary:
    """Load, validate and run the component of a profile until ``duration_s`` seconds
    on ``clock`` have passed, SIGINT/SIGTERM arrives (with ``handle_signals``) or
    ``ticker`` returns. ``ticker`` (e.g. :func:`ticks`, :func:`tick_lines`) ticks the
    context of a profile whose execution type is ExtTrigExecutionContext; without one
    such a context runs no cycle.

    Sequence: :func:`prepare_profile`, create the component and its context (owned by
    it), initialize, add, start, activate, run, then ``exit()`` (stop, deactivate,
    remove, finalize), also when activation fails or the run is cancelled. Raises
    ProfileError / ConfigurationError for bad input and RTCError when a lifecycle step
    fails.
    """
    _check_run(duration_s, handle_signals, ticker)
    prepared = prepare_profile(path, rate_hz=rate_hz, settings=settings)
    return await run_prepared(
        prepared,
        duration_s=duration_s,
        clock=clock,
        instance_name=instance_name,
        handle_signals=handle_signals,
        ticker=ticker,
    )


def _check_run(
    duration_s: float | None,
    handle_signals: bool,
    ticker: Ticker | None,
    spec: ExecutionSpec | None = None,
) -> None:
    if duration_s is not None and not (math.isfinite(duration_s) and duration_s > 0):
        raise ValueError(f"duration_s={duration_s!r}: expected a finite number of seconds > 0")
    if duration_s is None and not handle_signals and ticker is None:
        raise ValueError("a run without duration_s needs handle_signals or a ticker to end")
    if ticker is not None and spec is not None and not spec.ext_trig:
        raise ValueError(
            f"ticker: the profile's context is {spec.describe()}; only an "
            "ExtTrigExecutionContext is ticked"
        )


async def run_prepared(
    prepared: PreparedRun,
    *,
    duration_s: float | None = None,
    clock: Clock | None = None,
    instance_name: str | None = None,
    handle_signals: bool = True,
    ticker: Ticker | None = None,
) -> RunSummary:
    """Run a :class:`PreparedRun` (see :func:`run_profile`)."""
    profile, spec, config = prepared.profile, prepared.spec, prepared.configuration
    _check_run(duration_s, handle_signals, ticker, spec)
    clock = clock or MonotonicClock()
    comp = prepared.implementation(
        instance_name or profile.basic_info.name, configuration=config, clock=clock
    )
    ec = make_context(spec, owner=comp, clock=clock, name=f"{comp.instance_name}.ec0")
    run_log = log.bind(rtc=comp.instance_name, profile=str(prepared.path))
    run_log.info(
        "profile_loaded",
        id=profile.id,
        kind=str(spec.kind),
        rate_hz=spec.rate_hz,
        config_set=config.active_set,
    )
    summary = RunSummary(
        comp.instance_name, profile.id, spec.kind, spec.rate_hz, 0.0, ext_trig=spec.ext_trig
    )
    async with ec:
        await comp.initialize()
        start_ns = clock.now_ns()
        try:
            await ec.add_component(comp)
            await ec.start()
            await ec.activate_component(comp)
            with anyio.CancelScope() as waiting:
                async with anyio.create_task_group() as tg:
                    if handle_signals:  # listening before the run is announced
                        await tg.start(_until_signal, waiting, summary)
                    run_log.info("profile_running", duration_s=duration_s)
                    if duration_s is not None:
                        end = start_ns + round(duration_s * NS_PER_S)
                        tg.start_soon(_until_duration, clock, end, waiting)
                    if ticker is not None:
                        assert isinstance(ec, ExtTrigExecutionContext)
                        tg.start_soon(_drive, ticker, ec, waiting)
        finally:
            # Not shielded: on_finalize leaves what on_initialize entered (task groups
            # of HAL components), which must happen in this task's own scope.
            if comp in ec.participants:
                summary.final_state = ec.get_component_state(comp)
            summary.duration_s = (clock.now_ns() - start_ns) / NS_PER_S
            await comp.exit()
    stats = ec.stats
    summary.cycles, summary.overruns, summary.skipped = stats.cycles, stats.overruns, stats.skipped
    summary.timer_missed = stats.timer_missed
    summary.lateness_p50_us = stats.lateness.p50_ns / 1e3
    summary.lateness_p99_us = stats.lateness.p99_ns / 1e3
    summary.lateness_max_us = stats.lateness.max_ns / 1e3
    if isinstance(comp, MultiModeObject):
        summary.mode = comp.get_current_mode()
    summary.report = comp.report()
    run_log.info(
        "profile_finished",
        cycles=stats.cycles,
        overruns=stats.overruns,
        skipped=stats.skipped,
        periods_missed=stats.timer_missed,
    )
    return summary


def _parse_args(argv: Sequence[str]) -> argparse.Namespace:
    return parse_profile_run_args(argv)


def _settings(pairs: Sequence[str]) -> dict[str, str]:
    out: dict[str, str] = {}
    for pair in pairs:
        name, sep, value = pair.partition("=")
        if not sep or not name.strip():
            raise ConfigurationError(f"--set {pair!r}: expected NAME=VALUE")
        out[name.strip()] = value
    return out


def _tick_problem(args: argparse.Namespace) -> str | None:
    """What is wrong with --ticks / --tick-rate by themselves, or None."""
    if args.ticks is not None and not 0 <= args.ticks <= CLI_MAX_VIRTUAL_CYCLES:
        return f"--ticks must be a number of ticks from 0 to {CLI_MAX_VIRTUAL_CYCLES:,}"
    rate = args.tick_rate
    if rate is not None and not (math.isfinite(rate) and MIN_RATE_HZ <= rate <= MAX_RATE_HZ):
        return f"--tick-rate must be a number of Hz, {MIN_RATE_HZ:g} to {MAX_RATE_HZ:g}"
    return None


def _cli_ticker(spec: ExecutionSpec, args: argparse.Namespace) -> tuple[Ticker | None, str | None]:
    """The ticker of a command-line run and the problem, if any."""
    asked = args.ticks is not None or args.tick_rate is not None
    if not spec.ext_trig:
        if asked:
            option = "--ticks" if args.ticks is not None else "--tick-rate"
            return None, (
                f"{option} ticks an ExtTrigExecutionContext; this profile's context is "
                f"{spec.describe()}"
            )
        return None, None
    if args.virtual and args.ticks is None and args.tick_rate is not None:
        cycles = args.tick_rate * args.duration
        if cycles > CLI_MAX_VIRTUAL_CYCLES:
            return None, (
                f"--tick-rate {args.tick_rate:g} Hz for --duration {args.duration:g} s is "
                f"{cycles:.3g} ticks on the virtual clock; at most {CLI_MAX_VIRTUAL_CYCLES:,}"
            )
    if asked:
        return ticks(args.ticks, rate_hz=args.tick_rate), None
    if args.virtual:  # --duration without ticks: a virtual run of no cycles
        return None, None
    if sys.stdin.isatty():
        print(
            f"{PROG}: ExtTrigExecutionContext: Enter ticks once, a number N then Enter ticks "
            "N times, Ctrl-D ends the run",
            file=sys.stderr,
        )
    return tick_lines(), None


def _check_cli_rate(spec: ExecutionSpec, args: argparse.Namespace) -> str | None:
    """The work a command-line run may ask for (the context itself bounds the rate): the
    problem, or None."""
    if spec.rate_hz is None or spec.ext_trig:  # an ExtTrig rate is nominal
        return None
    rate = spec.rate_hz
    source = "--rate" if args.rate is not None else "the profile's rate"
    if args.virtual and args.duration is not None:
        cycles = rate * args.duration
        if cycles > CLI_MAX_VIRTUAL_CYCLES:
            return (
                f"{source} {rate:g} Hz for --duration {args.duration:g} s is {cycles:.3g} "
                f"cycles on the virtual clock; at most {CLI_MAX_VIRTUAL_CYCLES:,} (a lower "
                "rate or a shorter duration)"
            )
    return None


def run_profile_cli(path: Path, argv: list[str]) -> int:
    """``openel-async run PROFILE [--duration S] [--virtual | --realtime] [--rate HZ] [--set N=V]...
    [--ticks N] [--tick-rate HZ]``.

    Exit status: 0 after a clean run, 1 when a lifecycle step failed, 2 for a bad
    profile, configuration or command line (a rate the context cannot run included),
    130 / 143 when SIGINT / SIGTERM ended the run (after the summary).
    """
    from .system import is_system_file, run_system_cli

    if is_system_file(path):  # a system of components, not one profile
        return run_system_cli(path, argv)
    try:
        args = _parse_args(argv)
    except SystemExit as exc:  # argparse printed the problem
        return int(exc.code or 0) if exc.code in (0, None) else 2
    prog = PROG
    # --virtual without --duration: checked with the profile (--ticks may end the run)
    problem = duration_problem(args.duration, False) or _tick_problem(args)
    if problem is None and args.virtual and args.duration is None and args.ticks is None:
        problem = f"{duration_problem(None, True)}; or --ticks N for an ExtTrigExecutionContext"
    if problem is not None:
        print(f"{prog}: {problem}", file=sys.stderr)
        return 2
    try:
        settings = _settings(args.set)
    except ConfigurationError as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return 2

    try:
        prepared = prepare_profile(path, rate_hz=args.rate, settings=settings)
    except OSError as exc:
        print(f"{prog}: {path}: {read_problem(exc)}", file=sys.stderr)
        return 2
    except ProfileError as exc:
        print(f"{prog}: {path}: {exc}", file=sys.stderr)
        return 2
    except ConfigurationError as exc:
        print(f"{prog}: {path}: configuration: {exc}", file=sys.stderr)
        return 2
    problem = _check_cli_rate(prepared.spec, args)
    ticker, tick_problem = _cli_ticker(prepared.spec, args)
    problem = problem or tick_problem
    if problem is not None:
        print(f"{prog}: {path}: {problem}", file=sys.stderr)
        return 2

    async def main() -> RunSummary:
        run = partial(
            run_prepared,
            prepared,
            duration_s=args.duration,
            instance_name=args.name,
            ticker=ticker,
        )
        if not args.virtual:
            return await run()
        clock = VirtualClock()
        async with clock.autojump():
            return await run(clock=clock)

    return finish_run(path, main)
