"""Driver logic without ROS or a bus: command validation, limits, watchdogs, settings."""

from __future__ import annotations

import math

import pytest

from transparency_ros.core.driver import (
    CommandRejectedError,
    DriverCore,
    DriverMode,
    DriverSettings,
    JointTarget,
    SettingsError,
    TimeoutAction,
    parse_joint_command,
)


def test_parse_joint_command_picks_our_joint() -> None:
    target = parse_joint_command("knee", ["hip", "knee"], [0.1, 0.2], [1.0, 2.0], [])
    assert target == JointTarget(0.2, 2.0, 0.0)
    assert parse_joint_command("knee", [], [0.3], [], []) == JointTarget(0.3, 0.0, 0.0)


@pytest.mark.parametrize(
    ("names", "pos", "vel", "eff", "reason"),
    [
        (["a"], [math.nan], [], [], "position of 'a' is nan"),
        (["a"], [0.0], [math.inf], [], "velocity of 'a' is inf"),
        (["a", "b"], [0.0], [], [], r"position has 1 entries for 2 joint\(s\)"),
        (["a"], [0.0], [1.0, 2.0], [], "velocity has 2 entries"),
        (["b"], [0.0], [], [], "joint 'a' not in command names"),
        (["a"], [], [], [], "neither position nor effort given"),
        ([], [0.0, 1.0], [], [], r"position has 2 entries for 1 joint\(s\)"),
    ],
)
def test_bad_commands_are_rejected_with_a_reason(
    names: list[str], pos: list[float], vel: list[float], eff: list[float], reason: str
) -> None:
    with pytest.raises(CommandRejectedError, match=reason):
        parse_joint_command("a", names, pos, vel, eff)


def test_limits_clamp_targets() -> None:
    core = DriverCore(
        DriverSettings(
            position_min_rad=-1, position_max_rad=1, velocity_limit_rad_s=2, torque_limit_nm=0.5
        )
    )
    core.activate(0.0)
    assert core.set_target(JointTarget(5.0, -9.0, 3.0), now_s=0.0) is True
    cmd = core.command(0.0)
    assert cmd is not None
    assert (cmd.position_rad, cmd.velocity_rad_s, cmd.torque_ff_nm) == (1.0, -2.0, 0.5)
    assert core.status.commands_clamped == 1
    assert core.set_target(JointTarget(0.5), now_s=0.0) is False


def test_holds_the_activation_position_until_a_command_arrives() -> None:
    core = DriverCore(DriverSettings(k_s_nm_per_rad=3.0))
    assert core.command(0.0) is None  # inactive: nothing is driven
    core.activate(0.7)
    cmd = core.command(100.0)
    assert cmd is not None and cmd.position_rad == 0.7 and cmd.kp_nm_per_rad == 3.0
    assert not core.status.command_timed_out


@pytest.mark.parametrize("action", list(TimeoutAction))
def test_command_watchdog(action: TimeoutAction) -> None:
    core = DriverCore(
        DriverSettings(
            command_timeout_s=0.5, timeout_action=action, timeout_damping_nms_per_rad=0.2
        )
    )
    core.activate(0.0)
    core.set_target(JointTarget(1.0), now_s=10.0)
    core.on_feedback(0.8)
    live = core.command(10.4)
    assert live is not None and live.position_rad == 1.0
    stale = core.command(10.6)
    assert stale is not None and core.status.command_timed_out
    if action is TimeoutAction.HOLD:
        assert (stale.position_rad, stale.kp_nm_per_rad) == (0.8, 2.0)  # where it was
        core.on_feedback(0.9)
        again = core.command(11.0)
        assert again is not None and again.position_rad == 0.8  # the hold does not creep
    else:
        assert (stale.kp_nm_per_rad, stale.kd_nms_per_rad) == (0.0, 0.2)
    core.set_target(JointTarget(0.2), now_s=11.0)
    fresh = core.command(11.0)
    assert fresh is not None and fresh.position_rad == 0.2 and not core.status.command_timed_out


def test_reply_watchdog_trips_on_silence_over_enough_requests() -> None:
    """Silent = no reply for reply_silence_s since the first unanswered request, over at least
    min_unanswered requests: a stall of the host, during which nothing was asked, is not."""
    core = DriverCore(DriverSettings(reply_silence_s=0.010))
    core.activate(0.0)
    assert [core.on_missed_reply(t, 3) for t in (0.000, 0.004)] == [False, False]
    core.on_feedback(0.0, 0.006)  # a reply ends the silence
    assert core.status.longest_silence_s == pytest.approx(0.006)
    # the host stalls 0.5 s between two requests: long, but only two went unanswered
    assert [core.on_missed_reply(t, 3) for t in (1.000, 1.500)] == [False, False]
    core.on_feedback(0.0, 1.501)
    assert core.mode is DriverMode.ACTIVE and core.status.longest_silence_s == pytest.approx(0.501)
    # a motor that stays silent: 10 ms and at least 3 requests
    times = [2.000, 2.002, 2.004, 2.006, 2.008, 2.011]
    assert [core.on_missed_reply(t, 3) for t in times] == [False] * 5 + [True]
    assert core.mode is DriverMode.FAULT
    assert core.status.fault_reason == "no reply for 11 ms (6 requests unanswered)"
    assert core.command(2.012) is None
    assert core.status.missed_replies_total == 10
    core.deactivate()
    assert core.mode is DriverMode.FAULT  # only clear_fault (re-enable) leaves FAULT
    core.clear_fault()
    assert core.mode is DriverMode.INACTIVE


def test_settings_are_validated_and_updates_atomic() -> None:
    with pytest.raises(SettingsError, match="k_s must be >= 0"):
        DriverSettings(k_s_nm_per_rad=-1.0).validated()
    core = DriverCore(DriverSettings())
    with pytest.raises(SettingsError, match="position limits must satisfy min < max"):
        core.update_settings(position_min_rad=20.0, k_s_nm_per_rad=5.0)
    assert core.settings.k_s_nm_per_rad == 2.0  # nothing of the refused change applied
    assert core.update_settings(k_s_nm_per_rad=5.0).k_s_nm_per_rad == 5.0


def test_torque_commands_and_streamed_trajectories() -> None:
    core = DriverCore(DriverSettings(k_s_nm_per_rad=2.0, torque_limit_nm=3.0))
    core.activate(0.0)
    target = parse_joint_command("a", ["a"], [], [], [-9.0])
    assert target == JointTarget(None, 0.0, -9.0)
    core.set_target(target, now_s=1.0)
    cmd = core.command(1.0)
    assert cmd is not None and (cmd.kp_nm_per_rad, cmd.kd_nms_per_rad) == (0.0, 0.0)
    assert cmd.torque_ff_nm == -3.0  # clamped to the torque limit
    # theta_d moves on with theta_d' between updates: no stair steps at the command rate
    core.set_target(JointTarget(1.0, 2.0), now_s=2.0)
    later = core.command(2.004)
    assert later is not None and later.position_rad == pytest.approx(1.008)
