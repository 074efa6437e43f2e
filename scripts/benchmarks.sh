#!/usr/bin/env bash
# Every table of BENCHMARKS.md, re-run at one commit on this machine, one
# command after the other (never two at once: each timing assumes the cores
# are its own). Each command's output goes to its own file in
#   bench-output/<commit>/<section>.txt
# headed by the commit, date, `lscpu` model and the load average before it
# started, so that a table copied into BENCHMARKS.md carries its provenance.
#
#   scripts/benchmarks.sh                 # every section (about an hour on 2 cores)
#   scripts/benchmarks.sh 7 8             # only sections 7 and 8
#   scripts/benchmarks.sh --list          # the sections and their commands
#
# Sections needing what a fresh machine lacks are skipped with a note, not
# failed: 6 (Open MPI and libclang: `.ci/run` shows how to install them),
# 8's LAMMPS rows (Debian's `lammps` and `python3-numpy`), 9.1, 9.2 and
# 11's ASE row (the venv of `shake-py/test.sh`, with mici and ASE).
set -uo pipefail
cd "$(dirname "$0")/.."

commit=$(git rev-parse --short HEAD)
dirty=""
git diff --quiet HEAD || dirty="+dirty"
out="bench-output/$commit$dirty"
py="$PWD/target/shake-py-venv/bin/python"

# section | what it needs | command
sections=(
  "1|cargo|cargo bench -p geoshake-bench --bench step_cost"
  "2|cargo|cargo bench -p geoshake-bench --bench work_precision"
  "3|cargo|cargo bench -p geoshake-bench --bench scaling"
  "3.1|cargo|cargo test -p geoshake-macros --release -- --ignored --nocapture expansion_of_chains"
  "4.1|cargo|cargo test --release --test suite perf_derivatives:: -- --nocapture"
  "6|mpi|scripts/ensemble_mpi_throughput.sh"
  "7|cargo|cargo run --release --example overhead"
  "7.1|cargo|cargo run --release --example reverse_check_cost"
  "8|cargo|cargo run --release --example scale"
  "8-lammps|lammps|bench/lammps/compare.sh"
  "9|cargo|cargo run --release --example tape_cost"
  "9.1|venv|$py shake-py/bench/mici_compare.py"
  "9.2|venv|$py examples/sampler.py"
  "10|cargo|cargo test -p geoshake-macros --release -- --ignored --nocapture hostile_timings"
  "11|cargo|cargo run --release --example water_md -- --steps 2000 --equilibrate 500 --thermostat none"
  "11-gbaoab|cargo|cargo run --release --example water_md -- --steps 2000 --equilibrate 500 --thermostat gbaoab"
  "11-ase|venv|$py examples/ase_water.py --side 4"
)

if [ "${1:-}" = "--list" ]; then
  for s in "${sections[@]}"; do IFS='|' read -r name _ cmd <<<"$s"; printf '%-10s %s\n' "$name" "$cmd"; done
  exit 0
fi

# Whether what a section needs is here; prints why not.
available() {
  case $1 in
    cargo) return 0 ;;
    mpi) command -v mpirun >/dev/null && return 0; echo "no mpirun (Open MPI)" ;;
    lammps) command -v lmp >/dev/null && python3 -c "import numpy" 2>/dev/null && return 0
      echo "no lmp or no NumPy (apt-get install lammps python3-numpy)" ;;
    venv) [ -x "$py" ] && "$py" -c "import geoshake, mici, ase" 2>/dev/null && return 0
      echo "no venv with geoshake, mici and ase (bash shake-py/test.sh; $py -m pip install mici ase)" ;;
  esac
  return 1
}

mkdir -p "$out"
machine="$(lscpu | sed -n 's/^Model name: *//p'), $(nproc) cores"
status=0
for s in "${sections[@]}"; do
  IFS='|' read -r name need cmd <<<"$s"
  if [ $# -gt 0 ]; then
    wanted=0
    for w in "$@"; do [ "$name" = "$w" ] || [ "${name%%-*}" = "$w" ] && wanted=1; done
    [ $wanted = 1 ] || continue
  fi
  file="$out/$name.txt"
  if ! why=$(available "$need"); then
    echo "skip $name: $why" | tee "$file"
    continue
  fi
  {
    echo "# $cmd"
    echo "# commit $commit$dirty, $(date -u '+%Y-%m-%d %H:%M UTC'), $machine, load $(cut -d' ' -f1-3 /proc/loadavg)"
  } >"$file"
  echo "== $name: $cmd"
  start=$SECONDS
  if ! bash -c "$cmd" >>"$file" 2>&1; then
    echo "   FAILED (see $file)"
    status=1
  fi
  echo "# took $((SECONDS - start)) s, load after $(cut -d' ' -f1-3 /proc/loadavg)" >>"$file"
  echo "   $((SECONDS - start)) s -> $file"
done
exit $status
