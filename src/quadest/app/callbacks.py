"""The Hydra callbacks that finish an experiment when its run or multirun ends (``hydra.callbacks``
in an experiment file), so that one command makes every file the docs and the ledger read:

- :class:`AggregateCallback`: aggregate a sweep (:func:`quadest.aggregate.report.aggregate`), in
  full or compact (``output: compact`` under the callback, for large grids);
- :class:`RankingCallback`: seed 004's ranking of a job or a sweep (:mod:`quadest.aggregate.ranking`);
- :class:`ParticleCountCallback`: seed 001's particle-count figure and efficiency of a job, and the
  process-noise trend of a sweep over ``model.Q`` (:mod:`quadest.aggregate.particle_count`);
- :class:`ClosedLoopReport`: the loop modes of a closed-loop sweep side by side
  (:func:`quadest.closed_loop.report.control_report`);
- :class:`Seed003Report`: seed 003's paired table (:func:`quadest.closed_loop.seed003_report.seed003_report`).

They are the application layer's: each reads the output folder from Hydra's config and hands the
folder, a plain path, to the function that does the work. Each does what its command line does
(``python -m quadest.aggregate.ranking DIR``, ...), which stays for folders made elsewhere.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from hydra.experimental.callback import Callback
from omegaconf import DictConfig

from quadest.aggregate import particle_count, ranking
from quadest.aggregate.report import aggregate, check_output
from quadest.closed_loop.report import control_report
from quadest.closed_loop.seed003_report import seed003_report
from quadest.errors import ConfigError


def _finished_job(config: DictConfig) -> Path | None:
    """The run's output folder if its job wrote ``metrics.csv``; ``None`` after a one-line note."""
    job = Path(config.hydra.runtime.output_dir)
    if (job / "metrics.csv").is_file():
        return job
    print(f"{job}: no metrics.csv (the job failed); nothing to tabulate")
    return None


def _sweep_dir(config: DictConfig) -> Path:
    return Path(config.hydra.sweep.dir)


class AggregateCallback(Callback):
    """Hydra callback: aggregate the sweep folder when a multirun ends, with the wall time from the
    start of the multirun to the end of its last job.

    ``output`` (``hydra.callbacks.aggregate.output``): ``full`` (every table and figure) or
    ``compact`` (:mod:`quadest.aggregate.compact`). Hydra builds its callbacks before the sweep
    starts, so any other value ends the command there with one line and exit code 2.
    """

    def __init__(self, output: str = "full") -> None:
        try:
            self.output = check_output(output)
        except ConfigError as exc:
            print(f"quadest: error: {exc}", file=sys.stderr)
            sys.exit(2)
        self._start: float | None = None

    def on_multirun_start(self, config: DictConfig, **kwargs) -> None:
        self._start = time.perf_counter()

    def on_multirun_end(self, config: DictConfig, **kwargs) -> None:
        wall_time = None if self._start is None else time.perf_counter() - self._start
        report = aggregate(_sweep_dir(config), output=self.output, wall_time=wall_time)
        print(f"Aggregated: {report}")


class RankingCallback(Callback):
    """Hydra callback: ``ranking.md``, ``paired_grouped.csv`` and ``step_time.csv`` of the job when a
    run ends, or of the sweep (into ``aggregate/``) when a multirun ends."""

    def on_run_end(self, config: DictConfig, **kwargs) -> None:
        job = _finished_job(config)
        if job is not None:
            ranking.main([str(job)])

    def on_multirun_end(self, config: DictConfig, **kwargs) -> None:
        ranking.main([str(_sweep_dir(config))])


class ParticleCountCallback(Callback):
    """Hydra callback: the job's ``rmse_vs_particles.csv``, figure and ``efficiency.csv`` when a
    run ends; a multirun over two or more values of ``model.Q`` gets the sweep's trend tables."""

    def on_run_end(self, config: DictConfig, **kwargs) -> None:
        job = _finished_job(config)
        if job is not None:
            particle_count.main([str(job)])

    def on_multirun_end(self, config: DictConfig, **kwargs) -> None:
        sweep = _sweep_dir(config)
        if len({q for q, *_ in particle_count.read_sweep(sweep)}) >= 2:
            particle_count.sweep_main(sweep)
        else:
            print(f"{sweep}: not a sweep over model.Q; no trend tables")


class ClosedLoopReport(Callback):
    """Hydra callback: tabulate the loop modes of the sweep when the multirun ends
    (``<sweep>/closed_loop/``, docs/closed-loop.md)."""

    def on_multirun_end(self, config: DictConfig, **kwargs) -> None:
        print(f"Closed-loop report: {control_report(_sweep_dir(config))}")


class Seed003Report(Callback):
    """Hydra callback: seed 003's paired table when the multirun ends."""

    def on_multirun_end(self, config: DictConfig, **kwargs) -> None:
        print(f"Seed 003 report: {seed003_report(_sweep_dir(config))}")
