"""nodes.warm_start: the inference node's last posterior on disk, for a warm restart."""

import numpy as np
import pytest

from tactile_dock_ros.core import problems
from tactile_dock_ros.core.shape import GaussianShape
from tactile_dock_ros.nodes import journal, warm_start

PRIOR = problems.get("sloper").prior


def _snapshot(episode=5, rows=7, prior=PRIOR, samples=4) -> warm_start.WarmStart:
    z = np.random.default_rng(1).standard_normal((samples, prior.n_basis))
    return warm_start.WarmStart(episode, rows, warm_start.prior_fingerprint(prior), z, [2, 3])


def test_a_snapshot_survives_saving_exactly_and_leaves_no_temporary_file(tmp_path):
    saved = _snapshot()
    warm_start.save(tmp_path, saved)
    loaded = warm_start.load(tmp_path)
    assert (loaded.episode, loaded.history_length, loaded.prior) == (5, 7, saved.prior)
    np.testing.assert_array_equal(loaded.z, saved.z)  # bit-exact
    np.testing.assert_array_equal(loaded.dropped, [2, 3])
    assert sorted(p.name for p in tmp_path.iterdir()) == [warm_start.FILE_NAME]
    assert warm_start.load(tmp_path / "elsewhere") is None  # none saved: cold start


def test_a_snapshot_is_used_only_for_its_episode_prior_and_a_history_it_saw_part_of():
    saved = _snapshot(episode=5, rows=7)
    assert saved.unusable(5, 7, PRIOR) is None
    assert saved.unusable(5, 9, PRIOR) is None  # reports journaled after it: the loop's case
    assert "episode 5, not 6" in saved.unusable(6, 7, PRIOR)
    assert "7 history rows, the journal has 6" in saved.unusable(5, 6, PRIOR)
    shifted = GaussianShape(PRIOR.mean + 1e-9, PRIOR.basis, PRIOR.closed, PRIOR.friction)
    assert "another prior" in saved.unusable(5, 7, shifted)
    assert "another prior" in saved.unusable(5, 7, problems.get("notch").prior)
    # the fingerprint is of what z means: mean and basis, not friction
    same_basis = GaussianShape(PRIOR.mean, PRIOR.basis.copy(), PRIOR.closed, 0.9)
    assert saved.unusable(5, 7, same_basis) is None


@pytest.mark.parametrize(
    "content", [b"", b"not a zip file", b"PK\x03\x04 torn zip", "z_not_finite", "z_1d"]
)
def test_an_unreadable_snapshot_is_an_error_not_a_crash(tmp_path, content):
    path = tmp_path / warm_start.FILE_NAME
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        bad = np.full((2, PRIOR.n_basis), np.nan) if content == "z_not_finite" else np.ones(3)
        np.savez(path, episode=1, history_length=1, prior="x", z=bad, dropped=np.zeros(0))
    with pytest.raises(journal.JournalError, match=warm_start.FILE_NAME):
        warm_start.load(tmp_path)
