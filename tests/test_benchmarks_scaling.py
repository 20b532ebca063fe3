"""The ``scaling`` benchmark suite: corpus choice, forked measurements, results and figure.

The suite itself runs at smoke size in ``test_benchmarks_smoke.py``; these tests
check its parts on hand-made figures, so every ratio below is computed here
independently of :func:`benchmarks.suites.scaling.results`.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT))
try:
    from benchmarks.suites import scaling
finally:
    sys.path.remove(str(REPO_ROOT))


def _raw(
    train_peak: float | None = 300.0, gpu: bool = False, compiled: bool = False
) -> dict[str, Any]:
    """Raw figures of the smoke settings: batches (2, 4), threads (1, 2), corpora 1 and 2 clips."""
    methods = {}
    for i, method in enumerate(scaling.METHODS):
        k = 10.0 * (i + 1)
        methods[method] = {
            "cpu": {"b2_t1": k, "b4_t1": 1.5 * k, "b2_t2": 1.2 * k, "b4_t2": 2.4 * k},
            "gpu_bf16": {"b2": 5 * k, "b4": 9 * k} if gpu else {},
            "compiled": {"b2_t1": 1.1 * k} if compiled else {},
            "ddp2": 1.8 * k,
            "memory": {
                "lafan1_1clips": {
                    "prepare_peak_mib": 400.0,
                    "train_peak_mib": train_peak,
                    "cache_mib": 5.0,
                },
                "lafan1_2clips": {
                    "prepare_peak_mib": 420.0,
                    "train_peak_mib": train_peak and train_peak * 1.1,
                    "cache_mib": 10.0,
                },
            },
        }
    return {
        "base_rss_mib": 250.0,
        "devices": ["cpu"],
        "methods": methods,
        "corpus_frames": {"lafan1_1clips": 3945.0, "lafan1_2clips": 7890.0},
    }


def _by_name(results: list[Any]) -> dict[str, Any]:
    return {r.name: r for r in results}


def test_reference_batch_is_the_last_but_one() -> None:
    assert scaling.SETTINGS["default"].reference("vqpae") == 64
    assert scaling.SETTINGS["smoke"].reference("humot") == 2
    single = scaling.Settings(True, {"humot": (8,)}, (1,), (1,), 1, 1)
    assert single.reference("humot") == 8


def test_results_carry_same_run_baselines() -> None:
    rows = _by_name(scaling.results(_raw(), "smoke"))
    assert rows["base_rss_mib"].value == 250.0
    assert rows["corpus_frames_lafan1_2clips"].value == 7890.0
    # 1 thread: the smallest batch is the baseline (batch scaling)
    first = rows["vqpae_windows_per_s_b2_t1"]
    assert first.baseline is None and first.speedup is None
    b4 = rows["humot_windows_per_s_b4_t1"]
    assert b4.baseline_value == 20.0 and b4.speedup == pytest.approx(30.0 / 20.0)
    # 2 threads: the same batch at 1 thread (thread scaling)
    t2 = rows["pcmrl_recon_windows_per_s_b4_t2"]
    assert t2.baseline == "batch 4, 1 thread (same run)"
    assert t2.speedup == pytest.approx(72.0 / 45.0)
    # DDP against 1 process with 1 thread and with 2 threads, at the reference batch 2
    ddp = rows["pcmrl_interp_ddp2_windows_per_s_b2"]
    assert ddp.value == 72.0 and ddp.speedup == pytest.approx(72.0 / 40.0)
    vs2 = rows["pcmrl_interp_ddp2_windows_per_s_b2_vs_t2"]
    assert vs2.speedup == pytest.approx(72.0 / 48.0)
    # memory against the smallest corpus of the run: lower is better, 1 = flat
    mem = rows["vqpae_train_peak_rss_mib_lafan1_2clips"]
    assert mem.baseline == "lafan1_1clips (same run)" and not mem.higher_is_better
    assert mem.speedup == pytest.approx(300.0 / 330.0)
    assert rows["vqpae_prepare_peak_rss_mib_lafan1_1clips"].baseline is None
    assert rows["humot_cache_mib_lafan1_2clips"].value == 10.0
    assert not any("gpu" in name or "compiled" in name for name in rows)


def test_results_leave_absent_figures_absent() -> None:
    raw = _raw(train_peak=None)
    raw["base_rss_mib"] = None  # no /proc
    rows = _by_name(scaling.results(raw, "smoke"))
    assert not any("train_peak" in name for name in rows) and "base_rss_mib" not in rows
    assert "humot_prepare_peak_rss_mib_lafan1_2clips" in rows


def test_methods_choose_a_subset_in_report_order(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(scaling.METHODS_ENV, raising=False)
    assert scaling.selected_methods() == scaling.METHODS
    assert scaling.selected_methods("humot, vqpae") == ("vqpae", "humot")
    monkeypatch.setenv(scaling.METHODS_ENV, "pcmrl_interp")
    assert scaling.selected_methods() == ("pcmrl_interp",)
    with pytest.raises(ValueError, match=r"unknown method\(s\) dog; known: vqpae, humot"):
        scaling.selected_methods("vqpae,dog")
    with pytest.raises(ValueError, match="unknown method"):
        scaling.selected_methods(",")
    # a run of some methods has the rows of those only
    raw = _raw()
    del raw["methods"]["humot"], raw["methods"]["pcmrl_recon"]
    names = set(_by_name(scaling.results(raw, "smoke")))
    assert {n.split("_windows")[0].removesuffix("_ddp2") for n in names if "_windows" in n} == {
        "vqpae",
        "pcmrl_interp",
    }


def test_run_py_refuses_an_unknown_method() -> None:
    import subprocess
    import sys

    done = subprocess.run(
        [sys.executable, "benchmarks/run.py", "--suite", "scaling", "--methods", "cat"],
        cwd=Path(__file__).resolve().parents[1],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 2
    assert "--methods: scaling: unknown method(s) cat" in done.stderr


def test_results_gpu_and_compiled_rows() -> None:
    rows = _by_name(scaling.results(_raw(gpu=True, compiled=True), "smoke"))
    gpu = rows["humot_windows_per_s_b4_gpu_bf16"]
    assert gpu.baseline == "batch 2, gpu bf16-mixed (same run)"
    assert gpu.speedup == pytest.approx(180.0 / 100.0)
    compiled = rows["humot_windows_per_s_b2_t1_compiled"]
    assert compiled.baseline_value == 20.0 and compiled.speedup == pytest.approx(1.1)


def test_corpus_takes_the_first_files_by_name(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    folder = tmp_path / "lafan1"
    folder.mkdir()
    for name in ("walk1_subject2.bvh", "aiming1_subject1.bvh", "run1_subject3.bvh"):
        (folder / name).write_text("HIERARCHY\nMOTION\nFrames: 7\nFrame Time: 0.0333\n")
    (folder / "notes.txt").write_text("not a clip")
    label, files = scaling.corpus(2, tmp_path)
    assert label == "lafan1_2clips"
    assert [Path(f).name for f in files] == ["aiming1_subject1.bvh", "run1_subject3.bvh"]
    assert scaling.corpus(4, tmp_path) is None
    assert scaling.corpus(1, tmp_path / "missing") is None
    assert scaling.corpus_label(3, None) == "generated_3clips"
    assert scaling.bvh_frames(files[0]) == 7
    # --data-root (run.py sets the variable) wins over $SKELAGNOSTIC_DATA
    monkeypatch.setenv("SKELAGNOSTIC_DATA", str(tmp_path / "other"))
    monkeypatch.delenv(scaling.DATA_ENV, raising=False)
    assert scaling.corpus_root() == tmp_path / "other"
    monkeypatch.setenv(scaling.DATA_ENV, str(tmp_path))
    assert scaling.corpus_root() == tmp_path


def _allocate(mib: int) -> int:
    block = bytearray(mib * 2**20)
    block[::4096] = b"x" * len(block[::4096])
    return os.getpid()


def _fail() -> None:
    raise ValueError("deliberate")


def _sleep() -> None:
    time.sleep(120)


@pytest.mark.skipif(not hasattr(os, "fork"), reason="POSIX fork")
def test_forked_measurements_report_result_peak_and_errors() -> None:
    pid, small = scaling.in_fork(_allocate, 1, what="small")
    _, large = scaling.in_fork(_allocate, 200, what="large")
    assert pid != os.getpid()
    assert large - small > 150  # the child's own peak, not the parent's
    with pytest.raises(RuntimeError, match="ValueError: deliberate"):
        scaling.in_fork(_fail, what="failing")


@pytest.mark.skipif(not hasattr(os, "fork"), reason="POSIX fork")
def test_ranks_are_collected_together_and_a_failure_stops_the_others() -> None:
    ranks = scaling.collect_all([scaling.forked(_allocate, 1) for _ in range(2)], "rank")
    assert len({pid for pid, _ in ranks}) == 2
    sleeper = scaling.forked(_sleep)
    start = time.perf_counter()
    with pytest.raises(RuntimeError, match=r"rank 1 failed(.|\n)*ValueError: deliberate"):
        scaling.collect_all([sleeper, scaling.forked(_fail)], "rank")
    assert time.perf_counter() - start < 60  # the sleeping rank was killed, not awaited
    with pytest.raises(ChildProcessError):
        os.waitpid(sleeper[0], 0)  # already reaped
    assert not sleeper[1].exists()


@pytest.mark.skipif(not hasattr(os, "fork"), reason="POSIX fork")
def test_a_child_leaves_no_file_unless_it_finished_and_collecting_removes_it() -> None:
    """A killed benchmark must not leave empty result files in the temporary directory."""
    pid, path = scaling.forked(_sleep)
    assert path.parent == Path(tempfile.gettempdir()) and not path.exists()
    os.kill(pid, signal.SIGKILL)
    with pytest.raises(RuntimeError, match="sleeping: the measuring process died without"):
        scaling.collect((pid, path), "sleeping")
    assert not list(path.parent.glob(f"{path.name}*"))
    child = scaling.forked(_allocate, 1)
    os.waitpid(child[0], 0)
    assert json.loads(child[1].read_text())["result"] == child[0]  # complete once it exists
    assert scaling._payload(child[1], "done")[0] == child[0]
    assert not child[1].exists()


@pytest.mark.slow
@pytest.mark.skipif(not hasattr(os, "fork"), reason="POSIX fork")
def test_ddp_row_trains_pcmrl_stage_2_under_plain_ddp(tmp_path: Path) -> None:
    """The DDP row's two forked ranks train stage 2 (tiny) with Lightning's plain ``ddp``.

    Plain ``ddp`` stops at the first step when a trainable parameter gets no gradient,
    which stage 2's network had before its self-attention blocks froze their memory norm.
    """
    import skelagnostic as sa

    motion, _ = sa.procedural.generate("biped22", "walk", seconds=4.0, fps=30.0, seed=0)
    clip = tmp_path / "walk.bvh"
    sa.write_bvh(motion, clip)  # centimetres, as LaFAN1 (the suite reads it with units="cm")
    job = scaling.Job("pcmrl_interp", "smoke", 1, [str(clip)], 2, str(tmp_path / "cache"))
    got = scaling._ddp(job)
    assert got["windows_per_s"] > 0 and got["median_step_s"] > 0


def test_plot_writes_a_png_from_a_report(tmp_path: Path) -> None:
    results = [r.to_dict() for r in scaling.results(_raw(gpu=True), "smoke")]
    report = {
        "suite": "all",
        "machine": {
            "cpu_count": 2,
            "processor": "test cpu",
            "ram_gib": 1.0,
            "load_average_start": 1.0,
            "load_average_end": 2.0,
        },
        "versions": {},
        "results": [{**r, "name": f"scaling/{r['name']}"} for r in results],
    }
    (path,) = scaling.plot(report, tmp_path / "assets", date="2026-12-03")
    assert path.name == "scaling.png" and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    report["results"] = [{**r, "name": f"io/{r['name']}"} for r in results]
    assert scaling.plot(report, tmp_path / "none") == []


def test_outermost_keeps_the_networks_a_step_calls() -> None:
    called = ["characters.0.pae", "characters.0.pae.encoder", "net", "net.blocks.0",
              "characters.0.pose", "net", "net2.head"]  # fmt: skip
    assert scaling.outermost(called) == [
        "characters.0.pae",
        "characters.0.pose",
        "net",
        "net2.head",
    ]
