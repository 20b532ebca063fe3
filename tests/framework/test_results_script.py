"""scripts/results.py: committed held-out evaluations -> docs/results.md."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import yaml

from script_loader import load_script

REPO = Path(__file__).resolve().parents[2]

FIT = [
    "experiment=smoke",
    "model.hidden=8",
    "model.latent=4",
    "data.seconds=2.0",
    "data.clips_per_gait=2",
    "data.window=16",
    "data.stride=8",
    "data.test_fraction=0.3",
    "threads=1",
]

TARGETS = [
    "mpjpe_cm < mean_pose_on_trajectory",
    "mpjpe_cm <= 0.5 * mean_pose_on_trajectory",
    "mpjpe_over_height < 0.01",
    "mpjpe_over_height < 1e-9",
]

#: The model's errors in the entries' evaluation are this share of the trained
#: example's: a briefly trained model meets no target that no baseline meets, and
#: the page must show met targets too.
BETTER = 0.01


results = load_script("scripts/results.py", "results_script")


def _run_yaml(**changes: Any) -> dict[str, Any]:
    run: dict[str, Any] = {
        "method": "example",
        "title": "Example aligner on procedural clips",
        "date": "2026-12-03",
        "machine": {"cores": 2, "load": "about 3"},
        "budget": {"steps": 40, "cpu_time": "10 s"},
        "commands": {
            "fit": "skelagnostic fit model=example " + " ".join(FIT),
            "evaluate": "skelagnostic evaluate ckpt_path=runs/example/fit/<stamp>",
        },
        "quote": ["mpjpe_cm", "mpjpe_over_height"],
        "paper": {
            "mpjpe_cm": {"value": 1.19, "source": "Table 1"},
            "mpjpe_over_height": {"value": None, "why": "no height-relative figure"},
        },
        "targets": list(TARGETS),
        "notes": ["a smoke run"],
    }
    run.update(changes)
    return run


@pytest.fixture(scope="module")
def evaluation(tmp_path_factory: pytest.TempPathFactory, fit_example: Callable[..., Path]) -> Path:
    """A real ``evaluation.json``: the example aligner trained briefly, then ``evaluate``."""
    root = tmp_path_factory.mktemp("evaluated")
    fitted = fit_example(root, FIT)
    evaluated = fit_example(root, [*FIT, f"ckpt_path={fitted}"], task="evaluate")
    return evaluated / "evaluation.json"


def _better_model(report: dict[str, Any], factor: float = BETTER) -> dict[str, Any]:
    """The report with the model's errors scaled by ``factor`` (per clip and mean)."""
    report = json.loads(json.dumps(report))
    for values in [report["mean"], *(row["values"] for row in report["per_clip"])]:
        values["model"] = {k: v * factor for k, v in values["model"].items()}
    return report


@pytest.fixture
def heldout(evaluation: Path, tmp_path: Path) -> Path:
    """A directory of entries with one entry: that evaluation and its run.yaml."""
    entry = tmp_path / "heldout" / "example_smoke"
    entry.mkdir(parents=True)
    report = _better_model(json.loads(evaluation.read_text()))
    (entry / "evaluation.json").write_text(json.dumps(report))
    (entry / "run.yaml").write_text(yaml.safe_dump(_run_yaml()))
    return entry.parent


def _args(root: Path, out: Path, *extra: str) -> list[str]:
    return ["--root", str(root), "--out", str(out), "--methods", "example,humot", *extra]


def _tables(markdown: str) -> list[list[dict[str, str]]]:
    """Every Markdown table of a page, as rows of ``header -> cell``."""
    tables, lines = [], markdown.splitlines()
    for i, line in enumerate(lines[:-1]):
        if line.startswith("| ") and lines[i + 1].startswith("|---"):
            header = [c.strip() for c in line.strip("|").split(" | ")]
            rows = []
            for row in lines[i + 2 :]:
                if not row.startswith("| "):
                    break
                cells = [c.strip() for c in re.split(r"(?<!\\) \| ", row.strip()[2:-2])]
                rows.append(dict(zip(header, cells, strict=True)))
            tables.append(rows)
    return tables


def _status(page: str) -> list[dict[str, str]]:
    """The rows of the page's "Targets at a glance" table."""
    section = page.split("## Targets at a glance\n", 1)[1].split("\n## ", 1)[0]
    (table,) = _tables(section)
    return table


def _independent_mean(report: dict[str, Any], method: str, metric: str) -> float:
    values = [row["values"][method][metric] for row in report["per_clip"]]
    return sum(values) / len(values)


def test_page_quotes_the_evaluation_and_judges_the_targets(heldout: Path, tmp_path: Path) -> None:
    out = tmp_path / "results.md"
    assert results.main(_args(heldout, out)) == 0
    page = out.read_text()
    report = json.loads((heldout / "example_smoke" / "evaluation.json").read_text())
    quoted, per_clip = (t for t in _tables(page) if "paper" in t[0] or "clip" in t[0])
    # the quoted table: each mean figure of the model and of every baseline
    assert [row["metric"] for row in quoted] == ["`mpjpe_cm`", "`mpjpe_over_height`"]
    for row in quoted:
        metric = row["metric"].strip("`")
        for method in report["methods"]:
            if method == "ground_truth":  # a reference with its foot skate only
                assert row[method] == "-"
                continue
            assert float(row[method]) == pytest.approx(
                _independent_mean(report, method, metric), rel=5e-4
            ), (method, metric)
    assert quoted[0]["paper"] == "1.19 (Table 1)"
    assert quoted[1]["paper"] == "not comparable: no height-relative figure"
    # targets: met / not met recomputed here from the per-clip values
    model_cm = _independent_mean(report, "model", "mpjpe_cm")
    expected_cm = [
        model_cm < _independent_mean(report, "mean_pose_on_trajectory", "mpjpe_cm"),
        model_cm <= 0.5 * _independent_mean(report, "mean_pose_on_trajectory", "mpjpe_cm"),
    ]
    verdicts = [v.split(": ")[-1] for v in quoted[0]["target"].split("; ")]
    assert verdicts == ["**met**" if ok else "**not met**" for ok in expected_cm]
    assert quoted[1]["target"] == "< 0.01: **met**; < 1e-09: **not met**"
    bounds = [float(b) for b in re.findall(r"\(= ([0-9.e+-]+)\)", quoted[0]["target"])]
    assert bounds == pytest.approx(
        [
            _independent_mean(report, "mean_pose_on_trajectory", "mpjpe_cm"),
            0.5 * _independent_mean(report, "mean_pose_on_trajectory", "mpjpe_cm"),
        ],
        rel=5e-4,
    )
    # every per-clip figure of every method
    assert len(per_clip) == len(report["per_clip"]) * len(report["methods"])
    cells = {(r["clip"].strip("`"), r["method"]): r for r in per_clip}
    for row in report["per_clip"]:
        for method, values in row["values"].items():
            for metric, value in values.items():
                assert float(cells[row["clip"], method][metric]) == pytest.approx(value, rel=5e-4)
    # the split, budget, machine, date and commands; a method without entry says so
    clips = ", ".join(f"`{c}`" for c in report["data"]["clips"])
    assert f"the test split of `procedural`, {len(report['data']['clips'])} clips: {clips}" in page
    assert "- Budget: 40 steps, 10 s CPU time" in page
    assert "- Machine: 2 cores, load about 3" in page and "- Date: 2026-12-03" in page
    assert "$ skelagnostic fit model=example experiment=smoke" in page
    assert "$ skelagnostic evaluate ckpt_path=runs/example/fit/<stamp>" in page
    assert "## HuMoT\n\nNo held-out result committed yet." in page
    assert '<a id="per-clip-example-smoke"></a>' in page and "(#per-clip-example-smoke)" in page


def test_figures_of_extra_are_quoted_with_their_baselines(
    heldout: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Per-group means and corpus-level counts in ``extra`` (as VQ-PAE's Table 2 is reported)."""
    report_file = heldout / "example_smoke" / "evaluation.json"
    report = json.loads(report_file.read_text())
    groups: dict[str, dict[str, list[float]]] = {}
    for row in report["per_clip"]:
        kind = row["clip"].split("_")[0]  # biped22 / quadruped: the clip's skeleton
        for method, values in row["values"].items():
            if "mpjpe_cm" in values:  # not the ground_truth reference (its skate only)
                groups.setdefault(kind, {}).setdefault(method, []).append(values["mpjpe_cm"])
    by_kind = {k: {m: sum(v) / len(v) for m, v in g.items()} for k, g in groups.items()}
    report["extra"] = {
        "by_kind": by_kind,
        "clips.seen": {"count": len(report["per_clip"])},
        # method-major, as HuMoT's by_topology: method -> metric -> number
        "nested": {m: {"mpjpe_cm": v} for m, v in by_kind[sorted(by_kind)[-1]].items()},
    }
    report_file.write_text(json.dumps(report))
    quote = [f"extra.by_kind.{kind}" for kind in sorted(by_kind)] + ["extra.nested.mpjpe_cm"]
    quote += ["extra.clips.seen.count"]
    run = _run_yaml(
        quote=quote,
        paper={q: {"value": None, "why": "not in the paper"} for q in quote},
        targets=[
            f"{quote[0]} < mean_pose_on_trajectory",
            f"{quote[-1]} >= 3",
            f"{quote[-1]} > 99",
        ],
    )
    (heldout / "example_smoke" / "run.yaml").write_text(yaml.safe_dump(run))
    out = tmp_path / "results.md"
    assert results.main(_args(heldout, out)) == 0
    (quoted,) = (t for t in _tables(out.read_text()) if "paper" in t[0])
    rows = {row["metric"].strip("`"): row for row in quoted}
    for kind, figure in by_kind.items():
        for method, value in figure.items():
            assert float(rows[f"extra.by_kind.{kind}"][method]) == pytest.approx(value, rel=5e-4)
    for method, value in by_kind[sorted(by_kind)[-1]].items():
        assert float(rows["extra.nested.mpjpe_cm"][method]) == pytest.approx(value, rel=5e-4)
    first = by_kind[sorted(by_kind)[0]]
    met = first["model"] < first["mean_pose_on_trajectory"]
    assert rows[quote[0]]["target"].endswith("**met**" if met else "**not met**")
    count = rows["extra.clips.seen.count"]
    assert count["model"] == str(len(report["per_clip"])) and count["mean_pose"] == "-"
    expected = ["**met**" if len(report["per_clip"]) >= 3 else "**not met**", "**not met**"]
    assert [v.split(": ")[-1] for v in count["target"].split("; ")] == expected
    # a target against a baseline the figure lacks, a key extra does not have
    for change, message in [
        ({"targets": [f"{quote[-1]} < mean_pose"]}, "its baselines: none"),
        (
            {"quote": ["extra.by_kind.nope"]},
            f"extra.by_kind has no key 'nope' (its keys: {', '.join(by_kind)})",
        ),
        ({"quote": ["extra.by_kind"]}, "holds neither a number nor a mapping"),
        ({"quote": ["extra.nested.nope"]}, "extra.nested has no key 'nope'"),
    ]:
        bad = {**run, **change}
        if "quote" in change:
            bad["paper"] = {q: {"value": None, "why": "-"} for q in change["quote"]}
            bad["targets"] = []
        (heldout / "example_smoke" / "run.yaml").write_text(yaml.safe_dump(bad))
        assert results.main(_args(heldout, out)) == 2
        assert message in capsys.readouterr().err


def test_check_fails_on_a_stale_page_and_passes_on_a_fresh_one(
    heldout: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "results.md"
    assert results.main(_args(heldout, out)) == 0
    assert results.main(_args(heldout, out, "--check")) == 0
    status = _status(out.read_text())
    # one row per target: the model's mean, the bound's baseline and the verdict, each
    # recomputed here from the per-clip values
    rows = {(r["method"], r["held-out figure"], r["target"]): r for r in status}
    report = json.loads((heldout / "example_smoke" / "evaluation.json").read_text())
    model_cm = _independent_mean(report, "model", "mpjpe_cm")
    for target, baseline, factor in [
        ("< mean_pose_on_trajectory", "mean_pose_on_trajectory", 1.0),
        ("<= 0.5 × mean_pose_on_trajectory", "mean_pose_on_trajectory", 0.5),
    ]:
        row = rows["example", "`mpjpe_cm`", target]
        match = re.fullmatch(
            rf"`example_smoke` (\S+) \({baseline} (\S+)\): (met|\*\*not met\*\*)",
            row["runs (entry: model)"],
        )
        assert match, row
        bound = _independent_mean(report, baseline, "mpjpe_cm")
        assert float(match[1]) == pytest.approx(model_cm, rel=5e-4)
        assert float(match[2]) == pytest.approx(bound, rel=5e-4)
        met = model_cm < bound if target.startswith("<") else model_cm <= factor * bound
        assert match[3] == ("met" if met else "**not met**")
        assert row["met by"] == f"{int(met)} of 1" and row["paper's"] == "1.19 (Table 1)"
    height = _independent_mean(report, "model", "mpjpe_over_height")
    row = rows["example", "`mpjpe_over_height`", "< 1e-09"]
    assert row["runs (entry: model)"] == f"`example_smoke` {height:.4g}: **not met**"
    assert row["met by"] == "0 of 1" and row["paper's"] == "-"
    assert rows["example", "`mpjpe_over_height`", "< 0.01"]["met by"] == "1 of 1"
    assert ("HuMoT", "no held-out result committed yet", "-") in rows
    assert all(r["clips"] == "test split" for r in status[:-1])
    capsys.readouterr()
    # a stale page (a figure edited by hand) fails with a diff naming the file
    page = out.read_text()
    out.write_text(page.replace("- Date: 2026-12-03", "- Date: 2026-12-02"))
    assert results.main(_args(heldout, out, "--check")) == 1
    err = capsys.readouterr().err
    assert f"{out} (committed)" in err and "-- Date: 2026-12-02" in err
    # ... and so does a changed entry, until regenerated; --check writes nothing
    out.write_text(page)
    run = yaml.safe_load((heldout / "example_smoke" / "run.yaml").read_text())
    run["budget"]["steps"] = 41
    (heldout / "example_smoke" / "run.yaml").write_text(yaml.safe_dump(run))
    assert results.main(_args(heldout, out, "--check")) == 1
    assert "+- Budget: 41 steps" in capsys.readouterr().err and out.read_text() == page
    assert results.main(_args(heldout, out)) == 0
    assert results.main(_args(heldout, out, "--check")) == 0
    # a hand edit of the status table is stale too
    out.write_text(out.read_text().replace("(mean_pose_on_trajectory ", "(mean pose ", 1))
    assert results.main(_args(heldout, out, "--check")) == 1
    assert f"{out} (committed)" in capsys.readouterr().err


def test_the_status_table_lists_every_run_of_a_target(heldout: Path, tmp_path: Path) -> None:
    """Runs of one preset (seeds, machines) share a row per target: each value, met by k of n."""
    smoke = heldout / "example_smoke"
    report = json.loads((smoke / "evaluation.json").read_text())
    # a second run whose model is twice the baseline's error (fails "< mean_pose_on_trajectory")
    rerun = heldout / "example_rerun"
    rerun.mkdir()
    worse = json.loads(json.dumps(report))
    mean_pose = worse["mean"]["mean_pose_on_trajectory"]["mpjpe_cm"]
    worse["mean"]["model"]["mpjpe_cm"] = 2 * mean_pose
    (rerun / "evaluation.json").write_text(json.dumps(worse))
    targets = [
        "mpjpe_cm < mean_pose_on_trajectory",
        "mpjpe_over_height < 0.01",
        "mpjpe_over_height < 0.02",
    ]
    (rerun / "run.yaml").write_text(yaml.safe_dump(_run_yaml(targets=targets)))
    # the same run evaluated on other held-out clips is another row
    wider = heldout / "example_wider"
    wider.mkdir()
    other = json.loads(json.dumps(report))
    other["data"].update(split="heldout", split_name="validation and test splits")
    (wider / "evaluation.json").write_text(json.dumps(other))
    (wider / "run.yaml").write_text(yaml.safe_dump(_run_yaml(targets=targets[:1])))
    # an ablation without targets adds no row
    ablation = heldout / "example_ablation"
    ablation.mkdir()
    shutil.copy(smoke / "evaluation.json", ablation / "evaluation.json")
    (ablation / "run.yaml").write_text(yaml.safe_dump(_run_yaml(targets=[])))
    out = tmp_path / "results.md"
    assert results.main(_args(heldout, out)) == 0
    page = out.read_text()
    status = _status(page)
    half = _independent_mean(report, "model", "mpjpe_cm") <= 0.5 * _independent_mean(
        report, "mean_pose_on_trajectory", "mpjpe_cm"
    )
    # rows in the order the targets first appear (entries by name)
    met = _smoke_met(report)
    test = "test split"
    assert [(r["held-out figure"], r["clips"], r["target"], r["met by"]) for r in status[:-1]] == [
        ("`mpjpe_cm`", test, "< mean_pose_on_trajectory", "1 of 2" if met else "0 of 2"),
        ("`mpjpe_over_height`", test, "< 0.01", "2 of 2"),
        ("`mpjpe_over_height`", test, "< 0.02", "1 of 1"),
        ("`mpjpe_cm`", test, "<= 0.5 × mean_pose_on_trajectory", "1 of 1" if half else "0 of 1"),
        ("`mpjpe_over_height`", test, "< 1e-09", "0 of 1"),
        (
            "`mpjpe_cm`",
            "validation and test splits",
            "< mean_pose_on_trajectory",
            f"{int(met)} of 1",
        ),
    ]
    runs = status[0]["runs (entry: model)"].split("; ")
    assert [r.split(" ")[0] for r in runs] == ["`example_rerun`", "`example_smoke`"]
    assert (
        runs[0]
        == f"`example_rerun` {2 * mean_pose:.4g} (mean_pose_on_trajectory {mean_pose:.4g}): "
        "**not met**"
    )
    assert status[3]["runs (entry: model)"].startswith("`example_smoke` ")  # the rerun lacks it
    assert status[5]["runs (entry: model)"].startswith("`example_wider` ")
    assert "example_ablation" not in "".join(r["runs (entry: model)"] for r in status)
    assert status[-1]["held-out figure"] == "no held-out result committed yet"
    # the status table comes right after the table of entries, ahead of every method section
    assert _tables(page)[1] == status


def test_a_target_a_baseline_also_meets_is_refused(
    heldout: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """No target may be one that a non-learned baseline of the same run meets too."""
    entry = heldout / "example_smoke"
    report = json.loads((entry / "evaluation.json").read_text())
    # the baselines' values, computed here: mean pose > mean pose on the trajectory
    mean_pose = _independent_mean(report, "mean_pose", "mpjpe_cm")
    on_path = _independent_mean(report, "mean_pose_on_trajectory", "mpjpe_cm")
    assert on_path < mean_pose
    out = tmp_path / "results.md"
    for target, baseline in [
        ("mpjpe_cm < mean_pose", "mean_pose_on_trajectory"),  # a weaker baseline as the bound
        (f"mpjpe_cm < {mean_pose * 2:.6g}", "mean_pose"),  # a loose number: the first named
        ("mpjpe_over_height >= 0", "mean_pose"),  # trivially met by every method
        ("mpjpe_cm <= mean_pose_on_trajectory", "mean_pose_on_trajectory"),  # a tie
    ]:
        (entry / "run.yaml").write_text(yaml.safe_dump(_run_yaml(targets=[target])))
        assert results.main(_args(heldout, out)) == 2, target
        err = capsys.readouterr().err
        assert f"run.yaml: targets[0]: {target.split(' ')[0]}" in err
        assert f"is also met by the baseline {baseline} (" in err, err
        assert not out.exists()
    # a method that is not a baseline is exempt once named as a reference, with a reason
    loose = f"mpjpe_cm < {(on_path + mean_pose) / 2:.6g}"
    why = "the clip's own pose, for scale"
    run = _run_yaml(targets=[loose], references={"mean_pose_on_trajectory": why})
    (entry / "run.yaml").write_text(yaml.safe_dump(run))
    assert results.main(_args(heldout, out)) == 0
    assert f"- Reference, not a baseline: `mean_pose_on_trajectory`, {why}" in out.read_text()
    for references, message in [
        ({"lerp": why}, "references: 'lerp' is not a method of the run"),
        ({"mean_pose_on_trajectory": ""}, "references.mean_pose_on_trajectory: expected a"),
        (["mean_pose"], "references: expected a mapping method -> why"),
    ]:
        run = _run_yaml(targets=[loose], references=references)
        (entry / "run.yaml").write_text(yaml.safe_dump(run))
        assert results.main(_args(heldout, out)) == 2
        assert message in capsys.readouterr().err


def _smoke_met(report: dict[str, Any]) -> bool:
    model = _independent_mean(report, "model", "mpjpe_cm")
    return model < _independent_mean(report, "mean_pose_on_trajectory", "mpjpe_cm")


BAD_RUNS = [
    ({"budget": {"cpu_time": "1 h"}}, "run.yaml: budget.steps: missing"),
    ({"machine": {"cores": 0, "load": 1}}, "run.yaml: machine.cores: expected a positive"),
    ({"date": "yesterday"}, "run.yaml: date: expected a date YYYY-MM-DD"),
    ({"method": "humot"}, "run.yaml: method: 'humot', but evaluation.json evaluates "),
    ({"method": "hmuot"}, "run.yaml: method: 'hmuot' is not one of example, humot"),
    ({"quote": ["mpjpe_cm", "knn@0"]}, "run.yaml: quote[1]: 'knn@0' is not a metric"),
    ({"targets": ["mpjpe_cm ~ 3"]}, "run.yaml: targets[0]: 'mpjpe_cm ~ 3' is not"),
    ({"targets": ["mpjpe_cm < lerp"]}, "run.yaml: targets[0]: 'lerp' is neither a number"),
    (
        {"paper": {"mpjpe_cm": {"value": 1.0}, "mpjpe_over_height": {"value": None}}},
        "run.yaml: paper.mpjpe_cm.source: missing",
    ),
    (
        {"paper": {"mpjpe_cm": {"value": None, "source": "Table 1"}}},
        "run.yaml: paper.mpjpe_over_height: missing",
    ),
    ({"commands": {"fit": "skelagnostic fit"}}, "run.yaml: commands.evaluate: missing"),
    ({"budjet": 3}, "run.yaml: budjet: unknown key"),
]


def test_a_bad_run_yaml_names_the_file_and_key(
    heldout: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run_file = heldout / "example_smoke" / "run.yaml"
    for change, message in BAD_RUNS:
        run_file.write_text(yaml.safe_dump(_run_yaml(**change)))
        assert results.main(_args(heldout, tmp_path / "results.md")) == 2, change
        err = capsys.readouterr().err
        assert f"{run_file}: " in err and message in err, err
    assert not (tmp_path / "results.md").exists()
    run_file.write_text(yaml.safe_dump(_run_yaml()))
    assert results.main(_args(heldout, tmp_path / "results.md")) == 0
    report_file = heldout / "example_smoke" / "evaluation.json"
    report = json.loads(report_file.read_text())
    del report["mean"]
    report_file.write_text(json.dumps(report))
    assert results.main(_args(heldout, tmp_path / "results.md")) == 2
    assert f"{report_file}: mean: missing" in capsys.readouterr().err
    report_file.unlink()
    assert results.main(_args(heldout, tmp_path / "results.md")) == 2
    assert f"{report_file}: missing" in capsys.readouterr().err


def test_curves_of_extra_are_tabulated_point_by_point(
    heldout: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """HuMoT's denoising and upsampling curves (``extra.curves``) as tables on the page."""
    report_file = heldout / "example_smoke" / "evaluation.json"
    report = json.loads(report_file.read_text())
    curves = {
        "biped22 (seen)": {
            "denoising": {"sigma_cm": [0.0, 2.0, 4.0], "output_mpjpe_cm": [1.5, 1.75, 2.125]},
            "upsampling": {"fraction": [1.0, 0.5], "mpjpe_cm": [1.5, 3.25]},
        },
        "biped31 (unseen)": {"denoising": {"sigma_cm": [0.0, 2.0], "output_mpjpe_cm": [4.0, 5.5]}},
    }
    report.setdefault("extra", {})["curves"] = curves
    report_file.write_text(json.dumps(report))
    out = tmp_path / "results.md"
    assert results.main(_args(heldout, out)) == 0
    page = out.read_text()
    assert "Every metric of every clip, and the curves `denoising`, `upsampling`:" in page
    tables = {tuple(t[0]): t for t in _tables(page) if t and "series" in t[0]}
    denoising = tables["series", "sigma_cm", "output_mpjpe_cm"]
    expected = [
        (series, x, y)
        for series, kinds in curves.items()
        for x, y in zip(*kinds["denoising"].values(), strict=True)
    ]
    got = [
        (r["series"].strip("`"), float(r["sigma_cm"]), float(r["output_mpjpe_cm"]))
        for r in denoising
    ]
    assert got == expected
    (upsampling,) = (t for key, t in tables.items() if "fraction" in key)
    assert [(r["series"], r["fraction"], r["mpjpe_cm"]) for r in upsampling] == [
        ("`biped22 (seen)`", "1", "1.5"),
        ("`biped22 (seen)`", "0.5", "3.25"),
    ]
    # a malformed curve names the file and key
    for bad, message in [
        (
            {"g": {"denoising": {"sigma_cm": [0.0, 1.0], "output_mpjpe_cm": [1.0]}}},
            "differ in length",
        ),
        ({"g": {"denoising": {"sigma_cm": ["a"]}}}, "extra.curves.g.denoising.sigma_cm: expected"),
        ([1, 2], "extra.curves: expected a mapping"),
    ]:
        report["extra"]["curves"] = bad
        report_file.write_text(json.dumps(report))
        assert results.main(_args(heldout, out)) == 2
        assert f"{report_file}: " in (err := capsys.readouterr().err) and message in err, err


def test_targets_compare_the_model_with_a_bound() -> None:
    figures = {"l2p@15": {"model": 0.5, "lerp_slerp": 0.6, "nan_baseline": float("nan")}}
    cases = {
        "l2p@15 < lerp_slerp": True,
        "l2p@15 <= 0.8 * lerp_slerp": False,  # 0.5 > 0.48
        "l2p@15 >= 0.5": True,
        "l2p@15 > 0.5": False,
        "l2p@15 < 2x lerp_slerp": True,
        "l2p@15 < nan_baseline": None,  # no verdict without a value
    }
    for text, expected in cases.items():
        target = results.parse_target("run.yaml: targets[0]", text, figures)
        assert target.met(figures["l2p@15"]) is expected, text
    assert results.Target("l2p@15", "<", 1.0, None).met({"lerp_slerp": 0.6}) is None


def test_the_committed_results_page_is_up_to_date() -> None:
    done = subprocess.run(
        [sys.executable, str(REPO / "scripts" / "results.py"), "--check"],
        cwd=REPO,
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == 0, done.stderr


def test_an_entry_on_the_training_clips_is_never_called_held_out(
    heldout: Path, tmp_path: Path
) -> None:
    path = heldout / "example_smoke" / "evaluation.json"
    report = json.loads(path.read_text())
    report["data"]["split"] = "train"  # as `evaluate split=train` writes it
    report["data"]["split_name"] = "training split (clips the model trained on, not held out)"
    path.write_text(json.dumps(report))
    out = tmp_path / "results.md"
    assert results.main(_args(heldout, out)) == 0
    section = out.read_text().split("### Example aligner on procedural clips", 1)[1]
    assert "Mean over the training clips (not held out), the model beside" in section
    assert "- Evaluated on (not held out): the training split (clips the model trained on" in (
        section
    )
    assert "- Held out:" not in section and "Mean over the held-out clips" not in section
