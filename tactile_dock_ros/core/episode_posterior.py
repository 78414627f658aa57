"""An episode cycle's posterior: P(x | H) conditioned on the recorded slides too (Sec. IV, V-A2).

``sampling.sample_posterior`` draws shapes that satisfy every history row (eq. 13); a compliant
slide says more (``slides``): every edge it passed slipped the same way. ``draw`` conditions
the draws on the slides by rejection (``slides.consistent_with_slides``) and tops up: while
fewer than ``TOP_UP_SHARE`` of ``n_samples`` passed, the chains run on for the draws that the
share passed so far says are missing to ``n_samples`` (at most ``n_samples`` per round), up to
``TOP_UP_DRAWS`` times ``n_samples`` draws in all. Both episode loops call it
(``explore.run_episode`` and the inference node), so the planner gets the posterior the slides
leave.

Decision (2026-11-29): before, the planner filtered the ``n_samples`` draws it got and planned
on whatever passed. After a near miss, slides can rule out most of them (81-97 of 100 in a
three_ledges test episode of base seed 1, learned prior, compliant): P_dock was then estimated
on ~10 samples, none docked, and the planner gave up below 0.001 on a truth that holds (margin
-3.3 degrees). A give-up read off "0 of 10" is weak evidence; "0 of 100" is the planner's
usual sample.
Decision: top up only below half of ``n_samples``, with at most one more round of
``n_samples`` draws (``TOP_UP_DRAWS`` 2). Measured side by side with the code before on the
training truths (``bench docking --split train --strategies ours --mode compliant
non-compliant``, 2026-11-29). Learned prior (``--prior learned --instances 40 --episode-seeds
9``): most slides rule out a few draws (177 of 1028 three_ledges cycles rejected any, 6 more
than 50 of 100); topping every one of them up to 100 took 1.27x the run's summed cycle time
for the same outcome of every episode. Below half only (``--problems notch three_ledges
--instances 100``, 3600 episodes), 52 episodes changed and the summed time did not (233 ->
236 s): every feasible episode docked in both, one clearly infeasible one ran to the cap
instead of giving up. Generic depth prior (``--prior depth --episode-seeds 3``): sloper's
slides rule out most draws (130 of 436 cycles more than 50, many ~95 of 100); a budget of 4 x
``n_samples`` took 1.41x the summed time and 7 cycles over 1 s (0 before), 2 x took 1.25x and
2 (in an episode that took another course, at a cycle without a top-up), with the same
outcomes for both budgets: 84 of 360 episodes changed, every feasible one docked as before,
clearly infeasible give-ups 35 -> 34 of 42, ECE 0.1425 -> 0.1386 compliant, 0.0869 -> 0.0835
non-compliant.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from . import sampling, slides
from .episode import EpisodeState
from .shape import GaussianShape

TOP_UP_SHARE = 0.5  # top up while fewer than this share of n_samples passed the slides
TOP_UP_DRAWS = 2  # draws per cycle at most this many times n_samples (the slides' rejection)


def draw(
    shape: GaussianShape,
    state: EpisodeState,
    n_samples: int,
    rng: np.random.Generator,
    load,
    *,
    method: str = "hmc",
    threads: int = 1,
    top_up_draws: int = TOP_UP_DRAWS,
) -> sampling.PosteriorSamples:
    """Up to ``n_samples`` posterior samples of ``state`` on which every recorded slide could
    have happened: at least ``TOP_UP_SHARE`` x ``n_samples`` of them unless ``top_up_draws`` x
    ``n_samples`` draws left fewer; all of the first draws if fewer than two passed (the
    planner needs two and its own check tells).

    The first draws are the episode loop's ``sampling.sample_posterior`` call (warm start from
    ``state.warm_start``, its dropped and deferred rows, one seed round per call). A top-up
    continues the chains from the last draws on the same rows: the first call's dropped and
    deferred rows are left out (``known_dropped``), so every draw is of one posterior.
    ``load`` (2,) unit, the planner's load direction; the friction is ``shape``'s.
    Returned: ``z``/``vertices`` of the passed draws in draw order, ``dropped``/``deferral``/
    ``convergence`` of the first call (the state's), ``seconds`` in all, ``ess`` the sum over
    calls of each one's ESS times its passed share, and in ``info`` ``slide_draws`` (draws
    made) and ``slide_rejected`` (draws rejected; 0 when the first draws are returned whole).
    Raises ValueError on bad input (as ``sample_posterior``; ``top_up_draws`` < 1).
    """
    if int(top_up_draws) != top_up_draws or top_up_draws < 1:
        raise ValueError(f"top_up_draws must be an integer >= 1, got {top_up_draws}")
    start = time.perf_counter()
    first = sampling.sample_posterior(
        shape,
        state.history,
        n_samples,
        rng,
        method,
        init_z=state.warm_start,  # warm start from the previous cycle's posterior
        known_dropped=state.dropped,  # rows judged inconsistent stay out
        deferral=state.deferral,  # rows set aside while their seed search goes on
        seed_round_restarts=sampling.SEED_ROUND_RESTARTS,  # the rest: next cycle
        threads=threads,
    )
    keep = _consistent(shape, state, first, load)
    rounds, post = [(first, keep)], first  # each call's draws and which of them passed
    drawn, count = len(keep), int(keep.sum())
    budget, enough = top_up_draws * n_samples, int(np.ceil(TOP_UP_SHARE * n_samples))
    while count < enough and drawn < budget and len(post.z):  # a round gave none: stop
        expected = max(-(-(n_samples - count) * drawn // max(count, 1)), 1)  # at the share so far
        post = sampling.sample_posterior(
            shape,
            state.history,
            min(expected, n_samples, budget - drawn),
            rng,
            method,
            init_z=post.z,  # the chains run on from their last draws
            known_dropped=first.ignored,
            threads=threads,
        )
        more = _consistent(shape, state, post, load)
        rounds.append((post, more))
        drawn, count = drawn + len(more), count + int(more.sum())
    info = {**first.info, "slide_draws": drawn, "slide_rejected": drawn - count}
    if count < 2:  # the planner keeps all and reports its own count
        info["slide_rejected"] = 0
        return dataclasses.replace(first, info=info, seconds=time.perf_counter() - start)
    z = np.concatenate([p.z[m] for p, m in rounds])[:n_samples]
    return dataclasses.replace(
        first,
        z=z,
        vertices=shape.vertices(z),
        ess=float(sum(p.ess * _share(m) for p, m in rounds)),
        seconds=time.perf_counter() - start,
        info=info,
    )


def _share(mask: np.ndarray) -> float:
    return float(mask.mean()) if len(mask) else 1.0


def _consistent(shape, state, post: sampling.PosteriorSamples, load) -> np.ndarray:
    return slides.consistent_with_slides(
        post.vertices, shape.closed, state.history, state.move_ids, load, shape.friction,
        post.ignored,
    )  # fmt: skip
