"""The ``allocators`` benchmark suite: children's environments and results from hand-made figures.

The suite itself runs at smoke size in ``test_benchmarks_smoke.py``; the ratios
below are computed here, independently of :func:`benchmarks.suites.allocators.results`.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT))
try:
    from benchmarks.report import render
    from benchmarks.suites import allocators, scaling
finally:
    sys.path.remove(str(REPO_ROOT))


def test_batches_are_the_scaling_suites_ends() -> None:
    assert allocators.batches("pcmrl_recon", "default") == (4, 32)
    assert allocators.batches("vqpae", "large") == (16, 128)
    assert allocators.batches("humot", "smoke") == (2,)


def test_children_start_without_a_preloaded_allocator(tmp_path: Path) -> None:
    lib = tmp_path / "lib" / "libjemalloc.so.2"
    lib.parent.mkdir()
    lib.write_bytes(b"\x7fELF")
    environ = {
        "VIRTUAL_ENV": str(tmp_path),
        "LD_PRELOAD": "/usr/lib/libtcmalloc_minimal.so.4:/opt/keep.so",
        "SKELAGNOSTIC_ALLOCATOR": "tcmalloc",
    }
    system = allocators.environment("system", environ)
    assert system["LD_PRELOAD"] == "/opt/keep.so" and "SKELAGNOSTIC_ALLOCATOR" not in system
    assert "LD_PRELOAD" not in allocators.environment("system", {"LD_PRELOAD": "libjemalloc.so.2"})
    jemalloc = allocators.environment("jemalloc", environ)
    assert jemalloc["LD_PRELOAD"] == f"{lib}:/opt/keep.so"
    assert environ["LD_PRELOAD"].startswith("/usr/lib/libtcmalloc")  # unchanged


def _row(wps: float, share: float, faults: float, rss: float, sha: str = "a") -> dict[str, Any]:
    return {
        "weights_sha256": sha,
        "windows_per_s": wps,
        "sys_share": share,
        "minor_faults_per_step": faults,
        "peak_rss_mib": rss,
    }


def test_results_compare_every_allocator_with_the_system_one() -> None:
    raw = {
        "pcmrl_recon": {
            "b4_system": _row(0.6, 0.3, 2e6, 3600.0),
            "b4_tcmalloc": _row(0.9, 0.05, 2e5, 3000.0),
            "b32_system": _row(0.5, 0.4, 9e6, 9000.0),
            "b32_tcmalloc": _row(1.0, 0.0, 1e5, 8000.0, sha="b"),
        },
        "humot": {"b8_jemalloc": _row(20.0, 0.1, 10.0, 500.0)},  # no system row: no ratio
    }
    got = {r.name: r for r in allocators.results(raw, "default")}
    assert set(got) == {
        f"{m}_{k}_b{b}_{a}"
        for m, b, a in [
            ("pcmrl_recon", 4, "system"),
            ("pcmrl_recon", 4, "tcmalloc"),
            ("pcmrl_recon", 32, "system"),
            ("pcmrl_recon", 32, "tcmalloc"),
            ("humot", 8, "jemalloc"),
        ]
        for k in ("windows_per_s", "sys_share", "minor_faults_per_step", "peak_rss_mib")
    } | {"pcmrl_recon_same_weights_b4_tcmalloc", "pcmrl_recon_same_weights_b32_tcmalloc"}
    assert got["pcmrl_recon_same_weights_b4_tcmalloc"].value == 1.0
    assert got["pcmrl_recon_same_weights_b32_tcmalloc"].value == 0.0  # other weights
    fast = got["pcmrl_recon_windows_per_s_b32_tcmalloc"]
    assert fast.speedup == pytest.approx(2.0) and fast.baseline == (
        "system malloc, batch 32 (same run)"
    )
    assert got["pcmrl_recon_windows_per_s_b4_tcmalloc"].speedup == pytest.approx(1.5)
    assert got["pcmrl_recon_minor_faults_per_step_b4_tcmalloc"].speedup == pytest.approx(10.0)
    assert got["pcmrl_recon_peak_rss_mib_b4_tcmalloc"].speedup == pytest.approx(1.2)
    assert got["pcmrl_recon_sys_share_b32_tcmalloc"].speedup is None  # 0 in the denominator
    assert got["pcmrl_recon_windows_per_s_b4_system"].baseline is None
    assert got["humot_windows_per_s_b8_jemalloc"].baseline is None
    assert next(iter(got)).startswith("humot")  # the scaling suite's method order
    assert scaling.METHODS.index("humot") < scaling.METHODS.index("pcmrl_recon")


def test_run_restarts_on_the_allocator_it_is_given(tmp_path: Path) -> None:
    import json
    import subprocess

    from skelagnostic.cli.allocator import AllocatorError, find_allocator

    try:
        find_allocator("tcmalloc")
    except AllocatorError:
        pytest.skip("tcmalloc is not installed")
    out = tmp_path / "io.json"
    cmd = [sys.executable, "benchmarks/run.py", "--suite", "io", "--size", "smoke"]
    proc = subprocess.run(
        [*cmd, "--allocator", "tcmalloc", "--json", str(out)],
        cwd=REPO_ROOT, capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert proc.stderr.count("restarting on tcmalloc") == 1
    assert json.loads(out.read_text())["machine"]["allocator"] == "tcmalloc"
    proc = subprocess.run(
        [*cmd, "--allocator", "mimalloc"], cwd=REPO_ROOT, capture_output=True, text=True
    )
    assert proc.returncode == 2 and "--allocator: SKELAGNOSTIC_ALLOCATOR='mimalloc'" in proc.stderr


def test_report_names_an_allocator_other_than_the_system_one() -> None:
    machine = {"cpu_count": 2, "processor": "cpu", "ram_gib": 1.0}
    report = {"suite": "io", "machine": machine, "versions": {}, "results": []}
    assert "allocator" not in render([report])
    assert "allocator" not in render([{**report, "machine": {**machine, "allocator": "system"}}])
    header = render([{**report, "machine": {**machine, "allocator": "tcmalloc"}}])
    assert header.startswith("**Suite `io`**: 2 CPUs (cpu), 1.0 GiB RAM, tcmalloc allocator;")
