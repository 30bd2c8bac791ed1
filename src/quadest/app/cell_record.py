"""Which cells of a sweep failed, seen from the process that launched the sweep, whatever the launcher.

A sweep's cells run where its launcher puts them: in the main process (Hydra's basic launcher), in
worker processes (joblib), or in SLURM array tasks on other nodes (submitit). Each cell writes one
small file, ``ok DIR`` or ``failed DIR``, into ``SWEEP_DIR/.quadest-cells/`` (one file per cell,
named by its job number, so no two processes write the same file: safe on the shared file systems
of clusters, where appending to one file from several nodes is not). :class:`CellRecordCallback`
(configured in ``conf/config.yaml``, so every sweep has it) empties that folder when the sweep
starts and remembers it; after the sweep, :func:`failed_cells` reads it in the main process.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from hydra.core.hydra_config import HydraConfig
from hydra.experimental.callback import Callback
from omegaconf import DictConfig

FOLDER = ".quadest-cells"

_started: list[Path] = []
"""The record folders of the sweeps this process started (read by :func:`failed_cells`)."""


def record_cell(status: str, out_dir: Path) -> None:
    """In a sweep's cell: write ``status out_dir`` as this cell's record."""
    hc = HydraConfig.get()
    folder = Path(hc.sweep.dir) / FOLDER
    folder.mkdir(parents=True, exist_ok=True)
    (folder / str(hc.job.num)).write_text(f"{status} {out_dir}\n")


class CellRecordCallback(Callback):
    """Hydra callback: an empty record folder for each sweep this process starts."""

    def on_multirun_start(self, config: DictConfig, **kwargs) -> None:
        folder = Path(config.hydra.sweep.dir) / FOLDER
        shutil.rmtree(folder, ignore_errors=True)
        folder.mkdir(parents=True, exist_ok=True)
        _started.append(folder)


def failed_cells() -> tuple[list[str], int]:
    """The output folders of the failed cells of the sweeps this process ran, and how many cells
    wrote a record."""
    lines = [f.read_text().strip() for folder in _started if folder.is_dir() for f in sorted(folder.iterdir())]
    return [line.split(" ", 1)[1] for line in lines if line.startswith("failed ")], len(lines)
