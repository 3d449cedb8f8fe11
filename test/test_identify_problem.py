"""The identification simulator's kept runs (:meth:`ema_sim.identify.problem.Problem.simulate`).

A run asked for again (a Jacobian at the point whose residual was just taken, a stage restarting from the model
the one before ended on) is answered from the runs kept, never run twice; what is answered must be what a run
gives, to the last bit, whatever else shares its batch.
"""

from __future__ import annotations

import pickle
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
from identgen import make_record

from ema_sim.config import load_channel
from ema_sim.identify import problem as problem_module
from ema_sim.identify.problem import Cancelled, Problem
from ema_sim.models.second_order import SecondOrderParams

WING = load_channel("left_wing")


@pytest.fixture(scope="module")
def record():
    return make_record({"rate_limit": 90.0, "free_play": 0.1}, seed=5, duration_s=2.0)


def _sets() -> list[SecondOrderParams]:
    base = SecondOrderParams.basic(WING)
    return [base, base.replace(rate_limit_dps=80.0), base.replace(free_play_deg=0.2, delay_s=0.004)]


def _counting(problem: Problem) -> list[int]:
    """Record the size of each batch the kernel is actually given."""
    batches: list[int] = []
    run = problem._run

    def counted(params, flips, offsets):
        batches.append(len(params))
        return run(params, flips, offsets)

    problem._run = counted  # type: ignore[method-assign]
    return batches


def test_a_run_asked_for_again_is_not_run_again_and_is_the_same_to_the_bit(record):
    a, b, c = _sets()
    alone = {i: Problem(record, WING).simulate([p])[0] for i, p in enumerate((a, b, c))}
    problem = Problem(record, WING)
    batches = _counting(problem)
    first = problem.simulate([a, b])
    assert batches == [2]
    mixed = problem.simulate([c, a, c, b], [False] * 4)  # a and b kept; c twice in one batch: run once
    assert batches == [2, 1]
    for got, want in zip([*first, *mixed], [alone[0], alone[1], alone[2], alone[0], alone[2], alone[1]],
                         strict=True):
        assert np.array_equal(got, want)
    assert (problem.simulations, problem.reused) == (6, 3)
    mixed[1][:] = 0.0  # the caller's copy: the kept run is untouched
    assert np.array_equal(problem.simulate([a])[0], alone[0])
    assert batches == [2, 1]
    problem.forget_runs()  # a benchmark's: the next call runs again
    assert np.array_equal(problem.simulate([a])[0], alone[0])
    assert batches == [2, 1, 1]


def test_what_changes_a_run_is_in_its_key(record):
    a = _sets()[0].replace(compliance_deg_per_kinlb=0.3)  # the load moves it: a reversed load is another run
    problem = Problem(record, WING)
    batches = _counting(problem)
    held = problem.simulate([a])[0]
    flipped = problem.simulate([a], [True])[0]
    offsets = problem.simulate([a], command_offsets=[np.full(problem.breakpoints[0].size, 0.5)])[0]
    assert batches == [1, 1, 1]
    assert not np.array_equal(held, flipped)
    assert not np.array_equal(held, offsets)
    problem.step_s = 5e-4
    problem.simulate([a])
    assert batches == [1, 1, 1, 1]
    problem.step_s = 1e-3
    problem.set_command_sampled(True)  # new breakpoints: nothing kept from before them
    sampled = problem.simulate([a])[0]
    assert batches == [1, 1, 1, 1, 1]
    assert not np.array_equal(held, sampled)


def test_the_runs_kept_stay_within_their_memory_and_a_batch_beyond_it_is_whole(record, monkeypatch):
    problem = Problem(record, WING)
    one = problem.time_s.size * 3 * 8
    monkeypatch.setattr(problem_module, "KEPT_RUNS_BYTES", 2 * one)
    sets = _sets()
    out = problem.simulate(sets)
    assert len(problem._kept) == 2
    assert sum(r.nbytes for r in problem._kept.values()) <= 2 * one
    for got, p in zip(out, sets, strict=True):
        assert np.array_equal(got, Problem(record, WING).simulate([p])[0])


def test_a_problem_goes_to_a_worker_without_its_kept_runs(record):
    problem = Problem(record, WING)
    problem.simulate(_sets())
    copy = pickle.loads(pickle.dumps(problem))
    assert len(problem._kept) == 3
    assert len(copy._kept) == 0
    assert copy.simulations == problem.simulations
    assert np.array_equal(copy.simulate(_sets()[:1])[0], problem.simulate(_sets()[:1])[0])


def test_a_tally_counts_one_threads_simulations_apart_and_a_changed_input_is_never_kept(record):
    a, b, c = _sets()
    problem = Problem(record, WING)
    problem.simulate([a])
    with problem.tally() as counts:
        problem.simulate([a, b])  # a kept from before: one of the two reused
    assert (counts.simulations, counts.reused) == (2, 1)
    assert (problem.simulations, problem.reused) == (1, 0)  # the caller adds a tally once it takes the fit
    seen: list[tuple[int, int]] = []

    def other_thread() -> None:
        problem.simulate([c])  # no tally open in this thread: counted in the problem

    worker = threading.Thread(target=other_thread)
    with problem.tally() as counts:
        worker.start()
        worker.join()
        seen.append((counts.simulations, counts.reused))
    assert seen == [(0, 0)]
    assert problem.simulations == 2


def test_a_run_that_began_before_the_inputs_changed_is_not_kept_as_one_of_theirs(record):
    a = _sets()[0]
    problem = Problem(record, WING)
    run = problem._run

    def inputs_change_meanwhile(params, flips, offsets):
        out = run(params, flips, offsets)
        problem.set_command_sampled(True)  # as another thread would, while this run was going
        return out

    problem._run = inputs_change_meanwhile  # type: ignore[method-assign]
    held = problem.simulate([a])[0]
    problem._run = run  # type: ignore[method-assign]
    batches = _counting(problem)
    sampled = problem.simulate([a])[0]
    assert batches == [1]  # run again on the new inputs, not answered with the held command's run
    assert not np.array_equal(held, sampled)


def test_threads_sharing_a_problem_get_what_each_would_alone(record):
    sets = _sets()
    alone = [Problem(record, WING).simulate([p])[0] for p in sets]
    problem = Problem(record, WING)
    batches = _counting(problem)
    with ThreadPoolExecutor(3) as pool:
        got = list(pool.map(lambda i: problem.simulate([sets[i % 3], sets[(i + 1) % 3]]), range(12)))
    for i, pair in enumerate(got):
        assert np.array_equal(pair[0], alone[i % 3])
        assert np.array_equal(pair[1], alone[(i + 1) % 3])
    assert problem.simulations == 24
    assert problem.reused == 24 - sum(batches)  # what no thread had kept yet ran, the rest was reused
    assert sum(batches) < 24


def test_a_cancelled_fit_stops_at_its_next_simulation_and_others_go_on(record):
    a, b, _ = _sets()
    problem = Problem(record, WING)
    with problem.tally("round 0/delay") as counts:
        problem.simulate([a])
        problem.cancel("round 0/delay")
        with pytest.raises(Cancelled):
            problem.simulate([b])
    assert counts.simulations == 1
    with problem.tally("round 0/lag") as other:
        problem.simulate([b])  # another fit's token: not cancelled
    assert other.simulations == 1
    problem.simulate([b])  # the search itself (no tally) is never cancelled
    assert problem.simulations == 1
