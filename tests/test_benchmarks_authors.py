"""``benchmarks/run.py --authors-repo``: the official code as a same-run baseline.

The tests that run the authors' code need a checkout of it: set
``SKELAGNOSTIC_WALKTHEDOG_REPO`` to a checkout of github PeizhuoLi/walk-the-dog
(its trainer also needs tensorboard, scikit-learn, matplotlib and tqdm). Without
it they are skipped; everything else here runs without their code.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
if str(REPO_ROOT) not in sys.path:
    sys.path.insert(0, str(REPO_ROOT))

from benchmarks import authors  # noqa: E402
from benchmarks.authors import (  # noqa: E402
    AUTHORS_ENV,
    CHECKOUTS,
    AuthorsRepoError,
    authors_repo,
    export_authors_repos,
    parse_authors_repos,
)

#: Checkout of the WalkTheDog authors' repository for the tests that run their code.
WALKTHEDOG_ENV = "SKELAGNOSTIC_WALKTHEDOG_REPO"


def fake_checkout(root: Path, name: str) -> Path:
    """A directory holding (empty) the files that identify a checkout of ``name``."""
    for rel in CHECKOUTS[name]:
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).touch()
    return root


@pytest.fixture
def clean_env(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(AUTHORS_ENV, raising=False)


def test_parse_names_both_repositories(tmp_path: Path, clean_env: None) -> None:
    wtd = fake_checkout(tmp_path / "wtd", "walkthedog")
    pc = fake_checkout(tmp_path / "pc", "pcmrl")
    repos = parse_authors_repos([f"walkthedog={wtd},pcmrl={pc}"])
    assert repos == {"walkthedog": wtd.resolve(), "pcmrl": pc.resolve()}
    # repeatable, and the same as one comma-separated value
    assert parse_authors_repos([f"walkthedog={wtd}", f"pcmrl={pc}"]) == repos
    assert parse_authors_repos([]) == {}


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("walkthedog", "expected NAME=DIR"),
        ("=somewhere", "expected NAME=DIR"),
        ("pytorch3d=/tmp", "unknown repository 'pytorch3d'"),
    ],
)
def test_parse_rejects_malformed_values(spec: str, message: str) -> None:
    with pytest.raises(AuthorsRepoError, match=message):
        parse_authors_repos([spec])


def test_a_directory_that_is_not_a_checkout_is_named(tmp_path: Path) -> None:
    with pytest.raises(AuthorsRepoError, match=f"{tmp_path / 'nowhere'} is not a directory"):
        parse_authors_repos([f"walkthedog={tmp_path / 'nowhere'}"])
    # a PC-MRL checkout given as WalkTheDog's: the path and the missing files are named
    pc = fake_checkout(tmp_path / "pc", "pcmrl")
    with pytest.raises(AuthorsRepoError) as err:
        parse_authors_repos([f"walkthedog={pc}"])
    text = str(err.value)
    assert str(pc.resolve()) in text and "PeizhuoLi/walk-the-dog" in text
    assert "train_vq.py" in text and "offline_motion_matching.py" in text
    wtd = fake_checkout(tmp_path / "wtd", "walkthedog")
    with pytest.raises(AuthorsRepoError, match="walkthedog given twice"):
        parse_authors_repos([f"walkthedog={wtd}", f"walkthedog={wtd}"])


def test_children_see_the_checkouts_through_the_environment(
    tmp_path: Path, clean_env: None
) -> None:
    assert authors_repo("walkthedog") is None
    wtd = fake_checkout(tmp_path / "wtd", "walkthedog")
    export_authors_repos({"walkthedog": wtd})
    try:
        assert authors_repo("walkthedog") == wtd.resolve()
        assert authors_repo("pcmrl") is None
    finally:
        export_authors_repos({})
    assert AUTHORS_ENV not in os.environ


def test_run_py_reports_a_bad_checkout_before_running_anything(tmp_path: Path) -> None:
    proc = subprocess.run(
        [sys.executable, "benchmarks/run.py", "--suite", "training", "--size", "smoke",
         "--authors-repo", f"walkthedog={tmp_path}"],
        cwd=REPO_ROOT, capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert proc.returncode == 2
    assert str(tmp_path) in proc.stderr and "not a checkout" in proc.stderr


def _fake_measure(**kwargs: Any) -> tuple[dict[str, Any], float]:
    return {"median_step_s": 0.05, "data_share": 0.1}, 500.0


def test_vqpae_training_baseline_is_absent_without_the_option(
    monkeypatch: pytest.MonkeyPatch, clean_env: None
) -> None:
    from benchmarks.suites import training_vqpae

    monkeypatch.setattr(training_vqpae, "accelerators", lambda: ["cpu"])
    monkeypatch.setattr(training_vqpae, "run_child", lambda target, **kw: _fake_measure())
    monkeypatch.setattr(training_vqpae, "authors_baselines", pytest.fail)
    results = training_vqpae.run("smoke")
    assert results and all(r.baseline_value is None and r.baseline is None for r in results)
    assert {"vqpae_windows_per_s_pose", "vqpae_steps_per_s_pose", "vqpae_peak_rss_mib_pose"} <= {
        r.name for r in results
    }


def test_vqpae_training_baseline_comes_from_the_authors_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, clean_env: None
) -> None:
    from benchmarks.suites import training_vqpae

    wtd = fake_checkout(tmp_path / "wtd", "walkthedog")
    export_authors_repos({"walkthedog": wtd})
    monkeypatch.setattr(training_vqpae, "accelerators", lambda: ["cpu"])
    monkeypatch.setattr(training_vqpae, "run_child", lambda target, **kw: _fake_measure())
    seen: list[Path] = []

    def theirs(repo: Path, steps: int) -> dict[str, Any]:
        seen.append(repo)
        timing = {"median_step_s": 0.2, "children_peak_rss_mib": 300.0}
        return {"pose": (timing, 800.0), "nopose": ({**timing, "median_step_s": 0.1}, 700.0)}

    monkeypatch.setattr(training_vqpae, "authors_baselines", theirs)
    try:
        by_name = {r.name: r for r in training_vqpae.run("smoke")}
    finally:
        export_authors_repos({})
    assert seen == [wtd.resolve()]
    pose = by_name["vqpae_windows_per_s_pose"]
    assert pose.baseline_value == pytest.approx(64 / 0.2) and pose.speedup == pytest.approx(4.0)
    assert by_name["vqpae_steps_per_s_nopose"].speedup == pytest.approx(2.0)
    assert by_name["vqpae_peak_rss_mib_pose"].baseline_value == 800.0
    assert by_name["vqpae_authors_worker_peak_rss_mib_pose"].value == 300.0
    # the phase-rate rows have no counterpart in the authors' trainer
    assert by_name["vqpae_windows_per_s_pose_phase_rate"].baseline_value is None


def test_wtd_data_script_missing_is_a_clear_error(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from benchmarks.suites.authors_walkthedog import WTD_DATA_ENV, wtd_data_script

    monkeypatch.setenv(WTD_DATA_ENV, str(tmp_path / "wtd_data.py"))
    with pytest.raises(FileNotFoundError, match=str(tmp_path / "wtd_data.py")):
        wtd_data_script()


def walkthedog_checkout() -> Path:
    path = os.environ.get(WALKTHEDOG_ENV)
    if not path:
        pytest.skip(f"set {WALKTHEDOG_ENV} to a checkout of github PeizhuoLi/walk-the-dog")
    return authors.check_checkout("walkthedog", path)


@pytest.mark.slow
@pytest.mark.data
def test_authors_trainer_runs_and_is_timed(tmp_path: Path) -> None:
    from benchmarks.harness import run_child, shared_data
    from benchmarks.suites.authors_walkthedog import write_datasets

    repo = walkthedog_checkout()
    root = shared_data("human/lafan1", "dog/mann")
    if root is None:
        pytest.skip("needs the shared clips")
    dog = sorted((root / "dog" / "mann").glob("*.bvh"))[:3]
    datasets = write_datasets(
        tmp_path,
        {"human": ([root / "human" / "lafan1" / "Lafan1_example.bvh"], "biped"),
         "dog": (dog, "quadruped")},
    )  # fmt: skip
    out, rss = run_child(
        "benchmarks.suites.authors_walkthedog:train", repo=str(repo),
        datasets=[str(d) for d in datasets], steps=3, warmup=1, phase_decoder=False,
    )  # fmt: skip
    assert 0 < out["median_step_s"] < 60 and out["iterations_per_epoch"] >= 4
    assert rss > 0


@pytest.mark.slow
def test_authors_matching_kernel_picks_the_same_windows() -> None:
    from benchmarks.harness import run_child

    repo = walkthedog_checkout()
    ours, _ = run_child(
        "benchmarks.suites.matching:child_fast", frames=5000, query_frames=240, repeats=1
    )
    theirs, _ = run_child(
        "benchmarks.suites.matching:child_authors",
        frames=5000, query_frames=240, queries=4, repo=str(repo),
    )  # fmt: skip
    assert len(theirs["windows"]) == 4
    assert theirs["windows"] == ours["windows"][:4]


def test_report_updates_a_named_block_and_leaves_the_main_one(tmp_path: Path) -> None:
    from benchmarks.report import update

    page = tmp_path / "page.md"
    page.write_text(
        "a\n<!-- benchmarks:start -->\nmain\n<!-- benchmarks:end -->\n"
        "b\n<!-- benchmarks:authors:start -->\nold\n<!-- benchmarks:authors:end -->\nc\n"
    )
    update(page, "new\n", "authors")
    text = page.read_text()
    assert "main" in text and "old" not in text
    assert "<!-- benchmarks:authors:start -->\nnew\n<!-- benchmarks:authors:end -->" in text
    with pytest.raises(SystemExit, match="benchmarks:other:start"):
        update(page, "x\n", "other")


#: Checkout of the PC-MRL authors' repository for the test that runs their stage 1.
PCMRL_ENV = "SKELAGNOSTIC_PCMRL_REPO"


def test_pcmrl_baseline_only_on_stage_1_and_absent_without_the_option(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, clean_env: None
) -> None:
    from benchmarks.suites import training_pcmrl

    monkeypatch.setattr(training_pcmrl, "accelerators", lambda: ["cpu"])
    monkeypatch.setattr(training_pcmrl, "run_child", lambda target, **kw: _fake_measure())
    monkeypatch.setattr(training_pcmrl, "authors_stage1", pytest.fail)
    alone = training_pcmrl.run("smoke")
    assert all(r.baseline_value is None for r in alone)
    assert not any("authors_layout" in r.name for r in alone)  # only beside their trainer
    export_authors_repos({"pcmrl": fake_checkout(tmp_path / "pc", "pcmrl")})
    batches: list[int] = []

    def theirs(repo: Path, steps: int, batch: int) -> tuple[dict[str, Any], float]:
        batches.append(batch)
        return {"median_step_s": 0.5}, 900.0

    monkeypatch.setattr(training_pcmrl, "authors_stage1", theirs)
    layouts: list[Any] = []

    def fake(target: str, **kwargs: Any) -> tuple[dict[str, Any], float]:
        layouts.append(kwargs.get("layout"))
        batches.append(kwargs["batch"])
        step = 0.04 if kwargs.get("layout") == "authors" else 0.05
        return {"median_step_s": step, "data_share": 0.01}, 500.0

    monkeypatch.setattr(training_pcmrl, "run_child", fake)
    try:
        by_name = {r.name: r for r in training_pcmrl.run("smoke")}
    finally:
        export_authors_repos({})
    assert layouts == [None, "authors", None]  # recon, recon with their layout, interp
    # smoke's batch (2) is below what their trainer runs: both sides take its minimum
    assert training_pcmrl.BATCH["smoke"] < training_pcmrl.AUTHORS_MIN_BATCH
    assert batches == [training_pcmrl.AUTHORS_MIN_BATCH] * 4
    same = by_name["pcmrl_recon_authors_layout_steps_per_s"]
    assert same.value == pytest.approx(25.0) and same.speedup == pytest.approx(12.5)
    assert same.baseline == training_pcmrl.AUTHORS
    assert by_name["pcmrl_recon_steps_per_s"].speedup == pytest.approx(10.0)
    assert by_name["pcmrl_recon_windows_per_s"].baseline_value == pytest.approx(
        training_pcmrl.AUTHORS_MIN_BATCH / 0.5
    )
    assert by_name["pcmrl_recon_peak_rss_mib"].baseline_value == 900.0
    assert by_name["pcmrl_interp_steps_per_s"].baseline_value is None


def test_pcmrl_interp_rows_take_the_reference_network_as_baseline(
    monkeypatch: pytest.MonkeyPatch, clean_env: None
) -> None:
    from benchmarks.suites import training_pcmrl

    calls: list[dict[str, Any]] = []

    def fake(target: str, **kwargs: Any) -> tuple[dict[str, Any], float]:
        calls.append(kwargs)
        slow = kwargs.get("fast_path") is False  # the reference network: 1.5x the step
        return {"median_step_s": 0.75 if slow else 0.5, "data_share": 0.1}, 600.0 if slow else 500.0

    monkeypatch.setattr(training_pcmrl, "accelerators", lambda: ["cpu"])
    monkeypatch.setattr(training_pcmrl, "run_child", fake)
    by_name = {r.name: r for r in training_pcmrl.run("default")}
    assert [c.get("fast_path") for c in calls] == [None, None, False]
    assert calls[2]["stage"] == "interp"
    steps = by_name["pcmrl_interp_steps_per_s"]
    assert steps.baseline == training_pcmrl.REFERENCE
    assert steps.speedup == pytest.approx(1.5)
    assert by_name["pcmrl_interp_windows_per_s"].baseline_value == pytest.approx(
        training_pcmrl.BATCH["default"] / 0.75
    )
    assert by_name["pcmrl_interp_peak_rss_mib"].baseline_value == 600.0
    assert by_name["pcmrl_recon_steps_per_s"].baseline_value is None
    calls.clear()
    assert all(r.baseline_value is None for r in training_pcmrl.run("smoke"))
    assert all("fast_path" not in c for c in calls)


def test_authors_stage1_refuses_a_batch_their_loop_cannot_draw(tmp_path: Path) -> None:
    from benchmarks.suites.authors_pcmrl import VISUALISED_WINDOWS, train_stage1

    with pytest.raises(ValueError, match=f"batch_size >= {VISUALISED_WINDOWS}.*got 2"):
        train_stage1(
            str(tmp_path), "walk.bvh", "cmu.bvh", steps=1, batch_size=2
        )  # before their code is imported: no checkout needed


def test_pytorch3d_stand_ins_compute_the_definitions() -> None:
    import torch
    from benchmarks.suites.authors_pcmrl import (
        euler_angles_to_matrix,
        knn_gather,
        knn_points,
        matrix_to_quaternion,
        sample_farthest_points,
    )

    gen = torch.Generator().manual_seed(0)
    points = torch.randn(3, 40, 3, generator=gen)
    picked, idx = sample_farthest_points(points, K=10)
    for b in range(3):  # the greedy definition, one cloud at a time
        chosen = [0]
        closest = (points[b] - points[b, 0]).square().sum(-1)
        while len(chosen) < 10:
            chosen.append(int(closest.argmax()))
            closest = torch.minimum(closest, (points[b] - points[b, chosen[-1]]).square().sum(-1))
        assert idx[b].tolist() == chosen
        assert torch.equal(picked[b], points[b, chosen])
    knn = knn_points(picked, points, K=4)
    brute = (picked[:, :, None] - points[:, None]).square().sum(-1)
    assert torch.equal(knn.dists, brute.sort(-1).values[..., :4])
    assert torch.equal(brute.gather(-1, knn.idx), knn.dists)
    feats = torch.randn(3, 40, 5, generator=gen)
    gathered = knn_gather(feats, knn.idx)
    assert gathered.shape == (3, 10, 4, 5)
    assert torch.equal(gathered[1, 2, 3], feats[1, knn.idx[1, 2, 3]])
    angles = torch.randn(20, 3, generator=gen, dtype=torch.float64)
    matrix = euler_angles_to_matrix(angles, "ZYX")
    rz, ry, rx = (euler_angles_to_matrix(a, "XYZ") for a in (
        torch.stack([torch.zeros(20), torch.zeros(20), angles[:, 0]], -1).double(),
        torch.stack([torch.zeros(20), angles[:, 1], torch.zeros(20)], -1).double(),
        torch.stack([angles[:, 2], torch.zeros(20), torch.zeros(20)], -1).double(),
    ))  # fmt: skip
    assert torch.allclose(matrix, rz @ ry @ rx)
    assert torch.allclose(matrix.transpose(-1, -2) @ matrix, torch.eye(3, dtype=torch.float64))
    q = matrix_to_quaternion(matrix)  # w, x, y, z: rotating by q is multiplying by the matrix
    w, v = q[:, :1], q[:, 1:]
    x = torch.randn(20, 3, generator=gen, dtype=torch.float64)
    rotated = (
        x
        + 2 * w * torch.cross(v, x, dim=-1)
        + 2 * torch.cross(v, torch.cross(v, x, dim=-1), dim=-1)
    )
    assert torch.allclose(rotated, (matrix @ x[..., None])[..., 0])


@pytest.mark.slow
@pytest.mark.data
def test_authors_stage1_runs_and_is_timed() -> None:
    from benchmarks.harness import run_child, shared_data

    path = os.environ.get(PCMRL_ENV)
    if not path:
        pytest.skip(f"set {PCMRL_ENV} to a checkout of github MiniEval/PC-MRL")
    repo = authors.check_checkout("pcmrl", path)
    root = shared_data("human/lafan1", "human/xia_cmu")
    if root is None:
        pytest.skip("needs the shared clips")
    out, rss = run_child(
        "benchmarks.suites.authors_pcmrl:train_stage1", repo=str(repo),
        source=str(root / "human" / "lafan1" / "Lafan1_example.bvh"),
        target_skeleton=str(root / "human" / "xia_cmu" / "neutral_01_000.bvh"),
        steps=1, batch_size=4, window=16,
    )  # fmt: skip
    assert out["median_step_s"] > 0 and out["parameters"] > 0 and rss > 0
