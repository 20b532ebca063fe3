"""Write the viewer screenshot shown in docs/viz.md (docs/assets/viewer.png).

Builds a viewer page of three procedural characters (a 22-joint walker, a
31-joint runner and a dog) with skelagnostic.viz.to_html, opens it in headless
Chromium through skelagnostic.viz.browser (the machinery of the browser tests),
steps to a frame with the page's controls and saves the window.

Usage: python scripts/viewer_screenshot.py [OUT.png] [--html OUT.html]
Needs selenium (the test extra) and Debian's chromium + chromium-driver.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from PIL import Image

import skelagnostic as sa
from skelagnostic.viz import to_html
from skelagnostic.viz.browser import ViewerBrowser

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    """Render the page, take the screenshot, write the PNG."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", nargs="?", type=Path, default=ROOT / "docs/assets/viewer.png")
    parser.add_argument("--html", type=Path, default=None, help="also keep the page here")
    parser.add_argument("--frame", type=int, default=40, help="frame to show")
    args = parser.parse_args()
    clips = [
        sa.procedural.generate("biped22", "walk", seconds=3.0, fps=30, seed=0)[0],
        sa.procedural.generate("biped31", "run", seconds=3.0, fps=30, seed=1)[0],
        sa.procedural.generate("quadruped", "trot", seconds=3.0, fps=30, seed=2)[0],
    ]
    page = args.html or args.out.with_suffix(".html")
    to_html(
        clips,
        names=["walk (22 joints)", "run (31 joints)", "dog trot"],
        out=page,
        keyframes={0: [0, 30, 60, 90]},
        transitions={2: [25, 70]},
    )
    try:
        with ViewerBrowser(size=(960, 540)) as browser:
            browser.open(page)
            browser.step_to(args.frame)
            errors = browser.console_errors()
            if errors:
                raise SystemExit(f"the page logged errors: {errors}")
            image = browser.screenshot()
    finally:
        if args.html is None:
            page.unlink()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(image).save(args.out, optimize=True)
    print(args.out)


if __name__ == "__main__":
    main()
