"""The inference node's warm start on disk, so that a restarted node samples warm (ROS-free).

After each posterior the node writes the samples in whitened coordinates z with what they
belong to (``<state_directory>/inference_warm_start.npz``, replaced atomically:
``journal.replace_atomically``). A restarted node that restores the episode's history from
its journal (``nodes.journal``) takes them as the sampler's warm start
(``sample_posterior(init_z=...)``) once the prior arrives, instead of seeding cold from the
history alone. Decision (d6c96f4): a snapshot is used only if it is of the same episode, of
the same prior (z means nothing in another basis: ``prior_fingerprint``, a hash of the
prior's mean and basis) and of a history no longer than the restored one (a shorter one is
what every cycle of the loop warm-starts from: the previous posterior; a longer one means
the journal lost a report). Anything else, or a file that cannot be read, is a cold start.
The snapshot also holds the sampler's deferral (``sampling.Deferral``: rows left out while
their seed search goes on, the restarts spent on each, the descent starts not tried yet), so
that a restart neither judges a deferred row again from nothing (which would drop it later
than the one-call effort) nor repeats the starts already tried. A file written before the
deferral was saved loads with none.
"""

from __future__ import annotations

import hashlib
import io
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tactile_dock_ros.core.sampling import Deferral
from tactile_dock_ros.core.shape import GaussianShape
from tactile_dock_ros.nodes.journal import JournalError, replace_atomically

FILE_NAME = "inference_warm_start.npz"


def prior_fingerprint(prior: GaussianShape) -> str:
    """Hash of what z means under ``prior``: its mean and basis (shapes and bytes)."""
    digest = hashlib.sha256()
    for array in (prior.mean, prior.basis):
        digest.update(repr(array.shape).encode())
        digest.update(np.ascontiguousarray(array, dtype=float).tobytes())
    return digest.hexdigest()


@dataclass(frozen=True)
class WarmStart:
    """Posterior samples z (N, m) of ``episode`` after ``history_length`` history rows under
    the prior with fingerprint ``prior``; ``dropped``: the rows that posterior ignored;
    ``deferral``: the rows it left out for now (``PosteriorSamples.deferral``)."""

    episode: int
    history_length: int
    prior: str
    z: np.ndarray
    dropped: np.ndarray
    deferral: Deferral = field(default_factory=Deferral)

    def unusable(self, episode: int, history_length: int, prior: GaussianShape) -> str | None:
        """Why this snapshot cannot warm-start ``episode`` with ``history_length`` restored
        rows under ``prior`` (None: it can)."""
        if self.episode != episode:
            return f"it is of episode {self.episode}, not {episode}"
        if self.history_length > history_length:
            return f"it saw {self.history_length} history rows, the journal has {history_length}"
        if self.prior != prior_fingerprint(prior) or self.z.shape[1] != prior.n_basis:
            return "it was sampled under another prior"
        return None


def save(directory: str | Path, warm: WarmStart) -> None:
    """Write ``warm`` to ``directory`` atomically; JournalError when it cannot be written."""
    buffer = io.BytesIO()
    starts = warm.deferral.starts
    np.savez(
        buffer,
        episode=warm.episode,
        history_length=warm.history_length,
        prior=warm.prior,
        z=np.asarray(warm.z, dtype=float),
        dropped=np.asarray(warm.dropped, dtype=int),
        deferred_rows=warm.deferral.rows,
        deferred_effort=warm.deferral.effort,
        deferred_starts=np.zeros((0, warm.z.shape[1])) if starts is None else starts,
    )
    replace_atomically(Path(directory) / FILE_NAME, buffer.getvalue())


def load(directory: str | Path) -> WarmStart | None:
    """The snapshot in ``directory`` (None when there is none); JournalError when it cannot
    be read or is malformed."""
    path = Path(directory) / FILE_NAME
    if not path.exists():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            warm = WarmStart(
                int(data["episode"]),
                int(data["history_length"]),
                str(data["prior"]),
                np.array(data["z"], dtype=float),
                np.array(data["dropped"], dtype=int).reshape(-1),
                _deferral(data),
            )
    except (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile) as err:
        raise JournalError(f"{path}: unreadable warm start ({err})") from err
    if warm.z.ndim != 2 or not np.all(np.isfinite(warm.z)):
        raise JournalError(f"{path}: warm start z must be a finite (N, m) array")
    starts = warm.deferral.starts
    if starts is not None and (starts.shape[1] != warm.z.shape[1] or not np.isfinite(starts).all()):
        raise JournalError(f"{path}: deferred starts must be finite rows like z's")
    return warm


def _deferral(data) -> Deferral:
    """The saved deferral (none in a file written before it was saved); ValueError if bad."""
    if "deferred_rows" not in data:
        return Deferral()
    return Deferral(  # no rows of starts (saved as (0, m)): None, as ``Deferral`` makes it
        np.array(data["deferred_rows"], dtype=int),
        np.array(data["deferred_effort"], dtype=int),
        np.array(data["deferred_starts"], dtype=float),
    )
