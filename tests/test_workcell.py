"""The strategy runs on the robots it is handed (issue 22): the exploration loop
(:func:`explore3d.strategy.explore.explore_robots`) rerun on a :class:`LogWorkcell` of a simulated
exploration's own logs, with no simulator behind it, takes the same decisions and finds the same
contacts; the simulated workcell factory is picklable (worker processes each open their own)."""
from __future__ import annotations

import pickle

import numpy as np
import pytest

from explore3d.arm.spec import ArmSpec
from explore3d.robot.interface import LogMismatchError, LogWorkcell
from explore3d.strategy.explore import ExploreConfig, explore_robots, rough_bound
from explore3d.world.explore import SimWorkcells, explore
from explore3d.world.objects import cube

SMALL = ArmSpec(name="small12", n_links=12, link_length=0.025)


@pytest.fixture(scope="module")
def recorded():
    m = cube(0.05)
    cfg = ExploreConfig(directions=3, angles=1, probes=None, record=True, jobs=1)
    return m, cfg, explore(m, SMALL, cfg)


def test_the_loop_replayed_on_logs_finds_the_same_contacts(recorded):
    m, cfg, ex = recorded
    c, r = rough_bound(m.vertices)
    again = explore_robots(LogWorkcell(ex.logs), SMALL, cfg, ex.band, c, r)
    assert ex.n_contacts > 0 and len(ex.points) >= 4
    assert again.n_wraps == ex.n_wraps and again.steps == ex.steps
    assert np.array_equal(again.points, ex.points)
    assert np.array_equal(again.contacts.points, ex.contacts.points)
    for wa, wb in zip(again.attempts, ex.attempts):
        for a, b in zip(wa, wb):
            assert np.array_equal(a.q, b.q) and np.array_equal(a.contact, b.contact)
    # swept free space from the measured angles alone: the same
    assert len(again.swept) == len(ex.swept)


def test_a_different_strategy_on_the_logs_is_caught(recorded):
    """The log cell is not a simulator: asking for anything the log does not hold fails loudly."""
    m, cfg, ex = recorded
    c, r = rough_bound(m.vertices)
    with pytest.raises(LogMismatchError):
        explore_robots(LogWorkcell(ex.logs), SMALL, cfg, ex.band, c + np.array([0.01, 0.0, 0.0]), r)
    with pytest.raises(ValueError, match="wrap"):
        LogWorkcell(ex.logs).robot(cfg.sensors, wrap=len(ex.logs))
    with pytest.raises(ValueError, match="at least one"):
        LogWorkcell([])


def test_workcell_factories_are_picklable(recorded):
    m, cfg, ex = recorded
    sim = SimWorkcells(SMALL, np.asarray(m.vertices, float), np.asarray(m.faces, np.int64), cfg.sim)
    back = pickle.loads(pickle.dumps(sim))
    assert np.array_equal(back.vertices, sim.vertices) and back.spec == SMALL
    with back() as cell:
        assert cell.spec == SMALL and cell.steps == 0
    logs = pickle.loads(pickle.dumps(LogWorkcell(ex.logs)))
    assert len(logs.logs) == ex.n_wraps and logs().steps == 0
