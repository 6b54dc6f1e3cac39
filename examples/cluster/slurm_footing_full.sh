#!/bin/bash
# The full-size footing (runs/footing_full.toml), both models, as a SLURM batch job.
# Submit from the clone:   sbatch examples/cluster/slurm_footing_full.sh
# See docs/cluster.md. Checked with `bash -n` and, for the mpirun line, on one machine;
# not run on a real SLURM cluster.
#
# One rank per core, 1 Numba thread each. For one rank per socket with threads instead,
# set e.g. --ntasks-per-node=2 --cpus-per-task=16 (NUMBA_NUM_THREADS follows below).
#SBATCH --job-name=footing_full
#SBATCH --nodes=2
#SBATCH --ntasks-per-node=16
#SBATCH --cpus-per-task=1
#SBATCH --time=01:00:00
#SBATCH --requeue                    # allow `scontrol requeue` when the time limit comes
#SBATCH --signal=B:USR1@180          # USR1 to this script 3 min before the time limit
#SBATCH --open-mode=append           # a requeued job appends to the same log
#SBATCH --output=footing_full-%j.log

set -uo pipefail

COSIM_DIR=${COSIM_DIR:-$SLURM_SUBMIT_DIR}        # the clone, on a filesystem every node sees
CASE=${CASE:-runs/footing_full.toml}
OUT=${OUT:-$COSIM_DIR/runs/out/footing_full}       # must be on a shared filesystem too
LAUNCHER=${LAUNCHER:-mpirun}                       # or: srun (OpenMPI built with PMIx)
CHECKPOINT_S=${CHECKPOINT_S:-300}                  # wall-clock seconds between checkpoints

cd "$COSIM_DIR" || exit 1
source .venv/bin/activate
export NUMBA_NUM_THREADS=${SLURM_CPUS_PER_TASK:-1}
# If the clone is read-only on the nodes, keep the Numba kernels in a shared cache:
# export NUMBA_CACHE_DIR=$HOME/.cache/cosim-numba

# Near the time limit: put the job back in the queue. SLURM stops the run; its last
# checkpoint (at most CHECKPOINT_S old) is complete, and the requeued job resumes from it.
REQUEUED=0
requeue() {
    echo "time limit near: requeueing job $SLURM_JOB_ID"
    REQUEUED=1
    scontrol requeue "$SLURM_JOB_ID"
}
trap requeue USR1

launch() {
    if [ "$LAUNCHER" = srun ]; then
        srun --mpi=pmix --cpu-bind=none "$@"
    else
        # mpirun takes the ranks and hosts from the SLURM allocation
        mpirun --bind-to none -x NUMBA_NUM_THREADS -x PATH -x VIRTUAL_ENV "$@"
    fi
}

cosim check "$CASE" --out "$OUT" || exit 2        # bad input: stop before using the allocation

for MODEL in coupled dem; do
    if [ -e "$OUT/$MODEL/summary.json" ]; then
        echo "$MODEL: finished earlier"
        continue
    fi
    RESUME=""
    if [ -e "$OUT/$MODEL/footing_state.json" ]; then
        RESUME=--resume                            # a checkpoint of the loading phase exists
    fi
    echo "$MODEL: ${RESUME:-new run} on $SLURM_NTASKS ranks x $NUMBA_NUM_THREADS threads"
    launch cosim run "$CASE" --out "$OUT" --set footing.model="$MODEL" \
        --set output.checkpoint_interval="$CHECKPOINT_S" $RESUME &
    pid=$!
    wait $pid                                      # returns early when USR1 arrives
    status=$?
    if [ $REQUEUED = 1 ]; then
        wait $pid                                  # SLURM stops the run; the job comes back
        exit 0
    fi
    if [ $status -ne 0 ]; then
        echo "$MODEL: cosim exited with $status"
        exit $status
    fi
done
echo "both models done: $OUT/comparison.png"
