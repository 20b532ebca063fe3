import json
import os
import stat
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

import skelagnostic as sa
from skelagnostic.cli import main


def test_demo_procedural_writes_bvh_png_and_summary(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", f"out={out}", "seconds=1", "gif=false"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert [m["joints"] for m in summary["motions"]] == [22, 31, 17, 21]
    for entry in summary["motions"]:
        back = sa.read_bvh(entry["bvh"])
        assert back.num_frames == entry["frames"] == 31
        assert entry["round_trip_max_position_error"] < 1e-4
    sheet = np.asarray(Image.open(out / "demo.png").convert("L"))
    assert sheet.shape[0] > 100 and (sheet < 128).mean() > 0.001  # something was drawn
    assert "biped31_run_1" in capsys.readouterr().out


def test_demo_html_writes_the_viewer(tmp_path):
    out = tmp_path / "demo"
    assert main(["demo", f"out={out}", "seconds=0.5", "gif=false", "html=true"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["outputs"]["viewer"] == str(out / "demo.html")
    page = (out / "demo.html").read_text(encoding="utf-8")
    assert '"name":"quadruped_trot_3"' in page and "OrbitControls" in page


def test_demo_gltf_writes_and_reads_glb(tmp_path):
    out = tmp_path / "demo"
    assert main(["demo", f"out={out}", "seconds=0.5", "gif=false", "gltf=true"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    for entry in summary["motions"]:
        assert entry["gltf"] == str(out / "gltf" / f"{entry['name']}.glb")
        assert sa.read_gltf(entry["gltf"]).num_frames == entry["frames"]
        assert entry["gltf_round_trip_max_position_error"] < 1e-4
    # a glTF file is an input too
    again = tmp_path / "again"
    first = summary["motions"][0]["gltf"]
    assert main(["demo", first, f"out={again}", "gif=false"]) == 0
    summary = json.loads((again / "summary.json").read_text())
    assert summary["source"] == "gltf" and "gltf" not in summary["motions"][0]


@pytest.mark.data
def test_demo_on_real_bvh(tmp_path, shared_data):
    clip = shared_data / "human" / "xia_cmu" / "angry_13_000.bvh"
    out = tmp_path / "real"
    assert main(["demo", str(clip), f"out={out}", "gif=false"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["motions"][0]["frames"] == 140


def test_demo_bad_bvh_is_one_clear_line(tmp_path):
    bad = tmp_path / "broken.bvh"
    bad.write_text("HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0\n")
    proc = subprocess.run(
        [sys.executable, "-m", "skelagnostic.cli", "demo", str(bad), f"out={tmp_path / 'o'}"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 1
    assert "broken.bvh:4:" in proc.stderr and "Traceback" not in proc.stdout + proc.stderr
    assert not (tmp_path / "o" / "summary.json").exists()


def test_unknown_verb_and_help(capsys):
    assert main(["frobnicate"]) == 2
    assert "unknown verb" in capsys.readouterr().err
    assert main(["--help"]) == 0
    assert "demo" in capsys.readouterr().out


def test_demo_outputs_get_the_permissions_the_umask_allows(tmp_path):
    out = tmp_path / "demo"
    old = os.umask(0o022)
    try:
        assert main(["demo", f"out={out}", "seconds=0.3"]) == 0
    finally:
        os.umask(old)
    written = {str(p.relative_to(out)): stat.S_IMODE(p.stat().st_mode) for p in out.rglob("*")}
    assert {"demo.png", "demo.gif", "summary.json", "bvh/biped22_walk_0.bvh"} <= set(written)
    wrong = {name: oct(mode) for name, mode in written.items() if mode not in {0o644, 0o755}}
    assert wrong == {}


def test_demo_takes_key_value_options_like_every_verb(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (
        "skelagnostic demo: error: option --out: every verb takes key=value options, "
        "e.g. out=...; see 'skelagnostic demo --help'"
    )
    assert main(["demo", "seconds=abc"]) == 2
    assert "option seconds='abc': not a number" in capsys.readouterr().err
    assert main(["demo", "colour=red"]) == 2
    assert "unknown option(s) colour=" in capsys.readouterr().err
    assert main(["demo", "--help"]) == 0
    assert "threads" in capsys.readouterr().out
