"""evo's APE and RPE on two TUM files: the reference for ``tests/test_trajectory_errors.py``. Runs in
a *separate* environment (evo is GPL-3.0 and must never be a quadest dependency); imports only
numpy and evo, never quadest.

Usage (the test does this when ``QUADEST_EVO_PYTHON`` names that environment's Python)::

    python evo_trajectory_errors.py REFERENCE.txt ESTIMATE.txt D1 [D2 ...]

APE: the estimate aligned to the reference by ``PoseTrajectory3D.align`` (Umeyama, no scale),
then ``metrics.APE`` of the translation part (m) and of the rotation angle (rad), their RMSE.
RPE: ``metrics.RPE`` for each sub-trajectory length ``D`` in metres, all pairs, chosen along the
reference, relative tolerance 0.1: each pair's end index, translation error (m) and rotation
angle (rad). Prints one JSON line, with evo's version.
"""

from __future__ import annotations

import json
import sys
from importlib.metadata import version

from evo.core import metrics, sync
from evo.core.metrics import PoseRelation, StatisticsType, Unit
from evo.tools import file_interface


def main() -> None:
    reference = file_interface.read_tum_trajectory_file(sys.argv[1])
    estimate = file_interface.read_tum_trajectory_file(sys.argv[2])
    reference, estimate = sync.associate_trajectories(reference, estimate)
    out: dict = {"evo": version("evo"), "rpe": []}
    for d in map(float, sys.argv[3:]):
        found = {}
        for relation, key in (
            (PoseRelation.translation_part, "translation"),
            (PoseRelation.rotation_angle_rad, "rotation"),
        ):
            rpe = metrics.RPE(relation, delta=d, delta_unit=Unit.meters, rel_delta_tol=0.1, all_pairs=True,
                              pairs_from_reference=True)  # fmt: skip
            rpe.process_data((reference, estimate))
            found[key] = rpe.error.tolist()
            found["delta_ids"] = list(map(int, rpe.delta_ids))
        out["rpe"].append({"distance": d, **found})
    estimate.align(reference, correct_scale=False)
    for relation, key in (
        (PoseRelation.translation_part, "ape_translation_rmse"),
        (PoseRelation.rotation_angle_rad, "ape_rotation_rmse"),
    ):
        ape = metrics.APE(relation)
        ape.process_data((reference, estimate))
        out[key] = ape.get_statistic(StatisticsType.rmse)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
