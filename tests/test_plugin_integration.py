"""docs/plugins.md's worked example of a new integration (``tests/plugins/my_iekf.py``, shown
verbatim there): it meets the estimator contract, is the Kalman filter on a linear model, and is
quadest's own ``iekf`` on the pendulum, number for number."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from quadest.conformance import check_estimator
from quadest.estimators.iterated import IEKF
from quadest.models.book_pendulum import BookPendulumModel

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "plugins"))

from my_iekf import MyIEKF  # noqa: E402


def test_the_docs_show_the_tested_file():
    assert (ROOT / "tests" / "plugins" / "my_iekf.py").read_text().strip() in (ROOT / "docs" / "plugins.md").read_text()


def test_the_example_passes_the_conformance_kit():
    check_estimator(MyIEKF, {"iterations": 3})


def test_the_example_is_quadests_iekf():
    model = BookPendulumModel(0.01, 9.81, 0.01, 0.1, 2)
    rng = np.random.default_rng(7)
    z = np.sin(1.5 - 0.01 * np.arange(40))[None, :, None] + 0.3 * rng.standard_normal((2, 40, 1))
    u = np.zeros((2, 0))
    means = []
    for est in (MyIEKF(model, iterations=4), IEKF(model, iterations=4)):
        est.initialize(np.zeros((2, 2)), np.broadcast_to(np.eye(2), (2, 2, 2)).copy())
        run = []
        for k in range(40):
            est.predict(u)
            est.update(z[:, k], u)
            run.append(est.mean.copy())
        means.append(np.array(run))
    assert np.array_equal(means[0], means[1])
