"""See the explorer of chapter 08 as a person does: JupyterLab in headless Chromium (not part of CI).

Serves JupyterLab on this machine, opens notebooks/08_your_own_voice.ipynb in Chromium, runs all
its cells, waits for the explorer's viewer, and saves a screenshot; then moves the temperature
slider and the seed, waits for the new motion, and saves another. Needs Debian's chromium and the
Python package playwright (``apt-get install chromium``, ``.venv/bin/pip install playwright``; no
browser download: it drives /usr/bin/chromium). Run from the repository root:

    .venv/bin/python tools/screenshot_explorer.py            # writes outputs/explorer/*.png
"""

from __future__ import annotations

import os
import re
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

from playwright.sync_api import sync_playwright

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "outputs" / "explorer"
TOKEN = "explorer-screenshots"
CHROMIUM_FLAGS = [  # a machine without a network: no background connections
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def main() -> int:
    OUT.mkdir(parents=True, exist_ok=True)
    port = free_port()
    log = open(OUT / "jupyterlab.log", "w")  # noqa: SIM115 (closed after the server, below)
    lab = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "jupyter",
            "lab",
            "--no-browser",
            f"--port={port}",
            f"--ServerApp.token={TOKEN}",
            f"--ServerApp.root_dir={REPO}",
            "--allow-root",  # a container's user is often root
        ],
        env={**os.environ, "GESTURELIB_QUICK": "1"},
        stdout=log,
        stderr=subprocess.STDOUT,
    )
    try:
        with sync_playwright() as playwright:
            browser = playwright.chromium.launch(
                executable_path="/usr/bin/chromium", args=CHROMIUM_FLAGS
            )
            page = browser.new_page(viewport={"width": 1400, "height": 1000})
            url = (
                f"http://127.0.0.1:{port}/lab/tree/notebooks/08_your_own_voice.ipynb?token={TOKEN}"
            )
            for _ in range(120):  # the server takes a few seconds to start
                try:
                    urllib.request.urlopen(f"http://127.0.0.1:{port}/api?token={TOKEN}")
                    break
                except OSError:
                    time.sleep(1)
            page.goto(url)
            page.wait_for_selector(".jp-Notebook", timeout=120_000)
            page.wait_for_timeout(5000)
            page.screenshot(path=OUT / "opened.png")
            page.keyboard.press("Escape")
            # The menu bar's "Run", not a "Run" in the chapter's text.
            menu = page.locator(".lm-MenuBar-itemLabel", has_text=re.compile(r"^Run$"))
            menu.first.click(timeout=30_000)
            run_all = page.locator(".lm-Menu-itemLabel", has_text=re.compile(r"^Run All Cells$"))
            run_all.first.click(timeout=30_000)
            try:
                viewer = page.wait_for_selector(".gesturelib-viewer canvas", timeout=300_000)
            except Exception:
                page.screenshot(path=OUT / "failed.png")
                raise
            page.wait_for_selector("text=notebook run time", timeout=300_000)  # all cells done
            news = page.get_by_role("button", name="No", exact=True)  # JupyterLab asks about news
            for button in news.all():
                button.click()
            viewer.scroll_into_view_if_needed()
            explorer = (
                page.locator(".jp-OutputArea-output")
                .filter(has=page.locator(".gesturelib-viewer"))
                .first
            )
            show_at_4_s = "document.querySelector('.gesturelib-viewer audio').currentTime = 4"
            page.evaluate(show_at_4_s)  # a pose in mid-gesture rather than the first frame
            page.wait_for_timeout(2000)
            explorer.screenshot(path=OUT / "before.png")

            slider = (
                explorer.locator(".widget-slider")
                .filter(has_text="temperature")
                .locator(".noUi-handle")
                .first
            )
            slider.click()
            for _ in range(6):
                page.keyboard.press("ArrowLeft")  # temperature 1.0 -> 0.7
            seed = explorer.locator(".widget-text").filter(has_text="seed").locator("input")
            seed.fill("7")
            seed.press("Enter")
            page.wait_for_timeout(5000)
            page.evaluate(show_at_4_s)
            page.wait_for_timeout(2000)
            explorer.screenshot(path=OUT / "after.png")
            print(explorer.locator(".widget-html").first.inner_text())
            browser.close()
    finally:
        lab.terminate()
        lab.wait(timeout=30)
        log.close()
    print(f"screenshots in {OUT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
