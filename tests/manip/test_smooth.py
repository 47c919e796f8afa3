"""`manip.queries.smooth`: shortcuts decided by the cheap probe, the result certified, and
certified smoothing again when the probe was fooled.  A 2-D joint space with a thin wall
that the probe's sparse samples step over."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from regrasp_cli.manip.context import OnlineOptions
from regrasp_cli.manip.queries import smooth
from regrasp_cli.model.collision import segment_samples

WEIGHTS = np.ones(2)


class _Wall:
    """Scratch of a 2-D world: x in (0.6, 0.62) is a wall for y < 1.5; the certified
    check samples every 0.001, the probe every ``probe`` (the same call signatures as
    :class:`~regrasp_cli.manip.context.Scratch`), counting both."""

    def __init__(self, probe: float):
        self.probe, self.calls = probe, {"certified": 0, "probe": 0}
        self.options = OnlineOptions()
        self.problem = SimpleNamespace(robot=SimpleNamespace(groups={"x": np.array([0]), "y": np.array([1])}))

    @staticmethod
    def free(q) -> bool:
        return not (0.6 < q[0] < 0.62 and q[1] < 1.5)

    def _check(self, a, b, step) -> bool:
        return all(self.free(a + t * (b - a)) for t in segment_samples(a, b, step))

    def segment_free(self, world, a, b) -> bool:
        self.calls["certified"] += 1
        return self._check(a, b, 0.001)

    def probe_free(self, world, a, b) -> bool:
        self.calls["probe"] += 1
        return self._check(a, b, self.probe)


PATH = np.array([[0.0, 0.0], [0.0, 1.0], [0.0, 2.0], [0.5, 2.0], [1.0, 2.0], [1.0, 1.0], [1.0, 0.0]])


def _certified(path) -> bool:
    return all(_Wall(1.0)._check(a, b, 0.001) for a, b in zip(path[:-1], path[1:]))


def test_a_fooled_probe_still_gives_a_certified_path():
    scratch = _Wall(probe=0.25)  # steps over the 2 cm wall
    assert scratch.probe_free(None, PATH[0], PATH[-1]) and not scratch.segment_free(None, PATH[0], PATH[-1])
    out = smooth(scratch, np.random.default_rng(0), PATH, None, WEIGHTS)
    assert _certified(out)
    assert scratch.calls["certified"] > len(out)  # the probe's result was refused, then smoothed again
    assert np.array_equal(out[0], PATH[0]) and np.array_equal(out[-1], PATH[-1])
    assert len(out) < len(PATH)


def test_a_good_probe_certifies_only_the_result():
    scratch = _Wall(probe=0.005)  # never steps over the wall
    out = smooth(scratch, np.random.default_rng(0), PATH, None, WEIGHTS)
    assert _certified(out)
    assert scratch.calls["certified"] == len(out) - 1  # the result's segments, nothing else
    assert scratch.calls["probe"] > 3 * scratch.calls["certified"]
