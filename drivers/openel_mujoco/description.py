"""Declarative description of a MuJoCo simulation: which joints and sensors become OpenEL devices.

A :class:`SimDescription` is a plain, frozen dataclass that round-trips through a dict (and so
through YAML or JSON)::

    model: arm6            # shipped model name or MJCF/MJB path
    pacing: lockstep       # or realtime
    keyframe: home         # optional initial state
    joints:
      - base_yaw                                   # a name alone: every default
      - {joint: shoulder_pitch, max_velocity: 2.0}
      - {joint: elbow_pitch, mode: velocity, position_tolerance: 0.005}
    sensors:
      - imu_acc
      - {sensor: wrist_force, name: ft}
    effectors:             # MuJoCo actuators that do not drive one joint
      - suction                                    # the adhesion actuator of arm6

Joint, sensor and actuator names are those of the model; unknown names raise
:class:`~openel_mujoco.models.ModelLoadError` when the simulation is built.  Keys are
strict: an unknown key raises :class:`BadParameterError` with a "did you mean" for near
misses; read by :meth:`SimDescription.from_yaml`, every refusal starts with the file,
line and column (``arm.yaml:7:20: ...``).  Every field of
:class:`JointSpec`, :class:`SensorSpec` and :class:`EffectorSpec` can also be given in code,
e.g. ``sim.actuator("shoulder", max_velocity=2.0)`` or ``sim.effector("suction")``.
"""

from __future__ import annotations

import math
import os
import pathlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from typing import Any, Literal, TypeGuard, TypeVar, get_args

from openel_async.errors import BadParameterError
from openel_async.ids import DeviceKind
from openel_async.positioned import DocumentError, Location, YamlDocument, did_you_mean, relocate
from openel_async.sensor_kinds import HAL4RT_KIND_NAMES

from .models import ControlMode

__all__ = [
    "DEFAULT_HOLD_FORCE",
    "DEFAULT_LIMIT_MARGIN",
    "DEFAULT_POSITION_TOLERANCE",
    "DEFAULT_SETTLE_S",
    "DEFAULT_SETTLE_VELOCITY",
    "DEFAULT_TORQUE_TOLERANCE",
    "DEFAULT_VELOCITY_TOLERANCE",
    "EffectorSpec",
    "JointSpec",
    "Pacing",
    "SensorSpec",
    "SimDescription",
    "spec_of",
]

Pacing = Literal["lockstep", "realtime"]
"""``lockstep``: the simulation clock is the framework clock; ``realtime``: stepped against the
real clock at real-time factor 1.0 (see :class:`openel_mujoco.MujocoSim`)."""

_PACINGS: tuple[str, ...] = get_args(Pacing)
_MODES: tuple[str, ...] = get_args(ControlMode)

DEFAULT_POSITION_TOLERANCE = 0.01
"""rad (hinge) or m (slide): a position target is reached within this distance ..."""
DEFAULT_SETTLE_VELOCITY = 0.02
"""... while the joint moves slower than this (rad/s or m/s) ..."""
DEFAULT_SETTLE_S = 0.02
"""... continuously for this long (simulated seconds)."""
DEFAULT_VELOCITY_TOLERANCE = 0.02
"""rad/s or m/s: a velocity target is reached within this."""
DEFAULT_TORQUE_TOLERANCE = 0.05
"""N m or N: a torque target is reached when the actuator torque on the joint is within this."""
DEFAULT_LIMIT_MARGIN = 0.002
"""rad or m: LIMIT_REACHED is posted when the joint comes this close to a range limit."""
DEFAULT_HOLD_FORCE = 0.1
"""N: an adhesion effector holds something while its touch sensor reads at least this."""


def _finite(value: object) -> TypeGuard[int | float]:
    """A real number (not a bool) that converts to a finite float (huge ints do not)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:  # an int beyond the float range
        return False


def _positive(owner: str, name: str, value: object, *, allow_none: bool = True) -> None:
    if value is None and allow_none:
        return
    if not _finite(value) or value <= 0:
        raise BadParameterError(f"{owner}.{name}", value, "a finite number > 0")


def _settle(owner: str, value: object) -> None:
    if not _finite(value) or value < 0:
        raise BadParameterError(f"{owner}.settle_s", value, "a finite number >= 0")


@dataclass(frozen=True, slots=True)
class JointSpec:
    """One model joint (hinge or slide) mapped to an OpenEL Actuator (a :class:`MujocoJoint`).

    Actuators: ``actuators`` maps control modes to actuator names; by default the
    ``<joint>_pos`` / ``<joint>_vel`` / ``<joint>_torque`` convention of the shipped models is
    used, and failing that the actuators that drive the joint are classified by their gain and
    bias (position servo, velocity servo, motor).  A mode without its own actuator runs on a
    built-in PD controller over the joint's motor, with gains ``kp``/``kd`` (position) and
    ``kv`` (velocity); unset gains derive from the joint's inertia (5 Hz position, 10 Hz velocity
    bandwidth, critically damped).
    """

    joint: str
    """Joint name in the model."""
    name: str | None = None
    """Key in ``sim.joints`` and base of the component's product name (default: ``joint``)."""
    mode: ControlMode | None = None
    """Control mode selected when the device is created (default: the model's active actuator)."""
    actuators: Mapping[ControlMode, str] | None = None
    """Explicit actuator name per mode, e.g. ``{"position": "j1_servo"}``."""
    position_limits: tuple[float, float] | None = None
    """Allowed position targets (default: the joint range, else unbounded)."""
    max_velocity: float | None = None
    """Largest |velocity| target (default: the velocity actuator's ctrlrange, else unbounded)."""
    max_torque: float | None = None
    """Largest |torque| target (default: the motor's ctrl/force range, else unbounded)."""
    kp: float | None = None
    kd: float | None = None
    kv: float | None = None
    position_tolerance: float = DEFAULT_POSITION_TOLERANCE
    settle_velocity: float = DEFAULT_SETTLE_VELOCITY
    velocity_tolerance: float = DEFAULT_VELOCITY_TOLERANCE
    torque_tolerance: float = DEFAULT_TORQUE_TOLERANCE
    settle_s: float = DEFAULT_SETTLE_S
    limit_margin: float = DEFAULT_LIMIT_MARGIN

    def __post_init__(self) -> None:
        if not isinstance(self.joint, str) or not self.joint:
            raise BadParameterError("joint", self.joint, "a non-empty joint name")
        if self.name is not None and (not isinstance(self.name, str) or not self.name):
            raise BadParameterError("name", self.name, "a non-empty string or None")
        if self.mode is not None and self.mode not in _MODES:
            raise BadParameterError("mode", self.mode, f"one of {', '.join(_MODES)} or None")
        if self.actuators is not None:
            if not isinstance(self.actuators, Mapping):
                raise BadParameterError("actuators", self.actuators, "a mapping mode -> name")
            for mode, act in self.actuators.items():
                if mode not in _MODES:
                    raise BadParameterError("actuators", mode, f"modes among {', '.join(_MODES)}")
                if not isinstance(act, str) or not act:
                    raise BadParameterError(f"actuators[{mode!r}]", act, "an actuator name")
            object.__setattr__(self, "actuators", dict(self.actuators))
        if self.position_limits is not None:
            limits = self.position_limits
            if (
                isinstance(limits, str | bytes)
                or not isinstance(limits, Sequence)
                or len(limits) != 2
                or not all(_finite(v) for v in limits)
                or not limits[0] < limits[1]
            ):
                raise BadParameterError(
                    "position_limits",
                    limits,
                    "a (low, high) pair of finite numbers with low < high",
                )
            object.__setattr__(self, "position_limits", (float(limits[0]), float(limits[1])))
        for name in ("max_velocity", "max_torque", "kp", "kd", "kv"):
            _positive("JointSpec", name, getattr(self, name))
        for name in (
            "position_tolerance",
            "settle_velocity",
            "velocity_tolerance",
            "torque_tolerance",
            "limit_margin",
        ):
            _positive("JointSpec", name, getattr(self, name), allow_none=False)
        _settle("JointSpec", self.settle_s)

    @property
    def key(self) -> str:
        return self.name or self.joint

    @classmethod
    def from_value(cls, value: str | Mapping[str, Any] | JointSpec) -> JointSpec:
        """A spec from a joint name, a dict of fields (``joint`` required) or a spec."""
        if isinstance(value, JointSpec):
            return value
        if isinstance(value, str):
            return cls(joint=value)
        return cls(**_fields_of(cls, value, "joints[]", required="joint"))

    def to_dict(self) -> dict[str, Any]:
        """Only the fields that differ from their defaults (``joint`` always)."""
        return _non_default(self, "joint")


@dataclass(frozen=True, slots=True)
class SensorSpec:
    """One MuJoCo sensor mapped to an OpenEL Sensor (a :class:`MujocoSensor`)."""

    sensor: str
    """Sensor name in the model."""
    name: str | None = None
    """Key in ``sim.sensors`` and base of the component's product name (default: ``sensor``)."""
    kind: int | str | None = None
    """HALId device kind (default: from the sensor type, e.g. accelerometer -> ACCEL): an id
    in 0..0xFFFFFFFF or a name, a ``DeviceKind`` member (``gyro``, ``rotary_angle``) or a
    HAL4RT class (``Encoder``, ``GyroSensor``, ``Direction``...), case-insensitive; stored
    as the id."""
    units: tuple[str, ...] | None = None
    """SI unit of each value (default: from the sensor type, e.g. ('m/s^2',) * 3)."""

    def __post_init__(self) -> None:
        if not isinstance(self.sensor, str) or not self.sensor:
            raise BadParameterError("sensor", self.sensor, "a non-empty sensor name")
        if self.name is not None and (not isinstance(self.name, str) or not self.name):
            raise BadParameterError("name", self.name, "a non-empty string or None")
        if self.kind is not None:
            object.__setattr__(self, "kind", _kind_id(self.kind))
        if self.units is not None:
            if (
                isinstance(self.units, str | bytes)
                or not isinstance(self.units, Sequence)
                or not all(isinstance(u, str) for u in self.units)
            ):
                raise BadParameterError("units", self.units, "a sequence of unit strings")
            object.__setattr__(self, "units", tuple(self.units))

    @property
    def key(self) -> str:
        return self.name or self.sensor

    @property
    def kind_id(self) -> int | None:
        """``kind`` as an id (None: from the sensor type)."""
        return None if self.kind is None else int(self.kind)

    @classmethod
    def from_value(cls, value: str | Mapping[str, Any] | SensorSpec) -> SensorSpec:
        """A spec from a sensor name, a dict of fields (``sensor`` required) or a spec."""
        if isinstance(value, SensorSpec):
            return value
        if isinstance(value, str):
            return cls(sensor=value)
        return cls(**_fields_of(cls, value, "sensors[]", required="sensor"))

    def to_dict(self) -> dict[str, Any]:
        return _non_default(self, "sensor")


@dataclass(frozen=True, slots=True)
class EffectorSpec:
    """One MuJoCo actuator that does not drive a single hinge/slide joint (adhesion, tendon,
    site, body or other transmissions) mapped to an OpenEL Actuator (a
    :class:`~openel_mujoco.effectors.MujocoEffector`).

    The request mapping follows from the actuator (see the effectors module): adhesion ->
    TORQUE (adhesion force, N); a motor-like actuator -> TORQUE (actuator force); a position
    or velocity servo -> POSITION or VELOCITY of the actuator's length.  Tolerances are in the
    units of the commanded quantity.
    """

    actuator: str
    """Actuator name in the model."""
    name: str | None = None
    """Key in ``sim.effectors`` and base of the component's product name (default: actuator)."""
    position_tolerance: float = DEFAULT_POSITION_TOLERANCE
    """Position servos: a length target is reached within this (m for a tendon) ..."""
    settle_velocity: float = DEFAULT_SETTLE_VELOCITY
    """... while the length changes slower than this."""
    velocity_tolerance: float = DEFAULT_VELOCITY_TOLERANCE
    torque_tolerance: float = DEFAULT_TORQUE_TOLERANCE
    """Force targets (TORQUE): reached when the actuator force is within this (N or N m)."""
    settle_s: float = DEFAULT_SETTLE_S
    """Simulated seconds in tolerance before COMPLETED."""
    touch_sensor: str | None = None
    """Adhesion: touch sensor that tells when the adhesion holds something (default: the first
    touch sensor on a site of the adhesion body; none: the contact list of the body)."""
    hold_force: float = DEFAULT_HOLD_FORCE
    """Adhesion with a touch sensor: reading (N) from which the effector holds something."""

    def __post_init__(self) -> None:
        if not isinstance(self.actuator, str) or not self.actuator:
            raise BadParameterError("actuator", self.actuator, "a non-empty actuator name")
        if self.name is not None and (not isinstance(self.name, str) or not self.name):
            raise BadParameterError("name", self.name, "a non-empty string or None")
        if self.touch_sensor is not None and (
            not isinstance(self.touch_sensor, str) or not self.touch_sensor
        ):
            raise BadParameterError("touch_sensor", self.touch_sensor, "a sensor name or None")
        for name in (
            "position_tolerance",
            "settle_velocity",
            "velocity_tolerance",
            "torque_tolerance",
            "hold_force",
        ):
            _positive("EffectorSpec", name, getattr(self, name), allow_none=False)
        _settle("EffectorSpec", self.settle_s)

    @property
    def key(self) -> str:
        return self.name or self.actuator

    @classmethod
    def from_value(cls, value: str | Mapping[str, Any] | EffectorSpec) -> EffectorSpec:
        """A spec from an actuator name, a dict of fields (``actuator`` required) or a spec."""
        if isinstance(value, EffectorSpec):
            return value
        if isinstance(value, str):
            return cls(actuator=value)
        return cls(**_fields_of(cls, value, "effectors[]", required="actuator"))

    def to_dict(self) -> dict[str, Any]:
        return _non_default(self, "actuator")


_SpecT = TypeVar("_SpecT", JointSpec, SensorSpec, EffectorSpec)


def spec_of(
    cls: type[_SpecT],
    spec: _SpecT | str | Mapping[str, Any] | None,
    fields_: Mapping[str, Any],
    key: str,
) -> _SpecT:
    """The spec a device is built with: ``spec`` (a spec, a name or a dict of fields), or the
    fields given as keyword arguments -- a rig file's ``params``, ``name`` being the
    component's: then ``key`` (``joint``, ``sensor``, ``actuator``) defaults to ``name``, so
    a component named after its joint needs no params. ``spec`` with fields besides ``name``
    is refused."""
    if spec is None:
        values = dict(fields_)
        if key not in values and isinstance(values.get("name"), str):
            values[key] = values["name"]
        return cls.from_value(values)
    built = cls.from_value(spec)
    if not fields_:
        return built
    if set(fields_) == {"name"} and built.name in (None, fields_["name"]):
        return replace(built, name=fields_["name"])
    other = ([k for k in fields_ if k != "name"] or ["name"])[0]
    raise BadParameterError(
        other, fields_[other], f"no {other!r} besides spec (give either a spec or its fields)"
    )


@dataclass(frozen=True, slots=True)
class SimDescription:
    """A model, its pacing and the joints, sensors and effectors to map; see the module
    docstring."""

    model: str
    """Shipped model name (``arm2``, ``arm6``, ``so101``) or a path to an MJCF/MJB file."""
    joints: tuple[JointSpec, ...] = ()
    sensors: tuple[SensorSpec, ...] = ()
    pacing: Pacing = "lockstep"
    keyframe: str | None = None
    """Name of the keyframe giving the initial (and reset) state (default: the model's qpos0)."""
    timestep: float | None = None
    """Override of the model's ``opt.timestep`` in seconds."""
    name: str | None = None
    """Name of the simulation in logs (default: the model name)."""
    extra: Mapping[str, Any] = field(default_factory=dict)
    """Free-form application data (ignored by the driver, kept by to_dict)."""
    effectors: tuple[EffectorSpec, ...] = ()
    """Actuators that do not drive one joint (adhesion, tendon, site ...), see EffectorSpec."""

    def __post_init__(self) -> None:
        if not isinstance(self.model, str) or not self.model:
            raise BadParameterError("model", self.model, "a shipped model name or a file path")
        if self.pacing not in _PACINGS:
            raise BadParameterError("pacing", self.pacing, f"one of {', '.join(_PACINGS)}")
        if self.keyframe is not None and (not isinstance(self.keyframe, str) or not self.keyframe):
            raise BadParameterError("keyframe", self.keyframe, "a keyframe name or None")
        _positive("SimDescription", "timestep", self.timestep)
        if self.name is not None and (not isinstance(self.name, str) or not self.name):
            raise BadParameterError("name", self.name, "a non-empty string or None")
        if not isinstance(self.extra, Mapping):
            raise BadParameterError(
                "extra", self.extra, "a mapping of application data (omit the key for none)"
            )
        joints = _specs("joints", self.joints, JointSpec.from_value)
        sensors = _specs("sensors", self.sensors, SensorSpec.from_value)
        effectors = _specs("effectors", self.effectors, EffectorSpec.from_value)
        specs: tuple[JointSpec | SensorSpec | EffectorSpec, ...]
        for label, specs in (("joints", joints), ("sensors", sensors), ("effectors", effectors)):
            keys = [s.key for s in specs]
            duplicates = sorted({k for k in keys if keys.count(k) > 1})
            if duplicates:
                raise BadParameterError(label, duplicates, "unique names")
        object.__setattr__(self, "joints", joints)
        object.__setattr__(self, "sensors", sensors)
        object.__setattr__(self, "effectors", effectors)
        object.__setattr__(self, "extra", dict(self.extra))

    @classmethod
    def from_dict(
        cls, data: Mapping[str, Any], *, base_dir: str | os.PathLike[str] | None = None
    ) -> SimDescription:
        """Build from a dict (e.g. parsed YAML); unknown keys raise BadParameterError.

        ``base_dir`` resolves a relative model path (not a shipped name) against a directory.
        """
        values = _fields_of(cls, data, "description", required="model")
        model = values["model"]
        if base_dir is not None and isinstance(model, str) and model:
            from .models import SHIPPED_MODELS

            try:
                path = pathlib.Path(model).expanduser()
            except RuntimeError as exc:  # "~user/..." of an unknown user
                raise BadParameterError(
                    "model", model, f"a shipped model name or a file path ({exc})"
                ) from exc
            if model not in SHIPPED_MODELS and not path.is_absolute():
                values["model"] = str(pathlib.Path(base_dir) / path)
        return cls(**values)

    @classmethod
    def from_yaml(cls, path: str | os.PathLike[str]) -> SimDescription:
        """Read a YAML file; a relative model path is taken relative to that file.

        Every problem with the file (unreadable, not UTF-8, not YAML, not a mapping, bad
        fields, unknown keys) raises :class:`BadParameterError` naming the path or the
        field; its text starts with ``FILE:LINE:COL:`` where the problem is written.
        """
        file = pathlib.Path(path)
        try:
            raw = file.read_bytes()
        except OSError as exc:
            raise BadParameterError("path", str(path), f"a readable YAML file ({exc})") from exc
        doc = _parse_yaml(str(path), raw)
        data = doc.data
        if not isinstance(data, Mapping):
            error = BadParameterError(
                "path", str(path), f"a YAML file holding a mapping (it holds {_kind(data)})"
            )
            raise _at(error, doc.where(data))
        try:
            return cls.from_dict(data, base_dir=file.parent)
        except BadParameterError as exc:
            raise _at(exc, _locate(exc, doc)) from exc.__cause__

    def to_dict(self) -> dict[str, Any]:
        """A plain dict (YAML/JSON-able) that :meth:`from_dict` turns back into this."""
        out: dict[str, Any] = {"model": self.model, "pacing": self.pacing}
        if self.keyframe is not None:
            out["keyframe"] = self.keyframe
        if self.timestep is not None:
            out["timestep"] = self.timestep
        if self.name is not None:
            out["name"] = self.name
        out["joints"] = [_compact(j.to_dict(), "joint") for j in self.joints]
        out["sensors"] = [_compact(s.to_dict(), "sensor") for s in self.sensors]
        if self.effectors:
            out["effectors"] = [_compact(e.to_dict(), "actuator") for e in self.effectors]
        if self.extra:
            out["extra"] = dict(self.extra)
        return out


def _sequence(name: str, value: object) -> Sequence[Any]:
    if isinstance(value, str | bytes) or not isinstance(value, Sequence):
        raise BadParameterError(name, value, "a list of names or mappings")
    return value


_Spec = TypeVar("_Spec", JointSpec, SensorSpec, EffectorSpec)


def _specs(name: str, value: object, build: Callable[[Any], _Spec]) -> tuple[_Spec, ...]:
    """The specs of one list; a refused entry's error gets a note naming its index."""
    specs = []
    for index, item in enumerate(_sequence(name, value)):
        try:
            specs.append(build(item))
        except BadParameterError as exc:
            exc.add_note(f"in {name}[{index}]")
            raise
    return tuple(specs)


def _parse_yaml(path: str, raw: bytes) -> YamlDocument:
    """The YAML document of a file, with positions, or BadParameterError naming the path,
    the line and the column of the problem."""
    from openel_async.positioned import load_yaml

    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise BadParameterError(
            "path",
            path,
            f"a UTF-8 text file (byte 0x{raw[exc.start]:02x} at offset {exc.start} is not UTF-8)",
        ) from exc
    try:
        return load_yaml(text, path)
    except DocumentError as exc:
        problem = exc.message.removeprefix("invalid YAML: ").removeprefix("invalid YAML value: ")
        error = BadParameterError("path", path, f"a YAML file ({problem})")
        raise _at(error, exc.location) from None


def _at(error: BadParameterError, location: Location | None) -> BadParameterError:
    """``error`` with its text prefixed by ``FILE:LINE:COL:`` (and ``location`` on it)."""
    if location is None:
        return error
    return relocate(error, DocumentError(str(error), path=error.parameter, location=location))


_LISTS = ("joints", "sensors", "effectors")


def _locate(error: BadParameterError, doc: YamlDocument) -> Location:
    """Where the field a from_dict refusal names is written: the parameter's last part
    in the entry the note ``in joints[2]`` names, or at the top."""
    data = doc.data
    field = error.parameter.rpartition(".")[2]
    unknown = error.allowed.startswith("a known field")
    container: object = data
    for note in getattr(error, "__notes__", ()):
        name, _, index = note.removeprefix("in ").partition("[")
        items = data.get(name) if isinstance(data, Mapping) else None
        if name in _LISTS and isinstance(items, list) and index.rstrip("]").isdigit():
            i = int(index.rstrip("]"))
            if i < len(items):
                container = items[i]
                if not isinstance(container, Mapping):
                    return doc.value(items, i)
    if isinstance(container, Mapping):
        key: object = field
        if unknown:
            key = next((k for k in container if str(k) == field), field)
            return doc.key(container, key)
        if field in container:
            return doc.value(container, field)
        for name in _LISTS:  # a list-level problem (duplicate names...)
            if field == name and name in container:
                return doc.value(container, name)
    return doc.where(container)


def _kind(value: object) -> str:
    return "nothing" if value is None else f"a {type(value).__name__}"


def _kind_names() -> dict[str, int]:
    names: dict[str, int] = {}
    for kind, hal4rt in HAL4RT_KIND_NAMES.items():
        names[hal4rt.lower()] = int(kind)
        names[hal4rt.lower().removesuffix("sensor")] = int(kind)
    names.update((kind.name.lower(), int(kind)) for kind in DeviceKind)
    return names


_KIND_NAMES = _kind_names()


def _kind_id(value: object) -> int:
    """A sensor kind (an id or a name) as an id; BadParameterError naming ``kind``."""
    if isinstance(value, str):
        kind = _KIND_NAMES.get(value.strip().lower())
        if kind is None:
            raise BadParameterError(
                "kind",
                value,
                "a device kind id (0..0xFFFFFFFF) or name: "
                + ", ".join(sorted({k.name.lower() for k in DeviceKind}))
                + "; or a HAL4RT class: "
                + ", ".join(sorted(HAL4RT_KIND_NAMES.values())),
            )
        return kind
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 0xFFFFFFFF:
        raise BadParameterError(
            "kind", value, "a device kind id (int in 0..0xFFFFFFFF), a kind name or None"
        )
    return int(value)


def _fields_of(cls: type, data: object, where: str, *, required: str) -> dict[str, Any]:
    if not isinstance(data, Mapping):
        raise BadParameterError(where, data, "a name or a mapping of fields")
    known = {f.name for f in fields(cls)}
    unknown = sorted((k for k in data if k not in known), key=str)
    if unknown:
        key = unknown[0]  # the key itself: YAML keys need not be strings (1, null, ...)
        raise BadParameterError(
            f"{where}.{key}", data[key], f"a known field ({did_you_mean(str(key), known)})"
        )
    if required not in data:
        raise BadParameterError(f"{where}.{required}", None, f"a {required} name (required)")
    values = dict(data)
    for key in ("position_limits", "units"):
        if isinstance(values.get(key), list):
            values[key] = tuple(values[key])
    return values


def _non_default(spec: Any, always: str) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for f in fields(spec):
        value = getattr(spec, f.name)
        if f.name == always or value != f.default:
            if isinstance(value, tuple):
                value = list(value)
            elif isinstance(value, Mapping):
                value = dict(value)
            out[f.name] = value
    return out


def _compact(values: dict[str, Any], key: str) -> str | dict[str, Any]:
    return values[key] if len(values) == 1 else values
