"""What reached the wire of an emulated servo bus (endocal/emulate/servos.py), for the tests that
run the hardware backend against it."""

from __future__ import annotations

GOAL_POSITION, TORQUE_ENABLE = 116, 64


def goal_syncs(bus) -> list:
    """The goal stream: every Goal Position a servo received in a Sync Write, in order."""
    return [w for w in bus.writes(GOAL_POSITION) if w.sync]


def assert_torque_off_last(bus) -> None:
    """Every servo's torque is off, its last Torque Enable write was 0 and accepted, and no goal
    reached it after that."""
    assert not any(bus.torque().values()), bus.torque_line()
    writes = bus.writes()
    for i in bus.servos:
        mine = [w for w in writes if w.id == i]
        k = max(n for n, w in enumerate(mine) if w.address == TORQUE_ENABLE)
        assert mine[k].value == 0 and mine[k].error == 0, (i, mine[k])
        assert not [w for w in mine[k + 1:] if w.address == GOAL_POSITION], (i, mine[k + 1:])
