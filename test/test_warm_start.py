"""nodes.warm_start: the inference node's last posterior on disk, for a warm restart."""

import dataclasses

import numpy as np
import pytest

from tactile_dock_ros.core import problems
from tactile_dock_ros.core.sampling import Deferral
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


def test_the_deferral_survives_saving_and_an_older_file_has_none(tmp_path):
    """Rows deferred by the seed search, the restarts spent on each and the untried descent
    starts come back bit-exact; a snapshot written before they were saved loads without."""
    starts = np.random.default_rng(2).standard_normal((3, PRIOR.n_basis))
    deferral = Deferral(np.array([4, 6]), np.array([1, 3]), starts)
    saved = dataclasses.replace(_snapshot(), deferral=deferral)
    warm_start.save(tmp_path, saved)
    loaded = warm_start.load(tmp_path).deferral
    np.testing.assert_array_equal(loaded.rows, [4, 6])
    np.testing.assert_array_equal(loaded.effort, [1, 3])
    np.testing.assert_array_equal(loaded.starts, starts)
    warm_start.save(tmp_path, dataclasses.replace(saved, deferral=Deferral([5], [1])))
    assert warm_start.load(tmp_path).deferral.starts is None  # none left untried
    old = _snapshot()
    np.savez(tmp_path / warm_start.FILE_NAME, episode=5, history_length=7, prior=old.prior,
             z=old.z, dropped=np.array([2, 3]))  # fmt: skip
    assert len(warm_start.load(tmp_path).deferral) == 0


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
    "content",
    [b"", b"not a zip file", b"PK\x03\x04 torn zip", "z_not_finite", "z_1d", "effort_negative",
     "effort_missing", "starts_not_finite", "starts_other_width"],
)  # fmt: skip
def test_an_unreadable_snapshot_is_an_error_not_a_crash(tmp_path, content):
    path = tmp_path / warm_start.FILE_NAME
    if isinstance(content, bytes):
        path.write_bytes(content)
    elif content.startswith("z_"):
        bad = np.full((2, PRIOR.n_basis), np.nan) if content == "z_not_finite" else np.ones(3)
        np.savez(path, episode=1, history_length=1, prior="x", z=bad, dropped=np.zeros(0))
    else:
        m = PRIOR.n_basis
        starts = {
            "starts_not_finite": np.full((1, m), np.inf),
            "starts_other_width": np.ones((1, 2)),
        }
        effort = {"effort_negative": [-1], "effort_missing": []}.get(content, [1])
        np.savez(path, episode=1, history_length=1, prior="x", z=np.ones((2, m)),
                 dropped=np.zeros(0), deferred_rows=[0], deferred_effort=effort,
                 deferred_starts=starts.get(content, np.zeros((0, m))))  # fmt: skip
    with pytest.raises(journal.JournalError, match=warm_start.FILE_NAME):
        warm_start.load(tmp_path)
