"""Posterior shape sampling P(x | H) by rejection, Metropolis-Hastings, Gibbs and HMC with
constraint bouncing (paper Sec. IV-D..F, Alg. 1, App. A).

Everything runs in the whitened coordinates z (x = A z + mu, z ~ N(0, I) a priori) on a batch of
C independent chains at once. The MCMC samplers run on the pruned pair set (eqs. 16-17); every
returned sample is then checked against *all* observation/edge pairs with the exact geometric
test and dropped if it fails (the chains target the pruned posterior, and filtering its draws
by the remaining constraints leaves exactly the full posterior).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np

from . import descent_scan
from .constraint_systems import HistoryConstraints
from .constraints import (
    collision_bounds,
    crossed_free_pairs,
    observation_violations,
    prune_pairs,
)
from .convergence import (
    MASS_GAP_LIMIT,
    Convergence,
    chain_groups,
    chain_log_mass,
    mass_gap,
    rhat_limit,
    split_rhat,
    trapped_chains,
)
from .ess import effective_sample_size
from .history import History
from .hmc_exit import certificates, split_exits
from .intervals import (
    line_roots,
    line_scan,
    normal_log_mass,
    sample_truncated_normal,
    segment_edges,
    trig_to_quartic,
)
from .shape import GaussianShape

LOG = logging.getLogger(__name__)


@dataclass(frozen=True)
class Sampler:
    """One posterior sampler of the registry ``SAMPLERS``.

    Attributes:
        name: the ``method`` string of ``sample_posterior``, the nodes and the tools.
        mcmc: runs chains (``ChainRunner``); otherwise independent draws.
        on_node: offered by the inference node's ``method`` parameter.
        burn_in: default discarded moves per chain (cold seeds, warm seeds) for MCMC.
    """

    name: str
    mcmc: bool
    on_node: bool
    burn_in: tuple[int, int] = (0, 0)


SAMPLERS = {
    s.name: s
    for s in (
        Sampler("hmc", mcmc=True, on_node=True, burn_in=(3, 1)),
        # a benchmark method: on a late depth-prior cycle (three_ledges, 63 observations) 20
        # pooled runs lie 0.57 std (median coordinate) from an SMC reference, 1.33x too wide,
        # where HMC's lie 0.03 (2026-11-27; docs/inference.md): its axis sweeps do not cross the
        # posterior's correlations in the sweeps a cycle can afford
        Sampler("gibbs", mcmc=True, on_node=False, burn_in=(5, 1)),
        # a benchmark baseline only: its chains barely move (split R-hat ~4 on Fig. 9 problem
        # 2; std 0.35-0.63 of the posterior's on problem 3, docs/inference.md)
        Sampler("mh", mcmc=True, on_node=False, burn_in=(200, 50)),
        Sampler("rejection", mcmc=False, on_node=True),
    )
}
METHODS = tuple(SAMPLERS)  # every sampler (the benchmark compares them)
MCMC_METHODS = tuple(name for name, s in SAMPLERS.items() if s.mcmc)
NODE_METHODS = tuple(name for name, s in SAMPLERS.items() if s.on_node)
LINE_HALF_WIDTH = 9.0  # line scans cover the conditional mean +- this many std (mass < 1e-18 lost)
DESCENT_HALF_WIDTH = 3.0  # descent line scans: +- this many std (a seed, not a Gibbs draw)
DESCENT_CANDIDATES = 32  # segments per descent step judged against every observation
DESCENT_PATIENCE = 10  # seed search: a restart ends when no descent improved for this many steps
SEED_DESCENTS = 8  # descents per seeding restart (chains beyond share their seeds)
SEED_RESTARTS_DEFAULT = 8  # failed descent restarts on a row before it is dropped
SEED_ROUND_RESTARTS = 1  # failed restarts per seed-search round of one call (then: deferred)
SEED_MIN_DISTINCT = 3  # distinct seeds wanted (restart descents): one pocket holds < 1/2
SEED_PRIOR_BATCH = 128  # prior draws tried as exact seeds before anything else, at least
SEED_PRIOR_DRAWS = 32  # prior draws per chain at most for exact seeds, at least
SEED_COST_ROWS = 136  # a shorter history tries proportionally more exact seeds (_exact_seeds)
SEED_Z2_MARGIN = 4.0  # descent seeds with |z|^2 this many chi-square std above typical: dropped
RESEED_ROUNDS = 2  # re-seed + rerun rounds for trapped chains (``convergence``)
WINDOW_MIN_PRIMITIVES = 64  # HMC solves look-ahead windows only for larger systems
WINDOW_MIN = 0.01  # rad: smallest adaptive HMC look-ahead window
WINDOW_GROWTH = 4.0  # next window after a bounce at dt: this times dt (then clipped)
# the exit search keeps its pair certificates from window to window (``hmc_exit``); False:
# every window builds every pair, the same exits slower (``bench exits``' baseline)
EXIT_CERTIFICATES = True
HMC_TARGET_BOUNCES = 100  # burn-in shortens HMC moves to about this many bounces (limit 500)
HMC_MIN_DURATION = 0.02  # rad: shortest adapted HMC move
POSTERIOR_PRUNE_WIDEN = 2.0  # std factor of the warm rows' moment fit that prunes free pairs


@dataclass(frozen=True, eq=False)
class Deferral:
    """History rows a failed seed search set aside, not judged yet (``sample_posterior``).

    Attributes:
        rows: (d,) history rows left out of the posterior while their seed search goes on.
        effort: (d,) descent restarts run so far by the failed searches that left each violated.
        starts: (s, m) descent starts (z rows) the search has not tried yet: the next call's
            restarts begin from these, where this one stopped; None: none.
    """

    rows: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    effort: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    starts: np.ndarray | None = None

    def __post_init__(self) -> None:
        rows = np.asarray(self.rows, dtype=int).reshape(-1)
        effort = np.asarray(self.effort, dtype=int).reshape(-1)
        if len(effort) != len(rows) or np.any(effort < 0):
            raise ValueError(f"deferral effort {effort.tolist()} must be >= 0, one per row")
        object.__setattr__(self, "rows", rows)
        object.__setattr__(self, "effort", effort)
        if self.starts is not None:
            starts = np.asarray(self.starts, dtype=float)
            starts = starts.reshape(len(starts), -1) if starts.size else None
            object.__setattr__(self, "starts", starts)

    def __len__(self) -> int:
        return len(self.rows)


@dataclass(frozen=True)
class PosteriorSamples:
    """Samples of the posterior shape.

    Attributes:
        z: (N, m) whitened states; vertices: (N, n, 2) metres.
        method: sampler name; ess: effective sample size (min over vertex coordinates);
        seconds: wall time including pruning and seeding.
        dropped: indices into the given history of observations ignored as inconsistent.
        deferral: the observations left out of this call's posterior while their seed search
            goes on (``Deferral``; not judged yet: the next call, given it, tries them again);
            ``deferred`` their indices into the history, ``ignored`` dropped and deferred ones.
        info: sampler counters (steps, chains, pairs kept, acceptance, bounces, seeds, ...).
        convergence: between-chain checks and re-seeding (``core.convergence``); the default
            (R-hat nan, nothing trapped) for independent draws.
    """

    z: np.ndarray
    vertices: np.ndarray
    method: str
    ess: float
    seconds: float
    dropped: np.ndarray
    info: dict = field(default_factory=dict)
    convergence: Convergence = field(default_factory=Convergence)
    deferral: Deferral = field(default_factory=Deferral)

    @property
    def deferred(self) -> np.ndarray:
        """History rows left out for now (``deferral.rows``)."""
        return self.deferral.rows

    @property
    def ignored(self) -> np.ndarray:
        """History rows the samples need not satisfy: dropped and deferred ones, sorted."""
        return np.union1d(self.dropped, self.deferred).astype(int)

    @property
    def est(self) -> float:
        """Effective sample time, seconds per effectively independent draw (Sec. IV-F)."""
        return self.seconds / self.ess if self.ess > 0 else float("inf")


def feasible(system, z: np.ndarray) -> np.ndarray:
    """(C,) whether states z (C, m) satisfy every constraint of ``system``."""
    return np.all(system.violations(system.values(z)) <= 0, axis=-1)


def _violated_count(system, z: np.ndarray) -> np.ndarray:
    return np.sum(system.violations(system.values(z)) > 0, axis=-1)


def _line_scan(system, z: np.ndarray, d: np.ndarray):
    """Segments of the lines z + t d (C rows) and per-segment observation values (C, S, k).

    Along the line, N(0, I) restricted to it is N(mean, std^2) in t; the scan covers
    mean +- LINE_HALF_WIDTH std.
    """
    dd = np.sum(d * d, axis=1)
    mean, std = -np.sum(z * d, axis=1) / dd, 1.0 / np.sqrt(dd)
    lo, hi = mean - LINE_HALF_WIDTH * std, mean + LINE_HALF_WIDTH * std
    edges, values = line_scan(system, z, d, lo, hi)
    return edges, values, mean, std


def hmc_chains(
    system,
    z: np.ndarray,
    n_steps: int,
    rng: np.random.Generator,
    duration: float | np.ndarray = np.pi / 2,
    max_bounces: int = 500,
    window: float | None = None,
    burn_in: int = 0,
    threads: int = 1,
) -> tuple[np.ndarray, dict]:
    """``burn_in`` discarded then ``n_steps`` kept HMC-with-bouncing moves (Alg. 1) of each
    chain z (C, m): the kept states (C, n_steps, m).

    Each move draws p ~ N(0, I) and follows z(t) = z0 cos t + p sin t for t in [0, T];
    at the end of the feasible interval containing the current time the momentum is reflected
    about the gradient of the primitive whose root ends it. T is ``duration``, a scalar or one
    per chain (C,). Implementation decisions:
    - the chains run asynchronously in one batch: a chain that finishes a move starts its next
      one in the same iteration, so no chain waits for the one with the most bounces (burn-in
      moves included);
    - after each burn-in move a chain sets its own T for what follows from that move's bounce
      rate, ``HMC_TARGET_BOUNCES`` / (bounces per rad), within [HMC_MIN_DURATION, its
      ``duration``] (see ``ChainRunner``); the kept moves are plain HMC with that fixed T;
    - the feasible range is solved over look-ahead windows of at most ``window`` rad (default
      0.15 when the system has more than WINDOW_MIN_PRIMITIVES primitives, else the whole move;
      a window without an exit just advances the state: an exact reorganisation of Alg. 1's
      loop in which far fewer primitives can vanish per solve); per chain,
      ``hmc_exit.window_exits`` (compiled) builds the primitives' coefficients from the
      system's small ``ellipse_terms``, keeps those that may vanish (slope, then Bernstein
      bound) in pairs that can change the crossing pattern, solves their roots and finds the
      first infeasible segment;
    - on systems with quadratic primitives each chain adapts its window to its bounce rate:
      after a bounce at dt into the window the next one is WINDOW_GROWTH dt (at least
      WINDOW_MIN), after a window without an exit twice as long (at most ``window``). Any
      window sequence gives the same trajectory; short windows after frequent bounces (thin
      slabs) let the Bernstein filter cull most quartic solves (all-linear systems have
      none to cull: there the extra iterations only cost);
    - a move that needs more than ``max_bounces`` bounces, or whose first segment is judged
      infeasible (numerical grazing), is rejected: the chain keeps its state for that move;
    - roots closer than ROOT_MIN_TIME (1e-9) to the window start are ignored (the one just
      bounced on);
    - the momenta are drawn up front per (move, chain), so the draws do not depend on how the
      loop schedules windows and bounces;
    - ``threads`` > 1 deals each iteration's chains to that many threads for the exit search
      (``hmc_exit.split_exits``): the same draws in any thread count, only faster;
    - each chain keeps certificates of the pairs that cannot turn live until their edge has
      moved far enough (``hmc_exit``, "Certificates"): skipped, the same exits, only faster;
      a rejected move drops its chain's certificates.
    Returns the draws and counters (bounces, rejected moves, travel: rad followed by all
    chains, rejected moves included; ``duration``: each chain's T of its kept moves, (C,)).
    """
    z = np.array(z, dtype=float)
    c, m = z.shape
    longest = np.broadcast_to(np.asarray(duration, dtype=float), (c,))
    if not np.all((longest > 0) & (longest < np.pi)):
        raise ValueError(f"HMC duration must be in (0, pi), got {duration}")
    threads = _thread_count(threads)
    moves = burn_in + n_steps
    out = np.empty((c, n_steps, m))
    done = np.zeros(c, dtype=int)  # moves finished, burn-in included
    start = z.copy()
    momenta = rng.standard_normal((max(moves, 1), c, m))  # move k of chain c: [k, c]
    p = momenta[0].copy()
    dur = longest.copy()
    left = dur.copy()
    bounced = np.zeros(c, dtype=int)
    moved = np.zeros(c)  # rad travelled in the current move
    # per chain: how far each edge has moved, each pair's certificate (``hmc_exit``)
    travel, safe = certificates(c, system.n_edges, system.n_pairs)
    stats = {"bounces": 0, "rejected": 0, "travel": 0.0}
    move_max = float(np.max(duration))  # the longest move: the look-ahead bound
    if window is None:
        window = 0.15 if system.n_prims > WINDOW_MIN_PRIMITIVES else move_max
    win = np.full(c, float(window))
    # only quartic solves are worth culling; all-linear systems keep the fixed window
    all_linear = bool(np.all(system.linear))
    w_min = window if all_linear else min(WINDOW_MIN, window)
    doublings = int(np.ceil(np.log2(window / w_min))) + 1
    per_move = (max_bounces + 2) * (doublings + 1) + int(np.ceil(move_max / window)) + 1
    for _ in range(per_move * moves):  # every iteration advances each active chain
        idx = np.flatnonzero(done < moves)
        if idx.size == 0:
            break
        if not EXIT_CERTIFICATES:
            safe[:] = -np.inf
        zc, pc, lc = z[idx], p[idx], left[idx]
        span = np.minimum(lc, win[idx])
        phi = 0.5 * float(span.max())  # quartics in time shifted as in ``ellipse_roots``
        hit, dt, owner, stuck = split_exits(
            threads,
            *system.ellipse_terms(zc, pc),
            system.window_tables,
            span,
            phi,
            trig_to_quartic(phi),
            system.exit_structure,
            (travel, safe, idx),
        )
        stats["travel"] += float(dt.sum())
        moved[idx] += dt
        cos, sin = np.cos(dt)[:, None], np.sin(dt)[:, None]
        z_new, p_new = zc * cos + pc * sin, pc * cos - zc * sin
        bounce = hit & ~stuck
        if bounce.any():
            prim = owner[bounce]
            grad = system.gradient(z_new[bounce], prim)
            norm = np.sqrt((grad * grad).sum(axis=1, keepdims=True))
            unit = grad / np.where(norm > 0, norm, 1.0)
            pb = p_new[bounce]
            p_new[bounce] = pb - 2 * unit * np.sum(unit * pb, axis=1, keepdims=True)
            stats["bounces"] += int(bounce.sum())
        bounced[idx] += bounce
        grown = np.where(hit, win[idx], 2 * win[idx])
        win[idx] = np.clip(np.where(bounce, WINDOW_GROWTH * dt, grown), w_min, window)
        failed = stuck | (bounced[idx] > max_bounces)
        finished = failed | (~hit & (dt >= lc))
        z[idx], p[idx], left[idx] = z_new, p_new, lc - dt
        fin = idx[finished]
        if fin.size:
            rejected = idx[failed]
            z[rejected] = start[rejected]
            stats["rejected"] += int(rejected.size)
            kept = fin[done[fin] >= burn_in]
            out[kept, done[kept] - burn_in] = z[kept]
            warm = fin[done[fin] < burn_in]
            rate = bounced[warm] / np.maximum(moved[warm], 1e-12)
            wanted = HMC_TARGET_BOUNCES / np.maximum(rate, 1e-12)
            dur[warm] = np.clip(wanted, np.minimum(HMC_MIN_DURATION, longest[warm]), longest[warm])
            done[fin] += 1
            start[fin] = z[fin]
            p[fin] = momenta[np.minimum(done[fin], moves - 1), fin]
            left[fin] = dur[fin]
            bounced[fin] = 0
            moved[fin] = 0.0
            safe[rejected] = -np.inf  # back at the move's start: the certificates do not hold
    for ci in np.flatnonzero(done < moves):  # only if the iteration bound was hit
        out[ci, max(done[ci] - burn_in, 0) :] = start[ci]  # repeat the last state
    stats["duration"] = dur
    return out, stats


def _thread_count(threads) -> int:
    """``threads`` as an int; ValueError unless it is an integer >= 1."""
    if isinstance(threads, bool) or not isinstance(threads, int | np.integer) or threads < 1:
        raise ValueError(f"sampler threads must be an integer >= 1, got {threads!r}")
    return int(threads)


def gibbs_sweep(system, z: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """One Gibbs sweep over every coordinate of z (Sec. IV-D): z_i from N(0, 1) restricted to
    the feasible interval set along axis i (App. A). A row with no feasible mass keeps z_i."""
    z = np.array(z, dtype=float)
    c, m = z.shape
    for i in range(m):  # sequential by definition of Gibbs sampling
        d = np.zeros((c, m))
        d[:, i] = 1.0
        edges, values, mean, std = _line_scan(system, z, d)
        t, found = sample_truncated_normal(edges, np.all(values <= 0, axis=-1), mean, std, rng)
        z[:, i] += np.where(found, t, 0.0)
    return z


def mh_step(
    system, z: np.ndarray, rng: np.random.Generator, scale: float
) -> tuple[np.ndarray, np.ndarray]:
    """Random-walk Metropolis-Hastings (Sec. IV-D): Gaussian perturbation of std ``scale``,
    accepted with the prior density ratio if the proposal is feasible."""
    proposal = z + scale * rng.standard_normal(z.shape)
    log_ratio = 0.5 * (np.sum(z * z, axis=1) - np.sum(proposal * proposal, axis=1))
    accept = (np.log(rng.random(len(z))) < log_ratio) & feasible(system, proposal)
    return np.where(accept[:, None], proposal, z), accept


class ChainRunner:
    """Advances a batch of chains with one MCMC method on any constraint system."""

    def __init__(
        self,
        system,
        method: str,
        rng: np.random.Generator,
        hmc_duration: float = np.pi / 2,
        mh_scale: float | None = None,
        threads: int = 1,
    ):
        if method not in MCMC_METHODS:
            raise ValueError(f"unknown MCMC method {method!r}; choose from {MCMC_METHODS}")
        self.system, self.method, self.rng = system, method, rng
        self.hmc_duration = self.duration = hmc_duration
        self.threads = _thread_count(threads)  # HMC's exit search (``hmc_chains``)
        self.scale = mh_scale if mh_scale is not None else 0.5 / np.sqrt(max(system.n_dim, 1))
        self.stats = {"bounces": 0, "accepted": 0, "proposed": 0}

    def step(self, z: np.ndarray, adapt: bool = False) -> np.ndarray:
        if self.method == "gibbs":
            z = gibbs_sweep(self.system, z, self.rng)
            self.stats["accepted"] += len(z)
        else:
            z, accept = mh_step(self.system, z, self.rng, self.scale)
            self.stats["accepted"] += int(accept.sum())
            if adapt:  # Robbins-Monro towards 25 % acceptance; burn-in only
                self.scale *= np.exp(0.5 * (accept.mean() - 0.25))
        self.stats["proposed"] += len(z)
        return z

    def run(self, z: np.ndarray, steps: int, thin: int = 1, burn_in: int = 0) -> np.ndarray:
        """States after each of ``steps`` kept steps (``thin`` moves each) that follow
        ``burn_in`` discarded moves (MH adapts its step and HMC its duration during those
        only): (C, steps, m)."""
        if self.method == "hmc":
            return self._hmc(z, steps * thin, burn_in)[:, thin - 1 :: thin]
        for _ in range(burn_in):
            z = self.step(z, adapt=True)
        out = np.empty((len(z), steps, z.shape[1]))
        for i in range(steps):
            for _ in range(thin):
                z = self.step(z)
            out[:, i] = z
        return out

    def _hmc(self, z: np.ndarray, moves: int, burn_in: int) -> np.ndarray:
        """HMC moves; with ``burn_in`` each chain adapts its move duration T first.

        Decision (the paper fixes T = ``hmc_duration``): in a thin posterior (many contacts on
        a sharp depth prior) a T = pi/2 move needs thousands of bounces, so nearly every move
        hits ``max_bounces`` and is rejected; chains then stay at their seeds (notch, depth
        prior: 136 of 160 moves rejected, 20 s per cycle, split R-hat 3.7). After each burn-in
        move a chain sets T = HMC_TARGET_BOUNCES / (bounces per rad of that move), within
        [HMC_MIN_DURATION, hmc_duration] (``hmc_chains``): fixed before any kept move, so the
        kept moves are plain HMC with that T, one per chain (any fixed T leaves the posterior
        invariant). Per chain, not pooled over the chains: pooling made every burn-in move a
        barrier at which all chains waited for the one with the most bounces. A call without
        burn-in continues the chains of the last call with burn-in, with their T (all at
        ``hmc_duration`` if there was none)."""
        duration = self.hmc_duration if burn_in else self.duration
        draws, stats = hmc_chains(
            self.system, z, moves, self.rng, duration, burn_in=burn_in, threads=self.threads
        )
        if burn_in:
            self.duration = stats["duration"]
        self.stats["bounces"] += stats["bounces"]
        self.stats["accepted"] += len(z) * (burn_in + moves) - stats["rejected"]
        self.stats["proposed"] += len(z) * (burn_in + moves)
        return draws


def _descent_step(system, z, pick, d, count_now, rng) -> np.ndarray:
    """One coordinate step of ``random_descent``: states z (C, m) moved along directions d.

    The line is cut at every primitive root within the conditional mean +- DESCENT_HALF_WIDTH
    std (widened to keep t = 0). Decision: evaluating every observation at every segment costs
    O(segments x primitives) = O(K^2) (three_ledges, 77 segments: 2000 segments x 2320
    primitives, 0.3 s a step); only DESCENT_CANDIDATES segments are judged in full: the ones
    of most prior mass where the picked observation holds, topped up with the most massive
    others, and the current segment (so the violated count never increases). The step draws
    from the prior along the line restricted to the candidates with the fewest violations.
    """
    dd = np.sum(d * d, axis=1)
    mean, std = -np.sum(z * d, axis=1) / dd, 1.0 / np.sqrt(dd)
    lo = np.minimum(mean - DESCENT_HALF_WIDTH * std, 0.0)
    hi = np.maximum(mean + DESCENT_HALF_WIDTH * std, 0.0)
    coef = system.line_coefficients(z, d)
    roots, _ = line_roots(coef, lo, hi)
    edges, mids = segment_edges(roots, lo, hi)
    a, b = (
        (edges[:, :-1] - mean[:, None]) / std[:, None],
        (edges[:, 1:] - mean[:, None]) / std[:, None],
    )
    score = np.full(mids.shape, -np.inf)
    real = edges[:, 1:] > edges[:, :-1]  # not the padding collapsed onto hi
    score[real] = normal_log_mass(a[real], b[real])
    structure = system.exit_structure
    score += np.where(descent_scan.picked_violated(coef, mids, pick, structure), 0.0, 1e3)
    n_cand = min(DESCENT_CANDIDATES, score.shape[1])
    cand = np.argpartition(-score, n_cand - 1, axis=1)[:, :n_cand]
    current = np.sum(edges[:, 1:] < 0.0, axis=1)  # the segment holding t = 0
    cand = np.concatenate([cand, current[:, None]], axis=1)
    t = np.take_along_axis(mids, cand, 1)
    powers = np.stack([np.ones_like(t), t, t * t], axis=-1)
    values = np.matmul(powers, coef.swapaxes(1, 2))  # (C, candidates, K)
    cap = np.repeat(count_now, t.shape[1])  # above the current segment's: never the fewest
    count = descent_scan.violated_counts(values.reshape(-1, values.shape[-1]), structure, cap)
    count = count.reshape(t.shape)
    count = np.where(np.isfinite(np.take_along_axis(score, cand, 1)), count, np.iinfo(int).max)
    count[:, -1] = count_now  # the current segment: the rows' violated counts at t = 0
    best = np.zeros(mids.shape, dtype=bool)
    rows = np.repeat(np.arange(len(z)), cand.shape[1])
    best[rows, cand.ravel()] = (count == count.min(axis=1, keepdims=True)).ravel()
    t, found = sample_truncated_normal(edges, best, mean, std, rng)
    return z + np.where(found, t, 0.0)[:, None] * d


def random_descent(
    system,
    z: np.ndarray,
    rng: np.random.Generator,
    max_iters: int = 60,
    enough: int | None = None,
    patience: int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Random descent of f_H (Sec. IV-D) from states z (C, m): returns (z, violated counts).

    Decision: each iteration picks a random violated observation and a random coordinate axis
    of z, with probability proportional to the squared gradient of the observation's active
    primitive along it (so local columns, e.g. one vertex's depth noise, fix local contacts
    without disturbing the rest). The state jumps along that axis to a point, drawn from the
    prior along the line, of a segment with the fewest violated observations among the
    candidates of ``_descent_step``: the count never increases. Stops when ``enough`` rows
    (default all) are feasible, or, with ``patience``, when no row still violated has lowered
    its count for that many iterations.

    Decision (2026-11-28; the seed search passes DESCENT_PATIENCE): a descent that stalls
    rarely recovers. On sloper train truth 5 (depth prior, compliant, episode seed 0, cycle
    1, 24 rows; one-off trace of 64 descents over 120 iterations) the 5 that reached
    feasibility did so at iterations 3, 4, 6, 8 and 96; 56 of the 59 others last lowered their
    count by iteration 9. A restart whose descents all fail no longer runs its 60 iterations:
    a failed retry of deferred rows took 0.13-0.32 s instead of 0.73-1.0 s (sloper truth 5,
    non-compliant, episode seed 2, cycles 6-8 of each version's episode), a restart topping up
    distinct seeds 0.04-0.10 s instead of 0.17-0.21 s (the history above).
    """
    z = np.array(z, dtype=float)
    m = z.shape[1]
    count = _violated_count(system, z)
    enough = len(z) if enough is None else enough
    stalled = 0  # iterations since any row's count last dropped
    for _ in range(max_iters):
        todo = np.flatnonzero(count > 0)
        if len(z) - todo.size >= enough or (patience is not None and stalled >= patience):
            break
        values = system.values(z[todo])
        viol = system.violations(values) > 0
        pick = np.argmax(viol * rng.random(viol.shape), axis=1)  # a random violated one
        prim, _ = system.steepest_primitive(values, pick)
        weight = system.gradient(z[todo], prim) ** 2 + 1e-12 / m
        cum = np.cumsum(weight, axis=1)
        axis = np.argmax(cum >= rng.random((todo.size, 1)) * cum[:, -1:], axis=1)
        d = np.zeros((todo.size, m))
        d[np.arange(todo.size), axis] = 1.0
        z[todo] = _descent_step(system, z[todo], pick, d, count[todo], rng)
        now = _violated_count(system, z[todo])
        stalled = 0 if np.any(now < count[todo]) else stalled + 1
        count[todo] = now
    return z, count


def _consistent_rows(shape: GaussianShape, history: History, z: np.ndarray) -> np.ndarray:
    v = shape.vertices(z)
    return np.all(observation_violations(shape.closed, v, history, shape.friction) <= 0, axis=1)


def _contact_projection(
    shape: GaussianShape, history: History, z: np.ndarray, iters: int = 3
) -> np.ndarray:
    """Move prior draws z (C, m) so that the surface passes through every contact midpoint.

    Decision (the paper seeds descent from plain prior draws, which for thin contact slabs
    almost never reach the feasible set): each contact midpoint p gets the edge of the current
    shape its probe line crosses nearest to p, and Gauss-Newton minimum-norm steps solve
    cross(d - c, p - c) = 0 (g1 of eq. 7 with a = p) for all of them at once.
    """
    contact = np.flatnonzero(history.is_contact)
    if contact.size == 0:
        return z
    a, b = history.a[contact], history.b[contact]
    mid, u = 0.5 * (a + b), b - a
    u = u / np.linalg.norm(u, axis=1, keepdims=True)
    z = np.array(z, dtype=float)
    for c in range(len(z)):  # a handful of chains, each a small least-squares problem
        v = shape.vertices(z[c])
        ends = v[shape.edges]  # (E, 2, 2)
        e = ends[:, 1] - ends[:, 0]
        rel = ends[None, :, 0] - mid[:, None]  # (k, E, 2)
        den = u[:, None, 0] * e[None, :, 1] - u[:, None, 1] * e[None, :, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (rel[..., 0] * e[None, :, 1] - rel[..., 1] * e[None, :, 0]) / den
            lam = (rel[..., 0] * u[:, None, 1] - rel[..., 1] * u[:, None, 0]) / den
        score = np.where((lam >= 0) & (lam <= 1) & np.isfinite(s), np.abs(s), np.inf)
        host = np.argmin(score, axis=1)
        usable = np.isfinite(score[np.arange(len(contact)), host])
        if not usable.any():
            continue
        probe = History(mid[usable], mid[usable] + u[usable], np.ones(usable.sum(), int))
        pairs = np.stack([np.arange(usable.sum()), host[usable]], axis=1)
        system = HistoryConstraints(shape, probe, pairs)
        prims = system.primitive_index(np.arange(len(pairs)), 0)
        for _ in range(iters):
            g = system.values(z[c][None])[0, prims]
            jac = system.gradient(np.repeat(z[c][None], len(prims), 0), prims)
            z[c] -= np.linalg.lstsq(jac, g, rcond=None)[0]
    return z


MAX_HMC_CHAINS = 256  # widest default batch: 4096 samples as 256 chains x 16 draws


def default_chains(method: str, n_samples: int) -> int:
    """Chains when none are given: 16, and for HMC up to MAX_HMC_CHAINS so that each chain
    still yields >= 16 draws, as many chains as make chains x draws per chain closest above
    ``n_samples`` (no surplus draws). Decision: HMC's cost is dominated by per-bounce numpy
    calls over the whole batch, so wider batches (fewer bounce iterations per sample) are
    cheaper per draw, while each chain pays its own burn-in and 16 draws keep the per-chain
    autocorrelation estimate of the ESS meaningful."""
    if method == "hmc":
        per_chain = max(16, -(-n_samples // MAX_HMC_CHAINS))
        return int(np.clip(-(-n_samples // per_chain), 16, MAX_HMC_CHAINS))
    return 16


def _warm_seeds(shape, history, system, init_z, rng):
    """The rows of ``init_z`` consistent with the whole history and feasible for the pruned
    ``system``, and the rest of ``init_z`` (each in random order)."""
    ok = _consistent_rows(shape, history, init_z)
    ok[ok] = feasible(system, init_z[ok])
    good, rest = init_z[ok], init_z[~ok]
    return good[rng.permutation(len(good))], rest[rng.permutation(len(rest))]


def _posterior_pruned(shape, history, pairs, draws, threshold):
    """``pairs`` without the free-observation pairs whose collision bound (eqs. 16-17) is below
    ``threshold`` also under a Gaussian moment fit of posterior ``draws`` (z rows), its std
    widened POSTERIOR_PRUNE_WIDEN times.

    Decision (not in the paper, which prunes under the prior only): late in an episode most
    prior-kept pairs lie where no posterior draw goes (three_ledges truth 9, problem prior, 97
    observations: 636 pairs kept by the prior, 399 after this, the same HMC bounces; the
    moment fit needs at least 2 draws). Dropping a free pair only relaxes the chains'
    constraints, and every draw is verified against every pair, so the returned samples stay
    exact; a contact observation's pairs are never dropped (that would tighten it)."""
    x = shape.states(draws)
    mean = x.mean(axis=0)
    spread = POSTERIOR_PRUNE_WIDEN * (x - mean).T / np.sqrt(len(x) - 1)
    bounds = collision_bounds(shape.with_mean_basis(mean, spread), history)
    keep = bounds[pairs[:, 0], pairs[:, 1]] >= threshold
    return pairs[keep | history.is_contact[pairs[:, 0]]]


def _exact_seeds(shape, history, system, chains, rng):
    """Up to ``chains`` prior draws consistent with the history and feasible for the pruned
    ``system`` (exact posterior draws), and the prior draws spent: a first batch, then up to a
    budget per chain unless the first batch had no hit (acceptance too low for the budget to
    pay: descent seeds the chains). Since 2026-11-27 this runs on every call with a history,
    warm start or not, so the cheap test screens first (a first batch on a 136-row depth-prior
    history: 10 ms, the exact test of all 128 draws 64 ms).

    Decision (2026-11-29): the draw counts scale with 1 / rows so that the search costs at most
    what SEED_PRIOR_BATCH draws and SEED_PRIOR_DRAWS per chain cost on a SEED_COST_ROWS-row
    history (the test is linear in the rows): on a 4-row history, 4352 and 1088 per chain.
    Chains seeded by descent sit where the descents end, not where the posterior mass is: on a
    learned three_ledges prior fitted with a 0.05 mm floor, whose cycle-1 posterior has two
    modes (21 % in the smaller) and 0.36 % of prior draws fit, the first batch of 128 found no
    hit in 63 % of runs and 40 runs of 2000 draws pooled lay 0.21-0.31 posterior std from
    rejection (single runs 0.79); with these counts 0.054 (single runs 0.22)."""
    found, count, spent = [np.zeros((0, shape.n_basis))], 0, 0
    scale = max(1.0, SEED_COST_ROWS / max(len(history), 1))
    first = int(SEED_PRIOR_BATCH * scale)
    budget = max(first, int(SEED_PRIOR_DRAWS * scale) * chains)
    while count < chains and spent < budget:
        size = first if spent == 0 else min(8 * first, budget - spent)
        z = shape.sample_z(rng, size)
        spent += size
        ok = feasible(system, z)  # the pruned pairs first: ~6x cheaper than the exact test
        ok[ok] = _consistent_rows(shape, history, z[ok])
        found.append(z[ok])
        count += int(ok.sum())
        if count == 0:
            break
    return np.vstack(found)[:chains], spent


def _typical(z: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """(C,) whether seeds z are not far less likely under the prior than the ``reference``
    seeds: |z|^2 at most max(m, median reference |z|^2) + SEED_Z2_MARGIN sqrt(2 m) (the
    chi-square std). A seed at the reference median passes."""
    m = z.shape[1]
    level = max(float(m), float(np.median(np.sum(reference * reference, axis=1))))
    return np.sum(z * z, axis=1) <= level + SEED_Z2_MARGIN * np.sqrt(2.0 * m)


@dataclass
class _Seeds:
    z: np.ndarray | None  # (C, m) chain seeds; None if no restart reached feasibility
    system: HistoryConstraints | None  # the pruned constraints (with the pairs seeds missed)
    exact: np.ndarray  # (C,) seeds that are exact posterior draws (prior draws that fit)
    best_z: np.ndarray | None = None  # best state of failed descents (for dropping)
    restarts: int = 0  # descent restarts run
    untried: np.ndarray | None = None  # descent starts not tried (a failed search's)
    warm: int = 0  # distinct warm-start rows used
    distinct: int = 0  # distinct seeds
    screened: int = 0  # feasible descent seeds discarded as atypical (``_typical``)
    descended: int = 0  # chains seeded by descent (the others: exact seeds or warm rows)


def _seed(
    shape,
    history,
    rng,
    chains,
    threshold,
    restarts,
    max_iters,
    init_z=None,
    give_up=None,
    starts=None,
) -> _Seeds:
    """Feasible seeds for the chains and the HistoryConstraints they were found on; ``give_up``
    (default ``restarts``): after that many restarts in which no descent reached a feasible
    state the search ends, failed when there is no exact or warm seed either, and otherwise
    with those seeding the chains (decision 4 below); once a descent seed is found, restarts go
    on up to ``restarts`` for SEED_MIN_DISTINCT seeds as before. ``starts``: descent starts to
    try before the rows of ``init_z`` (an earlier failed search's untried ones, ``Deferral``);
    a failed search returns its own untried starts (``_Seeds.untried``).

    Decision (a seed in a feasible pocket of negligible mass traps every chain started from it;
    HMC never leaves a pocket, so a longer burn-in does not help):
    1. exact seeds: prior draws that satisfy the history are posterior draws, so chains seeded
       by them are in each pocket, and each of the posterior's separate regions, with its
       posterior probability (``_exact_seeds``: a bounded budget, skipped when the first batch
       has no hit). Tried first, also with ``init_z``: HMC chains cannot cross between
       separate regions, so chains seeded from the previous posterior keep its regions'
       shares, and each cycle adds the noise of its few chains to them. Measured (2026-11-27,
       ``bench posterior --reference rejection``, sloper truth 1, depth prior, non-compliant,
       20 warm runs pooled against 2000 rejection draws): warm seeds only were 0.31 (cycle 2,
       7 rows) and 0.40 (cycle 3, 11 rows) posterior std off in the median vertex
       coordinate, cold runs from exact seeds 0.05 and 0.04;
    2. warm start: rows of ``init_z`` (e.g. the previous posterior's samples) that satisfy the
       history seed the chains left (in random order, shared round-robin if fewer than
       ``chains`` but at least SEED_MIN_DISTINCT with the exact ones; with fewer, they seed one
       chain each and descents seed the rest); descents start from the other rows, each
       restart from rows not tried yet, before any prior draw (they already satisfy most
       observations: on three_ledges a restart from prior draws against 77 segments took
       26 s, one from previous-posterior rows 2 s); with at least ``chains`` such rows the
       free pairs are pruned under their widened moment fit as well (``_posterior_pruned``);
    3. the remaining chains get one descent each: prior draws projected onto the contacts,
       then random descent. Beyond SEED_DESCENTS remaining chains, SEED_DESCENTS descents run
       per restart, stop once half of them are feasible or none has lowered its violated
       count for DESCENT_PATIENCE steps (``random_descent``), and the chains share the descent
       seeds round-robin (descents are the costly part of seeding). A feasible descent
       seed far less likely under the prior than the typical seed (``_typical``; exact and
       warm seeds count as typical) is discarded; descents restart until SEED_MIN_DISTINCT
       seeds (with the warm / exact ones) are kept, so that one pocket seed holds less than
       half of the chains and the check after the run can tell which chains are trapped;
    4. a round of the episode loops (``give_up``, SEED_ROUND_RESTARTS) whose restarts bring no
       descent to a feasible state ends there also when exact or warm seeds exist, and those
       seed every chain, as they did after all ``restarts`` failed: the other restarts came
       to nothing at up to 0.35 s each (2026-11-29: a depth-prior cycle of 276 rows, sloper
       test truth 0, non-compliant, spent 2.8 of its 3.4 s in 8 such restarts for a third
       distinct seed). Side by side on the training truths (``bench docking --split train
       --prior generic --strategies ours --mode compliant non-compliant --episode-seeds 3``):
       every episode alike, slowest cycle 1.16 -> 1.13 s, summed 141 -> 146 s (noise); then
       on the test truths (``--split test --episode-seeds 8``) every episode alike, slowest
       cycle 3.30 -> 1.67 s.
    Pocket chains that get past this are caught after the run (``convergence``) and re-seeded.

    Pairs a seed violates outside the pruned set are added to it and the descent repeated; they
    are found on the seed's vertices (``crossed_free_pairs``, ~2 ms): a constraint system over
    every pair took 0.10-0.26 s of the search to build (7,850 pairs, depth prior; 2026-11-29).
    """
    pairs = prune_pairs(shape, history, threshold)
    system = HistoryConstraints(shape, history, pairs)
    warm = np.zeros((0, shape.n_basis))
    pool, _ = _exact_seeds(shape, history, system, chains, rng)  # exact seeds first, then warm
    n_exact = len(pool)
    if init_z is not None and len(init_z):
        consistent, warm = _warm_seeds(shape, history, system, init_z, rng)
        pool = np.vstack([pool, consistent[: chains - n_exact]])
        if len(pool) >= min(chains, SEED_MIN_DISTINCT):
            if len(consistent) >= max(chains, 2):
                pairs = _posterior_pruned(shape, history, pairs, consistent, threshold)
                system = HistoryConstraints(shape, history, pairs)
            share = np.arange(chains) % len(pool)
            return _Seeds(
                pool[share], system, share < n_exact, warm=len(pool) - n_exact, distinct=len(pool)
            )
    if n_exact == chains:
        return _Seeds(pool, system, np.ones(chains, dtype=bool), distinct=chains)
    if starts is not None and len(starts):
        warm = np.vstack([starts, warm])  # where an earlier search stopped, first
    best_z, best_count = None, np.inf
    tries = min(chains - len(pool), SEED_DESCENTS)
    found = np.zeros((0, shape.n_basis))  # feasible descent seeds so far
    good = found
    ran = 0
    for attempt in range(restarts):
        ran += 1
        start = warm[attempt * tries : (attempt + 1) * tries]
        if len(start) < tries:  # previous-posterior rows first: they already fit most rows
            start = np.vstack([start, shape.sample_z(rng, tries - len(start))])
        z0 = _contact_projection(shape, history, start)
        enough = tries if tries == chains - len(pool) else max(1, tries // 2)
        z, count = random_descent(system, z0, rng, max_iters, enough, DESCENT_PATIENCE)
        ok = (count == 0) & _consistent_rows(shape, history, z)
        # pairs the pruned set missed: add the ones these states violate
        missed = crossed_free_pairs(shape.closed, shape.vertices(z[count == 0]), history)
        merged = np.unique(np.vstack([pairs, missed]), axis=0)
        if len(merged) > len(pairs):
            pairs = merged
            system = HistoryConstraints(shape, history, pairs)
        found = np.vstack([found, z[ok]])
        if len(found):
            good = found[_typical(found, np.vstack([pool, found]))]
        if len(good) and len(pool) + len(good) >= min(SEED_MIN_DISTINCT, chains):
            break
        if not ok.any():
            full_count = np.sum(
                observation_violations(shape.closed, shape.vertices(z), history, shape.friction)
                > 0,
                axis=1,
            )
            if full_count.min() < best_count:
                best_count, best_z = full_count.min(), z[np.argmin(full_count)]
        if give_up is not None and ran >= give_up and not len(found):
            break  # no descent reached a feasible state: this round's search ends
    warm_used = len(pool) - n_exact
    if len(good):
        fill = good[np.arange(chains - len(pool)) % len(good)]
        return _Seeds(
            np.vstack([pool, fill]),
            system,
            np.arange(chains) < n_exact,
            warm=warm_used,
            distinct=len(pool) + len(good),
            screened=len(found) - len(good),
            restarts=ran,
            descended=chains - len(pool),
        )
    if len(pool):  # descent failed, but some chains have exact or warm seeds: share those
        share = np.arange(chains) % len(pool)
        return _Seeds(
            pool[share], system, share < n_exact, warm=warm_used, distinct=len(pool), restarts=ran
        )
    untried = warm[ran * tries :][: SEED_DESCENTS * SEED_RESTARTS_DEFAULT]  # enough for a row
    return _Seeds(
        None, None, np.zeros(chains, dtype=bool), best_z=best_z, restarts=ran, untried=untried
    )


def _stalled(counts, per_chain: int, full_elsewhere: int = 0) -> bool:
    """Whether the chains short of ``per_chain`` verified draws have none at all while at least
    half the chains (these and ``full_elsewhere`` full ones of the same run) are full: those
    will not catch up where they are."""
    counts = np.asarray(counts)
    short = counts < per_chain
    full = int(np.sum(~short)) + full_elsewhere
    return bool(
        short.any() and np.all(counts[short] == 0) and 2 * full >= len(counts) + full_elsewhere
    )


class _ChainRun:
    """Runs chains from given seeds to ``per_chain`` verified draws each (burn-in first); every
    draw is checked against the whole history and dropped if it fails. Counts steps per chain,
    chain moves and verified draws over all calls.

    Decision (not in the paper, which verifies nothing): a chain can sit where the pruned
    system admits states the exact test rejects, and then never verifies a draw. Such a chain
    must not cut the others to its length (it used to empty the result). Chains left short of
    ``per_chain`` while others are full restart once from the last state of a random full
    chain (with burn-in); chains then holding fewer than half the best chain's draws are
    dropped with a warning. The restart comes as soon as the short chains have verified nothing
    in 2 ``per_chain`` steps while at least half the chains are full (``_stalled``): waiting for
    ``max_steps`` (1350 steps of every chain at 100 samples: ~190 HMC calls of ~0.3 s on a late
    depth-prior cycle) would outlast the planner's wait for samples (60 s in the profiles)."""

    def __init__(self, runner, shape, history, per_chain, thin, burn_in, max_steps, rng):
        self.runner, self.shape, self.history = runner, shape, history
        self.per_chain, self.thin, self.burn_in = per_chain, thin, burn_in
        self.max_steps, self.rng = max_steps, rng
        self.steps = self.moves = self.verified = 0

    def _collect(self, z: np.ndarray, full_elsewhere: int = 0) -> tuple[list, np.ndarray]:
        """At most ``per_chain`` verified draws per chain (lists) and the last states;
        ``full_elsewhere``: full chains of the same run outside ``z`` (a restart's)."""
        chains, m = z.shape
        chain_draws = [[] for _ in range(chains)]
        counts, steps = [0] * chains, 0
        while min(counts) < self.per_chain and steps < self.max_steps:
            count = min(self.per_chain - min(counts), self.max_steps - steps)
            burn = 0 if steps else self.burn_in
            block = self.runner.run(z, count, thin=self.thin, burn_in=burn)  # (C, B, m)
            z, steps = block[:, -1], steps + count
            ok = _consistent_rows(self.shape, self.history, block.reshape(-1, m))
            ok = ok.reshape(chains, -1)
            self.verified += int(ok.sum())
            for c in range(chains):  # one list append per chain and block
                chain_draws[c].extend(block[c, ok[c]])
            counts = [len(c) for c in chain_draws]
            if steps >= 2 * self.per_chain and _stalled(counts, self.per_chain, full_elsewhere):
                break
        self.steps += steps
        self.moves += steps * chains
        return [c[: self.per_chain] for c in chain_draws], z

    def __call__(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Draws (K, L, m) of the K kept chains (L the fewest verified draws among them), their
        last states (K, m) and their indices into ``z`` (K,)."""
        chain_draws, z = self._collect(z)
        counts = np.array([len(c) for c in chain_draws])
        full = np.flatnonzero(counts >= self.per_chain)
        short = np.flatnonzero(counts < self.per_chain)
        if short.size and full.size:
            redo, z_redo = self._collect(z[self.rng.choice(full, short.size)], full.size)
            z = z.copy()
            for i, c in enumerate(short):
                chain_draws[c], z[c] = redo[i], z_redo[i]
            counts = np.array([len(c) for c in chain_draws])
        kept = np.flatnonzero(counts >= max(1, -(-counts.max() // 2)))
        if counts.max() == 0:
            kept = np.arange(len(z))
        elif kept.size < len(z):
            LOG.warning(
                "%d of %d %s chains dropped: fewer than half the verified draws of the best "
                "chain (%d) even after a restart from another chain",
                len(z) - kept.size,
                len(z),
                self.runner.method,
                counts.max(),
            )
        length = int(counts[kept].min())
        draws = np.array([chain_draws[c][:length] for c in kept]).reshape(kept.size, length, -1)
        return draws, z[kept], kept


def _trapped_and_sources(draws, coords, exact):
    """The chains to re-seed, the chains to re-seed them from, and whether posterior mass
    chose them. When the chains disagree (``trapped_chains`` names some, or split R-hat is
    above its limit), two splits are judged by ``mass_gap``: the named chains against the rest,
    and the split of the chain means at their widest gap (``chain_groups``); if the larger
    |gap| exceeds MASS_GAP_LIMIT, chains of the group over its share of the mass are re-seeded
    from the other (``_mass_allocation``).
    Otherwise the named chains are re-seeded from the rest (none named: none re-seeded, the
    R-hat warning stays). Exact seeds are never re-seeded.

    Decision: both splits. ``trapped_chains`` can miss the pocket's split: with 8 of 16 chains
    in a pocket it named 1 of the others (gap 1.1; the head count then re-seeded it into the
    pocket), while chain_groups split the two seeds' chains exactly (gap 10.9). chain_groups
    cuts at one gap only, which with three seed clusters can fall between two of them (not
    seen in the runs measured: with 10 chains on two pocket seeds it found the 6 others, as
    trapped_chains did, gap 7.4)."""
    everyone = np.arange(len(draws))
    named = trapped_chains(coords)
    disagree = named.size > 0 or np.max(split_rhat(coords)) > rhat_limit(*coords.shape)
    if len(draws) < 3 or not disagree:
        return named[:0], everyone, False
    splits = [chain_groups(coords)]
    if named.size:
        splits.append((named, np.setdiff1d(everyone, named)))
    gaps = [mass_gap(draws, group, rest) for group, rest in splits]
    best = int(np.argmax(np.nan_to_num(np.abs(gaps))))
    if abs(gaps[best]) > MASS_GAP_LIMIT:
        group, rest = splits[best]
        low, high = (rest, group) if gaps[best] > 0 else (group, rest)
        return (*_mass_allocation(draws, low, high, exact), True)
    trapped = np.setdiff1d(named, np.flatnonzero(exact))
    return trapped, np.setdiff1d(everyone, trapped), False


def _mass_allocation(draws, low, high, exact) -> tuple[np.ndarray, np.ndarray]:
    """The chains to re-seed and the chains to re-seed them from, so that the two groups'
    chain counts follow their posterior masses: group ``low`` holds the share ``1 / (1 + e^d)``,
    d the difference of the groups' mean ``chain_log_mass`` (nats: the log ratio of the
    masses of the regions they sample). Chains move only when a group is off its share by
    more than two binomial standard errors (at least one chain); exact seeds never move.

    Decision (2026-11-29): a gap of more than MASS_GAP_LIMIT standard errors used to re-seed
    every chain of the group with less mass. That removes a pocket (6.8 nats less, share
    0.1 %), but also a genuine second mode, and the more chains the smaller the gap that
    passes: on a learned three_ledges prior fitted with a 0.05 mm floor the chains of a mode
    holding ~20 % of the posterior scored 1.5-1.8 nats less (shares 14-18 %), 19-40 of 125
    chains, and all were moved out. 40 seeds of 2000 draws against rejection (pooled means,
    largest and median coordinate, in posterior std): that prior 0.31 / 0.25 -> 0.21 / 0.15;
    the library before's three_ledges case of ``test_sampling`` 0.10 / 0.075 -> 0.076 / 0.048
    (largest single run 0.255 -> 0.243); notch and problem 2's checks unchanged."""
    score = chain_log_mass(draws)
    total = low.size + high.size
    share = 1.0 / (1.0 + np.exp(score[high].mean() - score[low].mean()))
    target = total * share
    slack = max(1.0, 2.0 * np.sqrt(total * share * (1.0 - share)))
    fixed = np.flatnonzero(exact)
    if low.size - target > slack:
        return np.setdiff1d(low, fixed)[: round(low.size - target)], high
    if target - low.size > slack:
        return np.setdiff1d(high, fixed)[: round(target - low.size)], low
    return low[:0], np.union1d(low, high)


def _reseed_trapped(run, draws, last, exact, rng):
    """Checks the chains (``convergence``) and re-seeds trapped ones from the last states of
    random other chains (``_trapped_and_sources``), reruns them (with burn-in) and splices
    their draws in: at most RESEED_ROUNDS rounds. Chains with exact seeds are not re-seeded
    (they are in their pocket with its posterior probability). Logs a warning when chains
    disagree.

    Returns the draws (C, L, m) and the Convergence report."""
    shape = run.shape
    reseeded, rounds, by_mass = 0, 0, 0
    while True:
        coords = draws @ shape.basis.T + shape.mean
        trapped, good, mass_chose = _trapped_and_sources(draws, coords, exact)
        if trapped.size == 0 or rounds == RESEED_ROUNDS:
            break
        rounds += 1
        reseeded += trapped.size
        if mass_chose:
            by_mass += 1
            LOG.warning(
                "%d of %d %s chains re-seeded from %d others by posterior mass (a group "
                "narrower and less likely under the prior than its share of the chains)",
                trapped.size,
                len(draws),
                run.runner.method,
                good.size,
            )
        new, new_last, kept = run(last[rng.choice(good, trapped.size)])
        if new.shape[1] == 0:  # no rerun chain verified a draw: drop them all
            kept = kept[:0]
        lost, trapped = np.delete(trapped, kept), trapped[kept]
        draws, last = draws.copy(), last.copy()
        if kept.size:
            length = min(draws.shape[1], new.shape[1])
            draws = draws[:, :length]
            draws[trapped], last[trapped] = new[:, :length], new_last
        draws, last, exact = (np.delete(a, lost, axis=0) for a in (draws, last, exact))
        LOG.warning(
            "%d of %d %s chains trapped away from the others: re-seeded from other chains "
            "(round %d of %d)",
            trapped.size,
            len(draws),
            run.runner.method,
            rounds,
            RESEED_ROUNDS,
        )
    rhat = split_rhat(coords)
    report = Convergence(
        rhat=float(np.max(rhat)) if rhat.size else float("nan"),
        rhat_limit=rhat_limit(*coords.shape),
        trapped=int(trapped.size),
        reseeded=reseeded,
        rounds=rounds,
        mass_rounds=by_mass,
    )
    if not report.converged:
        LOG.warning(
            "%s chains disagree: split R-hat %.3f (limit %.2f), %d trapped chains",
            run.runner.method,
            report.rhat,
            report.rhat_limit,
            report.trapped,
        )
    return draws, report


def _prior_draws(shape, n_samples, rng, method, start, dropped, info, deferral=None):
    z = shape.sample_z(rng, n_samples)
    return PosteriorSamples(
        z,
        shape.vertices(z),
        method,
        float(n_samples),
        time.perf_counter() - start,
        dropped,
        info,
        deferral=Deferral() if deferral is None else deferral,
    )


def _deferral(set_aside: dict[int, int], starts) -> Deferral:
    """The Deferral of ``{row: restarts spent}`` (rows sorted) with untried ``starts``."""
    rows = sorted(set_aside)
    if not rows:
        return Deferral()
    return Deferral(np.array(rows, int), np.array([set_aside[r] for r in rows], int), starts)


def _rejection(shape, history, n_samples, rng, max_draws, batch):
    kept, draws = [], 0
    while sum(len(k) for k in kept) < n_samples and draws < max_draws:
        size = min(batch, max_draws - draws)
        z = shape.sample_z(rng, size)
        draws += size
        kept.append(z[_consistent_rows(shape, history, z)])
    z = np.vstack([np.zeros((0, shape.n_basis)), *kept])[:n_samples]
    return z, {"draws": draws, "acceptance": (sum(len(k) for k in kept) / max(draws, 1))}


def sample_posterior(
    shape: GaussianShape,
    history: History,
    n_samples: int,
    rng: np.random.Generator,
    method: str = "hmc",
    *,
    chains: int | None = None,
    burn_in: int | None = None,
    thin: int = 1,
    prune_threshold: float = 1e-4,
    hmc_duration: float = np.pi / 2,
    mh_scale: float | None = None,
    max_steps: int | None = None,
    max_draws: int = 2_000_000,
    seed_restarts: int = SEED_RESTARTS_DEFAULT,
    seed_iters: int = 60,
    init_z: np.ndarray | None = None,
    known_dropped=(),
    deferral: Deferral | None = None,
    seed_round_restarts: int | None = None,
    threads: int = 1,
) -> PosteriorSamples:
    """Draw ``n_samples`` shapes from P(x | H) (Sec. IV).

    Methods: "hmc" (Alg. 1, T = ``hmc_duration``), "gibbs" (one sweep per sample), "mh"
    (random walk, step adapted during burn-in), "rejection" (i.i.d. prior draws, at most
    ``max_draws``; may return fewer samples, even none, if the posterior is too unlikely).

    ``chains`` defaults to ``default_chains(method, n_samples)``. MCMC chains start from prior
    draws that fit the history or from seeds found by random descent of f_H (``_seed``); after
    the run, chains trapped away from the others - the group with clearly less posterior mass
    when the chains split (``_trapped_and_sources``) - are re-seeded and rerun, and split R-hat
    is checked (``convergence``, logged as a warning when the chains disagree). A seed search
    that fails marks the history as possibly inconsistent (sensor error): the observations
    violated by the best state found are set aside and sampling continues without them, round
    after round until the rest fits (each round sets aside at least one row; a depth prior
    with an open slice end needed more than three on sloper truth 2). A row set aside is
    ``dropped`` (judged inconsistent) once the failed searches that left it violated have run
    ``seed_restarts`` descent restarts in all, over this call and earlier ones; until then it
    is ``deferred``. Each round runs at most ``seed_round_restarts`` restarts. Every returned
    sample satisfies every observation that is neither dropped nor deferred under the exact
    geometric test. An empty history returns exact prior draws. ``max_steps`` (default
    50 n / chains + 1000) bounds the MCMC steps per chain; fewer samples are returned if
    verification keeps failing. ``threads``: threads of HMC's exit search (``hmc_chains``);
    the samples are the same in any count (the random draws do not depend on it).

    ``known_dropped``: history rows an earlier call dropped (the previous cycle's
    ``dropped``); they stay out and are reported in ``dropped`` again. Decision: a row once
    judged inconsistent is not judged again each cycle. Re-judging repeated the failing seed
    search (8 descent restarts) every cycle: sloper truth 5, depth prior, spent 30 of 33 s of
    sampling there, dropping the same row each time.

    ``deferral``: the previous call's ``deferral``: its rows are tried again (the first
    round's history holds them), their effort carries on and the first round's descents
    start from its untried starts. Decision (2026-11-28): the drop decision is spread over
    cycles. Judging a row took up to ``seed_restarts`` (8) restarts of 60 descent steps in one
    call: 2.3-7 s of a cycle on the depth prior (sloper train truth 10, cycle 2: 21-37 rows).
    Now a round gives up after ``seed_round_restarts`` (1) restarts that found no feasible
    state (none exact or warm either), and the rows its best state violates are deferred:
    left out of this call's posterior, tried again by the next call; each call adds the
    restarts of its failed rounds to the rows they left violated, and a row is dropped when
    its sum reaches ``seed_restarts`` (the one-call search's effort: never sooner). The next
    call's descents start where this search stopped, from the starts it has not tried (the
    posterior before the row came), not from the posterior without the row: on sloper train
    truth 5 (episode seed 1, cycle 1, 25 rows, a row the one-call search fits at restart 8),
    retries from the posterior without the row dropped it in 3 of 4 sampler seeds, retries
    from the untried starts kept it in 4 of 4. A search that finds a feasible state in its
    first restart, or has exact or warm seeds, runs as before, draw for draw;
    ``seed_round_restarts`` None (the default) is the one-call search of before, for callers
    that do not call again (a one-off posterior, evaluations, checks); the episode loops
    (``explore.run_episode``, the inference node) pass ``SEED_ROUND_RESTARTS``. Measured on
    ``bench docking --prior generic --split train --problems sloper`` (120 episodes, side by side
    with the code before): slowest cycle 5.65 -> 1.41 s, median 0.136 -> 0.133 s, the same
    docks and give-ups but one more (docs/inference.md, "Inconsistent history").
    Warm start: ``init_z`` (N0, m), e.g. the ``z`` of the posterior before the newest
    observations, seeds the chains that exact seeds leave (``_seed``): its rows consistent with
    the history (the previous posterior filtered by the new observations, i.e. already draws
    of the new one) are used directly, and when no chain starts from a descent seed (every
    seed is an exact seed or a warm row, rows shared round-robin when fewer than the chains)
    the default burn-in drops to 1 move (HMC, Gibbs) / 50 steps (MH); otherwise descent
    starts from its rows. Decision (2026-11-28): a chain that starts on a posterior draw
    needs no burn-in to reach its target; two chains that share one only start alike, which
    the discarded move and their own momenta undo. Before, 13-15 warm rows for 16 chains
    (late depth-prior three_ledges cycles) paid the 3 moves of descent seeds.
    """
    start = time.perf_counter()
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; choose from {METHODS}")
    if int(n_samples) != n_samples or n_samples < 0:
        raise ValueError(f"n_samples must be a non-negative integer, got {n_samples}")
    if chains is None:
        chains = default_chains(method, n_samples)
    if chains < 1 or thin < 1:
        raise ValueError("chains and thin must be >= 1")
    threads = _thread_count(threads)
    if init_z is not None:
        init_z = np.asarray(init_z, dtype=float).reshape(-1, shape.n_basis)
        if not np.all(np.isfinite(init_z)):
            raise ValueError("init_z must be finite")
    if seed_round_restarts is None:
        seed_round_restarts = seed_restarts
    if seed_restarts < 1 or seed_round_restarts < 1:
        raise ValueError("seed_restarts and seed_round_restarts must be >= 1")
    n_samples = int(n_samples)
    dropped = np.unique(np.asarray(known_dropped, dtype=int).reshape(-1))
    if np.any((dropped < 0) | (dropped >= len(history))):
        raise ValueError(
            f"known_dropped rows {dropped.tolist()} outside the {len(history)}-row history"
        )
    deferral = Deferral() if deferral is None else deferral
    if np.any((deferral.rows < 0) | (deferral.rows >= len(history))):
        raise ValueError(
            f"deferred rows {deferral.rows.tolist()} outside the {len(history)}-row history"
        )
    effort = {
        r: e
        for r, e in zip(deferral.rows.tolist(), deferral.effort.tolist(), strict=True)
        if r not in set(dropped.tolist())
    }
    kept_idx = np.setdiff1d(np.arange(len(history)), dropped)
    info: dict = {"chains": chains if SAMPLERS[method].mcmc else 0}
    if len(history) == 0 or n_samples == 0:
        return _prior_draws(shape, n_samples, rng, method, start, dropped, info, deferral)
    if not SAMPLERS[method].mcmc:  # no seed search: deferred rows are simply kept
        kept = history.subset(kept_idx)
        z, stats = _rejection(shape, kept, n_samples, rng, max_draws, max(1024, 4 * n_samples))
        info.update(stats)
        return PosteriorSamples(
            z,
            shape.vertices(z),
            method,
            float(len(z)),
            time.perf_counter() - start,
            dropped,
            info,
        )
    if shape.n_basis == 0:
        raise ValueError("MCMC needs at least one basis column; use method='rejection'")

    set_aside: dict[int, int] = {}  # rows deferred by this call -> restarts spent on them
    info["seed_restarts"] = 0
    give_up = min(seed_round_restarts, seed_restarts)
    starts, untried = deferral.starts, None
    retry = bool(effort)  # the first round holds deferred rows: it continues their search
    for _ in range(len(history) + 1):  # each round sets >= 1 row aside: then at most the prior
        sub = history.subset(kept_idx)
        if len(sub) == 0:
            info["dropped_all"] = True
            left = _deferral(set_aside, untried)
            return _prior_draws(shape, n_samples, rng, method, start, dropped, info, left)
        seeds = _seed(
            shape,
            sub,
            rng,
            chains,
            prune_threshold,
            give_up if retry else seed_restarts,  # a retry: no top-up beyond its budget
            seed_iters,
            init_z,
            give_up,
            starts,
        )
        retry = False
        info["seed_restarts"] += seeds.restarts
        if seeds.z is not None:
            break
        info["seed_failed_restarts"] = info.get("seed_failed_restarts", 0) + seeds.restarts
        if untried is None:  # the first failed round's: the search over the most rows
            untried = seeds.untried
        starts = None
        violated = (
            observation_violations(
                shape.closed, shape.vertices(seeds.best_z[None]), sub, shape.friction
            )[0]
            > 0
        )
        for row in kept_idx[violated].tolist():
            spent = effort.get(row, 0) + seeds.restarts
            if spent >= seed_restarts:
                dropped = np.sort(np.append(dropped, row))
            else:
                set_aside[row] = spent
        kept_idx = kept_idx[~violated]
    else:
        raise RuntimeError("no history-consistent seed found even after dropping observations")
    left = _deferral(set_aside, untried)

    per_chain = -(-n_samples // chains)
    warm = init_z is not None and seeds.descended == 0
    if burn_in is None:
        burn_in = SAMPLERS[method].burn_in[int(warm)]
    max_steps = 50 * per_chain + 1000 if max_steps is None else max_steps
    runner = ChainRunner(
        seeds.system, method, rng, hmc_duration=hmc_duration, mh_scale=mh_scale, threads=threads
    )
    run = _ChainRun(runner, shape, sub, per_chain, thin, burn_in, max_steps, rng)
    draws, last, kept = run(seeds.z)
    draws, convergence = _reseed_trapped(run, draws, last, seeds.exact[kept], rng)
    chains, length = draws.shape[:2]
    z = draws.swapaxes(0, 1).reshape(-1, shape.n_basis)[:n_samples]
    vertices = shape.vertices(z)
    if length >= 2:
        ess_coords = effective_sample_size(draws @ shape.basis.T + shape.mean)
        ess = float(ess_coords.min()) * len(z) / (chains * length)
    else:
        ess = float(len(z))
    info.update(
        runner.stats,
        steps=run.steps,
        burn_in=burn_in,
        pairs=seeds.system.n_pairs,
        warm_seeds=seeds.warm if init_z is not None else 0,
        exact_seeds=int(seeds.exact.sum()),
        distinct_seeds=seeds.distinct,
        screened_seeds=seeds.screened,
        pairs_total=len(sub) * shape.n_edges,
        verified_fraction=run.verified / max(run.moves, 1),
        chains_kept=chains,
    )
    if method == "mh":
        info["mh_scale"] = float(runner.scale)
    if method == "hmc":  # the kept moves' T: median and range over the chains
        durations = np.asarray(runner.duration, dtype=float)
        info["hmc_duration"] = float(np.median(durations))
        info["hmc_duration_range"] = (float(durations.min()), float(durations.max()))
    return PosteriorSamples(
        z,
        vertices,
        method,
        ess,
        time.perf_counter() - start,
        dropped,
        info,
        convergence,
        left,
    )
