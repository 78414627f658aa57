"""Crash-safe node state: an append-only JSON-lines journal (ROS-free, stdlib only).

A node that must survive ``kill -9`` writes each change of its state as one JSON line and
reads the lines back when it starts (docs/nodes.md, "Restart without loss"). Crash consistency:

* ``append`` writes the whole line with one ``write`` and ``fsync``s it before returning, so a
  record the node acted on (published a result for) is on disk;
* a crash during ``append`` can leave a prefix of the line, without its newline: ``read`` drops
  the text after the last newline and ``Journal`` truncates it before appending, so the next
  record starts on a line of its own; a complete line that is not a JSON object is corruption
  and raises ``JournalError`` (no guessing at a partial state);
* ``reset`` replaces the file atomically (temporary file, ``fsync``, ``rename``, directory
  ``fsync``): a reader sees the old journal or the new one, never a mixture.
"""

from __future__ import annotations

import json
import os
from pathlib import Path


class JournalError(Exception):
    """The journal file is corrupt (a bad line before the last one) or cannot be written."""


def read(path: Path) -> list[dict]:
    """The records of the journal at ``path`` ([] when there is none), torn last line dropped."""
    return _parse(Path(path))[0]


def _parse(path: Path) -> tuple[list[dict], int]:
    """(records, byte length of the complete lines). One ``write`` per record means a torn
    append is a prefix of a line without its newline: the text after the last newline."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return [], 0
    intact = data.rfind(b"\n") + 1
    records = []
    for number, line in enumerate(data[:intact].splitlines(), start=1):
        try:
            record = json.loads(line)
        except ValueError:
            record = None
        if not isinstance(record, dict):
            raise JournalError(f"{path}: line {number} is not a JSON object")
        records.append(record)
    return records, intact


class Journal:
    """An open journal at ``path`` (its directory is created); see the module docstring."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise JournalError(f"cannot create {self.path.parent}: {err}") from err
        self.records, intact = _parse(self.path)
        if self.path.exists() and self.path.stat().st_size != intact:
            with open(self.path, "r+b") as f:  # drop the torn tail before appending after it
                f.truncate(intact)
                os.fsync(f.fileno())

    def append(self, record: dict) -> None:
        line = (json.dumps(record, separators=(",", ":")) + "\n").encode()
        try:
            fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
            try:
                os.write(fd, line)
                os.fsync(fd)
            finally:
                os.close(fd)
        except OSError as err:
            raise JournalError(f"cannot append to {self.path}: {err}") from err
        self.records.append(record)

    def reset(self, records: list[dict]) -> None:
        """Replace the journal with ``records``, atomically."""
        text = "".join(json.dumps(r, separators=(",", ":")) + "\n" for r in records).encode()
        replace_atomically(self.path, text)
        self.records = list(records)


def replace_atomically(path: Path, data: bytes) -> None:
    """Write ``data`` as the file ``path``: temporary file, ``fsync``, rename, directory
    ``fsync``, so a reader sees the old file or the new one, never a mixture; JournalError
    when it cannot be written."""
    path = Path(path)
    tmp = path.with_suffix(path.suffix + ".tmp")
    try:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
        fd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
    except OSError as err:
        raise JournalError(f"cannot write {path}: {err}") from err


def for_node(state_directory: str, name: str) -> Journal | None:
    """The journal ``<state_directory>/<name>.jsonl`` of a node, None when the node's
    ``state_directory`` parameter is empty (no journal); an unusable one is a ValueError that
    names the parameter, which stops the node at start."""
    if not state_directory:
        return None
    try:
        return Journal(Path(state_directory) / f"{name}.jsonl")
    except JournalError as err:
        raise ValueError(f"parameter state_directory: {err}") from err
