"""models.fileio: atomic writes, the temporary paths an abrupt end removes, publishing never cut in half."""
import threading
import time

import pytest

from models import fileio
from models.fileio import (abandon_outputs, atomic_write_text, close_outputs, publishing, register_scratch,
                           release_scratch, reopen_outputs)


@pytest.fixture(autouse=True)
def reopen():
    yield
    reopen_outputs()


def test_atomic_write_leaves_one_complete_file(tmp_path):
    p = atomic_write_text(tmp_path / "a.txt", "one\n")
    atomic_write_text(p, "two\n")
    assert p.read_text() == "two\n" and [f.name for f in tmp_path.iterdir()] == ["a.txt"]
    assert not fileio._SCRATCH                      # nothing left registered


def test_closed_outputs_refuse_to_publish_and_leave_no_temporary_file(tmp_path):
    atomic_write_text(tmp_path / "a.txt", "old\n")
    close_outputs()
    with pytest.raises(KeyboardInterrupt, match="outputs closed"):
        atomic_write_text(tmp_path / "a.txt", "new\n")
    assert (tmp_path / "a.txt").read_text() == "old\n" and [f.name for f in tmp_path.iterdir()] == ["a.txt"]
    reopen_outputs()
    atomic_write_text(tmp_path / "a.txt", "new\n")
    assert (tmp_path / "a.txt").read_text() == "new\n"


def test_close_waits_for_a_publishing_block_in_progress():
    events = []
    inside = threading.Event()

    def publish():
        with publishing():
            inside.set()
            time.sleep(0.3)
            events.append("published")

    t = threading.Thread(target=publish)
    t.start()
    assert inside.wait(600)          # a hang guard only
    close_outputs()
    events.append("closed")
    t.join()
    assert events == ["published", "closed"]


def test_abandon_removes_registered_files_and_folders(tmp_path):
    d = tmp_path / ".report-x"
    d.mkdir()
    (d / "page01.png").write_bytes(b"x")
    f = tmp_path / ".a.txt.1.tmp"
    f.write_text("half")
    keep = tmp_path / "done.txt"
    keep.write_text("done")
    for p in (d, f, tmp_path / "never-created"):
        register_scratch(p)
    try:
        assert abandon_outputs() == 2
    finally:
        for p in (d, f, tmp_path / "never-created"):
            release_scratch(p)
    assert [p.name for p in tmp_path.iterdir()] == ["done.txt"]
    with pytest.raises(KeyboardInterrupt):          # abandoned outputs are closed too
        with publishing():
            pass


def test_a_pair_of_outputs_is_written_whole_or_not_at_all(tmp_path):
    """identify.json and identify.txt: both new, or (failure, interrupt) both old, never one of each."""
    from models.fileio import atomic_write_texts
    a, b = tmp_path / "x.json", tmp_path / "x.txt"
    assert atomic_write_texts({a: "1\n", b: "one\n"}) == [a, b]
    assert a.read_text() == "1\n" and b.read_text() == "one\n"
    (tmp_path / "sub").mkdir()
    with pytest.raises(IsADirectoryError):            # the second cannot be written: the first stays old
        atomic_write_texts({a: "2\n", tmp_path / "sub": "two\n"})
    with pytest.raises(UnicodeEncodeError):           # fails while writing the second
        atomic_write_texts({a: "2\n", b: "\ud800"})
    assert a.read_text() == "1\n" and b.read_text() == "one\n"
    close_outputs()                                    # an interrupt: nothing moved
    with pytest.raises(KeyboardInterrupt):
        atomic_write_texts({a: "3\n", b: "three\n"})
    assert a.read_text() == "1\n" and b.read_text() == "one\n"
    assert sorted(f.name for f in tmp_path.iterdir()) == ["sub", "x.json", "x.txt"] and not fileio._SCRATCH
