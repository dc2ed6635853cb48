#!/usr/bin/env bash
# Compares dofray's Rust packet loop (examples/packet_loop.rs, through the safe Embree wrapper)
# with the same loop in C++ straight against Embree (benches/cpp/packet_loop.cpp).
# Both trace the paper scene's 307200 coherent thin-lens rays single-threaded, with
# rtcIntersect16 and with 16 x rtcIntersect1; they must print identical checksums.
#
# Usage: benches/cpp/run.sh [ROUNDS] [REPS]
#   ROUNDS  alternating runs of each program (default 5); REPS timed passes per mode and run (default 15).
# Honours EMBREE_DIR (an install prefix with include/ and lib/) as build.rs does, and
# CARGO_TARGET_DIR (relative to the repository root, as cargo takes it when run from there).
# Nothing is downloaded; the C++ is built with g++ into the target directory.
# Both sides are compiled for x86-64-v3 (AVX2 + FMA): .cargo/config.toml sets target-cpu for
# Rust, -march=$CXX_MARCH (default x86-64-v3) for C++; override both together.
set -euo pipefail

cd "$(dirname "$0")/../.."
ROUNDS=${1:-5}
REPS=${2:-15}
TARGET_DIR=${CARGO_TARGET_DIR:-target}
CXX_MARCH=${CXX_MARCH:-x86-64-v3}
OUT=$TARGET_DIR/packet_loop_cpp
RUST=$TARGET_DIR/release/examples/packet_loop
mkdir -p "$TARGET_DIR"

# Same search order as build.rs: EMBREE_DIR, then system Embree 4, then Embree 3.
cxxflags=()
ldflags=()
major=
if [[ -n "${EMBREE_DIR:-}" ]]; then
    for m in 4 3; do
        if [[ -f "$EMBREE_DIR/include/embree$m/rtcore.h" ]]; then major=$m; break; fi
    done
    [[ -n "$major" ]] || { echo "run.sh: no embree3/4 headers under EMBREE_DIR=$EMBREE_DIR/include" >&2; exit 1; }
    libdir="$EMBREE_DIR/lib"
    [[ -d "$libdir" ]] || libdir="$EMBREE_DIR/lib64"
    cxxflags+=(-I"$EMBREE_DIR/include")
    ldflags+=(-L"$libdir" -Wl,-rpath,"$libdir")
else
    for m in 4 3; do
        if echo "#include <embree$m/rtcore.h>" | g++ -x c++ -fsyntax-only - 2>/dev/null; then
            major=$m
            break
        fi
    done
    [[ -n "$major" ]] || {
        echo "run.sh: Embree headers not found; install libembree-dev or set EMBREE_DIR" >&2
        exit 1
    }
fi

echo "== building C++ baseline against Embree $major (-march=$CXX_MARCH) into $OUT"
# -march matches Rust's target-cpu, so neither side gets wider vectors than the other.
# -ffp-contract=off: no FMA contraction, so the C++ generates the same rays bit for bit as Rust.
g++ -std=c++17 -O3 -march="$CXX_MARCH" -ffp-contract=off -Wall -Wextra \
    -DEMBREE_MAJOR="$major" "${cxxflags[@]}" \
    benches/cpp/packet_loop.cpp -o "$OUT" "${ldflags[@]}" -lembree"$major"
echo "== building Rust example into $RUST"
cargo build --release --quiet --example packet_loop

log=$(mktemp)
trap 'rm -f "$log"' EXIT
echo "== $ROUNDS alternating rounds, $REPS timed passes each"
for ((i = 1; i <= ROUNDS; i++)); do
    "$OUT" "$REPS" | tee -a "$log"
    "$RUST" "$REPS" | tee -a "$log"
done

# field NAME LINE: the value of NAME=... in a result line.
field() { sed -n "s/.* $1=\([^ ]*\).*/\1/p" <<<"$2"; }
median() { sort -g | awk '{ v[NR] = $1 } END { if (NR % 2) print v[(NR + 1) / 2]; else print (v[NR / 2] + v[NR / 2 + 1]) / 2 }'; }

echo
echo "== summary (median over rounds of each run's median Mrays/s)"
status=0
for mode in intersect16 intersect1; do
    for lang in cpp rust; do
        lines=$(grep "lang=$lang .*mode=$mode " "$log")
        sums=$(while read -r l; do echo "$(field rays_hash "$l") $(field hits "$l") $(field sum_t "$l")"; done <<<"$lines" | sort -u)
        declare "sum_${lang}=$sums"
        declare "med_${lang}=$(while read -r l; do field median_mrays "$l"; done <<<"$lines" | median)"
    done
    ratio=$(awk -v r="$med_rust" -v c="$med_cpp" 'BEGIN { printf "%.3f", r / c }')
    declare "ratio_${mode}=$ratio"
    printf '%-12s C++ %8.3f Mrays/s   Rust %8.3f Mrays/s   Rust/C++ %s\n' "$mode" "$med_cpp" "$med_rust" "$ratio"
    if [[ "$sum_cpp" == "$sum_rust" && $(wc -l <<<"$sum_cpp") == 1 ]]; then
        echo "             checksum match: rays_hash hits sum_t = $sum_cpp"
    else
        echo "             CHECKSUM MISMATCH: C++ [$sum_cpp] vs Rust [$sum_rust]"
        status=1
    fi
done
# Each run interleaves the two modes pass by pass, so its own intersect16 / intersect1 ratio is
# the least noisy speed-up figure; report the median of those ratios.
for lang in cpp rust; do
    declare "speedup_${lang}=$(grep '^packet_loop' "$log" | grep "lang=$lang " |
        awk '{ for (i = 1; i <= NF; i++) { split($i, kv, "="); f[kv[1]] = kv[2] }
               if (f["mode"] == "intersect16") p = f["median_mrays"]; else print p / f["median_mrays"] }' | median)"
done

echo
echo "== result"
printf 'Rust / C++ throughput (1.000 = parity, below 1 = Rust slower):\n'
printf '    intersect16        %s\n' "$ratio_intersect16"
printf '    16 x intersect1    %s\n' "$ratio_intersect1"
printf 'intersect16 speed-up over 16 x intersect1 (median of per-run ratios):\n'
printf '    C++                %.2fx\n' "$speedup_cpp"
printf '    Rust               %.2fx\n' "$speedup_rust"
if ((status == 0)); then
    echo "checksums: C++ and Rust traced identical hits"
else
    echo "checksums: MISMATCH (see above); the timings compare different work"
fi
exit $status
