#!/usr/bin/env bash
# make bench-mpi: strong scaling of radpt under Open MPI on this machine,
# K = 1 and 2 ranks with one thread each (issue 14, point 5).
#   1. the Cornell reference render (path tracing, REF_SPP samples/pixel);
#   2. uniform Gauss-Seidel with ELEMENTS elements (form factors + sweeps).
# Prints wall time, speedup and per-rank memory, and checks that the
# answers are the same (pixels bit-identical; radiosity to 1e-6).
set -euo pipefail
cd "$(dirname "$0")/.."
RADPT=${RADPT:-./radpt}
REF_SPP=${REF_SPP:-1024}
ELEMENTS=${ELEMENTS:-20000}
OUT=${OUT:-out/bench-mpi}
mkdir -p "$OUT"
MPIRUN=(mpirun -q --oversubscribe --bind-to none)
[ "$(id -u)" -eq 0 ] && MPIRUN+=(--allow-run-as-root)

now() { date +%s.%N; }
# run LABEL K ARGS...: K = 0 means a plain process
run() {
    local label=$1 k=$2; shift 2
    local t0 t1
    t0=$(now)
    if [ "$k" -eq 0 ]; then "$RADPT" "$@" > "$OUT/$label.out" 2> "$OUT/$label.err"
    else "${MPIRUN[@]}" -np "$k" "$RADPT" "$@" > "$OUT/$label.out" 2> "$OUT/$label.err"; fi
    t1=$(now)
    echo "$t0 $t1" | awk '{printf "%.3f", $2 - $1}' > "$OUT/$label.time"
}
secs() { cat "$OUT/$1.time"; }
ratio() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.2f", a / b }'; }
field() { # the number before WHAT in the "wrote" line of LABEL
    grep -o "[0-9.]* MiB $2" "$OUT/$1.out" | head -1 | cut -d' ' -f1
}

echo "== path tracing: scenes/cornell.scene, $REF_SPP spp, 1 thread per rank"
run pt1 0 render scenes/cornell.scene --method pathtrace --spp "$REF_SPP" --threads 1 -o "$OUT/pt1.exr"
run pt2 2 render scenes/cornell.scene --method pathtrace --spp "$REF_SPP" --threads 1 -o "$OUT/pt2.exr"
"$RADPT" compare "$OUT/pt1.exr" "$OUT/pt2.exr" --json > "$OUT/pt-compare.json"
same=$(grep -o '"max_abs_diff": [0-9.e+-]*' "$OUT/pt-compare.json" | awk '{print ($2 == 0) ? "bit-identical" : "DIFFERENT (max " $2 ")"}')
printf "  K=1 %8.3f s\n  K=2 %8.3f s   speedup %sx (target >= 1.8)   pixels %s\n" \
    "$(secs pt1)" "$(secs pt2)" "$(ratio "$(secs pt1)" "$(secs pt2)")" "$same"
grep -o "per rank at most[^)]*" "$OUT/pt2.out" | sed 's/^/  K=2 /' || true

echo "== uniform Gauss-Seidel: scenes/cornell.scene, $ELEMENTS elements, 1 thread per rank"
run gs1 0 probe scenes/cornell.scene --method gauss-seidel --elements "$ELEMENTS" --matrix dense --threads 1 --surface-averages --json
run gs2 2 probe scenes/cornell.scene --method gauss-seidel --elements "$ELEMENTS" --matrix dense --threads 1 --surface-averages --json
printf "  K=1 %8.3f s\n  K=2 %8.3f s   speedup %sx (target >= 1.6)\n" \
    "$(secs gs1)" "$(secs gs2)" "$(ratio "$(secs gs1)" "$(secs gs2)")"
m1=$(grep -o '"memory_bytes": [0-9.e+]*' "$OUT/gs1.out" | awk '{print $2 / 1048576}')
m2=$(grep -o '"memory_bytes": [0-9.e+]*' "$OUT/gs2.out" | awk '{print $2 / 1048576}')
printf "  memory held by the method: K=1 %.1f MiB, K=2 rank 0 %.1f MiB: ratio %s (target <= 0.6)\n" \
    "$m1" "$m2" "$(ratio "$m2" "$m1")"
# surface averages: largest relative difference
paste <(grep -o '"radiance": \[[^]]*\]' "$OUT/gs1.out" | tr -d '"radiance:[]' | tr ',' ' ') \
      <(grep -o '"radiance": \[[^]]*\]' "$OUT/gs2.out" | tr -d '"radiance:[]' | tr ',' ' ') |
    awk '{ n = NF / 2; for (i = 1; i <= n; i++) { a = $i; b = $(i + n); d = a - b; if (d < 0) d = -d;
           s = a < 0 ? -a : a; if (s > 0 && d / s > m) m = d / s } }
         END { printf "  surface averages: largest relative difference %.3g (target <= 1e-6)\n", m }'
echo "outputs in $OUT"
