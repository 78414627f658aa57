"""bench prior's held-out protocol: --split draws disjoint terrains and seeds, train as before."""

import json

import numpy as np

from tactile_dock_ros.core import problems
from tactile_dock_ros.core.shape import GaussianShape
from tactile_dock_ros.tools import bench
from tactile_dock_ros.tools.bench import prior, splits


def _terrains(split, seed=0, n_random=6, per_problem=3):
    return list(prior.terrains(n_random, per_problem, splits.split_seed(split, seed)))


def test_splits_draw_disjoint_terrains_and_train_keeps_the_old_ones():
    train, test = _terrains("train"), _terrains("test")
    old = list(prior.terrains(6, 3, 0))  # the int seed bench prior used before --split
    assert [label for label, _ in train] == [label for label, _ in old]
    for (_, a), (_, b) in zip(train, old, strict=True):
        np.testing.assert_array_equal(a, b)
    assert [label for label, _ in test] == [label for label, _ in train]
    shared = [
        (i, j)
        for i, (_, a) in enumerate(train)
        for j, (_, b) in enumerate(test)
        if a.shape == b.shape and np.allclose(a, b)
    ]
    assert not shared
    # the scoring seeds: train as before, test apart from train and from the terrains' stream
    assert [prior.terrain_seed("train", 2, i) for i in range(3)] == [2000, 2007, 2014]
    tests = {prior.terrain_seed("test", 2, i) for i in range(3)}
    assert len(tests) == 3 and all(s[0] == splits.TEST_KEY for s in tests)
    words = [np.random.SeedSequence(s).generate_state(4).tolist() for s in tests]
    words.append(np.random.SeedSequence(splits.split_seed("test", 2)).generate_state(4).tolist())
    words += [
        np.random.SeedSequence(2000 + 7 * i + k).generate_state(4).tolist()
        for i in range(3)
        for k in range(3)
    ]
    assert len({tuple(w) for w in words}) == len(words)


def test_the_json_records_the_split(tmp_path):
    rows = {}
    for split in ("train", "test"):
        out = tmp_path / f"{split}.json"
        argv = ["prior", "--random", "1", "--per-problem", "0", "--json", str(out)]
        assert bench.main([*argv, *(["--split", split] if split == "train" else [])]) == 0
        report = json.loads(out.read_text())
        assert report["split"] == split
        (rows[split],) = report["rows"]
    assert rows["train"]["calibration_error"] != rows["test"]["calibration_error"]


def test_learned_scores_the_learned_prior_of_the_same_images(tmp_path):
    out = tmp_path / "learned.json"
    argv = ["prior", "--random", "2", "--per-problem", "1", "--learned", "--json", str(out)]
    assert bench.main(argv) == 0
    report = json.loads(out.read_text())
    assert report["terrain_classes"].endswith("terrain_classes.npz")
    learned = report["summary"]["all"]["learned"]
    assert learned["terrains"] == 5 and learned["no_prior"] == 0
    # random walls are in no class: the gate gives them the generic prior, scored the same way
    random = report["summary"]["random"]["learned"]
    assert random["generic_fallbacks"] == 2 and random["vertex_coverage_2sigma"] is None
    rows = {r["kind"]: r["learned"] for r in report["rows"] if r["kind"] != "random"}
    for name, row in rows.items():  # one held-out image each (notch's is a 2.3-sigma camera)
        summary = report["summary"][name]["learned"]
        assert summary["class_correct"] == summary["learned"] == 1
        assert row["vertices"] == problems.get(name).prior.n_vertices
        assert summary["vertex_coverage_2sigma"] == row["vertices_covered"] / row["vertices"]
    covered = sum(r["vertices_covered"] for r in rows.values())
    assert learned["vertex_coverage_2sigma"] == covered / sum(r["vertices"] for r in rows.values())
    assert 0.5 <= learned["coverage_2sigma"] <= 1.0
    generic = next(r for r in report["rows"] if r["kind"] == "random")
    assert generic["learned"]["model"] == "generic" and generic["learned"]["vertices"] == 0


def test_vertex_coverage_counts_vertices_inside_their_two_sigma_ellipse():
    shape = GaussianShape(np.zeros(4), np.diag([1.0, 1.0, 2.0, 2.0]))
    inside = np.array([[1.0, 1.0], [2.0, 2.0]])  # 2.0 and 2.0 sigma^2 < 6.16
    outside = np.array([[3.0, 0.0], [5.0, 0.0]])  # 9.0 and 6.25
    assert prior.vertex_coverage(shape, inside) == 2
    assert prior.vertex_coverage(shape, outside) == 0
