"""Who waits for a sweep and what its cancels report (mows.sweep.requests), driven without ROS:
the graph's request writers and a steady clock in, decisions out (cancel the cycle, hand on a
step, a log line, how the goal ends), over a real SweepRunner answered by the stand-in driver
of test_runner."""

import pytest

from mows.estimate.probe_set import own_probe_entry
from mows.physics.probe import PAPER_PROBE as P
from mows.sweep.events import CycleAnswer, SweepGoal, SweepSettings
from mows.sweep.requests import (
    UNSEEN_S,
    Cancel,
    Ending,
    LogLine,
    Requesters,
    Severity,
    SweepRequests,
    goal_ending,
)
from mows.sweep.runner import SweepRunner, SweepState

from .test_runner import ANGLES, StandIn

OWN = (own_probe_entry(P),)  # the runner's probe: a set of one

SEND_GOAL = ("/mapper/rotation_sweep/_action/send_goal", "/mows/mapper/rotation_sweep/_action/send_goal")
GONE = "every node that asked for it through /mapper/rotation_sweep/_action/send_goal has left"
CLI, OTHER = b"cli", b"other"


def watched(goal=SweepGoal(ANGLES[:5], 1), seen=frozenset({CLI}), now_s=100.0):
    """A started sweep, watched from ``now_s`` with ``seen`` in the graph: the bookkeeping, the
    runner and its first step."""
    runner = SweepRunner()
    requests = SweepRequests(runner)
    runner.start(goal, SweepSettings(probes=OWN))
    requests.watch(SEND_GOAL, seen, now_s)
    return requests, runner, runner.begin()


def run_to_the_end(runner, step, driver):
    while step.decompose is None:
        step = driver.run(runner, step)
    return runner.on_decomposed(step.decompose())


# --- the rule: who may still wait --------------------------------------------------------------
def test_a_request_runs_while_one_of_its_requesters_stays():
    requesters = Requesters(SEND_GOAL, frozenset({b"mapper", CLI}), 0.0)
    assert not requesters.gone(frozenset({b"mapper", OTHER}), 60.0)  # the cli left, another came
    assert requesters.gone(frozenset({OTHER}), 60.0)  # one that came later never asked for it
    assert requesters.reason == GONE  # the first name: the node's own, not the alias


def test_requesters_shown_a_moment_after_the_request_are_its_requesters():
    requesters = Requesters(SEND_GOAL, frozenset(), 0.0)
    assert not requesters.gone(frozenset(), UNSEEN_S / 2)  # too early to tell
    assert not requesters.gone(frozenset({CLI}), UNSEEN_S * 0.75)
    assert not requesters.gone(frozenset({CLI, OTHER}), UNSEEN_S * 10)
    assert requesters.gone(frozenset({OTHER}), UNSEEN_S * 10)  # the one first shown has left


def test_requesters_never_shown_are_gone_once_the_graph_had_time():
    requesters = Requesters(SEND_GOAL, frozenset(), 10.0)
    assert not requesters.gone(frozenset(), 10.0 + UNSEEN_S * 0.99)
    assert requesters.gone(frozenset(), 10.0 + UNSEEN_S * 1.01)


# --- the node's own cancel: the client gone ----------------------------------------------------
def test_a_client_gone_mid_cycle_cancels_the_cycle_once_and_the_sweep_ends_cancelled():
    requests, runner, step = watched()
    assert step.run_cycle is not None  # the first cycle runs
    assert requests.service_names == SEND_GOAL
    assert requests.on_graph(frozenset({CLI, OTHER}), 160.0) is None  # still there: runs on
    cancel = requests.on_graph(frozenset({OTHER}), 160.1)
    warning = LogLine(Severity.WARNING, f"sweep cancelled, its cycle with it: {GONE}")
    assert cancel == Cancel(None, warning)  # the cycle to cancel; no fits awaited yet
    assert runner.cancelled()
    assert requests.on_graph(frozenset(), 160.2) is None  # told once
    step = runner.on_cycle(CycleAnswer(problem="cycle failed: cancelled: its goal was cancelled"))
    outcome = step.finished
    assert outcome.cancelled and not outcome.ok and step.publish == ()
    assert runner.cancels == 1 and runner.last_cancel == f"cancelled during orientation 0 (0.0°) ({GONE})"
    assert runner.last_failure == ""  # a cancel is no failure
    assert requests.ended(outcome) == LogLine(Severity.INFO, f"sweep {runner.last_cancel}")
    assert requests.service_names == ()  # watched no more


def test_a_client_gone_while_fits_are_awaited_hands_on_the_sweeps_end():
    requests, runner, step = watched()
    driver = StandIn()
    step = driver.run(runner, step)  # orientation 0 measured
    driver.cycle_id += 1
    assert not runner.on_cycle(CycleAnswer(driver.cycle_id, 1)).run_cycle  # its fit is awaited
    cancel = requests.on_graph(frozenset(), 101.0)
    assert cancel.log.severity == Severity.WARNING
    ended = cancel.step  # what the coroutine awaiting the fits is handed
    assert ended.finished.cancelled and ended.finished.message == "cancelled after 2 of 5 orientations"
    assert ended.decompose is None and ended.publish == () and runner.state == SweepState.IDLE
    assert runner.cancels == 1 and GONE in runner.last_cancel


def test_a_sweep_whose_client_stays_runs_to_its_map():
    requests, runner, step = watched()
    driver, now_s = StandIn(), 100.0
    while step.decompose is None:
        now_s += 1.0
        assert requests.on_graph(frozenset({CLI}), now_s) is None
        step = driver.run(runner, step)
    step = runner.on_decomposed(step.decompose())
    assert step.finished.ok and len(step.publish) == 1
    assert requests.on_graph(frozenset(), now_s + 60) is None  # ended: the map goes out, nothing to cancel
    assert requests.ended(step.finished) is None and runner.cancels == 0


def test_a_client_never_shown_cancels_the_sweep_only_once_the_graph_had_time():
    requests, runner, _ = watched(seen=frozenset(), now_s=0.0)
    assert requests.on_graph(frozenset(), UNSEEN_S * 0.99) is None and not runner.cancelled()
    assert requests.on_graph(frozenset(), UNSEEN_S * 1.01) is not None and runner.cancelled()


# --- the client's cancel -----------------------------------------------------------------------
def test_the_clients_cancel_ends_the_sweep_before_the_next_orientation_without_a_warning():
    requests, runner, step = watched()
    cancel = requests.on_cancel()
    assert cancel == Cancel(None, None)
    step = StandIn().run(runner, step)
    assert step.finished.cancelled and step.run_cycle is None
    assert runner.cancels == 1 and runner.last_cancel == "cancelled after 1 of 5 orientations"  # no reason
    assert requests.ended(step.finished) == LogLine(Severity.INFO, "sweep cancelled after 1 of 5 orientations")
    assert goal_ending(step.finished.ok, step.finished.cancelled, cancel_requested=True) == Ending.CANCELED


def test_a_cancel_after_the_sweep_ended_is_refused_and_counts_nothing():
    requests, runner, step = watched()
    step = run_to_the_end(runner, step, StandIn())
    assert step.finished.ok  # its map is being published
    assert requests.on_cancel() is None
    assert requests.ended(step.finished) is None
    assert requests.on_cancel() is None  # and after the goal ended
    assert runner.cancels == 0 and runner.last_cancel == "" and runner.sweeps == 1
    runner.start(SweepGoal(ANGLES[:5], 1), SweepSettings(probes=OWN))  # the next sweep starts clean
    assert not runner.cancelled()
    assert run_to_the_end(runner, runner.begin(), StandIn()).finished.ok


def test_the_counts_on_diagnostics_agree_with_the_cancels_carried_out_and_the_maps_published():
    """Three sweeps: one its client cancels, one whose client leaves, one to its map; and a
    cancel that comes too late. What /diagnostics counts is what happened."""
    runner = SweepRunner()
    requests, driver = SweepRequests(runner), StandIn()
    carried_out, published, lines = [], [], []
    for ending in ("cancel", "gone", "map", "late cancel"):
        runner.start(SweepGoal(ANGLES[:5], 1), SweepSettings(probes=OWN))
        requests.watch(SEND_GOAL, frozenset({CLI}), 0.0)
        step = runner.begin()
        if ending == "cancel":
            carried_out.append(requests.on_cancel())
        elif ending == "gone":
            carried_out.append(requests.on_graph(frozenset(), 1.0))
        while step.finished is None:
            step = runner.on_decomposed(step.decompose()) if step.decompose else driver.run(runner, step)
        if ending == "late cancel":
            carried_out.append(requests.on_cancel())
        published += step.publish
        lines.append(requests.ended(step.finished))
    done = [cancel for cancel in carried_out if cancel is not None]
    assert len(done) == runner.cancels == 2
    assert len(published) == runner.sweeps == 2 and runner.last_cancel == ""
    assert [line and line.severity for line in lines] == [Severity.INFO, Severity.INFO, None, None]


def test_a_failed_sweep_is_logged_as_a_warning_with_its_reason():
    requests, runner, step = watched()
    step = runner.on_cycle(CycleAnswer(problem="cycle failed: coil current above the cap"))
    line = requests.ended(step.finished)
    reason = "orientation 0 (0.0°): cycle failed: coil current above the cap"
    assert line == LogLine(Severity.WARNING, f"sweep aborted: {reason}")
    assert goal_ending(False, False, cancel_requested=False) == Ending.ABORTED


def test_an_exception_leaves_the_runner_free_and_unwatched():
    requests, runner, _ = watched()
    requests.abandon("the sweep ended unexpectedly (see the log)")
    assert runner.state == SweepState.IDLE and runner.last_failure.startswith("the sweep ended unexpectedly")
    assert requests.service_names == () and requests.on_graph(frozenset(), 1e6) is None


@pytest.mark.parametrize(
    ("succeeded", "cancelled", "cancel_requested", "ending"),
    [
        (True, False, False, Ending.SUCCEEDED),
        (False, False, False, Ending.ABORTED),
        (False, False, True, Ending.ABORTED),  # asked to cancel too late: it failed first
        (True, False, True, Ending.SUCCEEDED),
        (False, True, True, Ending.CANCELED),
        (False, True, False, Ending.ABORTED),  # cancelled by the node: never asked, so not CANCELED
    ],
)
def test_how_a_goal_ends(succeeded, cancelled, cancel_requested, ending):
    assert goal_ending(succeeded, cancelled, cancel_requested) == ending


# --- the workspace map -------------------------------------------------------------------------
MAP = ("/mapper/workspace_map/_action/send_goal",)


def test_a_map_is_refused_while_a_sweep_or_another_map_runs_or_for_several_probes():
    requests, runner, _ = watched()
    assert requests.start_map(1) == "a sweep is running"
    runner.abandon("stopped")
    assert requests.start_map(2) == "the arm carries one probe; the mapper has 2"
    assert requests.start_map(1) is None and requests.mapping
    assert requests.start_map(1) == "a workspace map is running"
    requests.map_ended()
    assert requests.start_map(1) is None


def test_a_clients_sweep_is_refused_while_a_map_runs_even_between_its_sweeps():
    requests = SweepRequests(SweepRunner())
    assert requests.sweep_refusal() is None
    assert requests.start_map(1) is None
    assert requests.sweep_refusal() == "a workspace map is running"
    requests.map_ended()
    assert requests.sweep_refusal() is None


def test_a_map_cancelled_between_its_sweeps_takes_no_further_sweep():
    runner = SweepRunner()
    requests = SweepRequests(runner)
    assert requests.on_cancel_map() is None  # no map: refused
    assert requests.start_map(1) is None and not requests.map_cancelled
    assert requests.on_cancel_map() == Cancel()  # nothing running to cancel, the map told
    assert requests.map_cancelled and runner.cancels == 0
    requests.map_ended()
    assert requests.on_cancel_map() is None  # ended: refused
    assert requests.start_map(1) is None and not requests.map_cancelled  # the next map starts clean


def test_a_map_cancelled_mid_sweep_cancels_that_sweep():
    runner = SweepRunner()
    requests = SweepRequests(runner)
    requests.start_map(1)
    runner.start(SweepGoal(ANGLES[:5], 1), SweepSettings(probes=OWN))
    requests.watch(MAP, frozenset({CLI}), 0.0)
    step = runner.begin()
    assert requests.on_cancel_map() == Cancel()
    assert requests.map_cancelled and runner.cancelled()
    assert StandIn().run(runner, step).finished.cancelled


def test_a_maps_sweeps_wait_for_the_maps_client_and_its_leaving_ends_the_map():
    runner = SweepRunner()
    requests = SweepRequests(runner)
    requests.start_map(1)
    for now_s, seen in ((0.0, {CLI}), (30.0, {CLI, OTHER})):  # another client came before the second sweep
        runner.start(SweepGoal(ANGLES[:5], 1), SweepSettings(probes=OWN))
        requests.watch(MAP, frozenset(seen), now_s)
        step = runner.begin()
        if now_s == 0.0:
            assert requests.on_graph(frozenset({CLI}), 1.0) is None
            requests.ended(run_to_the_end(runner, step, StandIn()).finished)
    cancel = requests.on_graph(frozenset({OTHER}), 31.0)  # the map's own client left
    assert cancel is not None and cancel.log.text.endswith(f"through {MAP[0]} has left")
    assert requests.map_cancelled and runner.cancelled()
    requests.map_ended()
    assert goal_ending(False, requests.map_cancelled, cancel_requested=False) == Ending.ABORTED
