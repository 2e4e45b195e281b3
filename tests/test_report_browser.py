"""The report opens in a real browser: a headless Chromium screenshot.

Skips where no Chromium is installed (on Debian: apt-get install chromium).
"""
import shutil
import subprocess

import numpy as np
import pytest

BROWSERS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")


def find_browser():
    for name in BROWSERS:
        path = shutil.which(name)
        if path:
            return path
    return None


@pytest.mark.skipif(find_browser() is None, reason="no Chromium/Chrome on PATH (apt-get install chromium)")
def test_report_renders_in_headless_chromium(tmp_path):
    from matplotlib.image import imread

    from analyses.experiment import Experiment
    from analyses.report import build_report, write_report

    report = build_report(Experiment("tetra", 24, n_processes=(1, 2, 8), cache_dir=tmp_path / "cache", progress=False))
    folder = write_report(report, tmp_path / "report")
    shot = tmp_path / "shot.png"
    completed = subprocess.run(
        [find_browser(), "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
         f"--screenshot={shot}", "--window-size=1200,1600", (folder / "index.html").as_uri()],
        capture_output=True, text=True, timeout=120)
    assert shot.is_file(), completed.stderr[-2000:]
    pixels = imread(shot)
    assert pixels.shape[0] >= 1000 and pixels.shape[1] >= 1000
    # A page with text, tables and figures, not a blank or error page.
    grey = pixels[..., :3].mean(axis=2)
    assert grey.std() > 0.05
    assert (grey < 0.5).mean() > 0.005  # some dark ink (text)
    assert np.unique((pixels[..., :3] * 255).astype(np.uint8).reshape(-1, 3), axis=0).shape[0] > 50  # images
