#!/usr/bin/env bash
# Runs every fuzz target (or those named) for SECONDS each, from the seed corpora
# (tests/fuzz/seeds.py) plus what earlier runs kept (tests/fuzz/corpus/, not in git).
# Prints one line per target: executions, corpus size, and what was found; exits non-zero
# on a crash, a leak, a timeout or an out-of-memory (the input is left under
# tests/fuzz/artifacts/TARGET/; turn it into a regression: fix it, and keep the input
# under tests/fuzz/regressions/TARGET/, which every run replays).
#
#   bash tests/fuzz/run.sh SECONDS [TARGET...]
#
# With FUZZ_RUNS=N in the environment a target also stops after N executions (the
# README's long campaign: FUZZ_RUNS=10000000 and a generous SECONDS).
#
# Installs cargo-fuzz if missing. On a stable toolchain the sanitizer flags need
# RUSTC_BOOTSTRAP=1 (set here unless a nightly is the default).
set -euo pipefail
cd "$(dirname "$0")/../.."
SECONDS_EACH="${1:?usage: run.sh SECONDS [TARGET...]}"
shift
ALL=(ply prepared mesh text_clouds markups volume pcd plus_sequence wire controller register)
TARGETS=("${@:-${ALL[@]}}")
[ "$#" -gt 0 ] && TARGETS=("$@") || TARGETS=("${ALL[@]}")

command -v cargo-fuzz >/dev/null || cargo install cargo-fuzz --version 0.13.1 --locked
rustc --version | grep -q nightly || export RUSTC_BOOTSTRAP=1

# Files the seeds are made from, written by the CLI.
GEN=target/fuzz-gen
if [ ! -f "$GEN/prepared.ply" ]; then
    cargo build --release -q -p ribreg-sim
    RIBREG=target/release/ribreg
    "$RIBREG" phantom -q --out-dir "$GEN/phantom"
    "$RIBREG" phantom sweep -q --line-spacing-mm 30 --out-dir "$GEN/sweep"
    "$RIBREG" template -q --cloud "$GEN/phantom/template.ply" --out "$GEN/template.ply" \
        --prepared "$GEN/prepared.ply"
fi
rm -rf target/fuzz-seeds
python3 tests/fuzz/seeds.py "$GEN" target/fuzz-seeds

cd tests/fuzz
cargo fuzz build -O
status=0
printf '%-14s %12s %8s %s\n' target executions corpus result
for t in "${TARGETS[@]}"; do
    mkdir -p "corpus/$t" "artifacts/$t"
    log="artifacts/$t/last-run.log"
    # Inputs that once failed (regressions/TARGET/, in git) run first, every time.
    regressions=()
    [ -d "regressions/$t" ] && regressions=("regressions/$t")
    if cargo fuzz run -O "$t" "corpus/$t" "../../target/fuzz-seeds/$t" "${regressions[@]}" -- \
        -max_total_time="$SECONDS_EACH" -max_len=65536 -rss_limit_mb=2048 -timeout=30 \
        -print_final_stats=1 -detect_leaks=1 ${FUZZ_RUNS:+-runs="$FUZZ_RUNS"} >"$log" 2>&1; then
        result="no crash, leak or timeout"
    else
        result="FOUND: $(grep -m1 -E 'ERROR|panicked|Test unit written' "$log" || tail -n 1 "$log")"
        status=1
    fi
    execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -n 1)
    printf '%-14s %12s %8s %s\n' "$t" "${execs:-?}" "$(ls "corpus/$t" | wc -l)" "$result"
done
exit "$status"
