"""The reply policy of the bridge (pure): latest velocity, zero once it is too old in simulation time."""
from robotatfactory.simtwo.watchdog import CommandWatchdog


def test_no_velocity_yet_replies_stop_with_the_magnet_as_set():
    wd = CommandWatchdog(0.5)
    wd.magnet = True
    cmd, tripped = wd.reply(3, 1000)
    assert (cmd.v, cmd.w, cmd.magnet, cmd.seq, tripped) == (0.0, 0.0, True, 3, False)


def test_fresh_velocity_then_watchdog_trips_once_and_recovers():
    wd = CommandWatchdog(0.5)
    wd.set_velocity(0.2, -1.0, 1000)
    assert wd.reply(1, 1500)[0].v == 0.2  # exactly the timeout: still fresh
    cmd, tripped = wd.reply(2, 1540)
    assert (cmd.v, cmd.w, tripped, wd.stopping, wd.stops) == (0.0, 0.0, True, True, 1)
    assert wd.reply(3, 1580)[1] is False and wd.stops == 1  # tripped once, not every cycle
    wd.set_velocity(0.1, 0.0, 1600)
    cmd, tripped = wd.reply(4, 1640)
    assert (cmd.v, tripped, wd.stopping) == (0.1, False, False)


def test_velocity_before_the_first_frame_is_fresh_at_the_next_one():
    wd = CommandWatchdog(0.5)
    wd.set_velocity(0.3, 0.0, None)
    assert wd.reply(0, 90_000)[0].v == 0.3
    assert wd.age_ms(90_040) == 40


def test_reset_forgets_commands_but_keeps_the_count():
    wd = CommandWatchdog(0.5)
    wd.set_velocity(0.3, 0.0, 0)
    wd.magnet = True
    wd.reply(0, 1000)
    wd.reset()
    cmd, _ = wd.reply(0, 0)
    assert (cmd.v, cmd.magnet, wd.have_velocity, wd.stops, wd.timeout_s) == (0.0, False, False, 1, 0.5)
