"""The fine-tuning recipe end to end on a tiny set: `concord learn dataset`, a few training steps
(the loss must fall; a second run with the same seed must give the same losses), export to GGUF,
then llama.cpp's server loads the adapter and answers an advice request within the schema.

Run with the training virtualenv (`deploy/llm/llm.sh setup-train`), `CONCORD_BIN` set to the
`concord` binary, and `deploy/llm/llm.sh setup` done (the model and the server come from .venv):

    CONCORD_BIN=target/debug/concord .venv-train/bin/python -m unittest deploy/llm/test_finetune.py
"""

import json
import os
import socket
import subprocess
import sys
import tempfile
import time
import unittest
import urllib.request
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
FINETUNE = HERE / "finetune.py"
SERVE_PY = ROOT / ".venv" / "bin" / "python"
MANEUVERS = ["accelerate", "decelerate", "keep_speed", "turn_left", "turn_right"]


def run(*cmd, **kw):
    r = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, **kw)
    if r.returncode != 0:
        raise AssertionError(f"{cmd} failed ({r.returncode}):\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}")
    return r


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def http(url: str, body=None, timeout=60.0):
    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(url, data=data, headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(req, timeout=timeout) as r:
        return json.loads(r.read().decode())


class TinyFineTune(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        binary = os.environ.get("CONCORD_BIN")
        if not binary or not Path(binary).exists():
            raise AssertionError("set CONCORD_BIN to the concord binary")
        cls.tmp = tempfile.TemporaryDirectory(prefix="concord-finetune-")
        cls.dir = Path(cls.tmp.name)
        cls.data = cls.dir / "data"
        run(binary, "learn", "dataset", "--out", cls.data, "--advice-train", "6",
            "--advice-heldout", "3", "--intents-train", "6", "--intents-heldout", "3", cwd=ROOT)

    @classmethod
    def tearDownClass(cls):
        cls.tmp.cleanup()

    def train(self, out: Path, steps: int) -> dict:
        # 8 examples in one batch, so every step sees the same examples.
        run(sys.executable, FINETUNE, "train", "--data", self.data, "--out", out, "--limit", "8",
            "--batch", "8", "--epochs", str(steps), "--lr", "3e-3", "--threads", "2",
            "--seed", "3", cwd=ROOT)
        return json.loads((out / "train.json").read_text())

    def test_intent_messages_are_given_intents_repeat_times(self):
        out = self.dir / "repeat"
        run(sys.executable, FINETUNE, "train", "--data", self.data, "--out", out,
            "--intents-repeat", "3", "--max-steps", "1", "--threads", "2", cwd=ROOT)
        report = json.loads((out / "train.json").read_text())
        lines = {n: len((self.data / n).read_text().splitlines())
                 for n in ("advice_train.jsonl", "intents_train.jsonl")}
        self.assertEqual(report["examples"],
                         lines["advice_train.jsonl"] + 3 * lines["intents_train.jsonl"], report)
        self.assertEqual(sum(f.endswith("intents_train.jsonl") for f in report["files"]), 3)

        bad = subprocess.run([sys.executable, str(FINETUNE), "train", "--data", str(self.data),
                              "--out", str(self.dir / "bad"), "--intents-repeat", "0"],
                             capture_output=True, text=True, cwd=ROOT)
        self.assertNotEqual(bad.returncode, 0)
        self.assertIn("--intents-repeat must be at least 1", bad.stderr)

    def test_loss_falls_the_run_repeats_and_the_server_answers_with_the_adapter(self):
        report = self.train(self.dir / "a", 6)
        losses = [s["loss"] for s in report["losses"]]
        self.assertEqual(len(losses), 6)
        self.assertLess(losses[-1], 0.7 * losses[0], losses)

        again = self.train(self.dir / "b", 2)
        self.assertEqual([s["loss"] for s in again["losses"]], losses[:2])

        gguf = self.dir / "adapter.gguf"
        run(sys.executable, FINETUNE, "export", "--adapter", self.dir / "a", "--out", gguf, cwd=ROOT)
        self.assertGreater(gguf.stat().st_size, 100_000)

        port = free_port()
        server = subprocess.Popen(
            [str(SERVE_PY), str(HERE / "serve.py"), "--port", str(port), "--threads", "1",
             "--adapter", str(gguf)],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        try:
            base = f"http://127.0.0.1:{port}"
            deadline = time.monotonic() + 60
            while True:
                try:
                    http(base + "/v1/models", timeout=2)
                    break
                except OSError:
                    if server.poll() is not None or time.monotonic() > deadline:
                        self.fail("server did not start: " + (server.stdout.read() or ""))
                    time.sleep(0.3)
            adapters = http(base + "/lora-adapters")
            self.assertEqual(len(adapters), 1, adapters)
            self.assertTrue(adapters[0]["path"].endswith("adapter.gguf"), adapters)

            example = json.loads((self.data / "advice_heldout.jsonl").read_text().splitlines()[0])
            schema = {"type": "object", "additionalProperties": False, "required": ["maneuver"],
                      "properties": {"maneuver": {"type": "string", "enum": MANEUVERS}}}
            reply = http(base + "/v1/chat/completions", {
                "messages": example["messages"], "temperature": 0, "max_tokens": 32,
                "response_format": {"type": "json_schema",
                                    "json_schema": {"name": "advice", "schema": schema}}})
            answer = json.loads(reply["choices"][0]["message"]["content"])
            self.assertIn(answer["maneuver"], MANEUVERS)
            self.assertEqual(set(answer), {"maneuver"})
        finally:
            server.terminate()
            try:
                server.wait(timeout=10)
            except subprocess.TimeoutExpired:
                server.kill()
                server.wait()


class Promotion(unittest.TestCase):
    def summary(self, path: Path, accuracy: float, ece: float, style=(0.80, 0.01)) -> Path:
        intents = [{"dimension": "style", "strong_correct": style[0], "strong_wrong": style[1]}]
        path.write_text(json.dumps({"fine-tuned": {"accuracy": accuracy, "ece": ece,
                                                   "intents": intents}}))
        return path

    def promote(self, new, old, target: Path):
        cand = target.parent / "cand.gguf"
        cand.write_bytes(b"GGUF candidate")
        return subprocess.run(
            [sys.executable, str(FINETUNE), "promote", "--adapter", str(cand), "--new", str(new),
             "--old", str(old), "--to", str(target)], capture_output=True, text=True)

    def test_a_candidate_replaces_the_adapter_only_without_losing_accuracy_calibration_or_intents(self):
        with tempfile.TemporaryDirectory() as d:
            d = Path(d)
            target = d / "shipped.gguf"
            target.write_bytes(b"GGUF shipped")
            old = self.summary(d / "old.json", 0.80, 0.04)
            worse = self.promote(self.summary(d / "n1.json", 0.79, 0.03), old, target)
            self.assertNotEqual(worse.returncode, 0)
            self.assertIn("accuracy", worse.stderr)
            self.assertEqual(target.read_bytes(), b"GGUF shipped")
            uncal = self.promote(self.summary(d / "n2.json", 0.85, 0.09), old, target)
            self.assertNotEqual(uncal.returncode, 0)
            self.assertIn("ECE", uncal.stderr)
            self.assertEqual(target.read_bytes(), b"GGUF shipped")
            deaf = self.promote(self.summary(d / "n4.json", 0.85, 0.03, (0.70, 0.01)), old, target)
            self.assertNotEqual(deaf.returncode, 0)
            self.assertIn("intent style strong and correct", deaf.stderr)
            rash = self.promote(self.summary(d / "n5.json", 0.85, 0.03, (0.80, 0.09)), old, target)
            self.assertNotEqual(rash.returncode, 0)
            self.assertIn("intent style strong and wrong", rash.stderr)
            self.assertEqual(target.read_bytes(), b"GGUF shipped")
            ok = self.promote(self.summary(d / "n3.json", 0.82, 0.05, (0.76, 0.03)), old, target)
            self.assertEqual(ok.returncode, 0, ok.stderr)
            self.assertEqual(target.read_bytes(), b"GGUF candidate")


if __name__ == "__main__":
    unittest.main()
