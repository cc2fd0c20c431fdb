"""The built-in endpoint table of an ODrive axis reachable by CANSimple RxSdo/TxSdo, for ODrive
firmware 0.6.x (ODrive Pro / S1), exact revision unknown: name, endpoint id and type
(:data:`ENDPOINTS`).

**It matches no exact firmware version.** Endpoint ids change between firmware builds, and
which 0.6 build this copy was taken from is not known: the driver and ``openel-async param``
never write an endpoint by these ids to a real ODrive (:mod:`openel_can.odrive_firmware`:
a write needs a table whose ``fw_version`` is the firmware the axis reports, i.e. the
``flat_endpoints.json`` of that firmware named in the rig). Reads by these ids are allowed
with a warning. The only firmware this table is declared for is the simulated ODrive's
(:data:`openel_can.odrive_firmware.SIMULATED_FIRMWARE`), which implements these ids by
construction.

Source: the ``flat_endpoints.json`` of firmware 0.6.x that ODrive Robotics publishes with
each release (docs.odriverobotics.com, "releases/firmware"), as copied into the endpoint
map of a third-party CANSimple library (a JavaScript package; the same copy
:data:`openel_can.odrive.VEL_RAMP_RATE_ENDPOINT`, ``WATCHDOG_TIMEOUT_ENDPOINT`` and
``ENABLE_WATCHDOG_ENDPOINT`` -- 390, 200, 201, the only endpoints the driver knew before --
come from). Carried over: the names, ids and type names, facts of the firmware's interface,
as data (no code of either); that copy's own licence was not established, so treat ODrive's
published file as the reference. Not checked against a 0.6.10/0.6.11 build or hardware:
endpoint ids change between builds, so compare them with the ``flat_endpoints.json`` of the
firmware you run (its release page) before writing. Kept: the device, CAN, inverter and
GPIO configuration, every ``axis0.config`` setting, the controller, trajectory, endstop,
thermistor and encoder settings and the main measurements (the task timers, stack
statistics and raw current samples are left out).

Types: the copy names ``float`` (float32), ``uint``, ``int`` and ``boolean``; a TxSdo value
field is 4 bytes, little-endian, a uint or int endpoint read as 32 bits (the firmware's
narrower types -- uint8/uint16 -- fill the low bytes; their upper bytes are zero in the
releases we know of), a boolean as its first byte.

Access: the copy carries no access rights (the official file does); here ``config``
settings, ``identify`` and the axis's commands are ``rw``, everything else ``ro``. The
commands -- ``requested_state``, ``controller.input_pos/vel/torque`` (:data:`COMMANDS`) --
are only read by ``openel-async param``: it never enables or moves an axis (the HAL does,
with its limits). Storage: ``ram`` for a
setting (kept at power-off only after ``save_configuration()``, which is a function
endpoint this table leaves out), ``volatile`` for a measurement.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final, Literal

__all__ = ["COMMANDS", "ENDPOINTS", "FIRMWARE", "Endpoint", "EndpointType", "endpoint_unit"]

FIRMWARE: Final = "0.6.x (ODrive Pro / S1; exact revision unknown: matches no firmware version)"
"""The firmware the built-in table is for, in words."""

EndpointType = Literal["float", "bool", "uint8", "int8", "uint16", "int16", "uint32", "int32"]
"""The value types an endpoint can have here: those of ``flat_endpoints.json`` that fit the
4-byte value field of RxSdo/TxSdo (little-endian, a narrower type in the low bytes)."""
_TYPES: Final[dict[str, EndpointType]] = {"f": "float", "u": "uint32", "i": "int32", "b": "bool"}


@dataclass(frozen=True)
class Endpoint:
    """One endpoint: its path from the device (``axis0.controller.config.vel_limit``),
    its id and type."""

    name: str
    id: int
    type: EndpointType
    access: str | None = None
    """``r``, ``w`` or ``rw`` as a ``flat_endpoints.json`` gives it (None: the built-in
    table, which carries no access rights)."""

    @property
    def writable(self) -> bool:
        """The file's access has ``w``; in the built-in table: a setting (a ``config``
        entry), ``identify`` or a command (module docstring)."""
        if self.access is not None:
            return "w" in self.access
        return (
            self.name.startswith("config.")
            or ".config." in self.name
            or self.name in COMMANDS
            or self.name == "identify"
        )


COMMANDS: Final = frozenset(
    {
        "axis0.requested_state",
        "axis0.controller.input_pos",
        "axis0.controller.input_vel",
        "axis0.controller.input_torque",
    }
)
"""Endpoints that command the axis (a state, a set-point): read, never written by ``param``."""


# id, type (f float, u uint, i int, b boolean), name
_TABLE: Final = """\
1 f vbus_voltage
2 f ibus
3 f ibus_report_filter_k
4 u control_loop_hz
5 u serial_number
6 u hw_version_major
7 u hw_version_minor
8 u hw_version_variant
9 u hw_version_revision
10 u fw_version_major
11 u fw_version_minor
12 u fw_version_revision
13 u commit_hash
14 u fw_version_unreleased
15 u bootloader_version
43 u system_stats.uptime
64 u user_config_loaded
65 b misconfigured
92 u can.error
93 u can.n_restarts
94 u can.n_rx
95 u can.config.baud_rate
96 u can.config.data_baud_rate
97 u can.config.tx_brs
98 u can.config.protocol
100 b identify
101 b reboot_required
102 u issues.length
137 b config.enable_uart_a
138 u config.uart_a_baudrate
139 u config.usb_cdc_protocol
140 u config.uart0_protocol
141 f config.max_regen_current
142 f config.dc_bus_undervoltage_trip_level
143 f config.dc_bus_overvoltage_trip_level
144 f config.dc_max_positive_current
145 f config.dc_max_negative_current
154 u config.gpio0_mode
155 u config.gpio1_mode
156 u config.gpio2_mode
157 u config.gpio3_mode
158 u config.gpio4_mode
159 u config.gpio5_mode
160 u config.gpio6_mode
161 u config.gpio7_mode
168 f config.inverter0.current_soft_max
169 f config.inverter0.current_hard_max
170 f config.inverter0.temp_limit_lower
171 f config.inverter0.temp_limit_upper
172 f config.inverter0.mod_magn_max
173 f config.inverter0.shunt_conductance
174 u config.inverter0.drv_config
175 u axis0.active_errors
176 u axis0.disarm_reason
177 b axis0.step_dir_active
178 u axis0.last_drv_fault
179 i axis0.steps
180 u axis0.current_state
181 u axis0.requested_state
182 f axis0.pos_estimate
183 f axis0.vel_estimate
184 b axis0.is_homed
185 f axis0.config.startup_max_wait_for_ready
186 b axis0.config.startup_motor_calibration
187 b axis0.config.startup_encoder_index_search
188 b axis0.config.startup_encoder_offset_calibration
189 b axis0.config.startup_closed_loop_control
190 b axis0.config.startup_homing
191 f axis0.config.init_torque
192 f axis0.config.init_vel
193 f axis0.config.init_pos
194 b axis0.config.enable_step_dir
195 b axis0.config.step_dir_always_on
196 f axis0.config.calib_range
197 f axis0.config.calib_scan_distance
198 f axis0.config.calib_scan_vel
199 b axis0.config.index_search_at_target_vel_only
200 f axis0.config.watchdog_timeout
201 b axis0.config.enable_watchdog
202 u axis0.config.step_gpio_pin
203 u axis0.config.dir_gpio_pin
204 u axis0.config.error_gpio_pin
205 b axis0.config.enable_error_gpio
206 f axis0.config.calibration_lockin.current
207 f axis0.config.calibration_lockin.ramp_time
208 f axis0.config.calibration_lockin.ramp_distance
209 f axis0.config.calibration_lockin.accel
210 f axis0.config.calibration_lockin.vel
211 f axis0.config.sensorless_ramp.initial_pos
212 f axis0.config.sensorless_ramp.current
213 f axis0.config.sensorless_ramp.ramp_time
214 f axis0.config.sensorless_ramp.ramp_distance
215 f axis0.config.sensorless_ramp.accel
216 f axis0.config.sensorless_ramp.vel
217 f axis0.config.sensorless_ramp.finish_distance
218 b axis0.config.sensorless_ramp.finish_on_vel
219 b axis0.config.sensorless_ramp.finish_on_distance
220 f axis0.config.general_lockin.initial_pos
221 f axis0.config.general_lockin.current
222 f axis0.config.general_lockin.ramp_time
223 f axis0.config.general_lockin.ramp_distance
224 f axis0.config.general_lockin.accel
225 f axis0.config.general_lockin.vel
226 f axis0.config.general_lockin.finish_distance
227 b axis0.config.general_lockin.finish_on_vel
228 b axis0.config.general_lockin.finish_on_distance
229 u axis0.config.can.node_id
230 u axis0.config.can.version_msg_rate_ms
231 u axis0.config.can.heartbeat_msg_rate_ms
232 u axis0.config.can.encoder_msg_rate_ms
233 u axis0.config.can.iq_msg_rate_ms
234 u axis0.config.can.error_msg_rate_ms
235 u axis0.config.can.temperature_msg_rate_ms
236 u axis0.config.can.bus_voltage_msg_rate_ms
237 u axis0.config.can.torques_msg_rate_ms
238 u axis0.config.can.powers_msg_rate_ms
239 u axis0.config.can.input_vel_scale
240 u axis0.config.can.input_torque_scale
241 u axis0.config.load_encoder
242 u axis0.config.commutation_encoder
243 f axis0.config.encoder_bandwidth
244 f axis0.config.commutation_encoder_bandwidth
245 f axis0.config.I_bus_hard_min
246 f axis0.config.I_bus_hard_max
247 f axis0.config.I_bus_soft_min
248 f axis0.config.I_bus_soft_max
249 f axis0.config.P_bus_soft_min
250 f axis0.config.P_bus_soft_max
251 f axis0.config.torque_soft_min
252 f axis0.config.torque_soft_max
253 u axis0.config.motor.motor_type
254 u axis0.config.motor.pole_pairs
255 f axis0.config.motor.phase_resistance
256 f axis0.config.motor.phase_inductance
257 b axis0.config.motor.phase_resistance_valid
258 b axis0.config.motor.phase_inductance_valid
259 f axis0.config.motor.torque_constant
260 f axis0.config.motor.direction
261 f axis0.config.motor.current_control_bandwidth
262 b axis0.config.motor.wL_FF_enable
263 b axis0.config.motor.bEMF_FF_enable
264 f axis0.config.motor.ff_pm_flux_linkage
265 b axis0.config.motor.ff_pm_flux_linkage_valid
269 f axis0.config.motor.calibration_current
270 f axis0.config.motor.resistance_calib_max_voltage
271 f axis0.config.motor.current_soft_max
272 f axis0.config.motor.current_hard_max
273 f axis0.config.motor.current_slew_rate_limit
274 b axis0.config.motor.fw_enable
275 f axis0.config.motor.fw_mod_setpoint
276 f axis0.config.motor.fw_fb_bandwidth
287 f axis0.config.motor.power_torque_report_filter_bandwidth
288 b axis0.config.anticogging.enabled
289 f axis0.config.anticogging.max_torque
290 f axis0.config.anticogging.calib_start_vel
291 f axis0.config.anticogging.calib_end_vel
292 f axis0.config.anticogging.calib_coarse_tuning_duration
293 f axis0.config.anticogging.calib_fine_tuning_duration
294 f axis0.config.anticogging.calib_fine_dist_scale
295 f axis0.config.anticogging.calib_coarse_integrator_gain
296 b axis0.config.anticogging.calib_bidirectional
309 f axis0.motor.alpha_beta_controller.I_bus
313 f axis0.motor.alpha_beta_controller.power
316 f axis0.motor.foc.p_gain
317 f axis0.motor.foc.i_gain
319 f axis0.motor.foc.Id_setpoint
320 f axis0.motor.foc.Iq_setpoint
325 f axis0.motor.foc.Id_measured
326 f axis0.motor.foc.Iq_measured
333 f axis0.motor.fet_thermistor.temperature
334 f axis0.motor.motor_thermistor.temperature
335 u axis0.motor.motor_thermistor.config.gpio_pin
336 f axis0.motor.motor_thermistor.config.r_ref
337 f axis0.motor.motor_thermistor.config.t_ref
338 f axis0.motor.motor_thermistor.config.beta
339 f axis0.motor.motor_thermistor.config.temp_limit_lower
340 f axis0.motor.motor_thermistor.config.temp_limit_upper
341 b axis0.motor.motor_thermistor.config.enabled
350 f axis0.motor.torque_estimate
351 f axis0.motor.mechanical_power
352 f axis0.motor.electrical_power
353 f axis0.motor.loss_power
354 f axis0.motor.effective_current_lim
367 f axis0.controller.input_pos
368 f axis0.controller.input_vel
369 f axis0.controller.input_torque
370 f axis0.controller.pos_setpoint
371 f axis0.controller.vel_setpoint
372 f axis0.controller.torque_setpoint
373 f axis0.controller.effective_torque_setpoint
374 b axis0.controller.trajectory_done
375 f axis0.controller.vel_integrator_torque
377 b axis0.controller.config.enable_vel_limit
378 b axis0.controller.config.enable_torque_mode_vel_limit
379 b axis0.controller.config.enable_gain_scheduling
380 f axis0.controller.config.gain_scheduling_width
381 b axis0.controller.config.enable_overspeed_error
382 u axis0.controller.config.control_mode
383 u axis0.controller.config.input_mode
384 f axis0.controller.config.pos_gain
385 f axis0.controller.config.vel_gain
386 f axis0.controller.config.vel_integrator_gain
387 f axis0.controller.config.vel_integrator_limit
388 f axis0.controller.config.vel_limit
389 f axis0.controller.config.vel_limit_tolerance
390 f axis0.controller.config.vel_ramp_rate
391 f axis0.controller.config.torque_ramp_rate
392 b axis0.controller.config.circular_setpoints
393 f axis0.controller.config.circular_setpoint_range
394 b axis0.controller.config.absolute_setpoints
395 b axis0.controller.config.use_commutation_vel
396 b axis0.controller.config.use_load_encoder_for_commutation_vel
397 f axis0.controller.config.commutation_vel_scale
398 i axis0.controller.config.steps_per_circular_range
399 f axis0.controller.config.homing_speed
400 f axis0.controller.config.inertia
401 f axis0.controller.config.input_filter_bandwidth
402 f axis0.controller.config.spinout_mechanical_power_bandwidth
403 f axis0.controller.config.spinout_electrical_power_bandwidth
404 f axis0.controller.config.spinout_mechanical_power_threshold
405 f axis0.controller.config.spinout_electrical_power_threshold
411 f axis0.controller.spinout_mechanical_power
412 f axis0.controller.spinout_electrical_power
416 f axis0.trap_traj.config.vel_limit
417 f axis0.trap_traj.config.accel_limit
418 f axis0.trap_traj.config.decel_limit
419 b axis0.min_endstop.state
420 u axis0.min_endstop.config.gpio_num
421 b axis0.min_endstop.config.enabled
422 f axis0.min_endstop.config.offset
423 b axis0.min_endstop.config.is_active_high
424 u axis0.min_endstop.config.debounce_ms
425 b axis0.max_endstop.state
426 u axis0.max_endstop.config.gpio_num
427 b axis0.max_endstop.config.enabled
428 f axis0.max_endstop.config.offset
429 b axis0.max_endstop.config.is_active_high
430 u axis0.max_endstop.config.debounce_ms
431 b axis0.enable_pin.state
432 u axis0.enable_pin.config.gpio_num
433 b axis0.enable_pin.config.enabled
435 b axis0.enable_pin.config.is_active_high
436 u axis0.enable_pin.config.debounce_ms
437 u axis0.mechanical_brake.config.gpio_num
438 b axis0.mechanical_brake.config.is_active_low
443 f axis0.pos_vel_mapper.pos_abs
444 f axis0.pos_vel_mapper.vel
447 b axis0.pos_vel_mapper.config.circular
448 f axis0.pos_vel_mapper.config.circular_output_range
449 f axis0.pos_vel_mapper.config.scale
450 b axis0.pos_vel_mapper.config.offset_valid
451 f axis0.pos_vel_mapper.config.offset
455 f axis0.pos_vel_mapper.config.index_offset
456 b axis0.pos_vel_mapper.config.use_index_gpio
458 u axis0.pos_vel_mapper.config.index_gpio
459 b axis0.pos_vel_mapper.config.use_endstop
532 u axis0.procedure_result
533 f axis0.disarm_time
534 b axis0.is_armed
535 f axis0.observed_encoder_scale_factor
549 b inc_encoder0.config.enabled
550 u inc_encoder0.config.cpr
556 b hall_encoder0.config.enabled
557 u hall_encoder0.config.hall_polarity
558 b hall_encoder0.config.hall_polarity_calibrated
559 b hall_encoder0.config.ignore_illegal_hall_state
"""


def _parse(text: str) -> tuple[Endpoint, ...]:
    endpoints = []
    for line in text.splitlines():
        ident, kind, name = line.split()
        endpoints.append(Endpoint(name, int(ident), _TYPES[kind]))
    return tuple(endpoints)


ENDPOINTS: Final = _parse(_TABLE)
"""The endpoints, by id."""

_EXACT: Final[dict[str, str]] = {
    "vbus_voltage": "V",
    "ibus": "A",
    "can.config.baud_rate": "bit/s",
    "can.config.data_baud_rate": "bit/s",
    "config.uart_a_baudrate": "bit/s",
    "axis0.pos_estimate": "turns",
    "axis0.vel_estimate": "turns/s",
    "axis0.config.watchdog_timeout": "s",
    "axis0.config.startup_max_wait_for_ready": "s",
    "axis0.config.calib_range": "turns",
    "axis0.config.init_pos": "turns",
    "axis0.config.init_vel": "turns/s",
    "axis0.config.init_torque": "Nm",
    "axis0.config.motor.phase_resistance": "Ω",
    "axis0.config.motor.phase_inductance": "H",
    "axis0.config.motor.torque_constant": "Nm/A",
    "axis0.config.motor.current_slew_rate_limit": "A/s",
    "axis0.controller.config.pos_gain": "(turns/s)/turn",
    "axis0.controller.config.vel_gain": "Nm/(turns/s)",
    "axis0.controller.config.vel_integrator_gain": "Nm/turn",
    "axis0.controller.config.vel_integrator_limit": "Nm",
    "axis0.controller.config.vel_ramp_rate": "turns/s²",
    "axis0.controller.config.torque_ramp_rate": "Nm/s",
    "axis0.controller.config.homing_speed": "turns/s",
    "axis0.controller.config.inertia": "Nm/(turns/s²)",
    "axis0.controller.config.circular_setpoint_range": "turns",
    "axis0.controller.config.vel_limit_tolerance": "",
    "axis0.trap_traj.config.accel_limit": "turns/s²",
    "axis0.trap_traj.config.decel_limit": "turns/s²",
    "axis0.disarm_time": "s",
}
_LOCKIN: Final[dict[str, str]] = {
    "current": "A",
    "ramp_time": "s",
    "ramp_distance": "rad",
    "initial_pos": "rad",
    "finish_distance": "rad",
    "accel": "rad/s²",
    "vel": "rad/s",
}
"""The lock-in and sensorless ramp settings: electrical radians."""
_SUFFIXES: Final = (
    ("_ms", "ms"),
    ("temperature", "°C"),
    ("temp_limit_lower", "°C"),
    ("temp_limit_upper", "°C"),
    ("bandwidth", "rad/s"),
    ("_power", "W"),
    ("power_threshold", "W"),
    ("P_bus_soft_min", "W"),
    ("P_bus_soft_max", "W"),
    ("trip_level", "V"),
    ("max_voltage", "V"),
    ("_current", "A"),
    ("current_soft_max", "A"),
    ("current_hard_max", "A"),
    ("current_lim", "A"),
    ("I_bus", "A"),
    ("vel_limit", "turns/s"),
    ("_vel", "turns/s"),
    ("vel_setpoint", "turns/s"),
    ("input_vel", "turns/s"),
    ("_pos", "turns"),
    ("pos_setpoint", "turns"),
    ("pos_abs", "turns"),
    ("_distance", "turns"),
    ("offset", "turns"),
    ("torque_estimate", "Nm"),
    ("torque_setpoint", "Nm"),
    ("input_torque", "Nm"),
    ("max_torque", "Nm"),
    ("torque_soft_min", "Nm"),
    ("torque_soft_max", "Nm"),
    ("vel_integrator_torque", "Nm"),
    ("ramp_time", "s"),
    ("_accel", "turns/s²"),
    ("_duration", "s"),
    ("Id_measured", "A"),
    ("Iq_measured", "A"),
    ("Id_setpoint", "A"),
    ("Iq_setpoint", "A"),
)


def endpoint_unit(name: str) -> str:
    """The unit of an endpoint's value, where ODrive's documentation gives one ("" else)."""
    if name in _EXACT:
        return _EXACT[name]
    last = name.rsplit(".", 1)[-1]
    if "lockin." in name or "sensorless_ramp." in name:  # electrical angles
        return _LOCKIN.get(last, "")
    if last == "current":
        return "A"
    if last == "power":
        return "W"
    if last.startswith("I_bus_"):
        return "A"
    for suffix, unit in _SUFFIXES:
        if last.endswith(suffix) or name.endswith(suffix):
            return unit
    return ""
