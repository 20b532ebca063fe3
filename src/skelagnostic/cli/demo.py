"""``skelagnostic demo``: the core end to end on procedural or real motion.

Generates procedural gaits on four skeletons (or reads the BVH or glTF files
given), runs forward kinematics, writes each motion as BVH (and with ``gltf=true``
as glTF 2.0 ``.glb``), reads it back to check the round trip, and renders all
characters side by side as a PNG contact sheet and an animated GIF (and with
``html=`` the interactive 3D viewer page).
Everything lands in one output directory with a ``summary.json``.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

_DEFAULT_CLIPS = (
    ("biped22", "walk"),
    ("biped31", "run"),
    ("biped17", "walk"),
    ("quadruped", "trot"),
)


#: Longest procedural clip ``demo`` generates, in seconds.
MAX_SECONDS = 600.0

#: Options of ``skelagnostic demo`` with their help.
OPTIONS: dict[str, str] = {
    "out": "output directory; default runs/demo",
    "seconds": "procedural clip length in seconds, at most 600; default 3",
    "fps": "procedural frame rate, at most 240; default 30",
    "seed": "procedural seed; default 0",
    "gif": "false to skip the animated GIF; default true",
    "html": "also write the interactive 3D viewer: a file name (in out=) or true for demo.html",
    "gltf": "true to also write each motion as glTF 2.0 (gltf/NAME.glb, needs the gltf "
    "extra) and check its round trip; default false",
}

_USAGE = """usage: skelagnostic demo [A.bvh B.glb ...] [key=value ...]

Procedural gaits on four skeletons (or the BVH / glTF files given) -> forward
kinematics -> BVH files (glTF with gltf=true), a PNG contact sheet, an animated
GIF and summary.json.

options:
{options}"""


def _usage() -> str:
    from skelagnostic.cli.render import END_OF_OPTIONS_HELP, THREADS_HELP

    lines = [f"  {k:<8} {v}" for k, v in {**OPTIONS, "threads": THREADS_HELP}.items()]
    return _USAGE.format(options="\n".join(lines)) + "\n\n" + END_OF_OPTIONS_HELP


def _options(argv: Sequence[str]) -> tuple[list[Path], dict[str, Any]]:
    """Motion file paths and typed options; raises SkelagnosticError naming the bad option."""
    from skelagnostic.cli.render import apply_threads, parse_arguments, split_end_of_options
    from skelagnostic.errors import SkelagnosticError

    flags = [w for w in split_end_of_options(argv)[0] if w.startswith("--")]
    if flags:
        name = flags[0][2:].split("=", 1)[0].replace("no-gif", "gif")
        raise SkelagnosticError(
            f"option {flags[0]}: every verb takes key=value options, "
            f"e.g. {name}=...; see 'skelagnostic demo --help'"
        )
    words, raw = parse_arguments(argv)
    apply_threads(raw)
    unknown = sorted(set(raw) - set(OPTIONS))
    if unknown:
        raise SkelagnosticError(
            f"unknown option(s) {', '.join(k + '=' for k in unknown)}; "
            "see 'skelagnostic demo --help'"
        )
    from skelagnostic.io.outputs import check_output_dir

    options: dict[str, Any] = {"out": check_output_dir(raw.get("out", "runs/demo"), "out")}
    for key, kind, default in (("seconds", float, 3.0), ("fps", float, 30.0)):
        try:
            options[key] = kind(raw.get(key, default))
        except ValueError:
            raise SkelagnosticError(f"option {key}={raw[key]!r}: not a number") from None
    seed = raw.get("seed", "0")
    if not seed.isdecimal():  # NumPy's generators take no negative seed
        raise SkelagnosticError(f"option seed={seed!r}: must be a whole number >= 0")
    options["seed"] = int(seed)
    from skelagnostic.viz.render import MAX_FPS

    # Checked before anything is generated: fps=1e6 would allocate millions of frames.
    for key, limit in (("seconds", MAX_SECONDS), ("fps", MAX_FPS)):
        if not 0 < options[key] <= limit:
            raise SkelagnosticError(
                f"option {key}={raw.get(key)!r}: must be above 0 and at most {limit:g}"
            )
    for key, default in (("gif", "true"), ("gltf", "false")):
        value = raw.get(key, default).lower()
        if value not in ("true", "false"):
            raise SkelagnosticError(f"option {key}={raw[key]!r}: true or false")
        options[key] = value == "true"
    html = raw.get("html")
    options["html"] = None if html in (None, "false") else ("demo.html" if html == "true" else html)
    if options["html"] is not None:
        from skelagnostic.io.outputs import check_output_file

        check_output_file(options["out"] / options["html"], "html")
    return [Path(w) for w in words], options


def main(argv: Sequence[str]) -> int:
    """Run the demo; returns the exit code."""
    from skelagnostic.cli.render import wants_help

    if wants_help(argv):
        print(_usage())
        return 0
    from skelagnostic.errors import SkelagnosticError, error_line

    try:
        bvh_files, args = _options(argv)
    except SkelagnosticError as exc:
        print(error_line("skelagnostic demo", exc), file=sys.stderr)
        return 2
    from skelagnostic.cli.lock import RunDirectoryLock, RunDirectoryRefused

    lock = RunDirectoryLock(args["out"], key="out")  # two demos never mix their files
    try:
        lock.acquire()
    except (RunDirectoryRefused, OSError) as exc:
        if isinstance(exc, OSError):
            exc = f"out={str(args['out'])!r}: cannot write there ({exc.strerror or exc})"
        print(error_line("skelagnostic demo", exc), file=sys.stderr)
        return 1
    try:
        return _demo(bvh_files, args)
    finally:
        lock.release()


def _demo(bvh_files: list[Path], args: dict[str, Any]) -> int:
    """Generate or read the clips, write the outputs into ``args["out"]``; the exit code."""
    from rich.console import Console
    from rich.table import Table

    import skelagnostic as sa
    from skelagnostic.errors import error_line, printable
    from skelagnostic.io.outputs import write_output

    console = Console(stderr=False)
    out: Path = args["out"]
    gltf_dir = out / "gltf" if args["gltf"] else None
    try:
        out.mkdir(parents=True, exist_ok=True)
        motions, source = _motions(bvh_files, args)
        table = Table(title=f"skelagnostic demo: {source}")
        for col in ("motion", "joints", "frames", "fps", "height", "speed/s", "BVH round trip"):
            table.add_column(col)
        bvh_dir = out / "bvh"
        bvh_dir.mkdir(exist_ok=True)
        if gltf_dir is not None:
            table.add_column("glTF round trip")
            gltf_dir.mkdir(exist_ok=True)
        summary = []
        for m in motions:
            row, entry = _round_trip(m, bvh_dir, gltf_dir)
            table.add_row(*row)
            summary.append(entry)
        console.print(table)
        outputs = _pictures(motions, out, args)
        write_output(
            out / "summary.json",
            json.dumps({"source": source, "motions": summary, "outputs": outputs}, indent=2),
            "out",
        )
    except sa.SkelagnosticError as exc:
        print(error_line("skelagnostic demo", exc), file=sys.stderr)
        return 1
    for kind, path in outputs.items():
        console.print(printable(f"{kind}: {path}"), markup=False, highlight=False)
    glb = f"  glTF files: {gltf_dir}" if gltf_dir is not None else ""
    console.print(
        printable(f"BVH files: {bvh_dir}{glb}  summary: {out / 'summary.json'}"),
        markup=False,
        highlight=False,
    )
    return 0


def _motions(bvh_files: list[Path], args: dict[str, Any]) -> tuple[list[Any], str]:
    """The clips of the demo: the files given, else the procedural gaits; and where from."""
    import skelagnostic as sa
    from skelagnostic.io.motion_files import motion_format, read_motion

    if bvh_files:
        motions = [read_motion(path, other="bvh") for path in bvh_files]  # other names: BVH
        return motions, ", ".join(sorted({motion_format(p, other="bvh") for p in bvh_files}))
    motions = [
        sa.procedural.generate(
            kind, gait, seconds=args["seconds"], fps=args["fps"], seed=args["seed"] + i
        )[0]
        for i, (kind, gait) in enumerate(_DEFAULT_CLIPS)
    ]
    return motions, "procedural (synthetic)"


def _round_trip(m: Any, bvh_dir: Path, gltf_dir: Path | None) -> tuple[list[str], dict[str, Any]]:
    """Write ``m`` as BVH (and glTF), read it back; its table row and its summary entry."""
    import skelagnostic as sa

    pos = m.global_positions()
    speed = float(m.root_local_velocities()[:, 0, [0, 2]].norm(dim=-1).mean())
    path = bvh_dir / f"{m.name}.bvh"
    sa.write_bvh(m, path)
    err = float((sa.read_bvh(path).global_positions() - pos).abs().max())
    row = [
        str(m.name),
        str(m.num_joints),
        str(m.num_frames),
        f"{m.fps:g}",
        f"{m.skeleton.height():.1f}",
        f"{speed:.1f}",
        f"max |dpos| {err:.1e}",
    ]
    entry = {
        "name": m.name,
        "joints": m.num_joints,
        "frames": m.num_frames,
        "fps": m.fps,
        "height": m.skeleton.height(),
        "root_speed": speed,
        "bvh": str(path),
        "round_trip_max_position_error": err,
    }
    if gltf_dir is not None:
        glb = gltf_dir / f"{m.name}.glb"
        sa.write_gltf(m, glb)
        gltf_err = float((sa.read_gltf(glb).global_positions() - pos).abs().max())
        row.append(f"max |dpos| {gltf_err:.1e}")
        entry["gltf"] = str(glb)
        entry["gltf_round_trip_max_position_error"] = gltf_err
    return row, entry


def _pictures(motions: list[Any], out: Path, args: dict[str, Any]) -> dict[str, str]:
    """The contact sheet, and the GIF and HTML viewer when asked; ``kind -> path``."""
    from skelagnostic.io.outputs import write_output
    from skelagnostic.viz import render_motion, to_html

    labels = [str(m.name) for m in motions]
    sheet = render_motion(
        motions, out / "demo.png", labels=labels, sheet_frames=6, columns=3, follow=True, key="out"
    )
    outputs = {"contact_sheet": str(sheet)}
    if args["gif"]:
        gif = render_motion(
            motions,
            out / "demo.gif",
            labels=labels,
            max_frames=90,
            follow=True,
            progress=True,
            key="out",
        )
        outputs["animation"] = str(gif)
    if args["html"] is not None:
        page = out / args["html"]
        write_output(page, to_html(motions, names=labels), "html")
        outputs["viewer"] = str(page)
    return outputs


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main(sys.argv[1:]))
