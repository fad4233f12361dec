"""The Go2 over unitree_sdk2's DDS: `Go2Robot` (the controller) and `Go2DdsLink` (the
simulated robot's side), each in a process of its own, on the loopback interface only.

The SDK holds one DDS domain per process and Cyclone DDS runs threads of its own, so both
ends live in helper processes (`HelperProcess`) and this process never starts DDS.
"""

from __future__ import annotations

import dataclasses
import itertools
import sys
import threading
import time
from typing import Any

import numpy as np
import pytest

pytest.importorskip("unitree_sdk2py", reason="needs the Go2 SDK: pip install 'quaddance[go2]'")

from quaddance.children import HelperProcess
from quaddance.deploy.dds import cyclonedds_config
from quaddance.deploy.go2_backend import SERVO_MODE, fill_low_cmd, reading_from_low_state
from quaddance.deploy.go2_sim import fill_low_state, joint_command_from_low_cmd
from quaddance.deploy.go2_wire import (
    decode_low_cmd,
    decode_low_state,
    seal_low_cmd,
    seal_low_state,
)
from quaddance.deploy.remote import DAMP_KEYS, KEY_A
from quaddance.deploy.robot import JointCommand
from quaddance.deploy.simulator import SensorState
from quaddance.errors import QuaddanceError
from quaddance.robots import GO2

DOMAIN = 86  #: this file's DDS domain, used by no other test
IDLE_MOTOR = 4  #: an SDK motor left in idle mode by the packed command

# A robot whose SDK order differs from the model's in every way the table allows.
_SHUFFLED = dataclasses.replace(
    GO2,
    sdk_joint_index=(3, 4, 5, 0, 1, 2, 9, 10, 11, 6, 7, 8),
    sdk_joint_sign=(-1.0, 1.0, 1.0, 1.0, -1.0, 1.0, 1.0, 1.0, -1.0, -1.0, -1.0, 1.0),
    sdk_foot_index=(2, 0, 3, 1),
)


def _f32(x: Any) -> np.ndarray:
    """What a value reads after a float32 field."""
    return np.asarray(x, dtype=np.float32).astype(np.float64)


def _command() -> JointCommand:
    j = np.arange(12.0)
    return JointCommand(0.1 * j - 0.5, 1.0 + j, 10.0 + j, 0.3 + 0.01 * j, -2.0 - 0.5 * j)


def _state(tick: int = 1234) -> SensorState:
    j = np.arange(12.0)
    quat = np.array([0.9, 0.1, -0.2, 0.3])
    return SensorState(
        tick=tick,
        time_s=2.468,
        mono_s=time.monotonic(),
        quat_wxyz=quat / np.linalg.norm(quat),
        gyro_rad_s=np.array([0.4, -0.5, 0.6]),
        accel_m_s2=np.array([0.1, 0.2, 9.7]),
        joint_pos_rad=0.05 * j - 0.3,
        joint_vel_rad_s=2.0 - 0.25 * j,
        joint_tau_nm=3.0 - 0.5 * j,
        foot_force_n=np.array([11.2, 22.7, 33.0, 44.4]),
        battery_pct=57.0,
        remote_keys=DAMP_KEYS | KEY_A,
    )


def _assert_command_equal(got: JointCommand, want: JointCommand) -> None:
    """Equal to float32 precision (the fields are float32 on the wire)."""
    for name in ("q_rad", "dq_rad_s", "kp", "kd", "tau_ff_nm"):
        np.testing.assert_allclose(getattr(got, name), getattr(want, name), 0, 1e-6, err_msg=name)


# ---- in this process: the tables, without DDS ---------------------------------------------


@pytest.mark.parametrize("robot", [GO2, _SHUFFLED], ids=["go2", "shuffled"])
def test_the_joint_map_round_trips(robot):
    from unitree_sdk2py.idl.default import (
        unitree_go_msg_dds__LowCmd_,
        unitree_go_msg_dds__LowState_,
    )

    values = np.arange(1.0, 13.0)
    np.testing.assert_array_equal(robot.from_sdk(robot.to_sdk(values)), values)
    np.testing.assert_array_equal(robot.feet_from_sdk(robot.feet_to_sdk(values[:4])), values[:4])

    msg = unitree_go_msg_dds__LowCmd_()
    motors = decode_low_cmd(fill_low_cmd(msg, _command(), robot))
    assert all(msg.motor_cmd[i].mode == SERVO_MODE for i in range(12))
    assert all(msg.motor_cmd[i].mode == 0 for i in range(12, 20))  # the Go2 has 12 motors
    assert motors is not None and motors.crc_ok
    _assert_command_equal(joint_command_from_low_cmd(motors, robot), _command())

    state = _state()
    low = unitree_go_msg_dds__LowState_()
    fill_low_state(low, state, robot)
    reading = reading_from_low_state(decode_low_state(seal_low_state(low)), robot)
    np.testing.assert_allclose(reading.joint_pos_rad, state.joint_pos_rad, 0, 1e-6)
    np.testing.assert_allclose(reading.joint_vel_rad_s, state.joint_vel_rad_s, 0, 1e-6)
    np.testing.assert_array_equal(reading.foot_force_n, np.rint(state.foot_force_n))
    # The table itself: model joint j is SDK motor sdk_joint_index[j], times its sign.
    for j, (i, sign) in enumerate(zip(robot.sdk_joint_index, robot.sdk_joint_sign, strict=True)):
        assert low.motor_state[i].q == pytest.approx(sign * state.joint_pos_rad[j], abs=1e-6)
        assert low.motor_state[i].tau_est == pytest.approx(sign * state.joint_tau_nm[j], abs=1e-6)
    for k, i in enumerate(robot.sdk_foot_index):
        assert low.foot_force[i] == round(state.foot_force_n[k])


def _fill_random(obj: Any, rng: np.random.Generator) -> None:
    """Give every field of an IDL message a random value (ints 0-127, to fit any integer type
    the SDK packs; floats exact in float32)."""
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if dataclasses.is_dataclass(value):
            _fill_random(value, rng)
        elif isinstance(value, list) and value and dataclasses.is_dataclass(value[0]):
            for item in value:
                _fill_random(item, rng)
        elif isinstance(value, list):
            setattr(obj, f.name, [_random_like(v, rng) for v in value])
        else:
            setattr(obj, f.name, _random_like(value, rng))


def _random_like(like: float, rng: np.random.Generator) -> float:
    if isinstance(like, int):
        return int(rng.integers(0, 128))
    return float(np.float32(rng.normal(0.0, 100.0)))


@pytest.mark.parametrize("seed", range(5))
def test_messages_serialize_to_cyclonedds_bytes_with_the_sdks_crc(seed):
    from unitree_sdk2py.idl.default import (
        unitree_go_msg_dds__LowCmd_,
        unitree_go_msg_dds__LowState_,
    )
    from unitree_sdk2py.utils.crc import CRC

    rng = np.random.default_rng(seed)
    for make, seal in (
        (unitree_go_msg_dds__LowCmd_, seal_low_cmd),
        (unitree_go_msg_dds__LowState_, seal_low_state),
    ):
        msg = make()
        _fill_random(msg, rng)
        wire = seal(msg)
        assert msg.crc == CRC().Crc(msg)
        assert wire == type(msg).serialize(msg)

    cmd = unitree_go_msg_dds__LowCmd_()
    _fill_random(cmd, rng)
    wire = seal_low_cmd(cmd)
    motors = decode_low_cmd(wire)
    assert motors is not None and motors.crc_ok
    for name in ("mode", "q", "dq", "tau", "kp", "kd"):
        np.testing.assert_array_equal(
            getattr(motors, name), [getattr(m, name) for m in cmd.motor_cmd]
        )
    corrupt = bytearray(wire)
    corrupt[100] ^= 1
    assert not decode_low_cmd(bytes(corrupt)).crc_ok
    assert decode_low_cmd(wire[:-4]) is None  # too short
    assert decode_low_cmd(b"\x00\x00" + wire[2:]) is None  # big-endian: not what a Go2 sends

    low = unitree_go_msg_dds__LowState_()
    _fill_random(low, rng)
    wire = seal_low_state(low)
    state = decode_low_state(wire)
    assert state is not None and state.crc_ok
    assert state.tick == low.tick and state.soc == low.bms_state.soc
    np.testing.assert_array_equal(state.quat_wxyz, low.imu_state.quaternion)
    np.testing.assert_array_equal(state.gyro_rad_s, low.imu_state.gyroscope)
    np.testing.assert_array_equal(state.q, [m.q for m in low.motor_state])
    np.testing.assert_array_equal(state.dq, [m.dq for m in low.motor_state])
    np.testing.assert_array_equal(state.foot_force, low.foot_force)
    assert state.wireless_remote == bytes(low.wireless_remote)
    corrupt = bytearray(wire)
    corrupt[200] ^= 1
    assert not decode_low_state(bytes(corrupt)).crc_ok
    assert decode_low_state(wire[:-4]) is None


def test_dds_stays_on_loopback_and_names_the_robots_interface():
    lo = cyclonedds_config("lo")
    assert 'multicast="false"' in lo and "<AllowMulticast>false</AllowMulticast>" in lo
    assert lo.count("<Peer ") == 1 and '<Peer Address="127.0.0.1"/>' in lo
    wired = cyclonedds_config("enp3s0")
    assert 'name="enp3s0"' in wired and "Peer" not in wired and "Multicast" not in wired
    with pytest.raises(QuaddanceError, match="not a network interface"):
        cyclonedds_config('eth0"/><x')


# ---- across processes: the simulated robot's link and the controller ----------------------

_here: dict[str, Any] = {}  # in each helper process: its DDS endpoints


def _open_link() -> None:
    from quaddance.deploy.go2_sim import Go2DdsLink

    _here["link"] = Go2DdsLink("lo", DOMAIN)


def _switcher() -> tuple[str, int]:
    s = _here["link"].switcher
    return s.mode, s.releases


def _poll(until_s: float, stop_when: JointCommand | None = None) -> tuple[list, int]:
    """Commands the link received within ``until_s`` (or up to one like ``stop_when``), and
    its count of rejected ones."""
    got: list[JointCommand] = []
    end = time.monotonic() + until_s
    while time.monotonic() < end:
        got += _here["link"].poll()
        if stop_when is not None and any(_same(c, stop_when) for c in got):
            break
        time.sleep(0.005)
    return got, _here["link"].rejected


def _same(a: JointCommand, b: JointCommand) -> bool:
    return all(
        np.array_equal(getattr(a, k), _f32(getattr(b, k)))
        for k in ("q_rad", "dq_rad_s", "kp", "kd", "tau_ff_nm")
    )


def _publish_states(state: SensorState) -> None:
    """Publish ``state`` at 100 Hz from a thread, its clock running."""

    def loop() -> None:
        for k in itertools.count():
            _here["link"].publish(dataclasses.replace(state, time_s=state.time_s + 0.01 * k))
            time.sleep(0.01)

    threading.Thread(target=loop, daemon=True).start()


def _sdk_low_cmd(base: float, idle_motor: int | None = None, bad_crc: bool = False) -> Any:
    """A LowCmd_ packed as the SDK's examples do: distinct values for every motor."""
    from unitree_sdk2py.idl.default import unitree_go_msg_dds__LowCmd_
    from unitree_sdk2py.utils.crc import CRC

    msg = unitree_go_msg_dds__LowCmd_()
    msg.head[:] = [0xFE, 0xEF]
    msg.level_flag = 0xFF
    for i in range(20):
        m = msg.motor_cmd[i]
        m.mode = 0 if i == idle_motor else SERVO_MODE
        m.q, m.dq = base + 0.1 * i, base - 0.2 * i
        m.kp, m.kd, m.tau = 20.0 + i, 0.5 + 0.01 * i, base + 0.3 * i
    msg.crc = CRC().Crc(msg)
    if bad_crc:
        msg.crc ^= 1
    return msg


def _send_sdk_low_cmds(msgs: list) -> None:
    from quaddance.deploy.dds import init_dds

    init_dds("lo", DOMAIN)
    if "pub" not in _here:
        from unitree_sdk2py.core.channel import ChannelPublisher
        from unitree_sdk2py.idl.unitree_go.msg.dds_ import LowCmd_

        _here["pub"] = ChannelPublisher("rt/lowcmd", LowCmd_)
        _here["pub"].Init()
    for msg in msgs:
        assert _here["pub"].Write(msg, 5.0)  # waits for the link to be matched
        time.sleep(0.005)


def _start_robot() -> tuple:
    from quaddance.deploy.go2_backend import Go2Robot

    robot = _here["robot"] = Go2Robot(DOMAIN, "lo")
    t0 = time.monotonic()
    reading = robot.start(timeout_s=10.0)
    return reading, time.monotonic() - t0, robot.info()


def _robot_send(cmd: JointCommand) -> None:
    _here["robot"].send(cmd)


def _expected_from_sdk(msg: Any, robot=GO2) -> JointCommand:
    """What the link must make of an SDK command: per model joint, its SDK motor's fields."""
    mc = [msg.motor_cmd[i] for i in robot.sdk_joint_index]
    sign = np.asarray(robot.sdk_joint_sign)
    servo = np.array([m.mode == SERVO_MODE for m in mc])
    return JointCommand(
        sign * _f32([m.q for m in mc]),
        sign * _f32([m.dq for m in mc]),
        np.where(servo, _f32([m.kp for m in mc]), 0.0),
        np.where(servo, _f32([m.kd for m in mc]), 0.0),
        np.where(servo, sign * _f32([m.tau for m in mc]), 0.0),
    )


@pytest.fixture(scope="module")
def sides():
    """(the simulated robot's process with its link, the controller's process)."""
    sim, ctl = HelperProcess(), HelperProcess()
    try:
        sim.call(_open_link)
        yield sim, ctl
    finally:
        for helper in (sim, ctl):
            helper.close()
        for helper in (sim, ctl):
            helper._proc.join(timeout=10)


def test_a_command_packed_by_the_sdk_decodes_to_every_field(sides):
    sim, ctl = sides
    msg = _sdk_low_cmd(0.25, idle_motor=IDLE_MOTOR)
    ctl.call(_send_sdk_low_cmds, msgs=[msg])
    want = _expected_from_sdk(msg)
    got, rejected = sim.call(_poll, until_s=5.0, stop_when=want)
    assert rejected == 0
    assert got, "no command reached the link"
    _assert_command_equal(got[-1], want)
    j = GO2.sdk_joint_index.index(IDLE_MOTOR)  # the idle motor: no gain, no torque
    assert got[-1].kp[j] == got[-1].kd[j] == got[-1].tau_ff_nm[j] == 0.0
    assert got[-1].q_rad[j] == pytest.approx(0.25 + 0.1 * IDLE_MOTOR, abs=1e-6)


def test_a_command_with_a_bad_crc_is_counted_and_never_applied(sides):
    sim, ctl = sides
    bad = _sdk_low_cmd(-0.75, bad_crc=True)
    good = _sdk_low_cmd(0.5)
    _, before = sim.call(_poll, until_s=0.0)
    ctl.call(_send_sdk_low_cmds, msgs=[bad, bad, bad, good])
    got, after = sim.call(_poll, until_s=5.0, stop_when=_expected_from_sdk(good))
    assert after - before == 3
    assert not any(_same(c, _expected_from_sdk(bad)) for c in got)
    assert _same(got[-1], _expected_from_sdk(good))


@pytest.fixture(scope="module")
def started(sides):
    """The controller's `Go2Robot` started against the link: what the link's motion switcher
    said before and after, the first reading, the start's duration and the backend's info."""
    sim, ctl = sides
    before = sim.call(_switcher)
    sim.call(_publish_states, state=_state())
    reading, start_s, info = ctl.call(_start_robot)
    after = sim.call(_switcher)
    return {"before": before, "after": after, "reading": reading, "start_s": start_s, "info": info}


def test_the_backend_releases_sport_mode_through_the_motion_switcher(started):
    assert started["before"] == ("normal", 0)
    assert started["after"] == ("", 1)
    assert started["info"]["released_modes"] == ["normal"]
    assert started["info"]["lowcmd_sent"] == 0
    assert started["start_s"] < 5.0


def test_a_state_published_by_the_link_reaches_read_with_every_field(started):
    r, s = started["reading"], _state()
    assert r.seq >= s.clock_ms and r.stamp_s == r.seq / 1000.0  # the robot's clock, ms
    np.testing.assert_array_equal(r.quat_wxyz, _f32(s.quat_wxyz))
    np.testing.assert_array_equal(r.gyro_rad_s, _f32(s.gyro_rad_s))
    np.testing.assert_array_equal(r.joint_pos_rad, _f32(s.joint_pos_rad))
    np.testing.assert_array_equal(r.joint_vel_rad_s, _f32(s.joint_vel_rad_s))
    np.testing.assert_array_equal(r.foot_force_n, [11.0, 23.0, 33.0, 44.0])  # int16 on a Go2
    assert r.battery_pct == 57.0
    assert r.remote_keys == DAMP_KEYS | KEY_A


def test_the_backend_sends_nothing_before_the_first_command_then_500_hz(sides, started):
    sim, ctl = sides
    got, rejected = sim.call(_poll, until_s=0.3)
    assert got == []  # started, reading, but no command yet: a dry run sends nothing
    cmd = _command()
    ctl.call(_robot_send, cmd=cmd)
    sim.call(_poll, until_s=5.0, stop_when=cmd)
    got, after = sim.call(_poll, until_s=1.0)
    assert after == rejected  # the backend's CRC is the SDK's
    assert all(_same(c, cmd) for c in got)
    assert len(got) > 250  # 500 Hz, with room for a busy machine


def _start_without_a_robot(domain: int) -> str:
    from quaddance.deploy.go2_backend import Go2Robot

    try:
        Go2Robot(domain, "lo", release_timeout_s=0.5).start(timeout_s=1.0)
    except QuaddanceError as err:
        return str(err)
    return "started"


def test_no_motion_switcher_is_one_clear_error():
    helper = HelperProcess()
    try:
        message = helper.call(_start_without_a_robot, domain=DOMAIN + 1)
    finally:
        helper.close()
        helper._proc.join(timeout=10)
    assert message.startswith("cannot release the Go2's sport mode on lo (DDS domain 87)")
    assert "no answer" in message


def test_a_missing_sdk_names_the_extra_to_install(monkeypatch):
    from quaddance.deploy.dds import load_sdk2

    monkeypatch.setitem(sys.modules, "unitree_sdk2py", None)  # as if not installed
    with pytest.raises(QuaddanceError, match=r"pip install 'quaddance\[go2\]'"):
        load_sdk2()


def _run_go2_sim(seconds: float) -> dict:
    """`--robot go2-sim` end to end: the simulator process, the unchanged backend."""
    from quaddance.deploy.go2_sim import go2_sim_robot

    robot = go2_sim_robot()
    first = robot.start(timeout_s=30.0)
    cmd = JointCommand.damping(first.joint_pos_rad, kd=1.0)
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        robot.send(cmd)
        time.sleep(0.02)
    last = robot.read()
    t0 = time.monotonic()
    robot.close()
    return {
        "first": first,
        "clock_ms": last.seq - first.seq,  # the robot's clock ran
        "close_s": time.monotonic() - t0,
        "received": robot.received(),
        "truth_rows": len(robot.truth()["seq"]),
    }


def test_the_go2_simulator_runs_behind_the_unchanged_backend():
    helper = HelperProcess()
    try:
        run = helper.call(_run_go2_sim, seconds=1.0)
    finally:
        helper.close()
        helper._proc.join(timeout=10)
    assert run["first"].battery_pct == 90.0 and run["first"].remote_keys == 0
    assert run["clock_ms"] > 500  # 1000 in 1 s, with room for a busy machine
    got = run["received"]
    assert got["rejected"] == 0 and got["commands"] == got["torque_commands"] > 250
    assert run["truth_rows"] > 0 and run["close_s"] < 5.0
