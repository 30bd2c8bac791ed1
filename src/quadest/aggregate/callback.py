"""The Hydra callback that aggregates a sweep when its multirun ends (``hydra.callbacks`` in an
experiment file: ``_target_: quadest.aggregate.callback.AggregateCallback``)."""

from __future__ import annotations

from pathlib import Path

from hydra.experimental.callback import Callback

from quadest.aggregate.report import aggregate


class AggregateCallback(Callback):
    """Hydra callback: aggregate the sweep folder when a multirun ends."""

    def on_multirun_end(self, config, **kwargs) -> None:
        report = aggregate(Path(config.hydra.sweep.dir))
        print(f"Aggregated: {report}")
