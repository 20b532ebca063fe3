"""SIGKILL at random moments of large checkpoint saves: the checkpoint on disk always loads."""

from __future__ import annotations

import itertools
import multiprocessing
import os
import random
import signal
import tempfile
import time
from multiprocessing.connection import Connection
from pathlib import Path

import pytest
import torch

from skelagnostic.callbacks import AtomicCheckpointIO

#: Size of the saved tensor: large enough that a save takes a noticeable time.
MEGABYTES = 256
#: Writer processes killed.
KILLS = 8
#: Generations of one writer are numbered from ``writer * GENERATIONS``.
GENERATIONS = 1000


def write_forever(path: str, first: int, conn: Connection) -> None:
    """Save generation ``first``, ``first + 1``, ... to ``path``; send each number once saved."""
    io = AtomicCheckpointIO()
    weight = torch.empty(MEGABYTES * 2**20 // 4)
    conn.send(0)  # allocated: saving starts now
    for generation in itertools.count(first):
        weight.fill_(generation)
        io.save_checkpoint({"generation": generation, "state_dict": {"weight": weight}}, path)
        conn.send(generation)


def received(conn: Connection) -> list[int]:
    out = []
    while conn.poll():
        try:
            out.append(conn.recv())
        except EOFError:
            break
    return out


@pytest.mark.slow
def test_killed_writers_leave_a_loadable_checkpoint_and_no_temporary(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    tmpdir = tmp_path / "tmpdir"
    tmpdir.mkdir()
    monkeypatch.setenv("TMPDIR", str(tmpdir))
    monkeypatch.setattr(tempfile, "tempdir", None)
    path = tmp_path / "checkpoints" / "last.ckpt"
    rng = random.Random(23)
    ctx = multiprocessing.get_context("fork")  # no interpreter start-up per kill
    on_disk, killed_mid_write = None, 0
    for writer in range(1, KILLS + 1):
        first = writer * GENERATIONS
        conn, child_conn = ctx.Pipe(duplex=False)
        proc = ctx.Process(target=write_forever, args=(str(path), first, child_conn))
        proc.start()
        child_conn.close()
        assert conn.recv() == 0
        time.sleep(rng.uniform(0.05, 3.0))
        os.kill(proc.pid, signal.SIGKILL)
        proc.join()
        assert proc.exitcode == -signal.SIGKILL
        saved = [g for g in received(conn) if g]
        conn.close()
        # the last save reported, or the next one if it was renamed but not reported yet
        allowed = {saved[-1], saved[-1] + 1} if saved else {on_disk, first}
        leftovers = {p.name for p in path.parent.iterdir()}
        assert leftovers <= {"last.ckpt", "last.ckpt.tmp"}
        killed_mid_write += "last.ckpt.tmp" in leftovers
        if path.exists():
            ckpt = torch.load(path, map_location="cpu", weights_only=True)
            assert ckpt["generation"] in allowed, (writer, saved)
            weight = ckpt["state_dict"]["weight"]
            assert weight.numel() == MEGABYTES * 2**20 // 4
            assert bool((weight == ckpt["generation"]).all())  # complete, not a torn write
            on_disk = ckpt["generation"]
        else:
            assert not saved and on_disk is None  # nothing was ever completed
        assert not any(tmpdir.iterdir()), "a save left a file in $TMPDIR"
    assert on_disk is not None and killed_mid_write >= 1
    AtomicCheckpointIO().save_checkpoint({"generation": 0}, path)  # the next save cleans up
    assert [p.name for p in path.parent.iterdir()] == ["last.ckpt"]
    assert torch.load(path, weights_only=True) == {"generation": 0}
