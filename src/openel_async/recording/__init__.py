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

from .live import LAYOUT_PATH, FoxgloveSink, LiveView
from .pipeline import Pipeline, PipelineStats, Sink, SinkStartError
from .reader import Recording, info_lines, read_recording
from .recorder import McapSink, Recorder
from .scene import PoseBytesSource, PoseSource, Primitive, SceneSource, Transform
from .tap import Tap

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
