#!/usr/bin/env python3
"""A reference for the advisor's held-out advice accuracy: what the prompt's own numbers support.

Reads the sets of `concord learn dataset` (default results/learn) and reports, on the held-out
scenes, the accuracy of the logit's favourite (the P_n line's argmax) and of k-nearest-neighbour
votes over the numbers each prompt states (route, P_n, the ego's line, the most salient
conflict's times, the implicit intent's shares, right of way, the number of road users),
standardised, with the training scenes as neighbours, in all and per scenario. numpy only.

    .venv-train/bin/python deploy/llm/knn_reference.py [DATA_DIR]
"""

import collections
import json
import re
import sys
from pathlib import Path

import numpy as np

NAMES = ["accelerate", "decelerate", "keep_speed", "turn_left", "turn_right"]


def load(path: Path) -> list:
    return [json.loads(line) for line in path.open() if line.strip()]


SHORT = {"acc": "accelerate", "dec": "decelerate", "keep": "keep_speed", "left": "turn_left",
         "right": "turn_right"}


def p_n(scene: dict) -> dict:
    """P_n in %, from the short OPM form the fine-tuned prompts use (`P acc 1 dec 98 ...`)."""
    line = re.search(r"^P (.*)$", scene["messages"][1]["content"], re.M).group(1)
    return {SHORT[k]: float(v) for k, v in re.findall(r"(\w+) (\d+)", line)}


def features(scene: dict) -> list:
    text = scene["messages"][1]["content"]
    p = p_n(scene)
    f = [1.0 if text.startswith("ego left") else 0.0] + [p.get(n, 0.0) for n in NAMES]
    ego = [float(v) for v in re.findall(r"-?\d+\.?\d*", text.split("\n")[0])]
    f += (ego + [0.0] * 4)[:4]
    m = re.search(r" at (-?\d+\.?\d*) ego (-?\d+\.?\d*)", text)
    f += ([float(v) for v in m.groups()] + [abs(float(m[1]) - float(m[2]))] if m
          else [99.0, 99.0, 99.0])
    m = re.search(r"yield (\d+) go (\d+)", text)
    f += [float(v) for v in m.groups()] if m else [0.0, 0.0]
    f += [1.0 if " row ego" in text else 0.0,
          1.0 if " row other" in text else 0.0, float(text.count("\nV"))]
    return f


def main() -> int:
    data = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("results/learn")
    train = load(data / "advice_train.jsonl")
    test = load(data / "advice_heldout.jsonl")
    logit = sum(max(p_n(s), key=p_n(s).get) == s["label"] for s in test) / len(test)
    print(f"held-out scenes: {len(test)}; logit favourite: {100 * logit:.1f} %")
    x = np.array([features(s) for s in train])
    z = np.array([features(s) for s in test])
    mu, sd = x.mean(0), x.std(0) + 1e-9
    x, z = (x - mu) / sd, (z - mu) / sd
    labels = [s["label"] for s in train]
    for k in (1, 5, 15):
        by_scenario = collections.defaultdict(lambda: [0, 0])
        for row, s in zip(z, test):
            nearest = np.argsort(((x - row) ** 2).sum(1))[:k]
            vote = collections.Counter(labels[i] for i in nearest).most_common(1)[0][0]
            by_scenario[s.get("scenario", "?")][0] += vote == s["label"]
            by_scenario[s.get("scenario", "?")][1] += 1
        ok, n = (sum(v) for v in zip(*by_scenario.values()))
        parts = ", ".join(f"{name} {100 * c / m:.0f} % of {m}"
                          for name, (c, m) in sorted(by_scenario.items()))
        print(f"{k}-nearest neighbours: {100 * ok / n:.1f} % ({parts})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
