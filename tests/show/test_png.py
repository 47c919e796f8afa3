"""`regrasp show --png` and `regrasp grasps show --png`: real pictures of the requested
size, not blank, different from one key frame to another."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from cli_helpers import SCENE_YAML, run

from .conftest import PNG_SIZE

NAMES = ("01_start.png", "02_pick.png", "03_exchange.png", "04_place.png", "05_end.png")


def pixels(path: Path) -> np.ndarray:
    with Image.open(path) as im:
        im.verify()
    with Image.open(path) as im:
        return np.asarray(im.convert("RGB"), dtype=float)


def assert_drawn(img: np.ndarray) -> None:
    """Not blank: many pixels away from the background (the most common colour)."""
    flat = img.reshape(-1, 3)
    colours, counts = np.unique(flat, axis=0, return_counts=True)
    background = colours[np.argmax(counts)]
    away = np.abs(flat - background).max(axis=1) > 30
    assert away.mean() > 0.05, f"only {away.mean():.1%} of the pixels are drawn"
    assert flat.std(axis=0).max() > 20


@pytest.fixture(scope="module")
def frames(shown):
    result, _, frames = shown
    assert result.exit_code == 0, (result.output, result.exception)
    return frames


def test_the_key_frames_are_pictures_of_the_requested_size(shown, frames):
    result = shown[0]
    assert sorted(p.name for p in frames.iterdir()) == list(NAMES)
    for name in NAMES:
        assert f"png: {frames / name}" in result.stdout
        img = pixels(frames / name)
        assert img.shape == (PNG_SIZE[1], PNG_SIZE[0], 3), name
        assert_drawn(img)


def test_the_key_frames_differ(frames):
    """The arms move between the frames: start and exchange differ, and so do pick and place."""
    for a, b in ((NAMES[0], NAMES[2]), (NAMES[1], NAMES[3])):
        diff = np.abs(pixels(frames / a) - pixels(frames / b)).max(axis=2)
        assert (diff > 30).mean() > 0.01, (a, b)


def test_grasps_show_draws_the_best_grasps(cache_dir, view, tmp_path):
    """Four grasps of the right hand's list the plan used, on a 4-wide grid of 320-pixel cells."""
    from regrasp_cli.store import sha256_file

    used = view.plan.stats["artefacts"]["grasps_right"]
    file = next(p for p in (cache_dir / "grasps").glob("*-right-*.h5") if sha256_file(p) == used)
    out = tmp_path / "grasps.png"
    result = run("--cache-dir", cache_dir, "grasps", "show", file, "--scene", SCENE_YAML, "--best", 4,
                 "--png", out)
    assert result.exit_code == 0, (result.output, result.exception)
    assert f"png: {out}" in result.stdout
    img = pixels(out)
    assert img.shape[1] == 4 * 320 and img.shape[0] > 320
    assert_drawn(img)
    # the contacts and normals are drawn in their own magenta
    magenta = (img[..., 0] > 150) & (img[..., 1] < 90) & (img[..., 2] > 90)
    assert magenta.sum() > 20
