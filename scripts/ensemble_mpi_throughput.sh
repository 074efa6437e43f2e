#!/usr/bin/env bash
# Members per second of examples/ensemble_mpi.rs for ranks x threads = 1x1,
# 1x2, 2x1 (and 2x1 writing a store), in rounds so that a change in the
# machine's load hits all configurations alike. BENCHMARKS.md, section 6.
set -euo pipefail
cd "$(dirname "$0")/.."
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
cargo build --release --features mpi --example ensemble_mpi >/dev/null 2>&1
exe=target/release/examples/ensemble_mpi
args=(--members "${MEMBERS:-4000}" --steps "${STEPS:-1000}")
store=$(mktemp -d)
echo "load before: $(uptime)"
for round in 1 2 3; do
  for cfg in "1 1" "1 2" "2 1" "2 1 store"; do
    set -- $cfg
    extra=()
    if [ "${3:-}" = store ]; then rm -rf "$store/s"; extra=(--store "$store/s"); fi
    # CPU time (user + sys of mpirun and its ranks, MPI start-up included)
    # alongside the wall-clock rate: under a shared machine's load the
    # former still gives the per-member cost.
    TIMEFORMAT='%U %S %R'
    # Open MPI binds each rank to one core when there are at most two ranks:
    # a rank's rayon threads would then share that core. `--bind-to none`
    # lets them spread (a hybrid job on a cluster maps ranks with
    # `--map-by ppr:1:node:pe=N` instead).
    { time mpirun -n "$1" --oversubscribe --bind-to none "$exe" "${args[@]}" --threads "$2" "${extra[@]}" \
        | tail -1 > "$store/line"; } 2> "$store/time"
    read -r user sys wall < "$store/time"
    echo "round=$round ${3:-memory} $(cat "$store/line") cpu_s=$(awk "BEGIN{print $user + $sys}") wall_s=$wall"
  done
done
echo "load after: $(uptime)"
rm -rf "$store"
