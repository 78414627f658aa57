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
non-compliant``, 2026-11-29). Learned prior (``--prior depth --instances 40 --episode-seeds
9``): most slides rule out a few draws (177 of 1028 three_ledges cycles rejected any, 6 more
than 50 of 100); topping every one of them up to 100 took 1.27x the run's summed cycle time
for the same outcome of every episode. Below half only (``--problems notch three_ledges
--instances 100``, 3600 episodes), 52 episodes changed and the summed time did not (233 ->
236 s): every feasible episode docked in both, one clearly infeasible one ran to the cap
instead of giving up. Generic depth prior (``--prior generic --episode-seeds 3``): sloper's
slides rule out most draws (130 of 436 cycles more than 50, many ~95 of 100); a budget of 4 x
``n_samples`` took 1.41x the summed time and 7 cycles over 1 s (0 before), 2 x took 1.25x and
2 (in an episode that took another course, at a cycle without a top-up), with the same
outcomes for both budgets: 84 of 360 episodes changed, every feasible one docked as before,
clearly infeasible give-ups 35 -> 34 of 42, ECE 0.1425 -> 0.1386 compliant, 0.0869 -> 0.0835
non-compliant.

Decision (a later cycle's give-up, ``hold_draws``): the planner caps each feature's P_dock at
the share of samples in which it holds, so "no sample of 100 holds" gives up below 0.001 on a
hold of 1 % probability 37 % of the time. The first cycle counts prior draws
(``planner.first_cycle_draws``); later ones had nothing: a feasible sloper truth 0.1 degrees
inside holding (learned prior, test base seed 4, truth 112) gave up at cycle 1 of its
non-compliant episodes, 1000-3000 draws of that cycle putting its hold at ~0.1 %. When no
passed draw lets an edge hold (a vertex only traps a compliant slide), the chains now run on to
``planner.give_up_draws`` of the threshold (3000 at 0.001), all returned. The cost grows with
the draws and the history's rows (HMC bounces, the slides' check, the planner's obstacle
region), so the draws are capped at ``HOLD_ROW_DRAWS`` / rows: 3000 up to 3 rows (truth 112's
cycle 1 had 3), 1000 at 10, none beyond 100 rows. Measured side by side on the
training truths (``bench docking --split train --prior depth --strategies ours --mode
compliant non-compliant --instances 120 --episode-seeds 3``, base seed 0, 2026-11-29, code
before / cap 30,000 / cap 10,000): every feasible episode docked and 312 of 312 clearly
infeasible ones gave up in all three, ECE 0.043 / 0.040, 0.042 / 0.039, 0.042 / 0.040
(compliant / non-compliant), z by truth 0.25 / -0.73, 0.24 / -0.75, 0.24 / -0.74; 36 and 25
of 2160 episodes changed, all on infeasible truths trying a hold of P_dock 0.001-0.01 once or
twice more before giving up; summed cycle time 82 s, 205 s, 119 s; slowest cycle 0.51 s, 1.26 s,
0.57 s. On test base seed 4 the cap of 10,000 docked truth 112 in all six episodes.

Decision (a later cycle's give-up read off too few samples, ``draw_on``; opt-in): the hold
draws above run only when no sample lets an edge hold. A give-up also comes when edges hold but
no path docks on the samples: on notch test truth 39 of base seed 1 (learned prior,
non-compliant, episode seed 1; 120 history rows, where ``HOLD_ROW_DRAWS`` / rows allows no hold
draws) the planner gave up at cycle 9 on 94 samples, and on 100-draw reference sets of that
posterior it gives up 1 time in 10, otherwise finding a path of median P_dock 0.015. With the
loops' ``give_up_samples`` (``explore.run_episode``, the planner node's parameter) a would-be
give-up after a contact on fewer samples draws on to that many (``draw_on``: the chains continue
on the same rows, as a top-up) and plans again; only the second answer counts. A prototype on
that episode's split (2026-11-29) gave up again with 100 more draws and docked with 300 more
(P_dock 0.007 and 0.013 on the drawn-on sets, in 11 cycles). Off by default: it costs cycle
time where histories are long (~2 ms per draw at ~100 rows and ~0.3 s to plan on 400 samples);
the measured trade-off is in docs/nodes.md ("Give-up check").
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from . import planner, sampling, slides
from .episode import EpisodeState
from .shape import GaussianShape

TOP_UP_SHARE = 0.5  # top up while fewer than this share of n_samples passed the slides
TOP_UP_DRAWS = 2  # draws per cycle at most this many times n_samples (the slides' rejection)
HOLD_ROW_DRAWS = 10_000  # a hold top-up's draws times the history's rows, at most


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
    hold_draws: int = 0,
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
    ``hold_draws`` (0: off; the episode loops pass ``planner.give_up_draws`` of the give-up
    threshold): after an observation, when none of the passed draws lets an edge hold the load
    (``planner.edge_holds_anywhere``), the chains run on to ``hold_draws`` draws in all (at most
    ``HOLD_ROW_DRAWS`` / rows) and every one that passes is returned (more than ``n_samples``);
    ``info["hold_draws"]`` counts the draws this made (0 when it did not run), ``slide_draws``
    and ``slide_rejected`` include them.
    Raises ValueError on bad input (as ``sample_posterior``; ``top_up_draws`` < 1,
    ``hold_draws`` < 0).
    """
    if int(top_up_draws) != top_up_draws or top_up_draws < 1:
        raise ValueError(f"top_up_draws must be an integer >= 1, got {top_up_draws}")
    if int(hold_draws) != hold_draws or hold_draws < 0:
        raise ValueError(f"hold_draws must be an integer >= 0, got {hold_draws}")
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
    rounds = [(first, keep)]  # each call's draws and which of them passed
    drawn, count = len(keep), int(keep.sum())
    budget, enough = top_up_draws * n_samples, int(np.ceil(TOP_UP_SHARE * n_samples))

    def run_on(wanted: int) -> tuple[int, int]:  # the chains go on from their last draws
        args = (first.ignored, rounds[-1][0].z, wanted, rng, load, method, threads)
        rounds.append(_continued(shape, state, *args))
        more = rounds[-1][1]
        return len(more), int(more.sum())

    while count < enough and drawn < budget and len(rounds[-1][0].z):  # a round gave none: stop
        expected = max(-(-(n_samples - count) * drawn // max(count, 1)), 1)  # at the share so far
        more, passed = run_on(min(expected, n_samples, budget - drawn))
        drawn, count = drawn + more, count + passed
    info = {
        **first.info,
        "slide_draws": drawn,
        "slide_rejected": drawn - count,
        "hold_draws": 0,
        "give_up_draws": 0,
    }
    if count < 2:  # the planner keeps all and reports its own count
        info["slide_rejected"] = 0
        return dataclasses.replace(first, info=info, seconds=time.perf_counter() - start)
    limit, rows = n_samples, len(state.history)
    wanted = min(hold_draws, HOLD_ROW_DRAWS // max(rows, 1))  # its cost grows with the rows
    if rows and count < wanted and not _holds(shape, rounds, load, n_samples):
        more, passed = run_on(wanted - count)
        info["hold_draws"], limit = more, count + passed
        info["slide_draws"], info["slide_rejected"] = drawn + more, drawn + more - limit
    z = np.concatenate([p.z[m] for p, m in rounds])[:limit]
    return dataclasses.replace(
        first,
        z=z,
        vertices=shape.vertices(z),
        ess=float(sum(p.ess * _share(m) for p, m in rounds)),
        seconds=time.perf_counter() - start,
        info=info,
    )


def draw_on(
    shape: GaussianShape,
    state: EpisodeState,
    post: sampling.PosteriorSamples,
    wanted: int,
    rng: np.random.Generator,
    load,
    *,
    method: str = "hmc",
    threads: int = 1,
) -> sampling.PosteriorSamples:
    """``post`` (``draw``'s samples of ``state``) followed by those of ``wanted`` more draws
    that pass the slides, for a would-be give-up (module docstring). The chains continue from
    ``post``'s samples on the same rows (``post``'s dropped and deferred rows stay out, no seed
    search runs), so every sample is of one posterior. ``info["give_up_draws"]`` counts the
    draws made; ``slide_draws``, ``slide_rejected`` and ``seconds`` include them; ``ess`` adds
    theirs times their passed share. Raises ValueError for ``wanted`` < 1 or fewer than two
    samples in ``post`` (nothing to continue from).
    """
    if int(wanted) != wanted or wanted < 1:
        raise ValueError(f"wanted must be an integer >= 1, got {wanted}")
    if len(post.z) < 2:
        raise ValueError(f"draw_on needs two samples to continue from, got {len(post.z)}")
    start = time.perf_counter()
    more, keep = _continued(
        shape, state, post.ignored, post.z, int(wanted), rng, load, method, threads
    )
    z = np.concatenate([post.z, more.z[keep]])
    info = dict(post.info, give_up_draws=len(keep))
    info["slide_draws"] = post.info.get("slide_draws", len(post.z)) + len(keep)
    info["slide_rejected"] = post.info.get("slide_rejected", 0) + int((~keep).sum())
    return dataclasses.replace(
        post,
        z=z,
        vertices=shape.vertices(z),
        ess=float(post.ess + more.ess * _share(keep)),
        seconds=post.seconds + time.perf_counter() - start,
        info=info,
    )


def _continued(shape, state, ignored, init_z, wanted, rng, load, method, threads):
    """``wanted`` more draws of ``state``'s rows but ``ignored`` (the first call's dropped and
    deferred ones), the chains going on from ``init_z``, and which of them pass the slides."""
    post = sampling.sample_posterior(
        shape, state.history, wanted, rng, method, init_z=init_z, known_dropped=ignored,
        threads=threads,
    )  # fmt: skip
    return post, _consistent(shape, state, post, load)


def _holds(shape, rounds, load, n_samples: int) -> bool:
    """Whether any of the first ``n_samples`` passed draws lets an edge hold ``load``."""
    vertices = np.concatenate([p.vertices[m] for p, m in rounds])[:n_samples]
    return planner.edge_holds_anywhere(vertices, shape, load)


def _share(mask: np.ndarray) -> float:
    return float(mask.mean()) if len(mask) else 1.0


def _consistent(shape, state, post: sampling.PosteriorSamples, load) -> np.ndarray:
    return slides.consistent_with_slides(
        post.vertices, shape.closed, state.history, state.move_ids, load, shape.friction,
        post.ignored,
    )  # fmt: skip
