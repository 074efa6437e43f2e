#!/usr/bin/env bash
# Side by side, on this machine and in one go: LAMMPS `fix rattle` and
# `fix shake` against geoshake's particle RATTLE, on the same rigid-water
# boxes (the same data files), 1 core, free flight: LAMMPS at its tolerance
# 1e-10, geoshake at its default (1e-12, the bond error LAMMPS delivers at
# its 1e-10) and at 1e-10.
#
#   bench/lammps/compare.sh            # 10^3 and 10^4 waters, 1000 steps, median of 3
#   STEPS=200 REPS=1 SIZES=1000 bench/lammps/compare.sh   # a quick look
#
# Needs Debian's `lammps` and `python3-numpy`:
#   apt-get install -y lammps python3-numpy
# LAMMPS' cost is the `Modify` row of its `timer full` breakdown with the fix
# minus the same row without it (cstyle none), per constraint per step; the
# errors are measured from the states alone: LAMMPS' final state
# (dump_error.py), geoshake's after every step of an untimed run as long as
# the timed one (the example's max_rel_bond_error) and its final state's
# velocities (max_rel_velocity).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
steps=${STEPS:-1000}
reps=${REPS:-3}
sizes=${SIZES:-"1000 10000"}
tol=1.0e-10

if ! command -v lmp >/dev/null 2>&1; then
    echo "compare.sh: no 'lmp' on PATH. Install LAMMPS and NumPy: apt-get install -y lammps python3-numpy" >&2
    exit 2
fi
py=""
for c in python3 /usr/bin/python3; do
    if "$c" -c "import numpy" >/dev/null 2>&1; then py=$c; break; fi
done
if [ -z "$py" ]; then
    echo "compare.sh: no python3 with numpy. Install it: apt-get install -y python3-numpy" >&2
    exit 2
fi

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
(cd "$work" && "$py" "$here/gen_data.py" >/dev/null)
(cd "$root" && cargo build --release --example scale >/dev/null 2>&1)

median() { sort -g | awk '{a[NR]=$1} END {print (NR % 2) ? a[(NR+1)/2] : (a[NR/2] + a[NR/2+1]) / 2}'; }

# The Modify row of one LAMMPS run: its CPU time in seconds (wall time × the
# row's %CPU), so that a busy machine inflates neither code's figure; our
# example reports its thread's CPU time too.
modify_time() {
    local data=$1 style=$2 dump=${3:-0}
    (cd "$work" && OMP_NUM_THREADS=1 lmp -nocite -in "$here/in.water" -var data "$data" \
        -var cstyle "$style" -var tol $tol -var nsteps "$steps" -var dumpn "$dump" -log none) |
        awk '$1 == "Modify" {print $5 * $11 / 100}'
}

echo "machine: $(lscpu | sed -n 's/^Model name: *//p'), $(nproc) cores; load: $(uptime | sed 's/.*load average: //')"
echo "LAMMPS: $(lmp -h 2>/dev/null | sed -n 's/^Large-scale[^-]*- //p' | head -1)"
echo
echo "| waters | constraints | code | ns / constraint / step | max relative length error | max relative velocity residual |"
echo "|---|---|---|---|---|---|"
for n in $sizes; do
    data=water_$n.data
    m=$((3 * n))
    base=$(for _ in $(seq "$reps"); do modify_time "$data" none; done | median)
    for style in shake rattle; do
        t=$(for _ in $(seq "$reps"); do modify_time "$data" "$style"; done | median)
        modify_time "$data" "$style" "$steps" >/dev/null
        errs=$("$py" "$here/dump_error.py" "$work/traj_$style.dump")
        ns=$(awk -v t="$t" -v b="$base" -v m="$m" -v s="$steps" 'BEGIN {printf "%.1f", (t - b) / (m * s) * 1e9}')
        le=$(echo "$errs" | sed 's/.*length_error=\([^ ]*\).*/\1/')
        ve=$(echo "$errs" | sed 's/.*velocity=\([^ ]*\).*/\1/')
        echo "| $n | $m | LAMMPS fix $style | $ns | $le | $ve |"
    done
    # At the default tolerance (LAMMPS' accuracy), and at LAMMPS' number.
    for ourtol in default 1e-10; do
        tolarg=()
        [ "$ourtol" = default ] || tolarg=(--tol "$ourtol")
        ours=$("$root/target/release/examples/scale" --lammps-data "$work/$data" --steps "$steps" \
            --repeats "$reps" "${tolarg[@]}" | grep '^scale ')
        ns=$(echo "$ours" | sed 's/.*ns_per_constraint=\([^ ]*\).*/\1/')
        used=$(echo "$ours" | sed 's/.* tol=\([^ ]*\).*/\1/')
        le=$(echo "$ours" | sed 's/.*max_rel_bond_error=\([^ ]*\).*/\1/')
        ve=$(echo "$ours" | sed 's/.*max_rel_velocity=\([^ ]*\).*/\1/')
        label="tol $used"
        [ "$ourtol" = default ] && label="$label (default)"
        echo "| $n | $m | geoshake RATTLE, $label | $ns | $le | $ve |"
    done
done
