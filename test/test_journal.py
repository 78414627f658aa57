"""nodes.journal: the crash-safe JSON-lines journal behind the restart of inference and planner."""

import json

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_dock_ros.nodes import journal

RECORDS = [{"episode": 7}, {"plan_id": 1, "a": [[0.1, 0.2]], "status": [0]}, {"x": 1e-300}]


def test_records_survive_reopening_exactly(tmp_path):
    path = tmp_path / "state" / "j.jsonl"  # the directory is created
    j = journal.Journal(path)
    for record in RECORDS:
        j.append(record)
    assert journal.read(path) == RECORDS == journal.Journal(path).records


@settings(max_examples=30, deadline=None)
@given(cut=st.integers(min_value=1, max_value=10_000))
def test_a_torn_last_append_is_dropped_and_truncated(tmp_path_factory, cut):
    """A crash inside ``append`` leaves a prefix of the last line: it is not a record, and the
    next append starts a line of its own."""
    path = tmp_path_factory.mktemp("torn") / "j.jsonl"
    j = journal.Journal(path)
    for record in RECORDS[:2]:
        j.append(record)
    line = json.dumps(RECORDS[2]) + "\n"
    with open(path, "a") as f:
        f.write(line[: cut % len(line)])  # never the newline: that would be a whole record
    assert journal.read(path) == RECORDS[:2]
    reopened = journal.Journal(path)
    reopened.append({"after": True})
    assert journal.read(path) == [*RECORDS[:2], {"after": True}]


@pytest.mark.parametrize("bad", [b"not json\n", b"[1, 2]\n", b"\n"])
def test_a_bad_complete_line_is_corruption(tmp_path, bad):
    path = tmp_path / "j.jsonl"
    path.write_bytes(b'{"ok": 1}\n' + bad + b'{"ok": 2}\n')
    with pytest.raises(journal.JournalError, match="line 2"):
        journal.read(path)
    with pytest.raises(journal.JournalError):
        journal.Journal(path)


def test_reset_replaces_the_journal_atomically(tmp_path):
    path = tmp_path / "j.jsonl"
    j = journal.Journal(path)
    j.append({"old": 1})
    j.reset([{"new": 1}, {"new": 2}])
    assert journal.read(path) == j.records == [{"new": 1}, {"new": 2}]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["j.jsonl"]  # no temporary left


def test_a_missing_journal_is_empty_and_an_unwritable_one_an_error(tmp_path):
    assert journal.read(tmp_path / "none.jsonl") == []
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(journal.JournalError, match="cannot create"):
        journal.Journal(blocker / "sub" / "j.jsonl")
    # A node's journal: none without a directory; an unusable one names the parameter.
    assert journal.for_node("", "planner") is None
    assert journal.for_node(str(tmp_path), "planner").path == tmp_path / "planner.jsonl"
    with pytest.raises(ValueError, match="parameter state_directory"):
        journal.for_node(str(blocker), "planner")
