#!/usr/bin/env bash
# N workers of one agvrl sweep as a Slurm job array; every array task is one worker, and all of
# them share the study in PostgreSQL (or a journal file on a shared file system).
#
#   sbatch --array=0-7 tools/cluster/slurm-sweep.sh configs/sweeps/ppo-racing.toml
#
# Needs, on every node: the agvrl wheel with its postgresql extra in the Python that runs this
# (pip install 'agvrl[postgresql]'), and AGVRL_SWEEP_STORAGE in the environment, e.g.
#   export AGVRL_SWEEP_STORAGE=postgresql://agvrl:PASSWORD@db-host:5432/agvrl
# (sbatch passes the submitting shell's environment on). Outside Slurm, set SLURM_ARRAY_TASK_ID
# by hand to run the same worker.
#SBATCH --job-name=agvrl-sweep
#SBATCH --cpus-per-task=2
#SBATCH --time=04:00:00
#SBATCH --output=agvrl-sweep-%A_%a.out
set -euo pipefail
spec="${1:?usage: slurm-sweep.sh SWEEP.toml}"
: "${SLURM_ARRAY_TASK_ID:?run under sbatch --array, or set SLURM_ARRAY_TASK_ID}"
: "${AGVRL_SWEEP_STORAGE:?set AGVRL_SWEEP_STORAGE to the database URL or journal:PATH of the study}"
# One training at a time per task, on the CPUs Slurm gave it.
exec "${PYTHON:-python3}" -m agvrl.sweep worker "$spec" \
  --storage "$AGVRL_SWEEP_STORAGE" \
  --threads "${SLURM_CPUS_PER_TASK:-1}"
