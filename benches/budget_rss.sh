#!/usr/bin/env bash
# Peak RSS against --memory-budget (issue 38): one `reconstruct` per scene, budget,
# thread count and run under /usr/bin/time -v, printed as a table (peak / budget; "OVER"
# when the peak exceeds the budget, "refused" when the run refused the budget before any
# work, as it must when the budget cannot be held). Not a test: the lead runs the full
# matrix (4M scenes, 5 runs) on a quiet machine.
#
#   benches/budget_rss.sh [-r RADIUS] [-n RUNS] [-t "1 2"] \
#       [-b "256MiB 384MiB 512MiB 1GiB 2GiB"] SCENE...
#
# Defaults: -r 0.012 (the 4M scenes are frame 25 tiled by examples/tile_scene, as
# benches/peers.py builds them), 5 runs, 1 and 2 threads, the budgets above. Uses
# target/release/meniscus (MENISCUS to override); outputs go to a temporary directory
# that is removed.
set -euo pipefail
cd "$(dirname "$0")/.."
radius=0.012
runs=5
threads="1 2"
budgets="256MiB 384MiB 512MiB 1GiB 2GiB"
while getopts "r:n:t:b:" opt; do
  case $opt in
    r) radius=$OPTARG ;;
    n) runs=$OPTARG ;;
    t) threads=$OPTARG ;;
    b) budgets=$OPTARG ;;
    *) sed -n '2,14p' "$0"; exit 2 ;;
  esac
done
shift $((OPTIND - 1))
[ $# -gt 0 ] || { sed -n '2,14p' "$0"; exit 2; }
bin=${MENISCUS:-target/release/meniscus}
[ -x "$bin" ] || { echo "build first: cargo build --release" >&2; exit 2; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# MiB of a budget written as NMiB or NGiB.
mib() {
  case $1 in
    *GiB) echo $(( ${1%GiB} * 1024 )) ;;
    *MiB) echo "${1%MiB}" ;;
    *) echo "budgets are written NMiB or NGiB: $1" >&2; exit 2 ;;
  esac
}

echo "# $(uptime)"
printf "%-16s %8s %7s %4s %9s %7s %s\n" scene budget threads run "peak MiB" "ratio" status
for scene in "$@"; do
  for budget in $budgets; do
    limit=$(mib "$budget")
    for t in $threads; do
      for run in $(seq 1 "$runs"); do
        set +e
        /usr/bin/time -v "$bin" reconstruct "$scene" -r "$radius" -o "$work/out.ply" \
          --memory-budget "$budget" --threads "$t" -q 2>"$work/err"
        code=$?
        set -e
        kib=$(sed -n 's/.*Maximum resident set size (kbytes): //p' "$work/err")
        peak=$(( kib / 1024 ))
        ratio=$(awk -v p="$kib" -v b="$limit" 'BEGIN { printf "%.3f", p / 1024 / b }')
        if [ "$code" -ne 0 ]; then
          status="refused: $(grep -m1 '^error' "$work/err" | cut -c1-90)"
        elif [ "$kib" -gt $(( limit * 1024 )) ]; then
          status=OVER
        else
          status=ok
        fi
        printf "%-16s %8s %7s %4s %9s %7s %s\n" "$(basename "$scene")" "$budget" "$t" "$run" \
          "$peak" "$ratio" "$status"
      done
    done
  done
done
