"""MuJoCo sensors of a :class:`~openel_mujoco.sim.MujocoSim` as OpenEL sensors
(:class:`MujocoSensor`, and one device class per HAL4RT sensor kind for the Device Kind ID
registry), their SI units and kinds, and the geomagnetic field their magnetometers measure.

Re-exported by :mod:`openel_mujoco.devices`.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Mapping, Sequence
from operator import itemgetter
from typing import TYPE_CHECKING, Any, ClassVar, Final, cast

import mujoco
import numpy as np

from openel_async.device import (
    BatchReader,
    DeviceContext,
    DeviceInfo,
    ErrorId,
    Reading,
    SensorDevice,
)
from openel_async.direction import MagneticField
from openel_async.errors import BadParameterError, HALError
from openel_async.ids import DeviceKind

from .description import SensorSpec, spec_of
from .device_base import (
    KIND_PRODUCT_IDS,
    OTHER_KIND,
    SENSOR_PRODUCT_ID,
    VENDOR_ID,
    VENDOR_NAME,
    product_name,
)
from .models import find_id

if TYPE_CHECKING:
    from .sim import MujocoSim

__all__ = [
    "SENSOR_DEVICE_CLASSES",
    "MujocoAccelerometer",
    "MujocoEncoder",
    "MujocoForceSensor",
    "MujocoGyro",
    "MujocoMagnetometer",
    "MujocoSensor",
    "MujocoTorqueSensor",
    "ReadPlan",
    "geomagnetic_field_enu",
    "sensor_kind",
    "sensor_units",
    "set_geomagnetic_field",
]

_S = mujoco.mjtSensor
_FIXED_UNITS: Final[Mapping[int, str]] = {
    _S.mjSENS_TOUCH: "N",
    _S.mjSENS_ACCELEROMETER: "m/s^2",
    _S.mjSENS_VELOCIMETER: "m/s",
    _S.mjSENS_GYRO: "rad/s",
    _S.mjSENS_FORCE: "N",
    _S.mjSENS_TORQUE: "N m",
    _S.mjSENS_MAGNETOMETER: "T",
    _S.mjSENS_RANGEFINDER: "m",
    _S.mjSENS_CAMPROJECTION: "px",
    _S.mjSENS_BALLQUAT: "1",
    _S.mjSENS_BALLANGVEL: "rad/s",
    _S.mjSENS_TENDONPOS: "m",
    _S.mjSENS_TENDONVEL: "m/s",
    _S.mjSENS_TENDONACTFRC: "N",
    _S.mjSENS_TENDONLIMITPOS: "m",
    _S.mjSENS_TENDONLIMITVEL: "m/s",
    _S.mjSENS_TENDONLIMITFRC: "N",
    _S.mjSENS_FRAMEPOS: "m",
    _S.mjSENS_FRAMEQUAT: "1",
    _S.mjSENS_FRAMEXAXIS: "1",
    _S.mjSENS_FRAMEYAXIS: "1",
    _S.mjSENS_FRAMEZAXIS: "1",
    _S.mjSENS_FRAMELINVEL: "m/s",
    _S.mjSENS_FRAMEANGVEL: "rad/s",
    _S.mjSENS_FRAMELINACC: "m/s^2",
    _S.mjSENS_FRAMEANGACC: "rad/s^2",
    _S.mjSENS_SUBTREECOM: "m",
    _S.mjSENS_SUBTREELINVEL: "m/s",
    _S.mjSENS_SUBTREEANGMOM: "kg m^2/s",
    _S.mjSENS_INSIDESITE: "1",
    _S.mjSENS_GEOMDIST: "m",
    _S.mjSENS_GEOMNORMAL: "1",
    _S.mjSENS_GEOMFROMTO: "m",
    _S.mjSENS_E_POTENTIAL: "J",
    _S.mjSENS_E_KINETIC: "J",
    _S.mjSENS_CLOCK: "s",
}
# joint-space sensors: (unit for hinge, unit for slide)
_JOINT_UNITS: Final[Mapping[int, tuple[str, str]]] = {
    _S.mjSENS_JOINTPOS: ("rad", "m"),
    _S.mjSENS_JOINTVEL: ("rad/s", "m/s"),
    _S.mjSENS_JOINTACTFRC: ("N m", "N"),
    _S.mjSENS_JOINTLIMITPOS: ("rad", "m"),
    _S.mjSENS_JOINTLIMITVEL: ("rad/s", "m/s"),
    _S.mjSENS_JOINTLIMITFRC: ("N m", "N"),
    _S.mjSENS_ACTUATORPOS: ("rad", "m"),
    _S.mjSENS_ACTUATORVEL: ("rad/s", "m/s"),
    _S.mjSENS_ACTUATORFRC: ("N m", "N"),
}
_KINDS: Final[Mapping[int, int]] = {
    _S.mjSENS_ACCELEROMETER: DeviceKind.ACCEL,
    _S.mjSENS_FRAMELINACC: DeviceKind.ACCEL,
    _S.mjSENS_GYRO: DeviceKind.GYRO,
    _S.mjSENS_FRAMEANGVEL: DeviceKind.GYRO,
    _S.mjSENS_FORCE: DeviceKind.FORCE,
    _S.mjSENS_TENDONACTFRC: DeviceKind.FORCE,
    _S.mjSENS_TORQUE: DeviceKind.TORQUE,
    _S.mjSENS_TOUCH: DeviceKind.TOUCH,
    _S.mjSENS_MAGNETOMETER: DeviceKind.COMPASS,
    _S.mjSENS_RANGEFINDER: DeviceKind.DISTANCE,
    _S.mjSENS_FRAMEPOS: DeviceKind.DISTANCE,
    _S.mjSENS_GEOMDIST: DeviceKind.DISTANCE,
    _S.mjSENS_TENDONPOS: DeviceKind.DISTANCE,
    _S.mjSENS_SUBTREECOM: DeviceKind.DISTANCE,
    _S.mjSENS_BALLQUAT: DeviceKind.ROTARY_ANGLE,
}


ReadPlan = tuple[list[SensorDevice], Callable[[tuple[float, ...]], tuple[tuple[float, ...], ...]]]
"""The devices a simulation's sensors were last read together as, and how to cut them out of
``sensordata`` (see ``MujocoSensor.read_values_many_nowait``)."""

# Reading's generated __new__ is Python code (~225 ns); tuple.__new__ builds the same
# named tuple in half the time, on the per-read path.
_new_reading: Final = tuple.__new__


def _cutter(
    slices: Sequence[slice],
) -> Callable[[tuple[float, ...]], tuple[tuple[float, ...], ...]]:
    """One call cutting a flat tuple of sensor values into each sensor's values."""
    if len(slices) == 1:
        one = slices[0]

        def cut(values: tuple[float, ...]) -> tuple[tuple[float, ...], ...]:
            return (values[one],)

        return cut
    return cast(Callable[[tuple[float, ...]], tuple[tuple[float, ...], ...]], itemgetter(*slices))


def _sensor_joint_type(model: mujoco.MjModel, sid: int) -> int | None:
    """Joint type behind a joint or actuator sensor (None if not joint-based)."""
    objtype = int(model.sensor_objtype[sid])
    objid = int(model.sensor_objid[sid])
    if objtype == mujoco.mjtObj.mjOBJ_JOINT:
        return int(model.jnt_type[objid])
    if objtype == mujoco.mjtObj.mjOBJ_ACTUATOR and (
        int(model.actuator_trntype[objid]) == mujoco.mjtTrn.mjTRN_JOINT
    ):
        return int(model.jnt_type[int(model.actuator_trnid[objid, 0])])
    return None


def sensor_units(model: mujoco.MjModel, sid: int) -> tuple[str, ...]:
    """SI unit of each value of sensor ``sid`` ('' where MuJoCo does not define one)."""
    stype = int(model.sensor_type[sid])
    dim = int(model.sensor_dim[sid])
    unit = _FIXED_UNITS.get(stype)
    if unit is None and stype in _JOINT_UNITS:
        jtype = _sensor_joint_type(model, sid)
        hinge, slide = _JOINT_UNITS[stype]
        if jtype == mujoco.mjtJoint.mjJNT_SLIDE:
            unit = slide
        elif jtype in (mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_BALL):
            unit = hinge
    return (unit or "",) * dim


def sensor_kind(model: mujoco.MjModel, sid: int) -> int:
    """HALId device kind for sensor ``sid`` (OTHER_KIND outside the OpenEL registry)."""
    stype = int(model.sensor_type[sid])
    kind = _KINDS.get(stype)
    if kind is not None:
        return kind
    if stype in _JOINT_UNITS:
        slide = _sensor_joint_type(model, sid) == mujoco.mjtJoint.mjJNT_SLIDE
        if stype in (_S.mjSENS_JOINTACTFRC, _S.mjSENS_ACTUATORFRC, _S.mjSENS_JOINTLIMITFRC):
            return DeviceKind.FORCE if slide else DeviceKind.TORQUE
        return DeviceKind.DISTANCE if slide else DeviceKind.ROTARY_ANGLE
    return OTHER_KIND


def geomagnetic_field_enu(field: MagneticField) -> tuple[float, float, float]:
    """A World Magnetic Model field (nT: X north, Y east, Z down) as MuJoCo's
    ``opt.magnetic`` (tesla) in a world frame with x east, y north, z up (ENU)."""
    return (field.y * 1e-9, field.x * 1e-9, -field.z * 1e-9)


def set_geomagnetic_field(model: mujoco.MjModel, field: MagneticField) -> None:
    """Make the model's magnetometers measure ``field`` (the world frame taken as ENU), so
    that a :class:`~openel_async.direction.DirectionSensor` over a magnetometer on a site
    (x forward, y left, z up) gives the site's heading."""
    model.opt.magnetic[:] = geomagnetic_field_enu(field)


class MujocoSensor(SensorDevice):
    """A MuJoCo sensor of a :class:`MujocoSim` as an OpenEL sensor.

    ``read()`` returns the sensor's ``sensordata`` values (SI; MuJoCo applies the sensor's
    ``cutoff``, not its ``noise``).  ``mj_step`` computes sensors in its forward pass, *before*
    integrating, so the values describe the state at the start of the latest physics step:
    the reading's ``time_ns`` is that state's time on the simulation's clock (one time step
    before ``now_ns()`` in lockstep), monotonic from reading to reading.

    ``sim.sensor(name)`` gives a ``MujocoSensor`` of the kind of the MuJoCo sensor
    (``info.kind``: gyro -> GYRO, accelerometer -> ACCEL, ... ``sensor_kind``), whose product
    id is that of the kind's device class below, so that its HALId creates the same device
    through the Device Kind ID registry. (One class for every kind keeps a ``SensorBank`` of
    a simulation's sensors one call: the framework batches devices of one class.)
    """

    info = DeviceInfo(
        kind=OTHER_KIND,
        vendor_id=VENDOR_ID,
        product_id=SENSOR_PRODUCT_ID,
        vendor_name=VENDOR_NAME,
        product_name="Sensor",
    )
    required_kind: ClassVar[int | None] = None
    """The kind a device class of one HAL4RT kind (MujocoGyro...) requires of its sensor."""

    def __init__(
        self,
        sim: MujocoSim,
        spec: SensorSpec | str | Mapping[str, Any] | None = None,
        **fields: Any,
    ) -> None:
        """The sensor of ``spec`` (a spec, a sensor name or a dict of SensorSpec fields), or
        of the SensorSpec ``fields`` as keywords (a rig file's ``params``: ``sensor``
        defaults to ``name``); it registers itself in ``sim.sensors`` (``BadParameterError``
        when its name is mapped already). ``sim.sensor(name)`` is the usual way."""
        spec = spec_of(SensorSpec, spec, fields, "sensor")
        sim._check_new_sensor(spec)
        model = sim.model
        self.sim = sim
        self.spec = spec
        self.name = spec.key
        self.sensor_id = sid = find_id(model, "sensor", spec.sensor)
        self.sensor_type = mujoco.mjtSensor(int(model.sensor_type[sid]))
        self.dim = int(model.sensor_dim[sid])
        self._start = int(model.sensor_adr[sid])
        self._end = self._start + self.dim
        self._slice = slice(self._start, self._end)
        self.units = spec.units if spec.units is not None else sensor_units(model, sid)
        if len(self.units) != self.dim:
            raise BadParameterError(
                "units", self.units, f"{self.dim} unit(s) for sensor {spec.sensor!r}"
            )
        kind = spec.kind_id
        if kind is None:
            kind = sensor_kind(model, sid)
        required = self.required_kind
        if required is not None and kind != required:
            raise BadParameterError(
                "sensor",
                spec.sensor,
                f"a sensor of kind {DeviceKind(required).name} for a {type(self).__name__} "
                f"(a {self.sensor_type.name.removeprefix('mjSENS_').lower()} sensor of kind "
                f"0x{kind:X}: use sim.sensor)",
            )
        self.info = DeviceInfo(
            kind=kind,
            vendor_id=VENDOR_ID,
            product_id=KIND_PRODUCT_IDS.get(kind, SENSOR_PRODUCT_ID),
            vendor_name=VENDOR_NAME,
            product_name=product_name(self.name, "Sensor"),
        )
        self._ctx: DeviceContext | None = None
        self._rejected = 0
        sim._sensors[spec.key] = self

    async def open(self, ctx: DeviceContext) -> None:
        if not self.sim._attach(self, ctx):
            self._rejected += 1  # the failed component's close() must not detach the owner
            raise HALError(f"{self.name}: device already belongs to a component")
        self._ctx = ctx

    async def init(self) -> None:
        self.sim._check_running_state()

    async def reset(self) -> None:
        self.sim._recover()

    async def close(self) -> None:
        if self._rejected:
            self._rejected -= 1
            return
        self.sim._detach(self)
        self._ctx = None

    async def read(self) -> Reading:
        return self.read_nowait()

    def read_nowait(self) -> Reading:
        sim = self.sim
        if sim._fault is not None:
            raise HALError(f"{self.name}: the simulation is faulted: {sim._fault}")
        values = sim._sensordata_tuple()[self._slice]
        return _new_reading(Reading, (values, sim._sensor_clock_ns))

    @classmethod
    def read_values_many_nowait(cls, devices: Sequence[SensorDevice]) -> list[Sequence[float]]:
        """Sensors of one simulation: slices of one conversion of ``sensordata``, cut by one
        ``itemgetter`` planned once per list of devices (a bank reads the same list at every
        step)."""
        first = devices[0] if devices else None
        if type(first) is not cls or not isinstance(first, MujocoSensor):
            return super().read_values_many_nowait(devices)
        sim = first.sim
        if sim._fault is not None:
            raise HALError(f"{sim.name}: the simulation is faulted: {sim._fault}")
        plan = sim._read_plan
        if plan is None or plan[0] != devices:
            plan = cls._read_plan_of(sim, devices)
            if plan is None:
                return super().read_values_many_nowait(devices)  # mixed devices or simulations
        return list(plan[1](sim._sensordata_tuple()))

    @classmethod
    def batch_reader(cls, devices: Sequence[SensorDevice]) -> BatchReader | None:
        """Sensors of one simulation: a SensorBank's read as one copy of their ``sensordata``
        values and one ``itemgetter`` cutting it into each sensor's tuple; None for other
        devices.  The copy is of one numpy view made here, spanning every sensor of the bank
        (and the values between them, when they are fewer than the bank's: the bank's
        finiteness check then covers them too, and looks sensor by sensor only if one is
        not finite), else one gather of exactly the bank's values."""
        sensors = [d for d in devices if type(d) is cls and isinstance(d, MujocoSensor)]
        if not sensors or len(sensors) != len(devices):
            return None
        sim = sensors[0].sim
        if any(s.sim is not sim for s in sensors):
            return None
        count = sum(s.dim for s in sensors)
        low = min(s._start for s in sensors)
        high = max(s._end for s in sensors)
        spanned = high - low <= 2 * count
        cuts: list[slice] = []
        at = 0
        for sensor in sensors:
            start = sensor._start - low if spanned else at
            cuts.append(slice(start, start + sensor.dim))
            at += sensor.dim
        cut = _cutter(cuts)
        sensordata = sim._sensordata
        if spanned:
            # the bytes of MjData's own buffer (never reallocated): the current values,
            # unpacked as they are into a tuple of floats
            span = memoryview(sensordata[low:high]).cast("B")
            unpack = struct.Struct(f"{high - low}d").unpack

            def read() -> tuple[Sequence[float], tuple[tuple[float, ...], ...]]:
                if sim._fault is not None:
                    raise HALError(f"{sim.name}: the simulation is faulted: {sim._fault}")
                flat = unpack(span)
                return flat, cut(flat)

        else:
            gather = np.array([i for s in sensors for i in range(s._start, s._end)], np.intp)

            def read() -> tuple[Sequence[float], tuple[tuple[float, ...], ...]]:
                if sim._fault is not None:
                    raise HALError(f"{sim.name}: the simulation is faulted: {sim._fault}")
                flat = tuple(sensordata[gather].tolist())
                return flat, cut(flat)

        return read

    @classmethod
    def _read_plan_of(cls, sim: MujocoSim, devices: Sequence[SensorDevice]) -> ReadPlan | None:
        slices = []
        for device in devices:
            # type() rather than isinstance(): ABC instance checks cost ~150 ns
            if type(device) is not cls or not isinstance(device, MujocoSensor):
                return None
            if device.sim is not sim:
                return None
            slices.append(device._slice)
        cut = _cutter(slices)
        plan = sim._read_plan = (list(devices), cut)
        return plan

    @property
    def values(self) -> tuple[float, ...]:
        """The current values, without the component (for recorders and tests)."""
        return tuple(self.sim._sensordata[self._start : self._end].tolist())

    def _fault(self, reason: str) -> None:
        ctx = self._ctx
        if ctx is not None:
            ctx.fault(ErrorId.DEVICE_ERROR, reason)

    def __repr__(self) -> str:
        kind = self.sensor_type.name.removeprefix("mjSENS_").lower()
        return f"MujocoSensor({self.name!r}, {kind}, dim={self.dim}, sim={self.sim.name!r})"


# -- one device class per HAL4RT sensor kind: the Device Kind ID registry's entries ----------


def _kind_info(kind: DeviceKind, product_name: str) -> DeviceInfo:
    return DeviceInfo(kind, VENDOR_ID, KIND_PRODUCT_IDS[kind], VENDOR_NAME, product_name)


class MujocoEncoder(MujocoSensor):
    """A ``jointpos`` (or ``actuatorpos``, ``jointvel``...) sensor of a hinge: HAL4RT Encoder
    (``ROTARY_ANGLE``), rad."""

    info = _kind_info(DeviceKind.ROTARY_ANGLE, "Encoder")
    units = ("rad",)
    required_kind = DeviceKind.ROTARY_ANGLE


class MujocoGyro(MujocoSensor):
    """A ``gyro`` (or ``frameangvel``) sensor: HAL4RT Gyro Sensor (``GYRO``), rad/s x3."""

    info = _kind_info(DeviceKind.GYRO, "Gyro")
    units = ("rad/s",) * 3
    required_kind = DeviceKind.GYRO


class MujocoAccelerometer(MujocoSensor):
    """An ``accelerometer`` (or ``framelinacc``) sensor: HAL4RT Acceleration Sensor
    (``ACCEL``), m/s^2 x3."""

    info = _kind_info(DeviceKind.ACCEL, "Accelerometer")
    units = ("m/s^2",) * 3
    required_kind = DeviceKind.ACCEL


class MujocoForceSensor(MujocoSensor):
    """A ``force`` sensor (or a slide's ``jointactuatorfrc``, ``tendonactfrc``...): HAL4RT
    Force Sensor (``FORCE``), N x3."""

    info = _kind_info(DeviceKind.FORCE, "ForceSensor")
    units = ("N",) * 3
    required_kind = DeviceKind.FORCE


class MujocoTorqueSensor(MujocoSensor):
    """A ``torque`` sensor (or a hinge's ``jointactuatorfrc``...): HAL4RT Torque Sensor
    (``TORQUE``), N m x3."""

    info = _kind_info(DeviceKind.TORQUE, "TorqueSensor")
    units = ("N m",) * 3
    required_kind = DeviceKind.TORQUE


class MujocoMagnetometer(MujocoSensor):
    """A ``magnetometer`` sensor: HAL4RT Direction Sensor (``COMPASS``), the raw field
    vector in the site's frame, T x3 (``DirectionSensor(frame="FLU")`` computes the heading;
    :func:`set_geomagnetic_field` sets the field)."""

    info = _kind_info(DeviceKind.COMPASS, "Magnetometer")
    units = ("T",) * 3
    required_kind = DeviceKind.COMPASS


SENSOR_DEVICE_CLASSES: Final[Mapping[int, type[MujocoSensor]]] = {
    cls.info.kind: cls
    for cls in (
        MujocoEncoder,
        MujocoGyro,
        MujocoAccelerometer,
        MujocoForceSensor,
        MujocoTorqueSensor,
        MujocoMagnetometer,
    )
}
"""The device class of each HAL4RT sensor kind MuJoCo simulates (registered by the driver)."""
