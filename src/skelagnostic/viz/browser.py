"""Drive a viewer page of :func:`~skelagnostic.viz.to_html` in headless Chromium.

Used by the browser tests and by ``scripts/viewer_screenshot.py`` (the image in
the docs). It needs the ``selenium`` package (the ``test`` extra) and
Chromium with its driver (Debian: ``apt-get install chromium chromium-driver``);
nothing is downloaded. WebGL runs on SwiftShader, Chromium's software renderer.
"""

from __future__ import annotations

import io
import shutil
import tempfile
import time
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np

from skelagnostic.viz.stick import RenderError

__all__ = ["ViewerBrowser", "browser_available"]

_BROWSERS = ("/usr/bin/chromium", "/usr/bin/chromium-browser", "/usr/bin/google-chrome")
_DRIVERS = ("/usr/bin/chromedriver", "/usr/lib/chromium/chromedriver")
_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--hide-scrollbars",
    "--force-device-scale-factor=1",
)


def _first(paths: tuple[str, ...], name: str) -> str | None:
    found = [p for p in paths if Path(p).is_file()]
    return found[0] if found else shutil.which(name)


def browser_available() -> str | None:
    """Why the viewer cannot be driven here, or ``None`` when it can.

    Returns:
        ``None`` when selenium, Chromium and chromedriver are all installed,
        else a sentence naming what is missing.
    """
    try:
        import selenium  # noqa: F401
    except ImportError:
        return "the selenium package is not installed (pip install 'skelagnostic[test]')"
    if _first(_BROWSERS, "chromium") is None:
        return "Chromium is not installed (Debian: apt-get install chromium chromium-driver)"
    if _first(_DRIVERS, "chromedriver") is None:
        return "chromedriver is not installed (Debian: apt-get install chromium-driver)"
    return None


class ViewerBrowser:
    """A headless Chromium showing one viewer page; a context manager.

    Args:
        size: Window ``(width, height)`` in CSS pixels (device scale factor 1).

    Raises:
        RenderError: If selenium, Chromium or chromedriver is missing.

    Examples:
        >>> with ViewerBrowser() as browser:  # doctest: +SKIP
        ...     browser.open("view.html")
        ...     browser.step_to(42)
        ...     image = browser.screenshot()
    """

    def __init__(self, size: tuple[int, int] = (960, 600)) -> None:
        missing = browser_available()
        if missing is not None:
            raise RenderError(f"cannot drive the viewer: {missing}")
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service

        self._profile = tempfile.mkdtemp(prefix="skelagnostic-chromium-")
        options = webdriver.ChromeOptions()
        options.binary_location = str(_first(_BROWSERS, "chromium"))
        for flag in (
            *_FLAGS,
            f"--window-size={size[0]},{size[1]}",
            f"--user-data-dir={self._profile}",
        ):
            options.add_argument(flag)
        options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
        service = Service(executable_path=str(_first(_DRIVERS, "chromedriver")))
        self.driver: Any = webdriver.Chrome(service=service, options=options)

    def __enter__(self) -> ViewerBrowser:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        self.close()

    def close(self) -> None:
        """Quit Chromium and remove its temporary profile."""
        try:
            self.driver.quit()
        finally:
            shutil.rmtree(self._profile, ignore_errors=True)

    def open(self, page: str | Path, timeout: float = 30.0) -> None:
        """Load a viewer page and wait until it has drawn.

        Args:
            page: Path of the ``.html`` file.
            timeout: Seconds to wait for the first drawn frame.

        Raises:
            RenderError: If the page has not drawn within ``timeout``.
        """
        self.driver.get(Path(page).resolve().as_uri())
        self._wait(
            lambda: self.driver.execute_script(
                "return !!(window.skelagnostic && window.skelagnostic.drawnFrame() >= 0)"
            ),
            timeout,
            "the viewer did not draw a frame",
        )

    def _wait(self, ready: Any, timeout: float, what: str) -> None:
        end = time.monotonic() + timeout
        while not ready():
            if time.monotonic() > end:
                raise RenderError(f"{what} within {timeout:g} s")
            time.sleep(0.05)

    def console_errors(self) -> list[str]:
        """Errors logged to the console (level SEVERE) and uncaught page errors so far."""
        logs = [e["message"] for e in self.driver.get_log("browser") if e["level"] == "SEVERE"]
        return logs + list(self.driver.execute_script("return window.skelagnostic.errors"))

    def step_to(self, frame: int, timeout: float = 10.0) -> None:
        """Go to ``frame`` through the page's controls and wait until it is drawn.

        The scrubber is moved to the frame before it (as a user drags it) and
        the "next frame" button is clicked once.

        Args:
            frame: Frame of the page's clock (``0 .. numFrames - 1``), at least 1.
            timeout: Seconds to wait for the frame to be drawn.
        """
        from selenium.webdriver.common.by import By

        scrub = self.driver.find_element(By.ID, "scrub")
        self.driver.execute_script(
            "arguments[0].value = arguments[1];"
            "arguments[0].dispatchEvent(new Event('input', {bubbles: true}));",
            scrub,
            str(frame - 1),
        )
        self.driver.find_element(By.ID, "next").click()
        self._wait(
            lambda: self.driver.execute_script("return window.skelagnostic.drawnFrame()") == frame,
            timeout,
            f"frame {frame} was not drawn",
        )
        # the frame counter is set before the draw returns: wait one more animation frame
        self.driver.execute_async_script(
            "const done = arguments[0]; requestAnimationFrame(() => requestAnimationFrame(done));"
        )

    def call(self, name: str, *args: Any) -> Any:
        """Call ``window.skelagnostic[name](*args)`` in the page and return its result."""
        return self.driver.execute_script(
            f"return window.skelagnostic.{name}(...arguments);", *args
        )

    def screenshot(self) -> np.ndarray:
        """The window as an ``[H, W, 3]`` uint8 RGB image (CSS pixels)."""
        from PIL import Image

        png = self.driver.get_screenshot_as_png()
        return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))
