"""Real sweeps through hydra-submitit-launcher end with an aggregate that holds every cell:
``hydra/launcher=submitit_local`` (local processes), and ``hydra/launcher=slurm`` against stand-ins
for ``sbatch``/``srun``/``sacct`` that run the submitted batch script's array tasks on this machine,
so that the script submitit writes from conf/hydra/launcher/slurm.yaml is checked and executed."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

pytest.importorskip("hydra_plugins.hydra_submitit_launcher", reason="needs the `cluster` extra (in `test`)")

TWO_CELLS = """
defaults:
  - config
  - override /estimator: [srukf]
  - _self_
runs: 2
duration: 0.3
workers: 1
progress: false
output: {saved_runs: 0, figures: false}
sweep: {alpha: 0.5}
estimator:
  srukf: {alpha: "${sweep.alpha}"}
hydra:
  mode: MULTIRUN
  sweep: {subdir: "${hydra.job.num}"}
  sweeper:
    params:
      sweep.alpha: 0.5,1.0
  callbacks:
    aggregate: {_target_: quadest.app.callbacks.AggregateCallback}
"""


def sweep_two_cells(
    tmp_path: Path, launcher_overrides: list[str], env: dict[str, str] | None = None, text: str = TWO_CELLS
) -> tuple[subprocess.CompletedProcess, Path]:
    (tmp_path / "two_cells.yaml").write_text(text)
    out = tmp_path / "sweep"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "quadest.app.cli",
            "-cd",
            str(tmp_path),
            "-cn",
            "two_cells",
            *launcher_overrides,
            f"hydra.sweep.dir={out}",
        ],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=180,
        env=env,
    )
    return proc, out


def run_two_cells(tmp_path: Path, launcher_overrides: list[str], env: dict[str, str] | None = None) -> Path:
    proc, out = sweep_two_cells(tmp_path, launcher_overrides, env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "Aggregated:" in proc.stdout
    # each cell ran as a submitit job: submitit's own folder holds one result pickle per job
    assert len(list((out / ".submitit").glob("*/*_result.pkl"))) == 2
    cells = pd.read_csv(out / "aggregate" / "cells.csv")
    assert sorted(cells["job"].unique()) == [0, 1]
    assert sorted(cells["sweep.alpha"].unique()) == [0.5, 1.0]
    assert (cells["estimator"] == "srukf").all()
    assert "ok: 2" in (out / "aggregate" / "report.md").read_text()
    return out


@pytest.mark.slow
def test_submitit_local_sweep_runs_both_cells_and_aggregates(tmp_path):
    run_two_cells(tmp_path, ["hydra/launcher=submitit_local", "hydra.launcher.timeout_min=5"])


# Stand-ins for SLURM's commands. sbatch records the script, answers with a job id and runs the
# array's tasks in a detached process once submitit has put each task's pickle in place (it does so
# after sbatch returns), with the environment SLURM gives an array task; srun runs its command with
# the output files it was given; sacct knows no job, so submitit waits for the result files.
FAKE_SBATCH = """#!{python}
import os, re, subprocess, sys, time
from pathlib import Path
script = Path(sys.argv[-1])
Path(os.environ["FAKE_SLURM_RECORD"]).write_text(script.read_text())
job = "4242"
if os.fork():
    print(f"Submitted batch job {{job}}")
    sys.exit(0)
os.setsid()
devnull = os.open(os.devnull, os.O_RDWR)
for fd in (0, 1, 2):  # let submitit's read of sbatch's output end now
    os.dup2(devnull, fd)
text = script.read_text()
tasks = int(re.search(r"--array=0-(\\d+)%", text).group(1)) + 1
folder = text.strip().split()[-1]
for i in range(tasks):
    pickle = Path(folder.replace("%j", f"{{job}}_{{i}}")) / f"{{job}}_{{i}}_submitted.pkl"
    deadline = time.time() + 60
    while not pickle.exists() and time.time() < deadline:
        time.sleep(0.1)
    env = dict(os.environ, SLURM_JOB_ID=str(4243 + i), SLURM_ARRAY_JOB_ID=job, SLURM_ARRAY_TASK_ID=str(i),
               SLURM_NTASKS="1", SLURM_JOB_NUM_NODES="1", SLURM_NODEID="0", SLURM_PROCID="0",
               SLURM_LOCALID="0", SLURM_JOB_NODELIST="localhost")
    subprocess.run(["bash", str(script)], env=env)
"""

FAKE_SRUN = """#!{python}
import os, subprocess, sys
args, files = sys.argv[1:], {{}}
while args[0].startswith("--"):
    flag = args.pop(0)
    if flag in ("--output", "--error"):
        path = args.pop(0)
        for key, value in (("%A", "SLURM_ARRAY_JOB_ID"), ("%a", "SLURM_ARRAY_TASK_ID"), ("%t", "SLURM_PROCID")):
            path = path.replace(key, os.environ[value])
        files[flag] = open(path, "a")
sys.exit(subprocess.run(args, stdout=files.get("--output"), stderr=files.get("--error")).returncode)
"""

FAKE_SACCT = """#!/bin/sh
echo "JobID|State|NodeList"
"""


def fake_slurm(tmp_path: Path) -> tuple[dict[str, str], Path]:
    """An environment whose ``sbatch``, ``srun`` and ``sacct`` are the stand-ins, and the file
    where the stand-in ``sbatch`` records the script it was given."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    for name, text in (("sbatch", FAKE_SBATCH), ("srun", FAKE_SRUN), ("sacct", FAKE_SACCT)):
        (bin_dir / name).write_text(text.format(python=sys.executable))
        (bin_dir / name).chmod(0o755)
    record = tmp_path / "sbatch_script.sh"
    env = dict(os.environ, PATH=f"{bin_dir}{os.pathsep}{os.environ['PATH']}", FAKE_SLURM_RECORD=str(record))
    return env, record


SLURM = ["hydra/launcher=slurm", "hydra.launcher.partition=debug", "hydra.launcher.array_parallelism=1"]


@pytest.mark.slow
def test_slurm_launcher_submits_an_array_with_the_documented_resources(tmp_path):
    env, record = fake_slurm(tmp_path)
    run_two_cells(tmp_path, SLURM, env=env)
    script = record.read_text().splitlines()
    for line in (
        "#SBATCH --array=0-1%1",  # one task per cell, at most array_parallelism at once
        "#SBATCH --cpus-per-task=1",
        "#SBATCH --mem=2GB",
        "#SBATCH --time=30",
        "#SBATCH --partition=debug",
        "export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1",
    ):
        assert line in script, line


@pytest.mark.slow
def test_a_slurm_sweep_with_a_failed_cell_exits_with_the_sweep_failed_status(tmp_path):
    """The cells run as array tasks in other processes (on a cluster, other nodes): the one whose
    value is refused inside the job still makes the submitting ``quadest`` exit 3 with one line,
    and the finished cell is kept. The cells' records are in the sweep folder, the one place a
    cluster's nodes share with the submitting process (not its ``/tmp``)."""
    env, _ = fake_slurm(tmp_path)
    failing = TWO_CELLS.replace("sweep.alpha: 0.5,1.0", "estimator.srukf.smoother: none,bogus")
    proc, out = sweep_two_cells(tmp_path, ["-m", *SLURM], env=env, text=failing)
    assert proc.returncode == 3, proc.stderr[-3000:]
    assert "quadest: 1 of 2 sweep cells failed" in proc.stderr
    assert (out / "0" / "metrics.csv").is_file()
    assert '"status": "failed"' in (out / "1" / "summary.json").read_text()
    assert (out / ".quadest-cells" / "1").read_text().startswith("failed ")
