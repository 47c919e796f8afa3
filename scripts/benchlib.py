"""Shared by the benchmark scripts: the machine line and fresh caches that keep only the
robot's self-collision matrix (a robot artefact every stage reuses)."""

from __future__ import annotations

import os
import platform
import shutil
from pathlib import Path


def machine(**settings) -> str:
    """One line describing the CPU, cores, Python and the benchmark's settings."""
    cpu = next((l.split(":", 1)[1].strip() for l in open("/proc/cpuinfo") if l.startswith("model name")), "?")
    extra = ", ".join(f"{k}={v}" for k, v in settings.items())
    return f"machine: {cpu}, {os.cpu_count()} cores, Python {platform.python_version()}; {extra}"


def fresh_cache(robot_cache: Path, cache: Path) -> Path:
    """``cache`` holding only the self-collision matrix computed in ``robot_cache``."""
    shutil.copytree(Path(robot_cache) / "self_collision", Path(cache) / "self_collision")
    return Path(cache)
