"""Issue 23 point 5: bus load computed, not hoped for -- frame times with worst-case stuffing,
the load of a rig's CAN bus from its nodes and the timer driving them, and ``rig check``
refusing a bus above 100 % with what fits."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from openel_async import BadParameterError
from openel_async.cli import main as cli_main
from openel_async.rig import load_rig, resolve_rig
from openel_can.busload import Traffic, bus_load, frame_bits, frame_time


def _stuffed_bits(bits: str) -> int:
    """The stuff bits a transmitter inserts into ``bits`` (after five equal bits, one of the
    other value, which starts the next run)."""
    inserted = 0
    run_bit, run = "", 0
    for b in bits:
        if b == run_bit:
            run += 1
        else:
            run_bit, run = b, 1
        if run == 5:
            inserted += 1
            run_bit, run = ("1" if b == "0" else "0"), 1
    return inserted


def test_known_frame_lengths() -> None:
    # Davis et al. 2007, eq. 1 plus the 3-bit intermission: 8 data bytes, 11-bit id
    assert frame_bits(8) == 135
    assert frame_bits(0) == 55  # a SYNC without counter
    assert frame_bits(1) == 65  # a heartbeat
    assert frame_bits(8, extended=True) == 160
    assert frame_time(8, 1_000_000) == pytest.approx(135e-6)
    assert frame_time(8, 500_000) == pytest.approx(270e-6)


@given(payload=st.integers(0, 8), extended=st.booleans())
def test_the_worst_case_bounds_every_bit_pattern_of_the_stuffed_field(
    payload: int, extended: bool
) -> None:
    """The worst case is reached (all zeros then alternating runs of four) and never exceeded:
    the alternating 0000 1111 ... pattern inserts a stuff bit every four bits after the
    first five."""
    stuffable = (54 if extended else 34) + 8 * payload
    fixed = (64 if extended else 44) + 8 * payload
    worst = "0" * 5 + "".join("1111" if i % 2 == 0 else "0000" for i in range(stuffable))
    worst = worst[:stuffable]
    assert frame_bits(payload, extended=extended) >= fixed + _stuffed_bits(worst) + 3
    assert frame_bits(payload, extended=extended) == fixed + (stuffable - 1) // 4 + 3


@given(st.text(alphabet="01", min_size=34, max_size=98))
def test_no_bit_pattern_stuffs_more_than_the_bound(bits: str) -> None:
    assert _stuffed_bits(bits) <= (len(bits) - 1) // 4


def test_fd_frames_switch_rate_in_the_data_phase() -> None:
    classic = frame_time(8, 1_000_000)
    fd_same_rate = frame_time(8, 1_000_000, fd=True)
    fd_fast = frame_time(8, 1_000_000, fd=True, data_bitrate=5_000_000)
    assert fd_fast < classic < fd_same_rate * 1.2
    assert frame_time(64, 1_000_000, fd=True, data_bitrate=5_000_000) < 200e-6
    assert frame_time(9, 500_000, fd=True) == frame_time(12, 500_000, fd=True)  # 12-byte DLC
    with pytest.raises(BadParameterError, match="payload"):
        frame_time(65, 1_000_000, fd=True)
    with pytest.raises(BadParameterError, match="payload"):
        frame_bits(9)
    with pytest.raises(BadParameterError, match="bitrate"):
        frame_time(8, 0)


def test_bus_load_adds_each_stream_at_its_rate() -> None:
    traffic = [Traffic("TPDO", 8, 0.001, count=2), Traffic("SYNC", 0, 0.001)]
    assert bus_load(traffic, 1_000_000) == pytest.approx((2 * 135 + 55) / 1000)
    with pytest.raises(BadParameterError, match=r"TPDO\.period"):
        bus_load([Traffic("TPDO", 8, 0.0)], 1_000_000)


def _rig(tmp_path: Path, axes: int, period_ms: float, bitrate: int = 1_000_000) -> Path:
    lines = [
        "buses:",
        f"  can0: {{type: can, interface: socketcan, channel: can0, bitrate: {bitrate}}}",
        "components:",
    ]
    for n in range(1, axes + 1):
        lines.append(
            f"  - {{name: J{n}, driver: can, device: cia402_drive, bus: can0, "
            f"params: {{node_id: {n}, sync: true}}, limits: {{velocity: 5.0, acceleration: 50.0}}}}"
        )
    names = ", ".join(f"J{n}" for n in range(1, axes + 1))
    lines += [
        "groups:",
        f"  arm: {{axes: [{names}], period_ms: {period_ms}, limits: {{max_jerk: 500.0}}}}",
    ]
    path = tmp_path / "rig.yaml"
    path.write_text("\n".join(lines) + "\n")
    return path


def test_six_axes_do_not_fit_one_millisecond_at_one_megabit(tmp_path: Path) -> None:
    path = _rig(tmp_path, 6, 1.0)
    with pytest.raises(BadParameterError) as info:
        resolve_rig(load_rig(path))
    message = str(info.value)
    assert message.startswith(f"{path}:2:9: buses.can0='219% bus load")
    assert "6 axes streamed every 1 ms" in message
    # per axis RPDO (6 bytes: 115 bits) + TPDO1 (8: 135) + TPDO2 (5: 105) = 355 us; SYNC 55 us
    assert [frame_bits(n) for n in (6, 8, 5, 0)] == [115, 135, 105, 55]
    assert "2185 us worst case at 1 Mbit/s" in message
    assert "at most 2 such axes every 1 ms, or these 6 every 2.2 ms or more" in message


def test_what_fits_is_accepted_and_reported(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _rig(tmp_path, 6, 2.5)
    resolved = resolve_rig(load_rig(path))
    load = resolved.buses["can0"].load
    assert load is not None and load.cycle_s == pytest.approx(0.0025)
    assert load.fraction == pytest.approx((6 * 355 + 55) / 2500 + 6 * 65 / 1e6, rel=1e-6)
    assert cli_main(["rig", "check", str(path)]) == 0
    out = capsys.readouterr().out
    assert "bus can0: 87% load (6 axes streamed every 2.5 ms: 19 frames a cycle" in out
    assert "warning: bus can0 is 87% loaded" in out
    assert cli_main(["rig", "show", str(path)]) == 0
    assert "    load 87%: 6 axes streamed every 2.5 ms" in capsys.readouterr().out


def test_a_slower_bus_is_refused_for_the_same_axes(tmp_path: Path) -> None:
    resolve_rig(load_rig(_rig(tmp_path, 2, 1.0)))
    with pytest.raises(BadParameterError, match=r"at most 1 such axes every 1 ms, or these 2"):
        resolve_rig(load_rig(_rig(tmp_path, 2, 1.0, bitrate=500_000)))


def test_a_bus_without_a_bitrate_is_not_computed(tmp_path: Path) -> None:
    path = tmp_path / "rig.yaml"
    path.write_text(
        "buses:\n  can0: {type: can, interface: socketcan, channel: can0}\n"
        "components:\n  - {name: J1, driver: can, device: cia402_drive, bus: can0, "
        "params: {node_id: 1}}\n"
    )
    assert resolve_rig(load_rig(path)).buses["can0"].load is None


def test_the_shipped_csp4_rig_fits_1_5_ms_and_is_refused_at_1_ms(tmp_path: Path) -> None:
    rigs = Path(__file__).resolve().parents[2] / "apps" / "openel_apps" / "rigs"
    text = (rigs / "csp4.yaml").read_text()
    load = resolve_rig(load_rig(rigs / "csp4.yaml")).buses["can0"].load
    assert load is not None and "1055 us worst case" in load.detail  # 4 RPDO + 4 TPDO + SYNC
    fast = tmp_path / "csp4-1ms.yaml"
    fast.write_text(text.replace("cycle: {period_ms: 1.5}", "cycle: {period_ms: 1.0}"))
    with pytest.raises(
        BadParameterError, match=r"at most 3 such axes every 1 ms, or these 4 every 1\.1 ms"
    ):
        resolve_rig(load_rig(fast))
