"""The report opens in a real browser: headless Chromium renders it with its figures."""

from __future__ import annotations

import os
import shutil
import subprocess

import numpy as np
import pytest

from slamrel.pipeline import run_pipeline, write_report


def _chromium() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    message = "headless Chromium not found (Debian: apt-get install chromium); .ci/run installs it"
    if os.environ.get("CI", "").lower() == "true":
        pytest.fail(message)
    pytest.skip(message)


def test_report_renders_in_headless_chromium(tmp_path):
    browser = _chromium()
    html = write_report(run_pipeline("simple1", noise="a", seed=0), tmp_path / "report")
    shot = tmp_path / "shot.png"
    cmd = [
        browser, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync",
        f"--user-data-dir={tmp_path / 'profile'}", f"--screenshot={shot}",
        "--window-size=1200,3000",
        html.as_uri(),
    ]  # fmt: skip
    subprocess.run(cmd, capture_output=True, timeout=120, check=False)
    assert shot.exists(), "Chromium wrote no screenshot"
    import matplotlib.image as mpimg

    img = mpimg.imread(shot)[..., :3]
    assert img.shape[0] >= 2000
    # the page is not blank: figures (coloured, dark strokes) cover a good part of it
    ink = np.mean(np.any(img < 0.85, axis=-1))
    colour = np.mean(img.max(axis=-1) - img.min(axis=-1) > 0.2)
    assert ink > 0.05 and colour > 0.005, (ink, colour)
