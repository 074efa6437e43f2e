#!/usr/bin/env bash
# Side by side, on this machine and in one go: LAMMPS `fix rattle` and
# `fix shake`, and GROMACS' SETTLE when it is installed, against geoshake's
# particle RATTLE, on the same rigid-water boxes (the same waters and
# velocities: gen_data.py writes them as a LAMMPS data file and as a GROMACS
# .gro/.top), 1 core, free flight: LAMMPS at its tolerance 1e-10, geoshake at
# its default (1e-12, the bond error LAMMPS delivers at its 1e-10) and at
# 1e-10, GROMACS' SETTLE in closed form (no tolerance).
#
#   bench/lammps/compare.sh            # 10^3 and 10^4 waters, 1000 steps, median of 3
#   STEPS=200 REPS=1 SIZES=1000 bench/lammps/compare.sh   # a quick look
#
# Needs Debian's `lammps` and `python3-numpy` (and, for the GROMACS rows,
# `gromacs`):
#   apt-get install -y lammps python3-numpy gromacs
# LAMMPS' cost is the `Modify` row of its `timer full` breakdown with the fix
# minus the same row without it (cstyle none), per constraint per step; the
# errors are measured from the states alone: LAMMPS' final state
# (dump_error.py), geoshake's after every step of an untimed run as long as
# the timed one (the example's max_rel_bond_error) and its final state's
# velocities (max_rel_velocity).
#
# GROMACS runs when `gmx_d` (double precision: the rows to compare) is on
# PATH, and `gmx` (mixed precision, for reference) too when present:
# water.mdp, leap-frog (`integrator = md`), h = 2 fs, SETTLE through
# `[ settles ]`, zero charges and c6 = c12 = 0 with the Verlet scheme, no
# centre-of-mass removal, no thermostat, one thread (-ntmpi 1 -ntomp 1,
# unpinned like the others). Its cost mirrors LAMMPS': the "Update" plus
# "Constraints" rows of md.log's cycle accounting with SETTLE minus the same
# rows without it (-DFREE drops the settles), so whatever the update does
# differently with constraints counts, and pair search and the (empty) pair
# kernel, in rows of their own, do not. md.log
# gives each row's cycles (and its wall time to the millisecond only); a
# row's CPU time is its share of the run's cycles times the run's CPU time
# (Core t, the thread's CPU clock), as LAMMPS' rows are wall time × %CPU;
# per call of the rows (nsteps + 1: mdrun also updates at its last step).
# The code column gives the Constraints row alone too. The errors come from
# the last frame of an extra run, read from the .trr in the binary's
# precision (trr_error.py); leap-frog's velocities are half-step
# differences, not projected onto the constraints. Debian builds GROMACS
# for SSE4.1 SIMD, so a build for the machine's own SIMD could be faster.
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

# GROMACS binaries to run: double precision first (the comparison), then
# mixed precision for reference.
gmxs=()
for g in gmx_d gmx; do
    if command -v "$g" >/dev/null 2>&1; then gmxs+=("$g"); fi
done

# A run input for one GROMACS binary, box and kind: "settle" (timed),
# "free" (timed, no constraints) or "dump" (SETTLE, last frame with x and v
# in the .trr). grompp warns once, on purpose, about comm-mode = None.
gmx_prepare() {
    local bin=$1 n=$2 kind=$3 d="$work/$1-$2-$3" define="" out=0
    [ "$kind" = free ] && define=-DFREE
    [ "$kind" = dump ] && out=$steps
    mkdir -p "$d"
    sed -e "s/^define .*/define = $define/" -e "s/^nsteps .*/nsteps = $steps/" \
        -e "s/^nstxout .*/nstxout = $out/" -e "s/^nstvout .*/nstvout = $out/" \
        "$here/water.mdp" >"$d/run.mdp"
    (cd "$d" && "$bin" grompp -maxwarn 1 -f run.mdp -c "$work/water_$n.gro" -p "$work/water_$n.top" \
        -o run.tpr >grompp.out 2>&1) || { cat "$d/grompp.out" >&2; exit 1; }
}

# One mdrun: "U+C C calls" from its md.log, the Update + Constraints rows and
# the Constraints row alone in CPU seconds (their Giga-Cycles over the Total
# row's, times Core t), and the rows' call count. The flop table above the
# cycle table has rows named Total too. GMX_MAXBACKUP=-1: overwrite, keep no
# #backups#.
gmx_time() {
    local bin=$1 n=$2 kind=$3 d="$work/$1-$2-$3"
    (cd "$d" && GMX_MAXBACKUP=-1 OMP_NUM_THREADS=1 "$bin" mdrun -ntmpi 1 -ntomp 1 -pin off -nb cpu \
        -s run.tpr -deffnm run -noconfout >mdrun.out 2>&1) || { cat "$d/mdrun.out" >&2; exit 1; }
    awk '/R E A L   C Y C L E/ {on = 1}
         on && $1 == "Update" {u = $6; k = $4}
         on && $1 == "Constraints" {c = $6}
         on && $1 == "Total" && !g {g = $3}
         $1 == "Time:" {cpu = $2}
         END {printf "%.9g %.9g %d\n", (u + c) / g * cpu, c / g * cpu, k}' "$d/run.log"
}

echo "machine: $(lscpu | sed -n 's/^Model name: *//p'), $(nproc) cores; load: $(uptime | sed 's/.*load average: //')"
echo "LAMMPS: $(lmp -h 2>/dev/null | sed -n 's/^Large-scale[^-]*- //p' | head -1)"
if [ ${#gmxs[@]} -eq 0 ] || [ "${gmxs[0]}" != gmx_d ]; then
    echo "GROMACS: skipped, no gmx_d (double precision) on PATH; Debian's gromacs package has it: apt-get install -y gromacs"
    gmxs=()
else
    for g in "${gmxs[@]}"; do
        echo "GROMACS: $g $("$g" --version 2>/dev/null | sed -n 's/^GROMACS version: *//p'), $("$g" --version 2>/dev/null | sed -n 's/^Precision: *//p') precision, SIMD $("$g" --version 2>/dev/null | sed -n 's/^SIMD instructions: *//p')"
    done
fi
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
    for g in "${gmxs[@]}"; do
        for kind in settle free dump; do gmx_prepare "$g" "$n" "$kind"; done
        with=$(for _ in $(seq "$reps"); do gmx_time "$g" "$n" settle; done)
        free=$(for _ in $(seq "$reps"); do gmx_time "$g" "$n" free; done)
        gmx_time "$g" "$n" dump >/dev/null
        errs=$("$py" "$here/trr_error.py" "$work/$g-$n-dump/run.trr")
        uc=$(echo "$with" | awk '{print $1}' | median)
        c=$(echo "$with" | awk '{print $2}' | median)
        calls=$(echo "$with" | awk 'NR == 1 {print $3}')
        base=$(echo "$free" | awk '{print $1}' | median)
        ns=$(awk -v t="$uc" -v b="$base" -v m="$m" -v s="$calls" 'BEGIN {printf "%.1f", (t - b) / (m * s) * 1e9}')
        nsc=$(awk -v t="$c" -v m="$m" -v s="$calls" 'BEGIN {printf "%.1f", t / (m * s) * 1e9}')
        le=$(echo "$errs" | sed 's/.*length_error=\([^ ]*\).*/\1/')
        ve=$(echo "$errs" | sed 's/.*velocity=\([^ ]*\).*/\1/')
        prec=$("$g" --version 2>/dev/null | sed -n 's/^Precision: *//p')
        echo "| $n | $m | GROMACS SETTLE, $prec ($g; Constraints row alone $nsc) | $ns | $le | $ve (leap-frog half step, not projected) |"
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
