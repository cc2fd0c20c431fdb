"""Flight recorder (MCAP) and live view (Foxglove) of an application's components and timers.

- :class:`Recorder`: every command, reading, event, completion, error, state change and timer
  tick of the observed components and timers, one channel per component, written to an MCAP
  file by a writer process of its own (bounded queue; what it drops is counted).
- :class:`LiveView`: the same channels and schemas, published live by Foxglove's WebSocket
  server (127.0.0.1 by default).
- :func:`read_recording`, :func:`info_lines`: a recording read back (also a cut one).
- :mod:`.plot`: the demos' joint plot from a recording; :mod:`.replay`: its commands fed to a
  rig at their recorded times.

Both are :class:`~openel_async.app.AppHook` objects: ``openel-async demo --record
FILE.mcap --foxglove`` attaches them to any app. docs/recording.md has the details.
"""

from typing import TYPE_CHECKING

from ..lazy import lazy_exports

if TYPE_CHECKING:
    from .live import LAYOUT_PATH, LiveView
    from .mcap_sink import McapSink
    from .pipeline import Pipeline, SinkStartError
    from .reader import Recording, info_lines, read_recording
    from .recorder import Recorder
    from .scene import PoseBytesSource, PoseSource, Primitive, SceneSource, Transform
    from .sinks import FoxgloveSink, PipelineStats, Sink
    from .tap import Tap

# Each name loads its module on first use: the writer process (sink_process) and a command
# that records without --foxglove do not import the Foxglove SDK's live server.
_LAZY = {
    "LAYOUT_PATH": "live",
    "FoxgloveSink": "sinks",
    "LiveView": "live",
    "Pipeline": "pipeline",
    "PipelineStats": "sinks",
    "Sink": "sinks",
    "SinkStartError": "pipeline",
    "Recording": "reader",
    "info_lines": "reader",
    "read_recording": "reader",
    "McapSink": "mcap_sink",
    "Recorder": "recorder",
    "PoseBytesSource": "scene",
    "PoseSource": "scene",
    "Primitive": "scene",
    "SceneSource": "scene",
    "Transform": "scene",
    "Tap": "tap",
}


__getattr__, __dir__ = lazy_exports(__name__, _LAZY)


__all__ = [
    "LAYOUT_PATH",
    "FoxgloveSink",
    "LiveView",
    "McapSink",
    "Pipeline",
    "PipelineStats",
    "PoseBytesSource",
    "PoseSource",
    "Primitive",
    "Recorder",
    "Recording",
    "SceneSource",
    "Sink",
    "SinkStartError",
    "Tap",
    "Transform",
    "info_lines",
    "read_recording",
]
